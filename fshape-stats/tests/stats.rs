//! Group tests against the textbook formulas, and their error rates on
//! data with a known answer: no effect (the family-wise false-positive
//! rate over many null datasets) and a localised effect of known place.

use fshape_mesh::FShape;
use fshape_mesh::generate::{SplitMix64, icosphere};
use fshape_stats::tfce::tfce;
use fshape_stats::{
    Covariates, Design, Inference, MeshGraph, StatKind, TfceParams, test_maps, test_maps_within, test_scores,
};

fn two_groups(n: usize) -> Design {
    let x = (0..n).flat_map(|i| [1.0, f64::from(u8::from(i >= n / 2))]).collect();
    Design::from_matrix(vec!["intercept".into(), "group".into()], x).unwrap()
}

#[test]
fn two_groups_give_the_pooled_two_sample_t_and_three_give_the_one_way_anova_f() {
    let mut rng = SplitMix64(1);
    let n = 12;
    let y: Vec<f64> = (0..n).map(|i| rng.range(0.0, 1.0) + if i >= 6 { 0.4 } else { 0.0 }).collect();
    let test = test_maps(
        &two_groups(n),
        &two_groups(n).contrast("group").unwrap(),
        &y,
        1,
        None,
        &Inference { permutations: 10, ..Inference::default() },
    )
    .unwrap();
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let (a, b) = (&y[..6], &y[6..]);
    let ss = |s: &[f64]| s.iter().map(|v| (v - mean(s)).powi(2)).sum::<f64>();
    let pooled = (ss(a) + ss(b)) / (n - 2) as f64;
    let t = (mean(b) - mean(a)) / (pooled * (1.0 / 6.0 + 1.0 / 6.0)).sqrt();
    assert!((test.statistic[0] - t).abs() < 1e-12 * t.abs());
    assert!((test.effect[0] - (mean(b) - mean(a))).abs() < 1e-14);
    assert_eq!((test.kind, test.dof), (StatKind::T, (1, 10)));

    // One-way ANOVA on three sites of 4.
    let table: String = std::iter::once("subject,site".to_string())
        .chain((0..n).map(|i| format!("{i},{}", ["a", "b", "c"][i / 4])))
        .collect::<Vec<_>>()
        .join("\n");
    let names: Vec<Vec<String>> = (0..n).map(|i| vec![i.to_string()]).collect();
    let (design, _) = Covariates::parse(&table, "t").unwrap().design(&names, None).unwrap();
    let test = test_maps(
        &design,
        &design.contrast("site").unwrap(),
        &y,
        1,
        None,
        &Inference { permutations: 10, ..Inference::default() },
    )
    .unwrap();
    let groups: Vec<&[f64]> = y.chunks(4).collect();
    let grand = mean(&y);
    let between: f64 = groups.iter().map(|g| 4.0 * (mean(g) - grand).powi(2)).sum::<f64>() / 2.0;
    let within: f64 = groups.iter().map(|g| ss(g)).sum::<f64>() / (n - 3) as f64;
    assert_eq!((test.kind, test.dof), (StatKind::F, (2, 9)));
    assert!((test.statistic[0] - between / within).abs() < 1e-12 * test.statistic[0]);
}

