//! Helpers for the tests of every fshape crate (feature `test-support`):
//! central finite differences, convergence orders, random fshapes for
//! proptest. Kept here, low in the dependency graph, so no crate needs a
//! dev-dependency on a crate above it.

use crate::generate::{self, SplitMix64};
use crate::shape::{CellKind, FShape};

/// The outcome of a finite-difference check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FdCheck {
    /// The analytic directional derivative ⟨∇f, v⟩ (or ‖J v‖ for vectors).
    pub analytic: f64,
    /// The central difference (f(x + hv) − f(x − hv)) / 2h.
    pub numeric: f64,
    /// |numeric − analytic| / max(|numeric|, |analytic|): the relative error.
    pub rel_error: f64,
}

fn axpy(x: &[f64], t: f64, v: &[f64]) -> Vec<f64> {
    x.iter().zip(v).map(|(a, b)| a + t * b).collect()
}

fn rel(a: f64, b: f64) -> f64 {
    let scale = a.abs().max(b.abs());
    if scale == 0.0 { 0.0 } else { (a - b).abs() / scale }
}

/// A random direction with entries uniform in [-1, 1].
pub fn random_direction(n: usize, rng: &mut SplitMix64) -> Vec<f64> {
    (0..n).map(|_| rng.range(-1.0, 1.0)).collect()
}

/// Central finite-difference check of a gradient along direction `v`:
/// compares ⟨grad, v⟩ with (f(x + hv) − f(x − hv)) / 2h. The truncation
/// error is O(h²‖f'''‖), the rounding error O(ε|f|/h): h ≈ 1e-5 × the
/// scale of x balances them for smooth f of moderate size.
pub fn check_gradient(f: impl Fn(&[f64]) -> f64, x: &[f64], grad: &[f64], v: &[f64], h: f64) -> FdCheck {
    assert_eq!(x.len(), grad.len(), "gradient length");
    assert_eq!(x.len(), v.len(), "direction length");
    let numeric = (f(&axpy(x, h, v)) - f(&axpy(x, -h, v))) / (2.0 * h);
    let analytic = grad.iter().zip(v).map(|(g, d)| g * d).sum();
    FdCheck { analytic, numeric, rel_error: rel(numeric, analytic) }
}

/// Central finite-difference check of a Jacobian–vector product: compares
/// `jv` with (F(x + hv) − F(x − hv)) / 2h componentwise; the relative error
/// is ‖numeric − jv‖ / max(‖numeric‖, ‖jv‖) and `analytic`/`numeric` hold
/// the two norms.
pub fn check_jvp(f: impl Fn(&[f64]) -> Vec<f64>, x: &[f64], v: &[f64], jv: &[f64], h: f64) -> FdCheck {
    let (a, b) = (f(&axpy(x, h, v)), f(&axpy(x, -h, v)));
    assert_eq!(a.len(), jv.len(), "Jacobian-vector product length");
    let fd: Vec<f64> = a.iter().zip(&b).map(|(p, m)| (p - m) / (2.0 * h)).collect();
    let norm = |u: &[f64]| u.iter().map(|t| t * t).sum::<f64>().sqrt();
    let diff: Vec<f64> = fd.iter().zip(jv).map(|(p, q)| p - q).collect();
    let (nf, nj) = (norm(&fd), norm(jv));
    let scale = nf.max(nj);
    FdCheck { analytic: nj, numeric: nf, rel_error: if scale == 0.0 { 0.0 } else { norm(&diff) / scale } }
}

