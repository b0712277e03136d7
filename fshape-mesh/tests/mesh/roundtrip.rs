//! Write → read round trips on random fshapes, exact, in every format; and
//! files checked by independent readers and writers (ply-rs-bw, vtkio,
//! tobj) to show other tools agree with ours.

use std::path::{Path, PathBuf};

use fshape_mesh::io::{Encoding, ReadOptions, read_mesh, write_mesh};
use fshape_mesh::test_support::strategies;
use fshape_mesh::{CellKind, FShape};
use proptest::prelude::*;
use proptest::test_runner::Config;

fn tmp(name: &str) -> PathBuf {
    // Under target/tmp (cargo's scratch space for integration tests), not
    // the system's temporary directory, which would keep every run's files.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("fshape-mesh-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn config() -> Config {
    fshape_mesh::test_support::strategies::config(24, 0x5eed_f5ba)
}

fn geometry_only(s: &FShape) -> FShape {
    s.clone().with_signal(None).unwrap()
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn every_format_round_trips_exactly(shape in strategies::any_small(), case in 0u32..1000) {
        for (ext, enc) in [
            ("ply", Encoding::Ascii), ("ply", Encoding::Binary), ("ply.gz", Encoding::Binary),
            ("vtk", Encoding::Ascii), ("vtk", Encoding::Binary), ("vtk.gz", Encoding::Ascii),
            ("obj", Encoding::Ascii), ("obj.gz", Encoding::Ascii),
        ] {
            let path = tmp(&format!("rt{case}.{ext}"));
            write_mesh(&path, &shape, enc).unwrap();
            let back = read_mesh(&path, &ReadOptions::default()).unwrap();
            // OBJ carries no signal; everything else is bitwise equal,
            // ASCII included ({:e} is Rust's shortest round-trip form).
            let expect = if ext.starts_with("obj") { geometry_only(&shape) } else { shape.clone() };
            prop_assert_eq!(&back, &expect, "{} {:?}", ext, enc);
            std::fs::remove_file(&path).unwrap();
        }
    }

    #[test]
    fn ply_rs_reads_our_ply(shape in strategies::any_small(), ascii in any::<bool>(), case in 0u32..1000) {
        let path = tmp(&format!("ind{case}.ply"));
        write_mesh(&path, &shape, if ascii { Encoding::Ascii } else { Encoding::Binary }).unwrap();
        let (pts, cells, signal) = read_with_ply_rs(&path);
        std::fs::remove_file(&path).unwrap();
        let ours = points_3d(&shape);
        prop_assert_eq!(pts, ours);
        prop_assert_eq!(cells, shape.cells().to_vec());
        prop_assert_eq!(signal.as_deref(), shape.signal());
    }

    #[test]
    fn vtkio_reads_our_vtk(shape in strategies::any_small(), ascii in any::<bool>(), case in 0u32..1000) {
        let path = tmp(&format!("ind{case}.vtk"));
        write_mesh(&path, &shape, if ascii { Encoding::Ascii } else { Encoding::Binary }).unwrap();
        let (pts, cells, signal) = read_with_vtkio(&path, shape.kind());
        std::fs::remove_file(&path).unwrap();
        let ours = points_3d(&shape);
        prop_assert_eq!(pts, ours);
        prop_assert_eq!(cells, shape.cells().to_vec());
        prop_assert_eq!(signal.as_deref(), shape.signal());
    }
}

/// The shape's points with z = 0 added in the plane, as both writers store them.
fn points_3d(shape: &FShape) -> Vec<f64> {
    let n = shape.dim();
    shape.points().chunks_exact(n).flat_map(|p| [p[0], p[1], if n == 3 { p[2] } else { 0.0 }]).collect()
}

