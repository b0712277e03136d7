//! Masked measures: a vertex mask makes each cell two measures, the
//! functional varifold of the masses m r and the plain varifold of the
//! masses (1 − m) r (m the smallest corner weight). Checked against a
//! double loop written from that definition, by central differences, and
//! for what a mask promises: masked values are never read, an all-ones mask
//! is no mask, and A stays a squared distance.

use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, random_direction};
use fshape_varifold::{Attachment, CellFeatures, GrassKernel, VarifoldKernel};

use crate::{kernels, shape_pairs};

/// A random mask: a third of the vertices 0, a third 1, the rest in (0, 1).
fn mask(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| match rng.next_u64() % 3 {
            0 => 0.0,
            1 => 1.0,
            _ => rng.range(0.05, 0.95),
        })
        .collect()
}

pub fn masked(s: &FShape, seed: u64) -> FShape {
    s.clone().with_mask(Some(mask(s.n_vertices(), seed))).unwrap()
}

/// ⟨μ_X, μ_Y⟩ from the definition: Σ r r k_p k_t (m m' k_f + (1 − m)(1 − m')),
/// without the second term when the masked geometry does not count.
pub fn brute_masked(x: &FShape, y: &FShape, k: &VarifoldKernel) -> f64 {
    let (ex, ey) = (CellFeatures::of(x).unwrap(), CellFeatures::of(y).unwrap());
    let one = |f: &CellFeatures| vec![1.0; f.len()];
    let (mx, my) =
        (ex.mask().map_or_else(|| one(&ex), <[f64]>::to_vec), ey.mask().map_or_else(|| one(&ey), <[f64]>::to_vec));
    let (d, du) = (ex.dim(), ex.dir_len());
    let mut total = 0.0;
    for i in 0..ex.len() {
        for j in 0..ey.len() {
            let u: f64 = (0..d).map(|c| (ex.centres()[i * d + c] - ey.centres()[j * d + c]).powi(2)).sum();
            let s: f64 = (0..du).map(|c| ex.dirs()[i * du + c] * ey.dirs()[j * du + c]).sum();
            let nf = ex.n_channels();
            let kf = match ex.signal().zip(ey.signal()) {
                Some((fx, fy)) => crate::oracle::signal_factor(
                    k.signal(),
                    &fx[i * nf..(i + 1) * nf],
                    &fy[j * ey.n_channels()..(j + 1) * ey.n_channels()],
                ),
                None => 1.0,
            };
            let kt = match k.grass() {
                GrassKernel::Linear => s,
                GrassKernel::Binet => s * s,
                GrassKernel::OrientedGaussian { sigma } => (-2.0 * (1.0 - s) / (sigma * sigma)).exp(),
                GrassKernel::UnorientedGaussian { sigma } => (-2.0 * (1.0 - s * s) / (sigma * sigma)).exp(),
            };
            let geometric = if k.masked_geometry() { (1.0 - mx[i]) * (1.0 - my[j]) } else { 0.0 };
            let share = mx[i] * my[j] * kf + geometric;
            total += ex.weights()[i] * ey.weights()[j] * k.position().value(u) * kt * share;
        }
    }
    total
}

/// Each kernel with the masked geometry counted (the default) and not.
fn both(kernels: Vec<VarifoldKernel>) -> Vec<VarifoldKernel> {
    kernels.into_iter().flat_map(|k| [k.clone(), k.with_masked_geometry(false)]).collect()
}

#[test]
fn a_masked_inner_product_is_the_definitions_double_sum() {
    for (what, x, y) in shape_pairs(31) {
        let (x, y) = (masked(&x, 1), masked(&y, 2));
        for k in both(kernels()).into_iter().filter(|k| k.position().taper().is_none()) {
            let (ex, ey) = (CellFeatures::of(&x).unwrap(), CellFeatures::of(&y).unwrap());
            let got = fshape_varifold::inner_product(&ex, &ey, &k).unwrap();
            let want = brute_masked(&x, &y, &k);
            let scale = k.position().value(0.0) * x.total_volume() * y.total_volume();
            assert!((got - want).abs() <= 1e-12 * scale, "{what}, {k:?}: {got} against {want}");
        }
    }
}

#[test]
fn one_masked_corner_keeps_its_cell_out_of_the_signal() {
    let s = fshape_mesh::test_support::perturbed_icosphere(1, 0.0, 1);
    let n = s.n_vertices();
    let mut m = vec![1.0; n];
    m[0] = 0.0;
    let f: Vec<f64> = (0..n).map(|v| v as f64).collect();
    let s = s.with_signal_and_mask(Some(f), Some(m)).unwrap();
    let e = CellFeatures::of(&s).unwrap();
    for (t, cell) in s.cell_iter().enumerate() {
        let share = e.mask().unwrap()[t];
        assert_eq!(share, if cell.contains(&0) { 0.0 } else { 1.0 }, "cell {t}");
        if cell.contains(&0) {
            assert_eq!(e.signal().unwrap()[t], 0.0, "a masked cell's signal is not read");
        }
    }
}

