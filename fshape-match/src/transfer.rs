//! Maps and labels carried through a registration.
//!
//! A registration ends with the source's vertices moved onto the target:
//! the matched shape (the source's cells at the shot positions). Values
//! carried from the source onto the target are read, at each target vertex,
//! at its closest point on the matched shape; values carried back, at each
//! matched vertex, at its closest point on the target. Both are one
//! operation, [`Correspondence`]: values on a mesh `from`'s vertices read at
//! the vertices of `onto`, through `from`'s exact closest points
//! ([`ClosestPoints`]).
//!
//! The rules, stated once:
//!
//! - **maps**: the barycentric mean of the closest cell's corners (linear
//!   interpolation on the surface). A corner without a value (NaN, as a
//!   masked vertex or HCP's medial wall) is left out and the others'
//!   weights renormalised, as long as the corners with a value carry at
//!   least half the weight; below that the point is in the missing region
//!   and gets NaN. The edge of a masked region therefore moves by less
//!   than one cell, and a point inside it stays missing.
//! - **labels** (integer keys, −1 for none): the key whose corners carry
//!   the largest total barycentric weight, ties to the smaller key (−1, no
//!   region, competes as a key). A label is never averaged.
//! - **distance**: a vertex of `onto` farther than `max_distance` from
//!   `from` gets NaN (maps) or −1 (labels): no part of the registration
//!   brought a value there.
//!
//! Connectome Workbench's `-metric-resample` does the same between two
//! spheres in register (its BARYCENTRIC method, with `-current-roi`
//! leaving out vertices outside the ROI); here the correspondence is the
//! registration's own matched surface, in the target's space, so no
//! sphere is needed, and the distance to it says where it is not to be
//! trusted.

use fshape_mesh::FShape;
use rayon::prelude::*;

use crate::MatchError;
use crate::quality::{Closest, ClosestPoints};

/// For every vertex of a mesh `onto`, its closest point on a mesh `from`:
/// the cell, the barycentric coordinates and the distance.
#[derive(Clone, Debug)]
pub struct Correspondence {
    /// The corners of each hit cell (the third repeats the second for a
    /// segment, whose third weight is 0).
    corners: Vec<[usize; 3]>,
    bary: Vec<[f64; 3]>,
    distance: Vec<f64>,
    from_vertices: usize,
}

/// What a map's carrying left without a value, counted over `onto`'s
/// vertices.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Carried {
    /// Vertices of `onto`.
    pub vertices: usize,
    /// Vertices farther than the distance limit from `from`.
    pub beyond: usize,
    /// Vertices within it whose closest cell carries less than half its
    /// weight on corners with a value.
    pub missing: usize,
}

impl Correspondence {
    /// The closest point on `from` (triangles or segments) of every vertex
    /// of `onto`, which must live in the same space (same dimension).
    pub fn new(from: &FShape, onto: &FShape) -> Result<Self, MatchError> {
        if from.dim() != onto.dim() {
            return Err(MatchError::Kinds(format!(
                "carrying values: a mesh in {}-D onto one in {}-D",
                from.dim(),
                onto.dim()
            )));
        }
        let closest = ClosestPoints::new(from)?;
        let dim = onto.dim();
        let hits: Vec<Closest> = (0..onto.n_vertices())
            .into_par_iter()
            .map(|v| {
                let x = onto.point(v);
                closest.closest([x[0], x[1], if dim == 3 { x[2] } else { 0.0 }])
            })
            .collect();
        let k = from.kind().n_corners();
        let corners = hits
            .iter()
            .map(|h| {
                let ids = &from.cells()[h.cell * k..(h.cell + 1) * k];
                [ids[0], ids[1], ids[k - 1]]
            })
            .collect();
        Ok(Correspondence {
            corners,
            bary: hits.iter().map(|h| h.bary).collect(),
            distance: hits.iter().map(|h| h.distance).collect(),
            from_vertices: from.n_vertices(),
        })
    }

    /// Each `onto` vertex's distance to `from`.
    pub fn distances(&self) -> &[f64] {
        &self.distance
    }

    /// Vertices of `onto`.
    pub fn len(&self) -> usize {
        self.distance.len()
    }

    /// Whether `onto` has no vertices.
    pub fn is_empty(&self) -> bool {
        self.distance.is_empty()
    }