/// Points (x, y, z), cell indices and `signal` as ply-rs-bw sees them.
fn read_with_ply_rs(path: &Path) -> (Vec<f64>, Vec<usize>, Option<Vec<f64>>) {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::{DefaultElement, Property};
    let file = std::fs::File::open(path).unwrap();
    let ply = Parser::<DefaultElement>::new().read_ply(&mut std::io::BufReader::new(file)).unwrap();
    let num = |p: &Property| match p {
        Property::Double(x) => *x,
        Property::Int(i) => *i as f64,
        other => panic!("unexpected property {other:?}"),
    };
    let verts = &ply.payload["vertex"];
    let pts = verts.iter().flat_map(|v| ["x", "y", "z"].map(|k| num(&v[k]))).collect();
    let signal = verts.first().and_then(|v| v.get("signal")).map(|_| verts.iter().map(|v| num(&v["signal"])).collect());
    let cells = if let Some(faces) = ply.payload.get("face") {
        faces
            .iter()
            .flat_map(|f| match &f["vertex_indices"] {
                Property::ListInt(l) => l.iter().map(|&i| i as usize).collect::<Vec<_>>(),
                other => panic!("unexpected face list {other:?}"),
            })
            .collect()
    } else {
        ply.payload.get("edge").map_or(vec![], |e| {
            e.iter().flat_map(|e| [num(&e["vertex1"]) as usize, num(&e["vertex2"]) as usize]).collect()
        })
    };
    (pts, cells, signal)
}

/// Points, cell indices and the `signal` array as vtkio sees them.
fn read_with_vtkio(path: &Path, kind: CellKind) -> (Vec<f64>, Vec<usize>, Option<Vec<f64>>) {
    use vtkio::model::{Attribute, DataSet, Piece};
    let vtk = vtkio::Vtk::import(path).unwrap();
    let DataSet::PolyData { pieces, .. } = vtk.data else { panic!("not polydata") };
    let Piece::Inline(piece) = pieces.into_iter().next().unwrap() else { panic!("not inline") };
    let pts = piece.points.cast_into::<f64>().unwrap();
    let topo = if kind == CellKind::Triangle { piece.polys } else { piece.lines };
    let (_, flat) = topo.map(|t| t.into_legacy()).unwrap_or((0, vec![]));
    let mut cells = Vec::new();
    let mut i = 0;
    while i < flat.len() {
        let k = flat[i] as usize;
        cells.extend(flat[i + 1..i + 1 + k].iter().map(|&v| v as usize));
        i += 1 + k;
    }
    let signal = piece.data.point.iter().find_map(|a| match a {
        Attribute::DataArray(d) if d.name == "signal" => d.data.cast_into::<f64>(),
        _ => None,
    });
    (pts, cells, signal)
}

#[test]
fn tobj_reads_our_obj() {
    let shape = fshape_mesh::test_support::perturbed_icosphere(2, 0.1, 3);
    let path = tmp("ind.obj");
    write_mesh(&path, &shape, Encoding::Ascii).unwrap();
    let (models, _) = tobj::load_obj(&path, &tobj::LoadOptions::default()).unwrap();
    std::fs::remove_file(&path).unwrap();
    let m = &models[0].mesh;
    for (k, &i) in m.indices.iter().enumerate() {
        assert_eq!(&m.positions[3 * i as usize..3 * i as usize + 3], shape.point(shape.cells()[k]));
    }
}

