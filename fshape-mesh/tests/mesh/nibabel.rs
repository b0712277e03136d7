//! Files written by nibabel (tests/data/nibabel, made by
//! scripts/make-nibabel-fixtures.sh, which checks each with nibabel's own
//! reader) read back to the arrays nibabel was given, in every encoding,
//! byte order and index order; and what fshape writes reads back the same.
//! (That nibabel reads fshape's files is checked by the Python tests.)

use std::path::{Path, PathBuf};

use fshape_mesh::io::{self, Encoding, ReadOptions, gifti};
use fshape_mesh::{CellKind, FShape};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/nibabel").join(name)
}

struct Expected {
    points: Vec<f64>,
    faces: Vec<usize>,
    thickness: Vec<f64>,
}

fn expected() -> Expected {
    let points = io::csv::read_vectors(&fixture("expected_points.csv"), 3).unwrap();
    let faces = io::csv::read_vectors(&fixture("expected_faces.csv"), 3).unwrap().iter().map(|&v| v as usize).collect();
    let thickness = io::csv::read_signal(&fixture("expected_thickness.csv"), false).unwrap().values;
    assert_eq!((points.len(), thickness.len()), (36, 12), "the fixture is the icosahedron");
    Expected { points, faces, thickness }
}

/// Binary files hold nibabel's float32 values exactly; nibabel writes ASCII
/// floats with six decimals.
fn assert_close(name: &str, got: &[f64], want: &[f64]) {
    let tol = if name.contains("ascii") { 5e-7 } else { 0.0 };
    assert_eq!(got.len(), want.len(), "{name}");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() <= tol, "{name}: value {k} is {g}, nibabel wrote {w}");
    }
}

const SURFACES: &[&str] = &[
    "surf_ascii.surf.gii",
    "surf_base64.surf.gii",
    "surf_gzipbase64.surf.gii",
    "surf_colmajor_gzipbase64.surf.gii",
    "surf_bigendian_gzipbase64.surf.gii",
];

const SIGNALS: &[&str] = &[
    "thickness_ascii.shape.gii",
    "thickness_base64.shape.gii",
    "thickness_gzipbase64.shape.gii",
    "thickness_bigendian_base64.shape.gii",
    "thickness_float64.func.gii",
    "lh.thickness",
    "thickness.mgh",
    "thickness.mgz",
];

#[test]
fn gifti_surfaces_from_nibabel_read_back_in_every_encoding_and_order() {
    let e = expected();
    for name in SURFACES {
        let opts = ReadOptions { signal_name: Some("thickness".into()) };
        let s = io::read_mesh(&fixture(name), &opts).unwrap_or_else(|err| panic!("{name}: {err}"));
        assert_eq!((s.dim(), s.kind()), (3, CellKind::Triangle), "{name}");
        assert_close(name, s.points(), &e.points);
        assert_eq!(s.cells(), e.faces, "{name}");
        assert_close(name, s.signal().unwrap(), &e.thickness);
        // Without a name, the signal is the array called `signal` (none here).
        assert!(io::read_mesh(&fixture(name), &ReadOptions::default()).unwrap().signal().is_none());
    }
}

#[test]
fn a_named_signal_missing_from_a_gifti_surface_lists_the_arrays_it_has() {
    let opts = ReadOptions { signal_name: Some("curv".into()) };
    let err = io::read_mesh(&fixture("surf_base64.surf.gii"), &opts).unwrap_err().to_string();
    assert!(err.contains("no per-vertex scalar named `curv` (available: thickness)"), "{err}");
}

#[test]
fn freesurfer_surfaces_from_nibabel_are_read_by_their_magic() {
    let e = expected();
    let s = io::read_mesh(&fixture("lh.icosahedron"), &ReadOptions::default()).unwrap();
    assert_eq!(s.points(), e.points);
    assert_eq!(s.cells(), e.faces);
    assert!(s.signal().is_none());
}