#[test]
#[expect(clippy::needless_range_loop, reason = "index notation follows the formulas")]
fn two_groups_scores_give_hotelling_s_two_sample_t_squared() {
    let mut rng = SplitMix64(2);
    let (n, k) = (16, 3);
    let scores: Vec<f64> = (0..n * k).map(|_| rng.normal()).collect();
    let design = two_groups(n);
    let test = test_scores(
        &design,
        &design.contrast("group").unwrap(),
        &scores,
        k,
        &Inference { permutations: 50, ..Inference::default() },
    )
    .unwrap();
    // T² = (n₁n₂/n) dᵀ S⁻¹ d with the pooled covariance S.
    let half = n / 2;
    let mean = |rows: std::ops::Range<usize>| -> Vec<f64> {
        (0..k).map(|c| rows.clone().map(|i| scores[i * k + c]).sum::<f64>() / half as f64).collect()
    };
    let (ma, mb) = (mean(0..half), mean(half..n));
    let mut s = vec![0.0; k * k];
    for i in 0..n {
        let m = if i < half { &ma } else { &mb };
        for a in 0..k {
            for b in 0..k {
                s[a * k + b] += (scores[i * k + a] - m[a]) * (scores[i * k + b] - m[b]) / (n - 2) as f64;
            }
        }
    }
    let d: Vec<f64> = (0..k).map(|c| mb[c] - ma[c]).collect();
    // Solve S x = d by Gaussian elimination (3 × 3).
    let mut aug: Vec<Vec<f64>> = (0..k).map(|r| (0..k).map(|c| s[r * k + c]).chain([d[r]]).collect()).collect();
    for col in 0..k {
        for row in col + 1..k {
            let f = aug[row][col] / aug[col][col];
            for c in col..=k {
                aug[row][c] -= f * aug[col][c];
            }
        }
    }
    let mut x = vec![0.0; k];
    for r in (0..k).rev() {
        x[r] = (aug[r][k] - (r + 1..k).map(|c| aug[r][c] * x[c]).sum::<f64>()) / aug[r][r];
    }
    let t2 = (half * half) as f64 / n as f64 * d.iter().zip(&x).map(|(a, b)| a * b).sum::<f64>();
    assert!((test.statistic - t2).abs() < 1e-10 * t2, "{} vs {t2}", test.statistic);
    assert!(test.p > 0.0 && test.p <= 1.0);
}

/// `subjects` maps on `sphere`: smooth noise (a few random Gaussian bumps
/// of random sign and white noise), an age trend, and in the second group
/// `effect` times a bump of width 0.35 at `centre`.
fn population(sphere: &FShape, subjects: usize, effect: f64, centre: [f64; 3], seed: u64) -> (Design, Vec<f64>) {
    let m = sphere.n_vertices();
    let mut rng = SplitMix64(seed);
    let bump = |c: &[f64], v: usize, width: f64| -> f64 {
        let p = sphere.point(v);
        (-(0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f64>() / (2.0 * width * width)).exp()
    };
    let mut x = Vec::new();
    let mut maps = Vec::with_capacity(subjects * m);
    for i in 0..subjects {
        let group = f64::from(u8::from(i % 2 == 1));
        let age = rng.range(20.0, 70.0);
        x.extend([1.0, group, age]);
        let noise: Vec<([f64; 3], f64)> = (0..6)
            .map(|_| {
                let c = [rng.normal(), rng.normal(), rng.normal()];
                let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                (c.map(|a| a / len), rng.normal())
            })
            .collect();
        for v in 0..m {
            let smooth: f64 = noise.iter().map(|(c, a)| a * bump(c, v, 0.5)).sum();
            maps.push(smooth + 0.5 * rng.normal() + 0.02 * age + group * effect * bump(&centre, v, 0.35));
        }
    }
    let design = Design::from_matrix(vec!["intercept".into(), "group".into(), "age".into()], x).unwrap();
    (design, maps)
}

#[test]
fn a_run_gives_the_same_bits_on_one_thread_and_on_several() {
    let sphere = icosphere(2, 1.0);
    let graph = MeshGraph::new(&sphere);
    let (design, maps) = population(&sphere, 12, 1.0, [0.0, 0.0, 1.0], 3);
    let contrast = design.contrast("group").unwrap();
    let inference = Inference { permutations: 64, seed: 9, tfce: Some(TfceParams::default()), ..Inference::default() };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| test_maps(&design, &contrast, &maps, sphere.n_vertices(), Some(&graph), &inference).unwrap())
    };
    let (one, several) = (run(1), run(3));
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&one.statistic), bits(&several.statistic));
    assert_eq!(bits(&one.p_fwe), bits(&several.p_fwe));
    assert_eq!(bits(&one.p_uncorrected), bits(&several.p_uncorrected));
    assert_eq!(bits(one.tfce_p_fwe.as_ref().unwrap()), bits(several.tfce_p_fwe.as_ref().unwrap()));
    assert_eq!(bits(&one.max_null), bits(&several.max_null));
}