#[test]
fn we_read_files_written_by_ply_rs_big_endian_with_extra_properties() {
    use ply_rs_bw::ply::{
        Addable, DefaultElement, ElementDef, Encoding as PEnc, Ply, Property, PropertyDef, PropertyType, ScalarType,
    };
    use ply_rs_bw::writer::Writer;
    let shape = fshape_mesh::test_support::perturbed_icosphere(1, 0.1, 9);
    for enc in [PEnc::BinaryBigEndian, PEnc::BinaryLittleEndian, PEnc::Ascii] {
        let mut ply = Ply::<DefaultElement>::new();
        ply.header.encoding = enc;
        let mut vdef = ElementDef::new("vertex".to_string());
        for name in ["x", "y", "z", "confidence", "signal"] {
            vdef.properties.add(PropertyDef::new(name.to_string(), PropertyType::Scalar(ScalarType::Double)));
        }
        let mut fdef = ElementDef::new("face".to_string());
        fdef.properties
            .add(PropertyDef::new("vertex_index".to_string(), PropertyType::List(ScalarType::UChar, ScalarType::UInt)));
        ply.header.elements.add(vdef);
        ply.header.elements.add(fdef);
        let f = shape.signal().unwrap();
        let verts = (0..shape.n_vertices())
            .map(|v| {
                let mut e = DefaultElement::new();
                let p = shape.point(v);
                for (k, name) in ["x", "y", "z"].iter().enumerate() {
                    e.insert(name.to_string(), Property::Double(p[k]));
                }
                e.insert("confidence".to_string(), Property::Double(0.5));
                e.insert("signal".to_string(), Property::Double(f[v]));
                e
            })
            .collect();
        let faces = shape
            .cell_iter()
            .map(|c| {
                let mut e = DefaultElement::new();
                e.insert("vertex_index".to_string(), Property::ListUInt(c.iter().map(|&v| v as u32).collect()));
                e
            })
            .collect();
        ply.payload.insert("vertex".to_string(), verts);
        ply.payload.insert("face".to_string(), faces);
        let mut buf = Vec::new();
        Writer::new().write_ply(&mut buf, &mut ply).unwrap();
        let path = tmp("plyrs.ply");
        std::fs::write(&path, &buf).unwrap();
        let back = read_mesh(&path, &ReadOptions::default()).unwrap();
        assert_eq!(back, shape, "{enc:?}");
    }
}

/// vtkio writes VTK 5.1's OFFSETS/CONNECTIVITY layout only for unstructured
/// grids (its POLYDATA keeps the legacy layout under a 5.1 header, which VTK
/// 9 itself rejects), so it is our oracle for version 4.2; the 5.1 layout is
/// checked on a hand-written file below.
#[test]
fn we_read_files_written_by_vtkio_legacy_4() {
    use vtkio::model::{Attributes, ByteOrder, DataSet, PolyDataPiece, Version, VertexNumbers, Vtk};
    let shape = fshape_mesh::test_support::perturbed_icosphere(1, 0.1, 4).with_signal(None).unwrap();
    let pts = shape.points().to_vec();
    let legacy: Vec<u32> =
        shape.cell_iter().flat_map(|c| std::iter::once(3).chain(c.iter().map(|&v| v as u32))).collect();
    for (version, polys) in [
        (
            Version::new_legacy(4, 2),
            VertexNumbers::Legacy { num_cells: shape.n_cells() as u32, vertices: legacy.clone() },
        ),
        (
            Version::new_legacy(3, 0),
            VertexNumbers::Legacy { num_cells: shape.n_cells() as u32, vertices: legacy.clone() },
        ),
    ] {
        for binary in [false, true] {
            let vtk = Vtk {
                version,
                title: "written by vtkio".into(),
                byte_order: ByteOrder::BigEndian,
                file_path: None,
                data: DataSet::inline(PolyDataPiece {
                    points: pts.clone().into(),
                    polys: Some(polys.clone()),
                    data: Attributes::new(),
                    ..Default::default()
                }),
            };
            let path = tmp("vtkio.vtk");
            if binary {
                vtk.export_be(&path).unwrap()
            } else {
                vtk.export_ascii(&path).unwrap()
            }
            let back = read_mesh(&path, &ReadOptions::default())
                .unwrap_or_else(|e| panic!("{version:?} binary={binary}: {e}"));
            assert_eq!(back, shape, "{version:?} binary={binary}");
        }
    }
}

#[test]
fn we_read_the_vtk_5_1_offsets_layout() {
    // Two triangles and a point array in the layout VTK 9 writes: n+1
    // offsets starting at 0, then the connectivity.
    let text = "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n\
        0 0 0 1 0 0 0 1 0\n1 1 0\n\nPOLYGONS 3 6\nOFFSETS vtktypeint64\n0 3 6\nCONNECTIVITY vtktypeint64\n\
        0 1 2 2 1 3\n\nPOINT_DATA 4\nFIELD FieldData 1\nsignal 1 4 double\n0.5 1.5 2.5 3.5\nMETADATA\nINFORMATION 0\n\n";
    let path = tmp("v51.vtk");
    std::fs::write(&path, text).unwrap();
    let s = read_mesh(&path, &ReadOptions::default()).unwrap();
    assert_eq!(s.cells(), &[0, 1, 2, 2, 1, 3]);
    assert_eq!(s.points()[9..12], [1.0, 1.0, 0.0]);
    assert_eq!(s.signal().unwrap(), &[0.5, 1.5, 2.5, 3.5]);
}

