//! Fuzz the GIfTI reader (XML, base64, zlib): no panic on any input; a
//! surface that parses survives write → parse with its values rounded to
//! the single precision GIfTI stores; any file's arrays survive the
//! writer in every encoding.
#![no_main]

use std::path::Path;

use fshape_mesh::io::{self, Encoding, Format, ReadOptions, gifti};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let opts = ReadOptions::default();
    if let Ok(shape) = io::parse_mesh(data, Format::Gifti, &opts, Path::new("fuzz.gii")) {
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, &shape, Format::Gifti, Encoding::Binary).expect("writing to memory succeeds");
        let back =
            io::parse_mesh(&bytes, Format::Gifti, &opts, Path::new("rewritten.gii")).expect("our own output parses");
        let single: Vec<f64> = shape.points().iter().map(|&x| f64::from(x as f32)).collect();
        assert_eq!(back.points(), single);
        assert_eq!(back.cells(), shape.cells());
    }
    if let Ok(g) = gifti::parse(data) {
        // Values written as the arrays' own types come back unchanged
        // (integers beyond 2^53 and NaN aside, which f64 cannot compare).
        let exact = g.arrays.iter().all(|a| a.values.iter().all(|v| v.is_finite() && v.abs() < 9.0e15));
        for encoding in [gifti::GiftiEncoding::Ascii, gifti::GiftiEncoding::Base64, gifti::GiftiEncoding::GzipBase64] {
            let mut bytes = Vec::new();
            let w = gifti::WriteOptions { encoding, big_endian: true, column_major: true };
            gifti::write_arrays(&mut bytes, &g.arrays, w).expect("writing to memory succeeds");
            let back = gifti::parse(&bytes).expect("our own output parses");
            if exact && encoding != gifti::GiftiEncoding::Ascii {
                assert_eq!(back.arrays.len(), g.arrays.len());
                for (a, b) in g.arrays.iter().zip(&back.arrays) {
                    assert_eq!(a.values, b.values);
                }
            }
        }
    }
});
