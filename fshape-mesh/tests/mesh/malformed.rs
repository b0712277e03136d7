//! The malformed-input corpus in tests/malformed/: each file gives an error
//! naming the file, the place and what was expected; none panics. The
//! expected places were worked out from the files' contents by hand.

use std::path::PathBuf;

use fshape_mesh::io::{ReadOptions, csv, read_mesh};

fn corpus(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/malformed").join(name)
}

/// (file, substrings the error message must contain).
const MESH_CASES: &[(&str, &[&str])] = &[
    ("ply_truncated_vertices.ply", &["unexpected end of data", "expected a vertex property value"]),
    ("ply_bad_count.ply", &["line 3", "expected an element count, found `four`"]),
    ("ply_huge_count.ply", &["claims 1000000000000 vertices"]),
    ("ply_non_numeric.ply", &["line 12", "found `1x`"]),
    ("ply_negative_index.ply", &["line 15", "cell 1 has the negative vertex index -2"]),
    ("ply_index_out_of_range.ply", &["cell 1 uses vertex 7, but there are only 4 vertices"]),
    ("ply_mixed_cell_sizes.ply", &["line 15", "cell 1 has 2 vertices, but the first cell has 3"]),
    ("ply_quad.ply", &["line 14", "cell 0 has 4 vertices", "triangulate"]),
    ("ply_nan_coordinate.ply", &["vertex 2 has a NaN or infinite coordinate"]),
    ("ply_no_magic.ply", &["line 1", "magic line `ply`", "found `PLY`"]),
    ("ply_no_end_header.ply", &["missing `end_header`"]),
    ("ply_unknown_format.ply", &["line 2", "unsupported PLY format: `binary_middle_endian`"]),
    ("ply_unknown_type.ply", &["line 4", "expected a PLY scalar type, found `float128`"]),
    ("ply_missing_x.ply", &["missing vertex property `x`"]),
    // Header of 172 bytes, two 24-byte vertices, x and y of the third and 3
    // stray bytes: 67 bytes cannot hold 3 vertices of 24 bytes, refused
    // before anything is allocated.
    ("ply_binary_cut.ply", &["byte 172", "the header claims 3 vertices, but only 67 bytes follow"]),
    // Big-endian header of 169 bytes, three vertices (72 bytes), the list
    // count (1 byte) and two indices (8 bytes): the third index is missing.
    ("ply_binary_be_cut_face.ply", &["byte 250", "expected a vertex index"]),
    // The POINTS line starts at byte 27 + 2 + 7 + 17 = 53; 9 doubles need 72
    // bytes and 7 (56 bytes) follow.
    ("vtk_binary_cut.vtk", &["byte 53", "the header claims 9 values, but only 56 bytes follow"]),
    ("vtk_truncated_points.vtk", &["unexpected end of data: expected a point coordinate"]),
    ("vtk_huge_count.vtk", &["line 5", "claims 300000000000 values"]),
    ("vtk_unstructured.vtk", &["unsupported VTK dataset", "UNSTRUCTURED_GRID"]),
    ("vtk_quad.vtk", &["cell 0 has 4 vertices"]),
    ("vtk_point_data_count.vtk", &["POINT_DATA tuples (one per point): expected 3, found 2"]),
    ("vtk_cells_cut.vtk", &["unexpected end of data: expected a cell list entry"]),
    ("vtk_missing_lookup_table.vtk", &["line 11", "expected `LOOKUP_TABLE name` after SCALARS"]),
    ("vtk_no_header.vtk", &["line 1", "# vtk DataFile Version"]),
    ("vtk_bad_encoding.vtk", &["line 3", "expected ASCII or BINARY, found `TEXT`"]),
    ("obj_bad_reference.obj", &["line 4", "found `x`"]),
    ("obj_zero_index.obj", &["line 4", "found `0`"]),
    ("obj_quad.obj", &["line 5", "cell 0 has 4 vertices"]),
    ("obj_mixed.obj", &["line 5", "mixed cell sizes"]),
    ("obj_short_vertex.obj", &["line 1", "three vertex coordinates"]),
];

#[test]
fn malformed_meshes_give_located_errors() {
    for (file, needles) in MESH_CASES {
        let err = read_mesh(&corpus(file), &ReadOptions::default()).expect_err(file);
        let msg = err.to_string();
        assert!(msg.contains(file), "{file}: the message names the file: {msg}");
        for n in *needles {
            assert!(msg.contains(n), "{file}: expected `{n}` in: {msg}");
        }
    }
}

