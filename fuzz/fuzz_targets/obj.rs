//! Fuzz the hand-written obj parser: no panic on any input, and whatever
//! parses survives a write → parse round trip unchanged.
#![no_main]

use std::path::Path;

use fshape_mesh::io::{self, Encoding, Format, ReadOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let opts = ReadOptions::default();
    if let Ok(shape) = io::parse_mesh(data, Format::Obj, &opts, Path::new("fuzz.obj")) {
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, &shape, Format::Obj, Encoding::Binary).expect("writing to memory succeeds");
        let back =
            io::parse_mesh(&bytes, Format::Obj, &opts, Path::new("rewritten.obj")).expect("our own output parses");
        assert_eq!(back, shape);
    }
});
