//! Fuzz the FreeSurfer readers (triangle surface, curv, MGH, annotation)
//! and the CIFTI-2 reader: no panic on any input, whatever parses survives
//! write → parse (the values are single precision already), and an
//! annotation's keys are rows of its table or −1.
#![no_main]

use std::path::Path;

use fshape_mesh::io::{self, Encoding, Format, ReadOptions, cifti, freesurfer};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let opts = ReadOptions::default();
    if let Ok(shape) = io::parse_mesh(data, Format::FreeSurfer, &opts, Path::new("lh.fuzz")) {
        let mut bytes = Vec::new();
        io::write_to(&mut bytes, &shape, Format::FreeSurfer, Encoding::Binary).expect("writing to memory succeeds");
        let back = io::parse_mesh(&bytes, Format::FreeSurfer, &opts, Path::new("lh.rewritten"))
            .expect("our own output parses");
        assert_eq!(back, shape);
    }
    if let Ok(v) = freesurfer::parse_curv(data) {
        let back =
            freesurfer::parse_curv(&freesurfer::curv_bytes(&v, 0).expect("small")).expect("our own output parses");
        assert!(back.iter().zip(&v).all(|(a, b)| a == b || (a.is_nan() && b.is_nan())));
    }
    if let Ok(v) = freesurfer::parse_mgh(data) {
        // Integer volumes are written back as float32.
        let back = freesurfer::parse_mgh(&freesurfer::mgh_bytes(&v).expect("small")).expect("our own output parses");
        assert!(back.iter().zip(&v).all(|(a, b)| *a == f64::from(*b as f32) || (a.is_nan() && b.is_nan())));
    }
    if let Ok(p) = freesurfer::parse_annot(data) {
        assert!(p.keys.iter().all(|&k| k == -1 || p.regions.iter().any(|r| r.key == k)));
    }
    if let Ok(c) = cifti::Cifti::parse(data.to_vec()) {
        for m in c.models.iter().filter(|m| m.surface_vertices.is_some()) {
            let n = m.surface_vertices.unwrap();
            if n <= 1 << 16
                && let Ok(v) = c.surface(&m.structure, Some("1"), n)
                && let Ok(bytes) = c.with_surface(&m.structure, Some("1"), &v)
            {
                let back = cifti::Cifti::parse(bytes).expect("our own output parses");
                let w = back.surface(&m.structure, Some("1"), n).unwrap();
                assert!(w.iter().zip(&v).all(|(a, b)| a.to_bits() == b.to_bits() || a.is_nan() && b.is_nan()));
            }
        }
    }
});