#[test]
fn every_corpus_file_is_covered_and_the_reference_reads() {
    let ok = read_mesh(&corpus("ok_reference.ply"), &ReadOptions::default()).unwrap();
    assert_eq!((ok.n_vertices(), ok.n_cells()), (4, 2));
    let mut listed: Vec<&str> = [MESH_CASES, CSV_CASES, SIGNAL_FILE_CASES, SURFACE_FILE_CASES]
        .iter()
        .flat_map(|cases| cases.iter().map(|c| c.0))
        .collect();
    listed.sort_unstable();
    listed.dedup(); // fs_cut_faces.pial is read both ways
    listed.push("ok_reference.ply");
    listed.sort_unstable();
    let mut present: Vec<String> =
        std::fs::read_dir(corpus("")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    present.sort_unstable();
    assert_eq!(present, listed, "every corpus file has an expectation");
}

const CSV_CASES: &[(&str, &[&str])] = &[
    ("csv_missing_value.csv", &["line 3", "missing values are not accepted here", "found `nan`"]),
    ("csv_no_header.csv", &["line 1", "header line naming the column", "found `1.5`"]),
    ("csv_two_columns.csv", &["line 1", "single column"]),
    ("csv_non_numeric.csv", &["line 3", "found `2.0q`"]),
];

#[test]
fn malformed_signal_csv_gives_located_errors() {
    for (file, needles) in CSV_CASES {
        let msg = csv::read_signal(&corpus(file), false).expect_err(file).to_string();
        assert!(msg.contains(file), "{msg}");
        for n in *needles {
            assert!(msg.contains(n), "{file}: expected `{n}` in: {msg}");
        }
    }
    // Where the caller accepts missing values, `nan` is read as NaN.
    let col = csv::read_signal(&corpus("csv_missing_value.csv"), true).unwrap();
    assert_eq!(col.name, "thickness");
    assert_eq!(col.values[0], 1.5);
    assert!(col.values[1].is_nan());
    assert_eq!(col.values[2], 2.0);
}

#[test]
fn truncating_a_valid_binary_file_anywhere_never_panics() {
    // Every prefix of a binary PLY and VTK file is an error or (for the
    // full file) the shape: never a panic or a wrong shape.
    let shape = fshape_mesh::test_support::perturbed_icosphere(0, 0.1, 1);
    for ext in ["ply", "vtk"] {
        let path = std::env::temp_dir().join(format!("fshape-trunc-{}.{ext}", std::process::id()));
        fshape_mesh::io::write_mesh(&path, &shape, fshape_mesh::io::Encoding::Binary).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let format = fshape_mesh::io::Format::from_path(&path).unwrap().0;
        for cut in 0..bytes.len() {
            let r = fshape_mesh::io::parse_mesh(&bytes[..cut], format, &ReadOptions::default(), &path);
            // A VTK file may legitimately end after a whole section (cells
            // and point data are optional): then it is the shape's points,
            // with no cells or all of them, and no signal or all of it (only
            // the final newline after the binary signal block is cut).
            if let Ok(s) = r {
                assert_eq!(ext, "vtk", "a cut PLY at {cut} parsed");
                assert_eq!(s.points(), shape.points(), "cut at {cut}");
                assert!(s.cells().is_empty() || s.cells() == shape.cells(), "cut at {cut}");
                assert!(s.signal().is_none() || s.signal() == shape.signal(), "cut at {cut}");
            }
        }
        assert_eq!(fshape_mesh::io::parse_mesh(&bytes, format, &ReadOptions::default(), &path).unwrap(), shape);
        std::fs::remove_file(&path).unwrap();
    }
}

/// GIfTI and FreeSurfer files read as signals (`fshape --signal`); the
/// lines and offsets were worked out from the files by hand (they were
/// written by a few lines of Python: the XML is plain text, and the
/// FreeSurfer headers are a magic, a comment and big-endian counts).
const SIGNAL_FILE_CASES: &[(&str, &[&str])] = &[
    ("gii_bad_base64.shape.gii", &["line 3", "expected base64 data", "Invalid symbol 33, offset 4"]),
    // Dim0 = 5 FLOAT32 values need 20 bytes; the data decode to 16.
    ("gii_wrong_dim.shape.gii", &["line 3", "bytes of data against the Dim attributes", "expected 20, found 16"]),
    (
        "gii_truncated_zlib.shape.gii",
        &["line 3", "zlib-compressed data (GZipBase64Binary)", "incomplete deflate stream"],
    ),
    ("gii_unknown_encoding.shape.gii", &["line 3", "unsupported GIfTI encoding: `Base32Binary`"]),
    ("gii_external.shape.gii", &["line 3", "missing the ExternalFileName", "ExternalFileBinary"]),
    ("gii_ascii_wrong_dim.shape.gii", &["line 3", "values in the Data element", "expected 4, found 3"]),
    ("gii_ascii_non_numeric.shape.gii", &["line 3", "expected a number, found `x`"]),
    ("gii_unknown_type.shape.gii", &["line 3", "expected a NIfTI data type, found `NIFTI_TYPE_FLOAT128`"]),
    ("gii_unknown_intent.shape.gii", &["line 3", "NIfTI intent name or code, found `NIFTI_INTENT_THICKNESS`"]),
    ("gii_no_dimensionality.shape.gii", &["line 3", "missing the DataArray's Dimensionality"]),
    ("gii_nan.shape.gii", &["the value of vertex 2 (counting from 0) is NaN"]),
    ("gii_array_count.shape.gii", &["data arrays against NumberOfDataArrays: expected 2, found 1"]),
    ("gii_unclosed.shape.gii", &["line 4", "well-formed XML", "expected `</Data>`"]),
    ("gii_not_gifti.gii", &["line 2", "expected the GIFTI root element, found `svg`"]),
    // Magic (3 bytes), three big-endian counts: the fourth word says 2.
    ("fs_curv_two_per_vertex.thickness", &["byte 11", "values per vertex (fshape reads 1): `2`"]),
    // Version, width, height, depth (4 bytes each): the frames are at byte 16.
    ("fs_frames.mgh", &["byte 20", "MGH frame count", "`3`"]),
    ("fs_cut_faces.pial", &["byte 0", "this is a mesh"]),
];

/// GIfTI and FreeSurfer files read as meshes.
const SURFACE_FILE_CASES: &[(&str, &[&str])] = &[
    ("gii_no_triangles.surf.gii", &["missing a NIFTI_INTENT_TRIANGLE array (the faces)"]),
    ("gii_float_triangles.surf.gii", &["an integer type for the triangles, found `NIFTI_TYPE_FLOAT32`"]),
    ("gii_triangle_out_of_range.surf.gii", &["cell 0 uses vertex 3, but there are only 3 vertices"]),
    // Magic (3) + "created by hand\n\n" (17) + vertex count (4): the triangle
    // count is at byte 24; 3 vertices take 36 of the 45 bytes after it.
    ("fs_cut_faces.pial", &["byte 24", "the header claims 1 triangles after the vertices, but only 9 bytes follow"]),
    ("fs_quad.white", &["byte 0", "quad file"]),
];

#[test]
fn malformed_gifti_and_freesurfer_files_give_located_errors() {
    for (file, needles) in SIGNAL_FILE_CASES {
        let msg = fshape_mesh::io::read_signal(&corpus(file)).expect_err(file).to_string();
        assert!(msg.contains(file), "{msg}");
        for n in *needles {
            assert!(msg.contains(n), "{file}: expected `{n}` in: {msg}");
        }
    }
    for (file, needles) in SURFACE_FILE_CASES {
        let msg = read_mesh(&corpus(file), &ReadOptions::default()).expect_err(file).to_string();
        assert!(msg.contains(file), "{msg}");
        for n in *needles {
            assert!(msg.contains(n), "{file}: expected `{n}` in: {msg}");
        }
    }
}

/// The fuzz target `table`'s committed corpus, replayed with its property
/// (every table that parses is written back to the same cells).
#[test]
fn the_table_fuzz_corpus_keeps_its_round_trip() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus/table");
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    assert!(files.len() >= 3, "{}: {} inputs", dir.display(), files.len());
    for file in files {
        let data = std::fs::read(&file).unwrap();
        let result = std::panic::catch_unwind(|| fshape_mesh::test_support::table_round_trip(&data));
        assert!(result.is_ok(), "{}", file.display());
    }
}
