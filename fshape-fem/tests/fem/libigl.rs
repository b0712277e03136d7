//! Agreement with libigl (an independent C++ implementation) through the
//! reference values in tests/reference/, made by scripts/fem_reference.sh
//! (libigl 2.6.3: massmatrix FULL and BARYCENTRIC, −cotmatrix).

use std::collections::HashMap;
use std::io::Read;
use std::path::PathBuf;

use fshape_fem::{Norm, SignalNorm};
use fshape_mesh::FShape;
use fshape_mesh::io::{ReadOptions, read_mesh};

fn repo(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

fn mesh(rel: &str) -> FShape {
    read_mesh(&repo(rel), &ReadOptions::default()).unwrap()
}

/// Our lower-triangle entries as a map (row, col) → value.
fn entries(s: &FShape, norm: Norm) -> HashMap<(usize, usize), f64> {
    let d = SignalNorm::try_new(s, norm).unwrap();
    let (col_ptr, row_idx) = d.pattern();
    let vals = d.assemble(s.points()).unwrap();
    let mut out = HashMap::new();
    for c in 0..d.n_vertices() {
        for e in col_ptr[c]..col_ptr[c + 1] {
            out.insert((row_idx[e], c), vals[e]);
        }
    }
    out
}

#[test]
fn bunny_matrices_match_libigl_entry_by_entry() {
    let s = mesh("data/stanford_bunny/bunny_qslim_2581v.ply.gz");
    let file = std::fs::File::open(repo("fshape-fem/tests/reference/bunny_qslim_fem.csv.gz")).unwrap();
    let mut text = String::new();
    flate2::read::GzDecoder::new(file).read_to_string(&mut text).unwrap();
    let mass = entries(&s, Norm::L2);
    let lumped = entries(&s, Norm::L2Lumped);
    let h1 = entries(&s, Norm::H1 { length: 1.0 });
    // The separate mass and stiffness values, on the shared pattern.
    let d = SignalNorm::try_new(&s, Norm::L2).unwrap();
    let (m_vals, k_vals) = d.assemble_mass_and_stiffness(s.points()).unwrap();
    let (col_ptr, row_idx) = d.pattern();
    let mut stiff = HashMap::new();
    for c in 0..d.n_vertices() {
        for e in col_ptr[c]..col_ptr[c + 1] {
            stiff.insert((row_idx[e], c), k_vals[e]);
            assert_eq!(m_vals[e], mass[&(row_idx[e], c)], "same mass values as assemble()");
        }
    }
    let (mut seen, mut worst) = (0, [0.0f64; 3]);
    let scale = [1e-5, 1e-5, 10.0]; // entry magnitudes in the file: areas ~1e-5 m², cotangents ~1–10
    for line in text.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|t| t.parse().unwrap()).collect();
        let key = (v[0] as usize, v[1] as usize);
        let ours_mass = mass.get(&key).copied().unwrap_or(0.0);
        let ours_lumped = lumped.get(&key).copied().unwrap_or(0.0);
        let ours_stiff = stiff.get(&key).copied().unwrap_or(0.0);
        // H1 with ℓ = 1 is mass + stiffness.
        let ours_h1 = h1.get(&key).copied().unwrap_or(0.0);
        assert!((ours_h1 - ours_mass - ours_stiff).abs() <= 1e-12 * scale[2]);
        for (k, (a, b)) in [(ours_mass, v[2]), (ours_lumped, v[3]), (ours_stiff, v[4])].into_iter().enumerate() {
            worst[k] = worst[k].max((a - b).abs() / scale[k]);
        }
        seen += 1;
    }
    // Every entry we store is in libigl's pattern (same connectivity).
    assert_eq!(seen, mass.len(), "same number of stored lower entries");
    // Both sides do a few dozen flops per entry in f64 from the same
    // coordinates: relative agreement to ~1e-13 of the entry scale.
    assert!(worst.iter().all(|&w| w < 1e-11), "worst relative differences {worst:?}");
}

#[test]
fn cortex_quadratic_forms_match_libigl() {
    let s = mesh("data/fsaverage5/lh.pial.thick.ply.gz");
    let text = std::fs::read_to_string(repo("fshape-fem/tests/reference/cortex_fem.json")).unwrap();
    let x = s.points();
    let n = s.n_vertices();
    let (lo, hi) = (s.bounding_box().min, s.bounding_box().max);
    let ptp: Vec<f64> = lo.iter().zip(&hi).map(|(a, b)| b - a).collect();
    // The same signals as scripts/fem_reference.py.
    let signals: [(&str, Vec<f64>); 3] = [
        ("ones", vec![1.0; n]),
        ("x", x.chunks_exact(3).map(|p| p[0] / ptp[0]).collect()),
        ("wave", x.chunks_exact(3).map(|p| (3.0 * p[0] / ptp[0]).sin() + p[1] / ptp[1]).collect()),
    ];
    let l2 = SignalNorm::try_new(&s, Norm::L2).unwrap();
    let lumped = SignalNorm::try_new(&s, Norm::L2Lumped).unwrap();
    let h1 = SignalNorm::try_new(&s, Norm::H1 { length: 1.0 }).unwrap();
    for (name, f) in &signals {
        let expect = |field: &str| -> f64 {
            // A tiny JSON lookup: "name": { ... "field": value ...}.
            let block = &text[text.find(&format!("\"{name}\"")).unwrap()..];
            let at = block.find(&format!("\"{field}\"")).unwrap() + field.len() + 3;
            block[at..].split([',', '\n', '}']).next().unwrap().trim().parse().unwrap()
        };
        let m = l2.quadratic(x, f).unwrap();
        let k = h1.quadratic(x, f).unwrap() - m;
        assert!((m - expect("mass_full")).abs() <= 1e-12 * m, "{name} mass");
        assert!((lumped.quadratic(x, f).unwrap() - expect("mass_barycentric")).abs() <= 1e-12 * m, "{name} lumped");
        // The stiffness form is a difference of two O(m) numbers: compare at
        // the mass scale (for `ones` both sides are rounding noise around 0).
        assert!((k - expect("stiffness")).abs() <= 1e-12 * m, "{name} stiffness {k} vs {}", expect("stiffness"));
    }
}
