//! The paper's experimental settings, built from the shipped data (the
//! demos of `fshape demo` and the shooting benchmarks use them).

use fshape_mesh::FShape;
use fshape_mesh::generate::icosphere;

use crate::MatchError;

/// The bunny experiment of the paper (section 5): returns (template,
/// target).
///
/// - Target: `bunny` (the 2581-vertex decimation,
///   `data/stanford_bunny/bunny_qslim_2581v.ply.gz`) translated so that its
///   vertex centroid is the origin and scaled to a bounding-box diagonal of
///   1, carrying f = sin(3x/ptp(x)) + y/ptp(y) in those coordinates (ptp:
///   the range max − min over the vertices).
/// - Template: the level-5 icosphere (10242 vertices) of radius 0.35 at the
///   origin, signal 0.
///
/// Model parameters are in `data/configs/bunny.toml`.
pub fn bunny_setting(bunny: &FShape) -> Result<(FShape, FShape), MatchError> {
    bunny_setting_at_level(bunny, 5)
}

/// [`bunny_setting`] with the icosphere of the given level as template
/// (3: 642 vertices, 4: 2562, 5: 10242, the paper's), for quick
/// experiments and coarse stages.
pub fn bunny_setting_at_level(bunny: &FShape, level: u32) -> Result<(FShape, FShape), MatchError> {
    if bunny.dim() != 3 || bunny.kind().dim() != 2 || bunny.n_vertices() == 0 {
        return Err(MatchError::InvalidInput(format!(
            "the bunny must be a non-empty triangle surface in R^3, got a {} mesh in R^{} with {} vertices",
            bunny.kind().name(),
            bunny.dim(),
            bunny.n_vertices()
        )));
    }
    let n = bunny.n_vertices() as f64;
    let mut centre = [0.0; 3];
    for p in bunny.points().chunks_exact(3) {
        for k in 0..3 {
            centre[k] += p[k] / n;
        }
    }
    let diag = bunny.bounding_box().diagonal();
    let pts: Vec<f64> =
        bunny.points().chunks_exact(3).flat_map(|p| (0..3).map(move |k| (p[k] - centre[k]) / diag)).collect();
    let range = |k: usize| {
        let (lo, hi) =
            pts.chunks_exact(3).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p[k]), hi.max(p[k])));
        hi - lo
    };
    let (px, py) = (range(0), range(1));
    let signal = pts.chunks_exact(3).map(|p| (3.0 * p[0] / px).sin() + p[1] / py).collect();
    let target = bunny.clone().with_points(pts)?.with_signal(Some(signal))?;
    let sphere = icosphere(level, 0.35);
    let n_sphere = sphere.n_vertices();
    let template = sphere.with_signal(Some(vec![0.0; n_sphere]))?;
    Ok((template, target))
}

/// `shape` mirrored through the plane x = 0 (a right hemisphere onto a
/// left one): x → −x, and each cell's last two corners swapped so that
/// normals still point out (a reflection reverses orientation); the
/// signal's maps and the mask go with their vertices.
pub fn mirror_x(shape: &FShape) -> Result<FShape, MatchError> {
    let dim = shape.dim();
    let points: Vec<f64> = shape
        .points()
        .chunks_exact(dim)
        .flat_map(|p| p.iter().enumerate().map(|(k, &c)| if k == 0 { -c } else { c }))
        .collect();
    let k = shape.kind().n_corners();
    let mut cells = shape.cells().to_vec();
    if k >= 2 {
        for c in cells.chunks_exact_mut(k) {
            c.swap(k - 2, k - 1);
        }
    }
    Ok(FShape::try_new(dim, shape.kind(), points, cells, None)?.with_signals_and_mask(
        shape.signal().map(<[f64]>::to_vec),
        shape.n_channels().max(1),
        shape.mask().map(<[f64]>::to_vec),
    )?)
}

/// A surface and its copy moved by a known smooth displacement with a
/// known signal change ([`displaced`]).
#[derive(Clone, Debug)]
pub struct DisplacedPair {
    /// The moved copy: the source's cells, its points plus `displacement`,
    /// its signal plus `signal_change`.
    pub target: FShape,
    /// The displacement of each vertex (P × n).
    pub displacement: Vec<f64>,
    /// The signal change at each vertex, map by map (P × k, a vertex's
    /// maps together).
    pub signal_change: Vec<f64>,
}