#[test]
fn signals_from_nibabel_read_back_from_gifti_curv_and_mgh() {
    let e = expected();
    for name in SIGNALS {
        let c = io::read_signal(&fixture(name)).unwrap_or_else(|err| panic!("{name}: {err}"));
        assert_close(name, &c.values, &e.thickness);
    }
    assert_eq!(io::read_signal(&fixture("thickness_base64.shape.gii")).unwrap().name, "thickness");
    assert_eq!(io::read_signal(&fixture("lh.thickness")).unwrap().name, "thickness");
    assert_eq!(io::read_signal(&fixture("thickness.mgz")).unwrap().name, "thickness");
    // A surface file has three arrays, one of them per vertex: that one is the signal.
    assert_eq!(io::read_signal(&fixture("surf_base64.surf.gii")).unwrap().values, e.thickness);
}

fn tmp(name: &str) -> PathBuf {
    // Under target/tmp (cargo's scratch space for integration tests), not
    // the system's temporary directory, which would keep every run's files.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("fshape-nibabel-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn what_fshape_writes_reads_back_the_same_arrays() {
    let e = expected();
    let shape =
        FShape::try_new(3, CellKind::Triangle, e.points.clone(), e.faces.clone(), Some(e.thickness.clone())).unwrap();
    // Every value is a float32, so every format keeps it exactly.
    for (name, encoding) in [
        ("w.gii", Encoding::Ascii),
        ("w.surf.gii", Encoding::Binary),
        ("w.gii.gz", Encoding::Binary),
        ("lh.pial", Encoding::Binary),
    ] {
        let path = tmp(name);
        io::write_mesh(&path, &shape, encoding).unwrap();
        let back = io::read_mesh(&path, &ReadOptions::default()).unwrap();
        assert_eq!(back.points(), shape.points(), "{name}");
        assert_eq!(back.cells(), shape.cells(), "{name}");
        let signal = if name == "lh.pial" { None } else { shape.signal() };
        assert_eq!(back.signal(), signal, "{name}");
    }
    for name in ["w.shape.gii", "lh.thickness", "w.mgh", "w.mgz", "w.csv"] {
        let path = tmp(name);
        io::write_signal(&path, "thickness", &e.thickness, e.faces.len() / 3).unwrap();
        assert_eq!(io::read_signal(&path).unwrap().values, e.thickness, "{name}");
    }
    // Every encoding, byte order and index order of the GIfTI writer.
    let arrays = gifti::surface_arrays(&shape, "thickness").unwrap();
    for encoding in [gifti::GiftiEncoding::Ascii, gifti::GiftiEncoding::Base64, gifti::GiftiEncoding::GzipBase64] {
        for big_endian in [false, true] {
            for column_major in [false, true] {
                let mut bytes = Vec::new();
                let opts = gifti::WriteOptions { encoding, big_endian, column_major };
                gifti::write_arrays(&mut bytes, &arrays, opts).unwrap();
                assert_eq!(gifti::parse(&bytes).unwrap().arrays, arrays, "{opts:?}");
            }
        }
    }
}

#[test]
fn curves_are_refused_by_the_surface_only_formats() {
    let curve =
        FShape::try_new(2, CellKind::Segment, vec![0.0, 0.0, 1.0, 0.0, 1.0, 1.0], vec![0, 1, 1, 2], None).unwrap();
    for name in ["c.gii", "lh.white"] {
        let err = io::write_mesh(&tmp(name), &curve, Encoding::Binary).unwrap_err().to_string();
        assert!(err.contains("triangle"), "{name}: {err}");
        assert!(!Path::new(&tmp(name)).exists(), "{name}: nothing is left behind");
    }
}

/// A scratch folder of its own for one test.
fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fshape-mesh-gifti-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A one-triangle surface whose arrays are in `external.dat` next to the
/// .gii (little-endian float32 points, then int32 triangles at byte 36),
/// with the encoding and byte order spelled as `encoding` and `endian`.
fn external_gii(dir: &Path, encoding: &str, endian: &str, dat: &[u8]) -> PathBuf {
    std::fs::write(dir.join("external.dat"), dat).unwrap();
    let array = |intent: &str, ty: &str, offset: usize| {
        format!(
            "<DataArray Intent=\"{intent}\" DataType=\"{ty}\" ArrayIndexingOrder=\"RowMajorOrder\" Dimensionality=\"2\" \
             Dim0=\"{}\" Dim1=\"3\" Encoding=\"{encoding}\" Endian=\"{endian}\" ExternalFileName=\"external.dat\" \
             ExternalFileOffset=\"{offset}\"><Data></Data></DataArray>",
            if intent.ends_with("POINTSET") { 3 } else { 1 }
        )
    };
    let gii = dir.join("external.gii");
    std::fs::write(
        &gii,
        format!(
            "<?xml version=\"1.0\"?>\n<GIFTI Version=\"1.0\" NumberOfDataArrays=\"2\">\n{}\n{}\n</GIFTI>\n",
            array("NIFTI_INTENT_POINTSET", "NIFTI_TYPE_FLOAT32", 0),
            array("NIFTI_INTENT_TRIANGLE", "NIFTI_TYPE_INT32", 36)
        ),
    )
    .unwrap();
    gii
}