    /// Whether vertex `i` of `onto` gets no value: farther than the limit,
    /// or its closest point not a number (coordinates so large that the
    /// distance overflowed).
    fn beyond(&self, i: usize, max_distance: f64) -> bool {
        let d = self.distance[i];
        d.is_nan() || d > max_distance || self.bary[i].iter().any(|w| w.is_nan())
    }

    fn check(&self, what: &str, n: usize, max_distance: f64) -> Result<(), MatchError> {
        if max_distance.is_nan() || max_distance < 0.0 {
            return Err(MatchError::InvalidInput(format!(
                "carrying {what}: the largest distance must be ≥ 0 (infinity for none), not {max_distance}"
            )));
        }
        if n != self.from_vertices {
            return Err(MatchError::InvalidInput(format!(
                "carrying {what}: {n} values for a mesh of {} vertices",
                self.from_vertices
            )));
        }
        Ok(())
    }

    /// A map on `from`'s vertices (NaN where it has no value) read at every
    /// vertex of `onto` (see the module's rules), with NaN beyond
    /// `max_distance`; and what was left without a value.
    pub fn map(&self, values: &[f64], max_distance: f64) -> Result<(Vec<f64>, Carried), MatchError> {
        self.check("a map", values.len(), max_distance)?;
        if let Some(v) = values.iter().position(|v| v.is_infinite()) {
            return Err(MatchError::InvalidInput(format!("carrying a map: vertex {v} is {}", values[v])));
        }
        let mut carried = Carried { vertices: self.len(), ..Carried::default() };
        let out = (0..self.len())
            .map(|i| {
                if self.beyond(i, max_distance) {
                    carried.beyond += 1;
                    return f64::NAN;
                }
                let (mut sum, mut weight) = (0.0, 0.0);
                for (&c, &w) in self.corners[i].iter().zip(&self.bary[i]) {
                    if w > 0.0 && !values[c].is_nan() {
                        sum += w * values[c];
                        weight += w;
                    }
                }
                if weight >= 0.5 {
                    sum / weight
                } else {
                    carried.missing += 1;
                    f64::NAN
                }
            })
            .collect();
        Ok((out, carried))
    }