/// The native-resolution benchmark's target: `source` (with a signal)
/// moved by six Gaussian bumps of displacement of width `width`, at
/// vertices and in directions drawn from `seed`, scaled so that the
/// largest displacement of a vertex is `amplitude`, and its signal changed
/// by four Gaussian bumps of the same width and of heights ±½ the signal's
/// standard deviation (over the vertices with a value: a masked source's
/// mask is kept and its masked vertices stay NaN). With several maps each
/// gets its own four bumps, at places drawn after the map before's (so the
/// first map's change is the one-map change). Deterministic: the same
/// inputs give the same bits.
pub fn displaced(source: &FShape, amplitude: f64, width: f64, seed: u64) -> Result<DisplacedPair, MatchError> {
    use fshape_mesh::generate::SplitMix64;
    let (n, dim) = (source.n_vertices(), source.dim());
    let signal = source
        .signal()
        .ok_or_else(|| MatchError::InvalidInput("the source of a displaced pair needs a signal".into()))?;
    if n == 0 || !(amplitude >= 0.0 && amplitude.is_finite() && width > 0.0 && width.is_finite()) {
        return Err(MatchError::InvalidInput(format!(
            "a displaced pair needs vertices, an amplitude ≥ 0 and a width > 0 (got {n} vertices, {amplitude}, {width})"
        )));
    }
    let mut rng = SplitMix64(seed);
    let x = source.points();
    let bump = |c: usize, p: &[f64]| {
        let u: f64 = (0..dim).map(|k| (p[k] - x[c * dim + k]).powi(2)).sum();
        (-u / (2.0 * width * width)).exp()
    };
    let mut displacement = vec![0.0; n * dim];
    for _ in 0..6 {
        let c = (rng.next_u64() % n as u64) as usize;
        let mut dir: Vec<f64> = (0..dim).map(|_| rng.range(-1.0, 1.0)).collect();
        let norm = dir.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
        dir.iter_mut().for_each(|v| *v /= norm);
        for (i, p) in x.chunks_exact(dim).enumerate() {
            let b = bump(c, p);
            for k in 0..dim {
                displacement[i * dim + k] += b * dir[k];
            }
        }
    }
    let largest =
        displacement.chunks_exact(dim).map(|d| d.iter().map(|v| v * v).sum::<f64>().sqrt()).fold(0.0, f64::max);
    let scale = if largest > 0.0 { amplitude / largest } else { 0.0 };
    displacement.iter_mut().for_each(|v| *v *= scale);
    // Each map's spread over the vertices with a value (a masked vertex's
    // is NaN and stays so on the target).
    let k = source.n_channels().max(1);
    let mut signal_change = vec![0.0; n * k];
    for channel in 0..k {
        let values = || signal.iter().skip(channel).step_by(k).filter(|v| !v.is_nan());
        let valued = values().count().max(1) as f64;
        let mean = values().sum::<f64>() / valued;
        let sd = (values().map(|v| (v - mean) * (v - mean)).sum::<f64>() / valued).sqrt();
        for b in 0..4 {
            let c = (rng.next_u64() % n as u64) as usize;
            let height = if b % 2 == 0 { 0.5 * sd } else { -0.5 * sd };
            for (i, p) in x.chunks_exact(dim).enumerate() {
                signal_change[i * k + channel] += height * bump(c, p);
            }
        }
    }
    let points: Vec<f64> = x.iter().zip(&displacement).map(|(a, b)| a + b).collect();
    let target_signal: Vec<f64> = signal.iter().zip(&signal_change).map(|(a, b)| a + b).collect();
    let target = source.clone().with_points(points)?.with_signals(Some(target_signal), k)?;
    Ok(DisplacedPair { target, displacement, signal_change })
}

#[cfg(test)]
mod tests {
    use fshape_mesh::test_support::perturbed_icosphere;

    /// Σ det(a, b, c)/6 over the triangles: the enclosed volume, positive
    /// when the faces are counter-clockwise seen from outside.
    fn signed_volume(points: &[f64], cells: &[usize]) -> f64 {
        let p = |i: usize| &points[3 * i..3 * i + 3];
        cells
            .chunks_exact(3)
            .map(|c| {
                let (a, b, d) = (p(c[0]), p(c[1]), p(c[2]));
                (a[0] * (b[1] * d[2] - b[2] * d[1]) - a[1] * (b[0] * d[2] - b[2] * d[0])
                    + a[2] * (b[0] * d[1] - b[1] * d[0]))
                    / 6.0
            })
            .sum()
    }