/// The observed convergence order: the least-squares slope of log(err)
/// against log(h) (`h` the mesh sizes, `err` the errors).
///
/// ```
/// use fshape_mesh::test_support::observed_order;
/// let h = [0.1, 0.05, 0.025];
/// let err: Vec<f64> = h.iter().map(|h| 3.0 * h * h).collect();
/// assert!((observed_order(&h, &err) - 2.0).abs() < 1e-12);
/// ```
pub fn observed_order(h: &[f64], err: &[f64]) -> f64 {
    assert_eq!(h.len(), err.len(), "one error per mesh size");
    let (x, y): (Vec<f64>, Vec<f64>) = h.iter().zip(err).map(|(h, e)| (h.ln(), e.ln())).unzip();
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(&y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    sxy / sxx
}

/// An icosphere of the given level with every vertex moved radially by a
/// factor in [1 − amplitude, 1 + amplitude], and a smooth random signal
/// (a random linear function of position plus a constant).
pub fn perturbed_icosphere(level: u32, amplitude: f64, seed: u64) -> FShape {
    let mut rng = SplitMix64(seed);
    let (dim, kind, mut points, cells, _) = generate::icosphere(level, 1.0).into_parts();
    for p in points.chunks_exact_mut(3) {
        let s = 1.0 + rng.range(-amplitude, amplitude);
        p.iter_mut().for_each(|x| *x *= s);
    }
    let signal = smooth_signal(&points, 3, &mut rng);
    FShape::try_new(dim, kind, points, cells, Some(signal)).expect("a perturbed icosphere is valid")
}

/// A Delaunay square with about `n` vertices (random interior seed points),
/// jittered slightly, with a smooth random signal.
pub fn random_square(n: usize, seed: u64) -> FShape {
    let mut rng = SplitMix64(seed ^ 0x5EED);
    let (dim, kind, points, cells, _) = generate::square(n, seed | 1).into_parts();
    let signal = smooth_signal(&points, 2, &mut rng);
    FShape::try_new(dim, kind, points, cells, Some(signal)).expect("a Delaunay square is valid")
}

/// A closed curve of `n` segments in R^dim: a circle with random radial
/// wobble (and random heights in 3-D), with a smooth random signal.
pub fn random_curve(dim: usize, n: usize, seed: u64) -> FShape {
    let mut rng = SplitMix64(seed);
    let n = n.max(3);
    let mut points = Vec::with_capacity(n * dim);
    for k in 0..n {
        let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
        let r = 1.0 + rng.range(-0.2, 0.2);
        points.extend([r * a.cos(), r * a.sin()]);
        if dim == 3 {
            points.push(rng.range(-0.2, 0.2));
        }
    }
    let signal = smooth_signal(&points, dim, &mut rng);
    let cells = (0..n).flat_map(|k| [k, (k + 1) % n]).collect();
    FShape::try_new(dim, CellKind::Segment, points, cells, Some(signal)).expect("a wobbly circle is valid")
}

fn smooth_signal(points: &[f64], dim: usize, rng: &mut SplitMix64) -> Vec<f64> {
    let a: Vec<f64> = (0..dim).map(|_| rng.range(-1.0, 1.0)).collect();
    let c = rng.range(-1.0, 1.0);
    points
        .chunks_exact(dim)
        .map(|p| c + p.iter().zip(&a).map(|(x, w)| x * w).sum::<f64>() + 0.3 * (2.0 * p[0]).sin())
        .collect()
}

/// A random vector field (momenta, velocities): `n` vectors of `dim`
/// components uniform in [-scale, scale], flat.
pub fn random_vector_field(n: usize, dim: usize, scale: f64, seed: u64) -> Vec<f64> {
    let mut rng = SplitMix64(seed);
    (0..n * dim).map(|_| rng.range(-scale, scale)).collect()
}

/// proptest strategies over random fshapes, driven by a random seed.
pub mod strategies {
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngSeed};

    /// The configuration of every property test of the workspace: `cases`
    /// cases drawn from the fixed `seed`, so that CI checks the same cases
    /// on every run, unless the environment chooses others:
    /// `FSHAPE_PROPTEST_SEED` (a u64) replaces the seed and
    /// `FSHAPE_PROPTEST_CASES` the number of cases, for every property test
    /// at once (README, "Development"; `scripts/proptest-seeds.sh` runs
    /// them over a range of seeds). A failure prints the minimal failing
    /// input; the same seed and cases reproduce it.
    ///
    /// # Panics
    /// If a variable is set to something other than a number.
    pub fn config(cases: u32, seed: u64) -> Config {
        let var = |name: &str| {
            std::env::var(name).ok().map(|v| {
                v.trim().parse::<u64>().unwrap_or_else(|_| panic!("{name} must be a non-negative integer, got {v:?}"))
            })
        };
        let cases = var("FSHAPE_PROPTEST_CASES").map_or(cases, |c| u32::try_from(c).unwrap_or(u32::MAX));
        let seed = var("FSHAPE_PROPTEST_SEED").unwrap_or(seed);
        Config { cases, rng_seed: RngSeed::Fixed(seed), failure_persistence: None, ..Config::default() }
    }

    use crate::shape::FShape;

    /// Perturbed icospheres of level 0..=`max_level` with a smooth signal.
    pub fn icospheres(max_level: u32) -> impl Strategy<Value = FShape> {
        (0..=max_level, any::<u64>()).prop_map(|(l, s)| super::perturbed_icosphere(l, 0.1, s))
    }

    /// Random Delaunay squares with 20..`max_vertices` vertices.
    pub fn squares(max_vertices: usize) -> impl Strategy<Value = FShape> {
        (20..max_vertices.max(21), any::<u64>()).prop_map(|(n, s)| super::random_square(n, s))
    }

    /// Random closed curves in R^dim with 3..`max_vertices` vertices.
    pub fn curves(dim: usize, max_vertices: usize) -> impl Strategy<Value = FShape> {
        (3..max_vertices.max(4), any::<u64>()).prop_map(move |(n, s)| super::random_curve(dim, n, s))
    }

    /// A shape from `shapes` with random momenta (one vector per vertex, of
    /// the shape's dimension, entries in [-scale, scale]).
    pub fn with_momenta(
        shapes: impl Strategy<Value = FShape>,
        scale: f64,
    ) -> impl Strategy<Value = (FShape, Vec<f64>)> {
        (shapes, any::<u64>()).prop_map(move |(s, seed)| {
            let p = super::random_vector_field(s.n_vertices(), s.dim(), scale, seed);
            (s, p)
        })
    }

    /// Any of the above, small: the mixed population for format round trips.
    pub fn any_small() -> impl Strategy<Value = FShape> {
        prop_oneof![icospheres(2), squares(80), curves(2, 30), curves(3, 30)]
    }
}

/// The property of the fuzz target `table`, also replayed on its corpus by
/// plain `cargo test`: any table that parses is written back to the same
/// cells, `parse(write(parse(x))) = parse(x)`, and its neutralised text
/// differs only by a `'` before cells a spreadsheet would run.
///
/// # Panics
///
/// When the property fails (that is the point).
pub fn table_round_trip(data: &[u8]) {
    use crate::io::table::{neutralise, parse_table, table_text};
    let Ok(rows) = parse_table(data) else { return };
    let cells: Vec<Vec<String>> = rows.into_iter().map(|r| r.fields).collect();
    let text = table_text(&cells, false);
    let back: Vec<Vec<String>> =
        parse_table(text.as_bytes()).expect("our own table parses").into_iter().map(|r| r.fields).collect();
    assert_eq!(back, cells, "written as {text:?}");
    let neutral: Vec<Vec<String>> = parse_table(table_text(&cells, true).as_bytes())
        .expect("our own table parses")
        .into_iter()
        .map(|r| r.fields)
        .collect();
    let expected: Vec<Vec<String>> =
        cells.iter().map(|row| row.iter().map(|c| neutralise(c).into_owned()).collect()).collect();
    assert_eq!(neutral, expected);
}