/// The one-sided binomial bound: a rate from `datasets` independent
/// nulls whose true value is α stays below α + 2.33 sd with probability 0.99.
fn bound(alpha: f64, datasets: usize) -> f64 {
    alpha + 2.33 * (alpha * (1.0 - alpha) / datasets as f64).sqrt()
}

/// The vertices of `sphere` outside a cap around −z (a medial wall's
/// stand-in: a fifth of the sphere).
fn outside_wall(sphere: &FShape) -> Vec<bool> {
    (0..sphere.n_vertices()).map(|v| sphere.point(v)[2] > -0.6).collect()
}

#[test]
fn under_no_effect_the_family_wise_false_positive_rate_is_five_percent_with_a_masked_wall() {
    let sphere = icosphere(2, 1.0);
    let graph = MeshGraph::new(&sphere);
    let tested = outside_wall(&sphere);
    let datasets = 1000;
    let (mut max_t, mut tfce) = (0, 0);
    for d in 0..datasets {
        let (design, mut maps) = population(&sphere, 16, 0.0, [0.0, 0.0, 1.0], 1000 + d as u64);
        // The wall's values are not read: NaN there would be refused.
        for (k, x) in maps.iter_mut().enumerate() {
            if !tested[k % tested.len()] {
                *x = f64::NAN;
            }
        }
        let inference = Inference {
            permutations: 100,
            seed: d as u64,
            tfce: Some(TfceParams { steps: 50, ..TfceParams::default() }),
            ..Inference::default()
        };
        let test =
            test_maps_within(&design, &design.contrast("group").unwrap(), &maps, &tested, Some(&graph), &inference)
                .unwrap();
        assert!(test.p_fwe.iter().zip(&tested).all(|(p, t)| p.is_nan() != *t));
        max_t += usize::from(test.p_fwe.iter().any(|&p| p <= 0.05));
        tfce += usize::from(test.tfce_p_fwe.unwrap().iter().any(|&p| p <= 0.05));
    }
    let (max_t, tfce) = (max_t as f64 / datasets as f64, tfce as f64 / datasets as f64);
    eprintln!("family-wise false-positive rate over {datasets} nulls, wall masked: max-t {max_t}, TFCE {tfce}");
    // A correct test sits at 5 %: not above (beyond chance), and not far
    // below (a test that never rejects would pass the first check alone).
    for rate in [max_t, tfce] {
        assert!(rate <= bound(0.05, datasets), "{rate}");
        assert!(rate >= 0.05 - (bound(0.05, datasets) - 0.05), "{rate}");
    }
}