#[test]
fn exr_images_round_trip_and_become_grids() {
    use fshape_mesh::io::image::{Image, read_image, write_exr};
    // f32-representable values: the EXR channel is 32-bit float.
    let im = Image { width: 5, height: 3, values: (0..15).map(|k| (k as f64) * 0.25 - 1.0).collect() };
    let path = tmp("im.exr");
    write_exr(&path, &im).unwrap();
    let back = read_image(&path, None).unwrap();
    assert_eq!(back, im);
    assert_eq!(read_image(&path, Some("Y")).unwrap(), im);
    let err = read_image(&path, Some("R")).unwrap_err().to_string();
    assert!(err.contains("`R`") && err.contains("available: Y"), "{err}");
    let grid = fshape_mesh::generate::image_grid(&back).unwrap();
    assert_eq!(grid.n_vertices(), 15);
    assert_eq!(grid.signal().unwrap(), im.values.as_slice());
    // A NaN pixel is refused with its vertex (= pixel) index.
    let mut bad = im.clone();
    bad.values[7] = f64::NAN;
    let e = fshape_mesh::generate::image_grid(&bad).unwrap_err().to_string();
    assert!(e.contains("vertex 7"), "{e}");
}

#[test]
fn signal_csv_round_trips_exactly() {
    use fshape_mesh::io::csv::{read_signal, write_signal};
    let values = vec![0.1, -2.5e-300, 1.0 / 3.0, f64::NAN, 7.0];
    for name in ["s.csv", "s.csv.gz"] {
        let path = tmp(name);
        write_signal(&path, "thickness", &values).unwrap();
        let col = read_signal(&path, true).unwrap();
        assert_eq!(col.name, "thickness");
        assert_eq!(col.values.len(), 5);
        assert!(col.values.iter().zip(&values).all(|(a, b)| a == b || (a.is_nan() && b.is_nan())));
        assert!(read_signal(&path, false).is_err(), "NaN refused when missing values are not accepted");
    }
}