#[test]
fn masked_gradients_match_central_differences() {
    let mut rng = SplitMix64(5);
    for (what, x, y) in shape_pairs(37) {
        let (x, y) = (masked(&x, 3), masked(&y, 4));
        for k in both(kernels()) {
            let att = Attachment::new(&y, k.clone()).unwrap();
            let (_, g) = att.eval_grad(&x).unwrap();
            let a = |s: &FShape| att.eval(s).unwrap().value;
            let v = random_direction(x.points().len(), &mut rng);
            let c = check_gradient(|p| a(&x.clone().with_points(p.to_vec()).unwrap()), x.points(), &g.points, &v, 1e-5);
            let size: f64 = g.points.iter().zip(&v).map(|(a, b)| (a * b).abs()).sum();
            assert!((c.numeric - c.analytic).abs() < 1e-7 * size, "{what}, {k:?}: ∂A/∂x {c:?}");
            // The signal at masked vertices is NaN and its gradient 0; move
            // only the others.
            let m = x.mask().unwrap();
            let f: Vec<f64> = x.signal().unwrap().iter().map(|v| if v.is_nan() { 0.0 } else { *v }).collect();
            let v: Vec<f64> = random_direction(f.len(), &mut rng)
                .iter()
                .zip(m)
                .map(|(d, w)| if *w > 0.0 { *d } else { 0.0 })
                .collect();
            let c = check_gradient(|f| a(&x.clone().with_signal(Some(f.to_vec())).unwrap()), &f, &g.signal, &v, 1e-5);
            let size: f64 = g.signal.iter().zip(&v).map(|(a, b)| (a * b).abs()).sum::<f64>().max(1e-300);
            assert!((c.numeric - c.analytic).abs() < 1e-7 * size.max(c.analytic.abs()), "{what}, {k:?}: ∂A/∂f {c:?}");
            for (v, w) in m.iter().enumerate() {
                if *w == 0.0 {
                    assert_eq!(g.signal[v], 0.0, "{what}: a masked vertex's signal has a gradient");
                }
            }
        }
    }
}

#[test]
fn masked_values_are_never_read_and_an_all_ones_mask_is_no_mask() {
    for (what, x, y) in shape_pairs(41) {
        let k = &kernels()[0];
        let (mx, my) = (mask(x.n_vertices(), 6), mask(y.n_vertices(), 7));
        let fill = |s: &FShape, m: &[f64], value: f64| {
            let f: Vec<f64> =
                s.signal().unwrap().iter().zip(m).map(|(f, w)| if *w == 0.0 { value } else { *f }).collect();
            s.clone().with_signal_and_mask(Some(f), Some(m.to_vec())).unwrap()
        };
        let run = |value: f64| {
            let att = Attachment::new(&fill(&y, &my, value), k.clone()).unwrap();
            let (d, g) = att.eval_grad(&fill(&x, &mx, value)).unwrap();
            (d.value.to_bits(), g.points.iter().chain(&g.signal).map(|v| v.to_bits()).collect::<Vec<_>>())
        };
        let reference = run(f64::NAN);
        assert!(f64::from_bits(reference.0).is_finite(), "{what}");
        for value in [0.0, 1e300, -7.0] {
            assert_eq!(run(value), reference, "{what}: masked values {value} changed the result");
        }
        // All ones: the bits of no mask.
        let ones = |s: &FShape| s.clone().with_mask(Some(vec![1.0; s.n_vertices()])).unwrap();
        let plain = Attachment::new(&y, k.clone()).unwrap().eval_grad(&x).unwrap();
        let ones_run = Attachment::new(&ones(&y), k.clone()).unwrap().eval_grad(&ones(&x)).unwrap();
        assert_eq!(plain.0.value.to_bits(), ones_run.0.value.to_bits(), "{what}");
        assert_eq!(plain.1, ones_run.1, "{what}");
    }
}

#[test]
fn a_masked_attachment_is_a_squared_distance() {
    for (what, x, y) in shape_pairs(43) {
        for k in kernels() {
            let (mx, my) = (masked(&x, 8), masked(&y, 9));
            let a = Attachment::new(&my, k.clone()).unwrap().eval(&mx).unwrap();
            assert!(a.value >= -1e-12 * (a.xx + a.yy), "{what}, {k:?}: A = {}", a.value);
            let own = Attachment::new(&mx, k.clone()).unwrap().eval(&mx).unwrap();
            assert!(own.value.abs() <= 1e-12 * own.xx, "{what}, {k:?}: A(X, X) = {}", own.value);
            // The Gram matrix of a few masked measures is positive semi-definite.
            let shapes = [masked(&x, 10), masked(&x, 11), mx.clone()];
            let feats: Vec<CellFeatures> = shapes.iter().map(|s| CellFeatures::of(s).unwrap()).collect();
            let g: Vec<Vec<f64>> = feats
                .iter()
                .map(|a| feats.iter().map(|b| fshape_varifold::inner_product(a, b, &k).unwrap()).collect())
                .collect();
            let det2 = g[0][0] * g[1][1] - g[0][1] * g[1][0];
            assert!(g[0][0] > 0.0 && det2 >= -1e-10 * g[0][0] * g[1][1], "{what}, {k:?}: {g:?}");
        }
    }
}