#[test]
fn a_masked_vertex_is_never_read_and_no_cluster_crosses_it() {
    let sphere = icosphere(2, 1.0);
    let graph = MeshGraph::new(&sphere);
    let m = sphere.n_vertices();
    // A masked belt |z| < 0.3 between two caps.
    let tested: Vec<bool> = (0..m).map(|v| sphere.point(v)[2].abs() >= 0.3).collect();
    let (design, maps) = population(&sphere, 12, 1.5, [0.0, 0.0, 1.0], 5);
    let inference = Inference { permutations: 64, seed: 2, tfce: Some(TfceParams::default()), ..Inference::default() };
    let contrast = design.contrast("group").unwrap();
    let with = |fill: f64| {
        let mut maps = maps.clone();
        for (k, x) in maps.iter_mut().enumerate() {
            if !tested[k % m] {
                *x = fill;
            }
        }
        test_maps_within(&design, &contrast, &maps, &tested, Some(&graph), &inference).unwrap()
    };
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let reference = with(0.0);
    for fill in [f64::NAN, 1e300, -7.0] {
        let other = with(fill);
        assert_eq!(bits(&reference.statistic), bits(&other.statistic));
        assert_eq!(bits(reference.tfce.as_ref().unwrap()), bits(other.tfce.as_ref().unwrap()));
        assert_eq!(bits(&reference.max_null), bits(&other.max_null));
    }
    // TFCE on the belted sphere: a plateau on each cap. The north cap's
    // enhancement does not see the south one (their clusters are apart),
    // unlike on the whole sphere with the belt at the plateau's height.
    let north = |v: usize| sphere.point(v)[2] >= 0.3;
    let caps: Vec<f64> = (0..m).map(|v| if tested[v] { 1.0 } else { 0.0 }).collect();
    let kept: Vec<usize> = (0..m).filter(|&v| tested[v]).collect();
    let restricted = graph.restricted(&tested);
    let params = TfceParams::default();
    let enhance = |s: &[f64], g: &MeshGraph| {
        let mut out = vec![0.0; s.len()];
        tfce(s, g, params, &mut out);
        out
    };
    let both = enhance(&kept.iter().map(|&v| caps[v]).collect::<Vec<_>>(), &restricted);
    let north_only = enhance(&kept.iter().map(|&v| if north(v) { 1.0 } else { 0.0 }).collect::<Vec<_>>(), &restricted);
    let joined = enhance(&vec![1.0; m], &graph);
    let areas = sphere.vertex_volumes();
    let north_area: f64 = (0..m).filter(|&v| north(v)).map(|v| areas[v]).sum();
    for (k, &v) in kept.iter().enumerate() {
        if north(v) {
            assert_eq!(both[k].to_bits(), north_only[k].to_bits());
            // E = 1, H = 2, one threshold band: ∫_0^1 e h² dh = e / 3 (as the sum at
            // 100 steps gives it, within its step).
            assert!((both[k] - north_area / 3.0).abs() < 0.02 * north_area, "{} vs {}", both[k], north_area / 3.0);
            assert!(joined[v] > 1.5 * both[k]);
        }
    }
}

#[test]
fn a_localised_effect_is_found_at_its_place() {
    let sphere = icosphere(3, 1.0);
    let graph = MeshGraph::new(&sphere);
    let centre = [0.6, 0.0, 0.8];
    let (design, maps) = population(&sphere, 24, 2.0, centre, 77);
    let inference = Inference { permutations: 500, seed: 1, tfce: Some(TfceParams::default()), ..Inference::default() };
    let test =
        test_maps(&design, &design.contrast("group").unwrap(), &maps, sphere.n_vertices(), Some(&graph), &inference)
            .unwrap();
    let distance = |v: usize| (0..3).map(|k| (sphere.point(v)[k] - centre[k]).powi(2)).sum::<f64>().sqrt();
    for (name, p) in [("max-t", &test.p_fwe), ("TFCE", test.tfce_p_fwe.as_ref().unwrap())] {
        let found: Vec<usize> = (0..sphere.n_vertices()).filter(|&v| p[v] < 0.05).collect();
        assert!(!found.is_empty(), "{name}: nothing found");
        // Within twice the effect's width of its centre, and the positive
        // side (group 1 higher).
        let far = found.iter().map(|&v| distance(v)).fold(0.0, f64::max);
        eprintln!("{name}: {} vertices at p_FWE < 0.05, the farthest {far:.3} from the centre", found.len());
        assert!(far < 0.7, "{name}: a vertex {far} from the effect");
        assert!(found.iter().all(|&v| test.statistic[v] > 0.0));
    }
    let peak = (0..sphere.n_vertices()).max_by(|&a, &b| test.statistic[a].total_cmp(&test.statistic[b])).unwrap();
    assert!(distance(peak) < 0.35, "peak {} from the centre", distance(peak));
}