#[test]
fn vtkio_reads_our_point_fields_and_our_csv_reader_reads_our_vector_csv() {
    use vtkio::model::{Attribute, DataSet, ElementType, Piece};
    for shape in [fshape_mesh::test_support::perturbed_icosphere(1, 0.1, 4), fshape_mesh::generate::circle(12, 1.5)] {
        let (n, dim) = (shape.n_vertices(), shape.dim());
        let p0: Vec<f64> = (0..n * dim).map(|i| (i as f64 * 0.37).sin() * 1e-3).collect();
        let pf: Vec<f64> = (0..n).map(|i| (i as f64 * 0.11).cos()).collect();
        let path = tmp(&format!("fields{dim}.vtk"));
        let mut bytes = Vec::new();
        fshape_mesh::io::vtk::write_point_fields(&mut bytes, &shape, "momenta", &[("p0", &p0)], &[("pf", &pf)])
            .unwrap();
        fshape_mesh::io::write_atomic(&path, &bytes, false).unwrap();
        let (pts, cells, _) = read_with_vtkio(&path, shape.kind());
        assert_eq!((pts, cells), (points_3d(&shape), shape.cells().to_vec()));
        let vtk = vtkio::Vtk::import(&path).unwrap();
        let DataSet::PolyData { pieces, .. } = vtk.data else { panic!("not polydata") };
        let Piece::Inline(piece) = pieces.into_iter().next().unwrap() else { panic!("not inline") };
        let field = |name: &str| {
            piece.data.point.iter().find_map(|a| match a {
                Attribute::DataArray(d) if d.name == name => Some((d.elem.clone(), d.data.clone().cast_into::<f64>()?)),
                _ => None,
            })
        };
        let (elem, vectors) = field("p0").expect("p0");
        assert_eq!(elem, ElementType::Vectors);
        let ours: Vec<f64> =
            p0.chunks_exact(dim).flat_map(|r| [r[0], r[1], if dim == 3 { r[2] } else { 0.0 }]).collect();
        assert_eq!(vectors, ours);
        assert_eq!(field("pf").expect("pf").1, pf);
        std::fs::remove_file(&path).unwrap();
        // Wrong lengths and names are refused, not written.
        let mut sink = Vec::new();
        let err = fshape_mesh::io::vtk::write_point_fields(&mut sink, &shape, "t", &[("p0", &p0[1..])], &[]);
        assert!(err.unwrap_err().to_string().contains("p0"));
        let err = fshape_mesh::io::vtk::write_point_fields(&mut sink, &shape, "t", &[], &[("p f", &pf)]);
        assert!(err.unwrap_err().to_string().contains("one word"));
        // The momentum CSV reads back bit for bit.
        let csv = tmp(&format!("p0_{dim}.csv"));
        let names = if dim == 3 { vec!["p_x", "p_y", "p_z"] } else { vec!["p_x", "p_y"] };
        fshape_mesh::io::csv::write_vectors(&csv, &names, &p0).unwrap();
        assert_eq!(fshape_mesh::io::csv::read_vectors(&csv, dim).unwrap(), p0);
        std::fs::remove_file(&csv).unwrap();
    }
    let pvd = fshape_mesh::io::vtk::collection(&[(0.0, "state_000.vtk"), (0.5, "a&b.vtk")]);
    assert!(pvd.contains("timestep=\"0.5\" part=\"0\" file=\"a&amp;b.vtk\""), "{pvd}");
    // Read back as written, whatever the names hold.
    let names = ["state_000.vtk", "a&b \"<c>\"\tline\nend.vtk"];
    let pvd = fshape_mesh::io::vtk::collection(&[(0.0, names[0]), (0.25, names[1])]);
    let back = fshape_mesh::io::vtk::parse_collection(&pvd).unwrap();
    assert_eq!(back, [(0.0, names[0].to_string()), (0.25, names[1].to_string())]);
    for (text, says) in [
        ("<VTKFile><Collection></Collection></VTKFile>", "the collection holds no state"),
        ("<Collection><DataSet timestep=\"x\" file=\"a.vtk\"/></Collection>", "a number timestep"),
        ("<Collection><DataSet file=\"a.vtk\"/></Collection>", "a DataSet's timestep and file"),
        ("<Collection><DataSet timestep=\"0\" file=\"a.vtk\"></Colection>", "a well-formed .pvd"),
    ] {
        let e = fshape_mesh::io::vtk::parse_collection(text).unwrap_err().to_string();
        assert!(e.contains(says), "{text}: {e}");
    }
}

#[test]
fn a_masked_shape_round_trips_through_ply_vtk_and_gifti_with_its_mask() {
    use fshape_mesh::io::{Encoding, Format, ReadOptions, parse_mesh, write_to};
    let s = fshape_mesh::generate::icosphere(1, 1.0);
    let n = s.n_vertices();
    let m: Vec<f64> = (0..n).map(|v| [0.0, 0.5, 1.0][v % 3]).collect();
    let f: Vec<f64> = (0..n).map(|v| v as f64).collect();
    let s = s.with_signal_and_mask(Some(f), Some(m)).unwrap();
    let bits = |v: &[f64]| v.iter().map(|x| (x.is_nan(), if x.is_nan() { 0 } else { x.to_bits() })).collect::<Vec<_>>();
    for (format, name) in [(Format::Ply, "m.ply"), (Format::Vtk, "m.vtk"), (Format::Gifti, "m.surf.gii")] {
        for enc in [Encoding::Ascii, Encoding::Binary] {
            let mut bytes = Vec::new();
            write_to(&mut bytes, &s, format, enc).unwrap();
            let back = parse_mesh(&bytes, format, &ReadOptions::default(), Path::new(name)).unwrap();
            // (GIfTI stores float32: the mask's 0, 0.5, 1 and these signal
            // values are exact there, the coordinates are not.)
            if format != Format::Gifti {
                assert_eq!(back, s, "{name}, {enc:?}");
            }
            assert_eq!(back.mask(), s.mask(), "{name}, {enc:?}");
            assert_eq!(bits(back.signal().unwrap()), bits(s.signal().unwrap()), "{name}, {enc:?}");
        }
    }
}

