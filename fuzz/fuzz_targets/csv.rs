//! Fuzz the signal and digit CSV parsers: no panic on any input.
#![no_main]

use fshape_mesh::io::{csv, image};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(col) = csv::parse_signal(data, false) {
        assert!(col.values.iter().all(|v| v.is_finite()));
    }
    let _ = csv::parse_signal(data, true);
    if let Ok(im) = image::parse_image_csv(data) {
        assert_eq!(im.values.len(), im.width * im.height);
    }
});