    /// Integer labels on `from`'s vertices (−1: no region) read at every
    /// vertex of `onto` (see the module's rules), −1 beyond `max_distance`.
    pub fn labels(&self, keys: &[i32], max_distance: f64) -> Result<Vec<i32>, MatchError> {
        self.check("labels", keys.len(), max_distance)?;
        Ok((0..self.len())
            .map(|i| {
                if self.beyond(i, max_distance) {
                    return -1;
                }
                // At most three candidate keys: sum each one's weight.
                let mut tally: [Option<(i32, f64)>; 3] = [None; 3];
                for (&c, &w) in self.corners[i].iter().zip(&self.bary[i]) {
                    let key = keys[c];
                    for slot in tally.iter_mut() {
                        match slot {
                            Some((k, t)) if *k == key => *t += w,
                            Some(_) => continue,
                            None => *slot = Some((key, w)),
                        }
                        break;
                    }
                }
                tally.iter().flatten().max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0))).map_or(-1, |&(k, _)| k)
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use fshape_mesh::test_support::perturbed_icosphere;
    use fshape_mesh::{CellKind, FShape};

    use super::*;

    /// A smooth map of the position.
    fn g(x: &[f64]) -> f64 {
        (1.3 * x[0]).sin() + x[1] * x[2] + 0.5 * x[2]
    }

    /// A smooth diffeomorphism of space (a shear and a twist), and its
    /// inverse.
    fn phi(x: &[f64]) -> [f64; 3] {
        let a = 0.3 * x[2];
        let (c, s) = (a.cos(), a.sin());
        [c * x[0] - s * x[1] + 0.2, s * x[0] + c * x[1], 1.1 * x[2] + 0.1 * x[0]]
    }

    fn phi_inverse(y: &[f64]) -> [f64; 3] {
        // Fixed point on z: 1.1 z + 0.1 x = y₂ with x = c(y₀ − 0.2) + s y₁.
        let mut z = y[2] / 1.1;
        let mut x = [0.0; 3];
        for _ in 0..100 {
            let a = 0.3 * z;
            let (c, s) = (a.cos(), a.sin());
            x = [c * (y[0] - 0.2) + s * y[1], -s * (y[0] - 0.2) + c * y[1], z];
            z = (y[2] - 0.1 * x[0]) / 1.1;
        }
        x
    }

    fn moved(shape: &FShape) -> FShape {
        let points = (0..shape.n_vertices()).flat_map(|v| phi(shape.point(v))).collect();
        shape.clone().with_points(points).unwrap()
    }

    /// A source sphere moved by a known φ (the registration's ideal
    /// result), and a target that is φ of a *different* mesh of the same
    /// sphere: a map g on the source, carried onto the target, is g∘φ⁻¹
    /// there up to the interpolation error O(h²), and carried back it is
    /// g again; the error falls by about 4 when h halves.
    #[test]
    fn a_map_carried_through_a_known_diffeomorphism_is_the_map_composed_with_its_inverse() {
        let mut errors = Vec::new();
        for level in [2, 3, 4] {
            let source = perturbed_icosphere(level, 0.0, 1);
            let matched = moved(&source);
            // The target: another sphere mesh (rotated, so no vertex is shared), moved.
            let other = perturbed_icosphere(level, 0.0, 1);
            let (c, s) = (0.7f64.cos(), 0.7f64.sin());
            let rotated: Vec<f64> = (0..other.n_vertices())
                .flat_map(|v| {
                    let x = other.point(v);
                    [c * x[0] - s * x[1], s * x[0] + c * x[1], x[2]]
                })
                .collect();
            let target = moved(&other.clone().with_points(rotated).unwrap());
            let f: Vec<f64> = (0..source.n_vertices()).map(|v| g(source.point(v))).collect();
            let (on_target, carried) = Correspondence::new(&matched, &target).unwrap().map(&f, 0.1).unwrap();
            assert_eq!((carried.beyond, carried.missing), (0, 0));
            let error = (0..target.n_vertices())
                .map(|v| {
                    // The truth: g at φ⁻¹(y) projected onto the unit sphere
                    // (the source's vertices lie on it, its cells inside).
                    let x = phi_inverse(target.point(v));
                    let r = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
                    (on_target[v] - g(&[x[0] / r, x[1] / r, x[2] / r])).abs()
                })
                .fold(0.0, f64::max);
            // And back: the target's true map read at the matched vertices.
            let truth: Vec<f64> = (0..target.n_vertices())
                .map(|v| {
                    let x = phi_inverse(target.point(v));
                    let r = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
                    g(&[x[0] / r, x[1] / r, x[2] / r])
                })
                .collect();
            let (back, _) = Correspondence::new(&target, &matched).unwrap().map(&truth, 0.1).unwrap();
            let back_error = (0..source.n_vertices()).map(|v| (back[v] - f[v]).abs()).fold(0.0, f64::max);
            errors.push((error, back_error));
        }
        for pair in errors.windows(2) {
            let ((e0, b0), (e1, b1)) = (pair[0], pair[1]);
            assert!(e1 < e0 / 3.0 && b1 < b0 / 3.0, "not second order: {errors:?}");
        }
        let (e, b) = errors[2];
        assert!(e < 5e-3 && b < 5e-3, "{errors:?}");
    }

    /// Labels by half-spaces of the source carry onto the target exactly,
    /// except at vertices within one cell of a region's edge.
    #[test]
    fn labels_carried_are_the_true_regions_but_within_a_cell_of_their_edges() {
        let source = perturbed_icosphere(4, 0.0, 1);
        let matched = moved(&source);
        let target = moved(&perturbed_icosphere(3, 0.0, 1));
        let region = |x: &[f64]| {
            if x[2] > 0.3 {
                2
            } else if x[0] > 0.0 {
                5
            } else {
                -1
            }
        };
        let keys: Vec<i32> = (0..source.n_vertices()).map(|v| region(source.point(v))).collect();
        let carried = Correspondence::new(&matched, &target).unwrap().labels(&keys, 0.1).unwrap();
        let h = 0.1; // above the longest edge of the level-4 sphere
        let (mut wrong, mut far_from_edges) = (0, 0);
        for (v, &key) in carried.iter().enumerate() {
            let x = phi_inverse(target.point(v));
            let near_edge = (x[2] - 0.3).abs() < h || (x[2] <= 0.3 + h && x[0].abs() < h);
            if !near_edge {
                far_from_edges += 1;
                if key != region(&x) {
                    wrong += 1;
                }
            }
        }
        assert!(far_from_edges > target.n_vertices() / 2);
        assert_eq!(wrong, 0);
        // Every key that exists is carried, nothing else appears.
        let mut seen: Vec<i32> = carried.clone();
        seen.sort();
        seen.dedup();
        assert_eq!(seen, vec![-1, 2, 5]);
    }

    /// A registration's ideal end on a brain-sized sphere (radius 50 mm):
    /// the matched source is ψ(source) for a twist, a stretch and a shift
    /// that move every point by 10 to 35 mm, far more than the map's
    /// features (Gaussian bumps 10 mm across at half height) and than the
    /// region (12 mm in radius). The target is ψ of another mesh of the
    /// sphere. Through the matched surface the map arrives within 1 % of
    /// its range and the region with a Dice ≥ 0.95; the closest points on
    /// the unmoved source (no registration) do at least 10× worse.
    #[test]
    fn maps_and_regions_cross_displacements_much_larger_than_their_features() {
        const R: f64 = 50.0;
        let psi = |x: &[f64]| {
            let a = 0.8 * x[2] / R;
            let (c, s) = (a.cos(), a.sin());
            [1.2 * (c * x[0] - s * x[1]) + 15.0, 0.85 * (s * x[0] + c * x[1]) - 10.0, x[2] + 5.0]
        };
        // ψ⁻¹, then the radial projection onto the sphere the source's
        // vertices lie on.
        let on_sphere_before = |y: &[f64]| {
            let (u, v, z) = ((y[0] - 15.0) / 1.2, (y[1] + 10.0) / 0.85, y[2] - 5.0);
            let a = -0.8 * z / R;
            let (c, s) = (a.cos(), a.sin());
            let x = [c * u - s * v, s * u + c * v, z];
            let r = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
            [R * x[0] / r, R * x[1] / r, R * x[2] / r]
        };
        let sphere = |turn: f64| {
            let unit = perturbed_icosphere(6, 0.0, 1);
            let (c, s) = (turn.cos(), turn.sin());
            let points = (0..unit.n_vertices())
                .flat_map(|v| {
                    let x = unit.point(v);
                    // A turn about z, then about x: no vertex of one mesh on the other's.
                    let (x0, x1) = (c * x[0] - s * x[1], s * x[0] + c * x[1]);
                    [R * x0, R * (c * x1 - s * x[2]), R * (s * x1 + c * x[2])]
                })
                .collect();
            unit.with_points(points).unwrap()
        };
        let moved = |shape: &FShape| {
            let points = (0..shape.n_vertices()).flat_map(|v| psi(shape.point(v))).collect();
            shape.clone().with_points(points).unwrap()
        };
        let source = sphere(0.0);
        let target = moved(&sphere(0.7));
        let matched = moved(&source);
        // Bumps at twelve spread directions (a golden-angle spiral).
        let centres: Vec<[f64; 3]> = (0..12)
            .map(|i| {
                let z = 1.0 - (2.0 * i as f64 + 1.0) / 12.0;
                let (r, a) = ((1.0 - z * z).sqrt(), 2.399963 * i as f64);
                [R * r * a.cos(), R * r * a.sin(), R * z]
            })
            .collect();
        let sigma = 10.0 / (2.0 * (2.0 * 2f64.ln()).sqrt());
        let g = |x: &[f64]| -> f64 {
            centres
                .iter()
                .map(|c| (-(0..3).map(|k| (x[k] - c[k]).powi(2)).sum::<f64>() / (2.0 * sigma * sigma)).exp())
                .sum()
        };
        let region = |x: &[f64]| (0..3).map(|k| (x[k] - centres[4][k]).powi(2)).sum::<f64>() < 144.0;
        let f: Vec<f64> = (0..source.n_vertices()).map(|v| g(source.point(v))).collect();
        let keys: Vec<i32> = (0..source.n_vertices()).map(|v| if region(source.point(v)) { 1 } else { -1 }).collect();
        let truth: Vec<[f64; 3]> = (0..target.n_vertices()).map(|u| on_sphere_before(target.point(u))).collect();
        let range = f.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b)) - f.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        let judge = |from: &FShape| {
            let c = Correspondence::new(from, &target).unwrap();
            let (map, _) = c.map(&f, f64::INFINITY).unwrap();
            let error = map.iter().zip(&truth).map(|(m, x)| (m - g(x)).abs()).fold(0.0, f64::max) / range;
            let labels = c.labels(&keys, f64::INFINITY).unwrap();
            let (mut both, mut got, mut true_) = (0, 0, 0);
            for (l, x) in labels.iter().zip(&truth) {
                let (a, b) = (*l == 1, region(x));
                both += usize::from(a && b);
                got += usize::from(a);
                true_ += usize::from(b);
            }
            (error, 2.0 * both as f64 / (got + true_) as f64, true_)
        };
        let (error, dice, size) = judge(&matched);
        let (naive_error, naive_dice, _) = judge(&source);
        assert!(size >= 200, "the region has {size} vertices");
        assert!(error <= 0.01 && dice >= 0.95, "through the matched surface: error {error}, Dice {dice}");
        assert!(
            naive_error >= 10.0 * error && 1.0 - naive_dice >= 10.0 * (1.0 - dice),
            "the unmoved source: error {naive_error} against {error}, Dice {naive_dice} against {dice}"
        );
        eprintln!("error {error:.5} (naive {naive_error:.3}), Dice {dice:.4} (naive {naive_dice:.3}), {size} vertices");
    }

    /// The rule for missing corners and the distance limit, on one
    /// triangle: a point at a corner's weights gets the renormalised mean
    /// while the corners with a value carry half the weight, NaN below;
    /// a point farther than the limit gets NaN and −1.
    #[test]
    fn missing_corners_and_the_distance_limit_follow_the_stated_rule() {
        let tri = FShape::try_new(3, CellKind::Triangle, vec![0., 0., 0., 1., 0., 0., 0., 1., 0.], vec![0, 1, 2], None)
            .unwrap();
        let at = |p: &[[f64; 3]]| {
            FShape::try_new(3, CellKind::Triangle, p.iter().flatten().copied().collect(), vec![0, 1, 2], None).unwrap()
        };
        // Barycentric (0.6, 0.3, 0.1), (0.2, 0.4, 0.4), and a point 2 above (0.2, 0.2, 0.6).
        let onto = at(&[[0.3, 0.1, 0.0], [0.4, 0.4, 0.0], [0.2, 0.6, 2.0]]);
        let c = Correspondence::new(&tri, &onto).unwrap();
        let (v, carried) = c.map(&[f64::NAN, 10.0, 20.0], 1.0).unwrap();
        // Corner 0 is missing: 0.4 of the weight remains at the first point
        // (NaN), 0.8 at the second ((0.4·10 + 0.4·20)/0.8 = 15).
        assert!(v[0].is_nan() && (v[1] - 15.0).abs() < 1e-12 && v[2].is_nan(), "{v:?}");
        assert_eq!(carried, Carried { vertices: 3, beyond: 1, missing: 1 });
        let (v, _) = c.map(&[1.0, 10.0, 20.0], f64::INFINITY).unwrap();
        assert!((v[0] - (0.6 + 3.0 + 2.0)).abs() < 1e-12 && (v[2] - (0.2 + 2.0 + 12.0)).abs() < 1e-12, "{v:?}");
        // Labels: the first point is corner 0's (0.6); the second ties 0.4
        // against 0.4 when corners 1 and 2 differ (the smaller key wins) and
        // sums 0.8 when they agree.
        assert_eq!(c.labels(&[7, 3, 4], 1.0).unwrap(), vec![7, 3, -1]);
        assert_eq!(c.labels(&[7, 9, 9], f64::INFINITY).unwrap(), vec![7, 9, 9]);
        assert!(matches!(c.map(&[1.0, 2.0], 1.0), Err(MatchError::InvalidInput(_))));
        assert!(matches!(c.map(&[1.0, f64::INFINITY, 0.0], 1.0), Err(MatchError::InvalidInput(_))));
        assert!(matches!(c.map(&[1.0, 2.0, 3.0], f64::NAN), Err(MatchError::InvalidInput(_))));
        assert!(matches!(c.labels(&[1, 2, 3], -1.0), Err(MatchError::InvalidInput(_))));
    }
}