#[test]
fn one_map_of_a_table_or_of_a_gifti_file_of_several_is_read_by_name_or_number() {
    use fshape_mesh::io::gifti::{DataArray, WriteOptions, signal_array, write_arrays};
    use fshape_mesh::io::read_signal_for;
    let table = tmp("maps.csv");
    std::fs::write(&table, "thickness, myelin\n2.5,1.5\n3,nan\n2.75,1.25\n").unwrap();
    let at = |p: &Path, sel: &str| PathBuf::from(format!("{}:{sel}", p.display()));
    for sel in ["myelin", "2"] {
        let c = read_signal_for(&at(&table, sel), Some(3), true).unwrap();
        assert_eq!((c.name.as_str(), c.values[0], c.values[2]), ("myelin", 1.5, 1.25));
        assert!(c.values[1].is_nan());
    }
    assert_eq!(read_signal_for(&at(&table, "thickness"), Some(3), false).unwrap().values, [2.5, 3.0, 2.75]);
    // The missing value needs --allow-missing, named by its vertex.
    let e = read_signal_for(&at(&table, "myelin"), Some(3), false).unwrap_err().to_string();
    assert!(e.contains("vertex 1"), "{e}");
    // A name the table does not have lists those it has; a short row is
    // named by its line; a table without a selector is not read as one
    // column.
    let e = read_signal_for(&at(&table, "curv"), Some(3), true).unwrap_err().to_string();
    assert!(e.contains("no column named `curv`") && e.contains("thickness") && e.contains("myelin"), "{e}");
    let e = read_signal_for(&at(&table, "3"), Some(3), true).unwrap_err().to_string();
    assert!(e.contains("no column named `3`"), "{e}");
    let short = tmp("short.csv");
    std::fs::write(&short, "thickness,myelin\n2.5,1.5\n3\n").unwrap();
    let e = read_signal_for(&at(&short, "myelin"), Some(2), true).unwrap_err().to_string();
    assert!(e.contains("line 3") && e.contains("expected 2, found 1"), "{e}");
    assert!(read_signal_for(&table, Some(3), true).is_err());
    // A GIfTI data file of two maps: by name or number; without a
    // selector, refused, naming both.
    let gii = tmp("maps.func.gii");
    let arrays: Vec<DataArray> =
        vec![signal_array("thickness", &[2.5, 3.0, 2.75]), signal_array("myelin", &[1.5, 1.0, 1.25])];
    let mut bytes = Vec::new();
    write_arrays(&mut bytes, &arrays, WriteOptions::default()).unwrap();
    std::fs::write(&gii, bytes).unwrap();
    for sel in ["myelin", "2"] {
        let c = read_signal_for(&at(&gii, sel), Some(3), false).unwrap();
        assert_eq!((c.name.as_str(), c.values.as_slice()), ("myelin", &[1.5, 1.0, 1.25][..]));
    }
    let e = read_signal_for(&gii, Some(3), false).unwrap_err().to_string();
    assert!(e.contains("FILE:NAME") && e.contains("thickness") && e.contains("myelin"), "{e}");
    let e = read_signal_for(&at(&gii, "curv"), Some(3), false).unwrap_err().to_string();
    assert!(e.contains("no per-vertex data array named `curv`"), "{e}");
    // A file of one map takes no selector.
    let curv = tmp("lh.thickness");
    fshape_mesh::io::write_signal(&curv, "thickness", &[2.5, 3.0, 2.75], 1).unwrap();
    let e = read_signal_for(&at(&curv, "2"), Some(3), false).unwrap_err().to_string();
    assert!(e.contains("selector after a file of one map"), "{e}");
}