fn triangle_bytes() -> Vec<u8> {
    let points: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.5];
    let mut b: Vec<u8> = points.iter().flat_map(|x| x.to_le_bytes()).collect();
    b.extend([0i32, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
    b
}

#[test]
fn external_data_files_and_the_gifti_enum_spellings_read_as_nibabel_reads_them() {
    let dir = scratch("external");
    for (encoding, endian) in [
        ("ExternalFileBinary", "LittleEndian"),
        ("GIFTI_ENCODING_EXTBIN", "GIFTI_ENDIAN_LITTLE"),
        ("External", "LittleEndian"),
    ] {
        let gii = external_gii(&dir, encoding, endian, &triangle_bytes());
        let s = io::read_mesh(&gii, &ReadOptions::default()).unwrap();
        assert_eq!(s.points(), &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.5], "{encoding} {endian}");
        assert_eq!(s.cells(), &[0, 1, 2]);
    }
    // A short external file, and a missing one, are errors naming them.
    let gii = external_gii(&dir, "ExternalFileBinary", "LittleEndian", &triangle_bytes()[..40]);
    let e = io::read_mesh(&gii, &ReadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("external data file") && e.contains("expected 12") && e.contains("found 4"), "{e}");
    std::fs::remove_file(dir.join("external.dat")).unwrap();
    let e = io::read_mesh(&gii, &ReadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("external.dat"), "{e}");
    // Parsed from memory, there is no folder to look in.
    let e = gifti::parse(&std::fs::read(&gii).unwrap()).unwrap_err().to_string();
    assert!(e.contains("without the .gii's folder"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bzip2_files_are_read_and_never_written() {
    use std::io::Write as _;
    let dir = scratch("bz2");
    let shape =
        FShape::try_new(3, CellKind::Triangle, vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], vec![0, 1, 2], None)
            .unwrap();
    let plain = dir.join("t.gii");
    io::write_mesh(&plain, &shape, Encoding::Ascii).unwrap();
    let mut z = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::default());
    z.write_all(&std::fs::read(&plain).unwrap()).unwrap();
    let packed = dir.join("t.gii.bz2");
    std::fs::write(&packed, z.finish().unwrap()).unwrap();
    assert_eq!(io::read_mesh(&packed, &ReadOptions::default()).unwrap(), shape);
    let e = io::write_mesh(&dir.join("u.ply.bz2"), &shape, Encoding::Binary).unwrap_err().to_string();
    assert!(e.contains("use .gz"), "{e}");
    assert!(!dir.join("u.ply.bz2").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

fn column(name: &str) -> Vec<f64> {
    io::csv::read_signal(&fixture(name), true).unwrap().values
}

fn keys(name: &str) -> Vec<i32> {
    column(name).iter().map(|&k| k as i32).collect()
}

#[test]
fn parcellations_from_nibabel_read_to_its_keys_and_names() {
    let annot = io::read_parcellation(&fixture("lh.parcels.annot")).unwrap();
    assert_eq!(annot.keys, keys("expected_parcels.csv"));
    let names: Vec<&str> = annot.regions.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["precentral", "postcentral", "insula"]);
    assert_eq!(annot.regions[1].rgba, [20.0 / 255.0, 220.0 / 255.0, 60.0 / 255.0, 1.0]);
    let gii = io::read_parcellation(&fixture("parcels.label.gii")).unwrap();
    assert_eq!(gii.keys, keys("expected_label_gii_keys.csv"));
    assert_eq!((gii.name(7), gii.name(0), gii.name(5)), (Some("postcentral"), Some("???"), None));
    assert_eq!(gii.regions[1].rgba, [0.8, 0.1, 0.05, 1.0]);
    // The same regions as masks, from either file.
    let want: Vec<f64> = annot.keys.iter().map(|&k| f64::from(u8::from(k == 0 || k == 2))).collect();
    assert_eq!(io::read_mask(&fixture("lh.parcels.annot:precentral,insula"), 12).unwrap(), want);
    let path = format!("{}:precentral, insula", fixture("parcels.label.gii").display());
    assert_eq!(io::read_mask(path.as_ref(), 12).unwrap(), want);
    for (path, says) in [
        (
            format!("{}", fixture("lh.parcels.annot").display()),
            "name the regions after the file, as FILE:REGION,REGION (the file has: precentral, postcentral, insula)",
        ),
        (
            format!("{}:precentral,cuneus", fixture("lh.parcels.annot").display()),
            "no region named `cuneus` (the file has: precentral, postcentral, insula)",
        ),
    ] {
        let e = io::read_mask(path.as_ref(), 12).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
    let e = io::read_mask(&fixture("lh.parcels.annot:insula"), 13).unwrap_err().to_string();
    assert!(e.contains("12 values for a surface of 13 vertices"), "{e}");
}

#[test]
fn parcellations_write_as_gifti_label_files_that_read_back_with_their_keys_and_table() {
    // nibabel's label file (keys 0 `???`, 4, 7, 9) written again reads
    // back the same.
    let gii = io::read_parcellation(&fixture("parcels.label.gii")).unwrap();
    let dir = std::env::temp_dir().join(format!("fshape-label-gii-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    io::write_parcellation(&dir.join("again.label.gii"), &gii).unwrap();
    assert_eq!(io::read_parcellation(&dir.join("again.label.gii")).unwrap(), gii);
    // An annotation's vertices in no region (−1) take a transparent `???`
    // of key 0 when 0 is free, else the largest key plus one; names that
    // need escaping survive.
    let mut annot = io::read_parcellation(&fixture("lh.parcels.annot")).unwrap();
    annot.regions[2].name = "a <b> & \"c\"".into();
    for (shift, none) in [(1, 0), (0, 3)] {
        let mut p = annot.clone();
        p.keys.iter_mut().filter(|k| **k >= 0).for_each(|k| *k += shift);
        p.regions.iter_mut().for_each(|r| r.key += shift);
        let path = dir.join(format!("shift{shift}.label.gii"));
        io::write_parcellation(&path, &p).unwrap();
        let back = io::read_parcellation(&path).unwrap();
        let want: Vec<i32> = p.keys.iter().map(|&k| if k == -1 { none } else { k }).collect();
        assert_eq!(back.keys, want, "shift {shift}");
        assert_eq!(back.name(none), Some("???"));
        assert_eq!(back.regions.iter().find(|r| r.key == none).unwrap().rgba, [0.0; 4]);
        assert_eq!(&back.regions.iter().filter(|r| r.key != none).cloned().collect::<Vec<_>>(), &p.regions);
    }
    let e = io::write_parcellation(&dir.join("p.gii"), &gii).unwrap_err().to_string();
    assert!(e.contains("a parcellation is written as .annot (FreeSurfer), .label.gii (GIfTI) or .csv"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn annotations_are_written_byte_for_byte_as_nibabel_writes_them() {
    let annot = io::read_parcellation(&fixture("lh.parcels.annot")).unwrap();
    assert!(io::freesurfer::annot_bytes(&annot).unwrap() == std::fs::read(fixture("lh.parcels.annot")).unwrap());
    // A GIfTI label table (keys 0, 4, 7, 9; 0 is HCP's black `???`) as an
    // annotation: numbered by their rows as nibabel numbers a table (so
    // that its read_annot indexes the names), the black region's vertices
    // as none.
    let gii = io::read_parcellation(&fixture("parcels.label.gii")).unwrap();
    assert_eq!(gii.regions.iter().map(|r| r.key).collect::<Vec<_>>(), [0, 4, 7, 9]);
    let back = io::freesurfer::parse_annot(&io::freesurfer::annot_bytes(&gii).unwrap()).unwrap();
    let row = |k: i32| [0, 4, 7, 9].iter().position(|&r| r == k).map_or(-1, |i| i as i32);
    let want: Vec<i32> = gii.keys.iter().map(|&k| if k == 0 { -1 } else { row(k) }).collect();
    assert_eq!(back.keys, want);
    assert_eq!(back.regions.iter().map(|r| r.key).collect::<Vec<_>>(), [0, 1, 2, 3]);
    assert_eq!(
        back.regions.iter().map(|r| r.name.as_str()).collect::<Vec<_>>(),
        ["???", "precentral", "postcentral", "insula"]
    );
    // Two regions of one colour would read back as one.
    let mut same = annot.clone();
    same.regions[1].rgba = same.regions[0].rgba;
    let e = io::freesurfer::annot_bytes(&same).unwrap_err().to_string();
    assert!(e.contains("regions \"precentral\" and \"postcentral\" have one colour"), "{e}");
}

#[test]
fn cifti_maps_from_nibabel_read_per_structure_with_nan_off_the_model() {
    let same = |got: &[f64], want: &[f64]| {
        assert_eq!(got.len(), want.len());
        for (k, (g, w)) in got.iter().zip(want).enumerate() {
            assert!(g == w || g.is_nan() && w.is_nan(), "vertex {k}: {g} against nibabel's {w}");
        }
    };
    let maps = fixture("maps.dscalar.nii").display().to_string();
    for (selector, expected) in [
        ("CORTEX_LEFT:thickness", "expected_cifti_left_thickness.csv"),
        ("CIFTI_STRUCTURE_CORTEX_LEFT:2", "expected_cifti_left_myelin.csv"),
        ("CORTEX_RIGHT:myelin", "expected_cifti_right_myelin.csv"),
    ] {
        let path = format!("{maps}:{selector}");
        let c = io::read_signal_for(path.as_ref(), Some(12), true).unwrap_or_else(|e| panic!("{selector}: {e}"));
        same(&c.values, &column(expected));
    }
    // NaN off the model is a missing value, refused unless allowed.
    let e = io::read_signal_for(format!("{maps}:CORTEX_LEFT:1").as_ref(), Some(12), false).unwrap_err();
    assert!(e.to_string().contains("vertex 5 (counting from 0) is NaN"), "{e}");
    for (selector, n, says) in [
        (
            "",
            12,
            "name the surface structure after the file, as FILE:STRUCTURE or FILE:STRUCTURE:MAP (the file has: CORTEX_LEFT, CORTEX_RIGHT)",
        ),
        (":CORTEX_LEFT", 12, "name the map (the file has several) after the file"),
        (":THALAMUS_LEFT", 12, "no surface structure named `THALAMUS_LEFT` (the file has: CORTEX_LEFT, CORTEX_RIGHT)"),
        (":CORTEX_LEFT:curvature", 12, "no map named `curvature` (the file has: thickness, myelin)"),
        (":CORTEX_LEFT:3", 12, "no map named `3`"),
        (":CORTEX_LEFT:myelin", 32492, "a map of another surface?): expected 32492, found 12"),
    ] {
        let e = io::read_signal_for(format!("{maps}{selector}").as_ref(), Some(n), true).unwrap_err().to_string();
        assert!(e.contains(says), "{selector}: {e}");
    }
}

#[test]
fn a_cifti_map_written_back_changes_that_map_of_that_structure_only() {
    let like = fixture("maps.dscalar.nii");
    let original = std::fs::read(&like).unwrap();
    let c = io::read_cifti_file(&like).unwrap();
    let new: Vec<f64> = (0..12).map(|k| 0.5 + k as f64 / 8.0).collect();
    let bytes = c.with_surface("CORTEX_RIGHT", Some("myelin"), &new).unwrap();
    assert_eq!(bytes.len(), original.len());
    let c2 = io::cifti::Cifti::parse(bytes.clone()).unwrap();
    // The structure's vertices carry the new values, vertex 0 (off it) NaN.
    let got = c2.surface("CORTEX_RIGHT", Some("myelin"), 12).unwrap();
    assert!(got[0].is_nan() && got[1..] == new[1..], "{got:?}");
    // Every other map and structure is the file's: the bytes differ only
    // in the right cortex's myelin values (11 float32).
    for (s, m) in [("CORTEX_LEFT", "thickness"), ("CORTEX_LEFT", "myelin"), ("CORTEX_RIGHT", "thickness")] {
        let (a, b) = (c.surface(s, Some(m), 12).unwrap(), c2.surface(s, Some(m), 12).unwrap());
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()), "{s} {m}");
    }
    let changed = original.iter().zip(&bytes).filter(|(a, b)| a != b).count();
    assert!((1..=44).contains(&changed), "{changed} bytes changed");
    let e = c.with_surface("CORTEX_RIGHT", Some("myelin"), &new[..11]).unwrap_err().to_string();
    assert!(e.contains("expected 12, found 11"), "{e}");
}

#[test]
fn cifti_label_files_from_nibabel_read_as_parcellations_with_their_tables() {
    let file = fixture("parcels.dlabel.nii").display().to_string();
    // Each map with its own table; the medial wall (off the structure)
    // carries the `???` key, 0, as Workbench writes it.
    let left = io::read_parcellation(format!("{file}:CORTEX_LEFT:parcels").as_ref()).unwrap();
    assert_eq!(left.keys, keys("expected_dlabel_left_parcels.csv"));
    assert_eq!((left.name(7), left.name(0)), (Some("postcentral"), Some("???")));
    assert_eq!(left.regions[3].rgba, [1.0, 0.75, 0.125, 1.0]);
    let right = io::read_parcellation(format!("{file}:CORTEX_RIGHT:2").as_ref()).unwrap();
    assert_eq!(right.keys, keys("expected_dlabel_right_halves.csv"));
    let names: Vec<&str> = right.regions.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["???", "front", "back"]);
    assert_eq!(right.regions[2].rgba, [0.25, 1.0, 0.5, 1.0]);
    // Regions as a mask: FILE:STRUCTURE[:MAP]:REGION,REGION.
    let want: Vec<f64> = left.keys.iter().map(|&k| f64::from(u8::from(k == 4 || k == 9))).collect();
    let mask = io::read_mask(format!("{file}:CORTEX_LEFT:parcels:precentral,insula").as_ref(), 12).unwrap();
    assert_eq!(mask, want);
    for (path, says) in [
        (format!("{file}:CORTEX_LEFT"), "name the structure and regions after the file"),
        (format!("{file}:CORTEX_LEFT:insula"), "name the map (the file has several)"),
        (format!("{file}:CORTEX_LEFT:parcels:"), "name the regions after the file"),
        (format!("{file}:CORTEX_LEFT:parcels:cuneus"), "no region named `cuneus`"),
    ] {
        let e = io::read_mask(path.as_ref(), 12).unwrap_err().to_string();
        assert!(e.contains(says), "{path}: {e}");
    }
    let e = io::read_mask(format!("{file}:CORTEX_LEFT:parcels:insula").as_ref(), 13).unwrap_err().to_string();
    assert!(e.contains("expected 13, found 12"), "{e}");
    // Gzipped, as such files are often kept.
    let dir = std::env::temp_dir().join(format!("fshape-dlabel-gz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let gz = dir.join("parcels.dlabel.nii.gz");
    let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut z, &std::fs::read(fixture("parcels.dlabel.nii")).unwrap()).unwrap();
    std::fs::write(&gz, z.finish().unwrap()).unwrap();
    let packed = io::read_mask(format!("{}:CORTEX_LEFT:parcels:precentral,insula", gz.display()).as_ref(), 12);
    assert_eq!(packed.unwrap(), want);
    std::fs::remove_dir_all(&dir).unwrap();
    // Keys are no map, and values no parcellation.
    let e = io::read_signal_for(format!("{file}:CORTEX_LEFT:parcels").as_ref(), Some(12), true).unwrap_err();
    assert!(e.to_string().contains("it holds region keys (a .dlabel.nii)"), "{e}");
    let maps = fixture("maps.dscalar.nii").display().to_string();
    let e = io::read_parcellation(format!("{maps}:CORTEX_LEFT:thickness").as_ref()).unwrap_err().to_string();
    assert!(e.contains("it holds values, not labels"), "{e}");
    let e = io::read_parcellation(format!("{}:CORTEX_LEFT", fixture("lh.parcels.annot").display()).as_ref());
    assert!(e.unwrap_err().to_string().contains("only a CIFTI-2 file takes FILE:STRUCTURE"));
}