    #[test]
    fn mirroring_negates_x_keeps_the_signal_and_keeps_the_normals_outward() {
        let sphere = icosphere(2, 1.0);
        let pts: Vec<f64> =
            sphere.points().chunks_exact(3).flat_map(|p| [p[0] + 3.0, p[1] - 1.0, p[2] + 2.0]).collect();
        let signal: Vec<f64> = pts.chunks_exact(3).map(|p| p[0] * p[1]).collect();
        let mask: Vec<f64> = (0..pts.len() / 3).map(|v| f64::from(u8::from(v % 5 != 0))).collect();
        let masked: Vec<f64> = signal.iter().zip(&mask).map(|(&f, &m)| if m > 0.0 { f } else { f64::NAN }).collect();
        let shape = sphere
            .with_points(pts.clone())
            .unwrap()
            .with_signals_and_mask(Some(signal.clone()), 1, Some(mask.clone()))
            .unwrap();
        let m = mirror_x(&shape).unwrap();
        for (a, b) in m.points().chunks_exact(3).zip(pts.chunks_exact(3)) {
            assert_eq!(a, [-b[0], b[1], b[2]]);
        }
        assert_eq!(m.mask().unwrap(), &mask[..]);
        let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same(m.signal().unwrap(), &masked));
        let v = signed_volume(&pts, shape.cells());
        // Inscribed in the unit sphere: a little below 4π/3.
        assert!(v > 3.5 && v < 4.0 * std::f64::consts::PI / 3.0, "{v}");
        assert!((signed_volume(m.points(), m.cells()) - v).abs() < 1e-12 * v);
        // The reflection alone turns the faces inside out.
        assert!((signed_volume(m.points(), shape.cells()) + v).abs() < 1e-12 * v);
    }

    use super::*;

    /// A masked source moves as the unmasked one; its target keeps the mask
    /// (NaN there) and the signal bumps scale with the spread of the
    /// values that exist.
    #[test]
    fn a_masked_source_gives_the_same_displacement_and_keeps_its_mask() {
        let whole = perturbed_icosphere(2, 0.05, 3);
        let n = whole.n_vertices();
        let mask: Vec<f64> = (0..n).map(|v| if whole.point(v)[2] > 0.5 { 0.0 } else { 1.0 }).collect();
        let values: Vec<f64> = whole.signal().unwrap().to_vec();
        let masked = whole.clone().with_signal_and_mask(Some(values.clone()), Some(mask.clone())).unwrap();
        let (a, b) = (displaced(&whole, 0.2, 0.5, 7).unwrap(), displaced(&masked, 0.2, 0.5, 7).unwrap());
        assert_eq!(a.displacement, b.displacement);
        assert_eq!(b.target.mask(), Some(&mask[..]));
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt()
        };
        let kept: Vec<f64> = (0..n).filter(|&v| mask[v] > 0.0).map(|v| values[v]).collect();
        let ratio = sd(&kept) / sd(&values);
        for v in 0..n {
            assert!((b.signal_change[v] - ratio * a.signal_change[v]).abs() < 1e-12, "vertex {v}");
            let t = b.target.signal().unwrap()[v];
            assert!(if mask[v] == 0.0 { t.is_nan() } else { (t - values[v] - b.signal_change[v]).abs() < 1e-12 });
        }
    }

    /// With two maps the first changes as alone (the same bits) and the
    /// second by its own bumps, scaled by its own spread, elsewhere.
    #[test]
    fn each_map_changes_by_its_own_bumps_and_the_first_as_alone() {
        let one = perturbed_icosphere(2, 0.05, 3);
        let n = one.n_vertices();
        let first = one.signal().unwrap().to_vec();
        let second: Vec<f64> = (0..n).map(|v| 100.0 * one.point(v)[0]).collect();
        let both: Vec<f64> = first.iter().zip(&second).flat_map(|(a, b)| [*a, *b]).collect();
        let two = one.clone().with_signals(Some(both), 2).unwrap();
        let (a, b) = (displaced(&one, 0.2, 0.3, 7).unwrap(), displaced(&two, 0.2, 0.3, 7).unwrap());
        assert_eq!(a.displacement, b.displacement);
        let channel = |c: usize| -> Vec<f64> { b.signal_change.iter().skip(c).step_by(2).copied().collect() };
        assert_eq!(channel(0), a.signal_change);
        assert_eq!(b.target.n_channels(), 2);
        // The second map's change is of its own size (±½ its deviation at
        // most, four bumps) and not the first's shape.
        let largest = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let (c0, c1) = (channel(0), channel(1));
        let ratio = largest(&c1) / largest(&c0);
        assert!(ratio > 10.0, "{ratio}");
        let scaled: Vec<f64> = c0.iter().map(|x| x * ratio).collect();
        let apart = c1.iter().zip(&scaled).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(apart > 0.1 * largest(&c1), "{apart}");
    }
}
