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
        return Err(MatchError::Shapes(format!(
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
