//! How close a registration came: distances between the matched shape and
//! the target, and the signal error, as numbers a user can judge without
//! reading J.
//!
//! Both shapes are sampled by area (or length): every triangle at the
//! centroids of its four midpoint sub-triangles, every segment at its
//! quarter points, each sample weighted by its share of the cell's volume.
//! From each sample the exact closest point on the other shape is found
//! (point-to-triangle or point-to-segment distances, over the cells that a
//! k-d tree of cell centres proves to be candidates). Reported, as
//! fractions of the target's bounding-box diagonal:
//!
//! - the mean symmetric closest-point distance: the area-weighted mean of
//!   d(x, Y) over X and of d(y, X) over Y, averaged;
//! - its 95th percentile (both sides pooled, each with half the weight);
//! - the share of the target's area within 1 % of the diagonal of X.
//!
//! And the signal error: at each target sample, the matched signal
//! interpolated at its closest point on X minus the target's signal there;
//! its area-weighted root mean square as a fraction of the target signal's
//! range (max − min over the vertices), and its 99th percentile (isolated
//! spots of wrong value, which the rms dilutes). The rms is also split
//! between the target's area within 1 % of the diagonal of X (where the
//! geometry matched: the error there is the signal's own) and the area
//! beyond (where part of the error is the geometry's, and where the paper
//! sees lumped-L² oscillations).
//!
//! The target's samples cannot see parts of the shape that no part of the
//! target is near (a sphere's caps over the holes of an open target), so
//! the signal error is measured again from the shape's side: at each
//! sample of the shape, its signal minus the target's at its closest
//! point, over the whole shape, over its area beyond 1 % of the diagonal
//! from the target, and over its area past the target's boundary (whose
//! closest point of the target lies on a boundary edge, or the end of a
//! curve), with the share of the shape's area each region covers and the
//! roughness there.
//!
//! And the signal's roughness: the Dirichlet seminorm of the matched
//! signal on the matched shape, (∫_X |∇f|²)^½ of the P1 interpolant, over
//! the target signal's on the target. A faithful match gives about 1; a
//! signal that oscillates between vertices (the paper's lumped-L²
//! artefacts) gives more, one smoothed too much gives less. For surfaces
//! both integrals have the same units whatever the size of the shape, so
//! the ratio compares shapes of different sizes; for curves it scales as
//! the inverse length ratio, near 1 once the shapes are close.

use std::collections::HashSet;

use fshape_mesh::{CellKind, FShape};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::MatchError;

/// How close a shape is to a target (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quality {
    /// The target's bounding-box diagonal, in the shapes' units (the unit
    /// of the distances below).
    pub diagonal: f64,
    /// Mean symmetric closest-point distance / diagonal.
    pub mean_distance: f64,
    /// 95th percentile of the closest-point distances / diagonal.
    pub p95_distance: f64,
    /// Largest closest-point distance (Hausdorff) / diagonal.
    pub max_distance: f64,
    /// Share of the target's area (or length) within 1 % of the diagonal
    /// of the shape.
    pub target_within_1pct: f64,
    /// RMS of the signal error at closest points / the target signal's
    /// range; `None` when the target has no signal or a constant one.
    pub signal_rms: Option<f64>,
    /// 99th percentile of the absolute signal error at closest points /
    /// the target signal's range (area-weighted); `None` as `signal_rms`.
    #[serde(default)]
    pub signal_p99: Option<f64>,
    /// The same rms over the target's area within 1 % of the diagonal of
    /// the shape (the share `target_within_1pct`); `None` as `signal_rms`
    /// or when that area is empty.
    #[serde(default)]
    pub signal_rms_within_1pct: Option<f64>,
    /// The same rms over the rest of the target's area; `None` as
    /// `signal_rms` or when the whole target is within 1 %.
    #[serde(default)]
    pub signal_rms_beyond_1pct: Option<f64>,
    /// Dirichlet seminorm of the shape's signal over the target's
    /// (module docs); `None` when either has no signal or the target's
    /// signal is constant.
    #[serde(default)]
    pub signal_roughness: Option<f64>,
    /// RMS of the signal error seen from the shape's side: at each sample
    /// of the shape, its signal minus the target's at the closest point of
    /// the target, over the target signal's range. Unlike `signal_rms` it
    /// sees the parts of the shape that no part of the target is close to
    /// (e.g. where the shape closes the target's holes, compared with
    /// their rims); `None` as `signal_rms`.
    #[serde(default)]
    pub signal_rms_on_shape: Option<f64>,
    /// The same over the shape's area farther than 1 % of the diagonal from
    /// the target (the share `shape_beyond_1pct`); `None` as `signal_rms`
    /// or when that area is empty.
    #[serde(default)]
    pub signal_rms_on_shape_beyond_1pct: Option<f64>,
    /// Share of the shape's area (or length) farther than 1 % of the
    /// diagonal from the target.
    #[serde(default)]
    pub shape_beyond_1pct: f64,
    /// The shape signal's roughness on that area: the root of its mean
    /// Dirichlet energy per unit area there over the target's per unit
    /// area (each cell of the shape counted in proportion to its samples
    /// beyond 1 %). Where the target gives the signal nothing to match, a
    /// regular metamorphosis fills in a smooth signal (near or below 1)
    /// and an L² one may oscillate (the paper's figure of the bunny seen
    /// from below). `None` without that area or without signals.
    #[serde(default)]
    pub signal_roughness_beyond_1pct: Option<f64>,
    /// Share of the shape's area (or length) past the target's boundary:
    /// off the target, with its closest point of the target on a boundary
    /// edge (or the end of a curve). For the bunny, the caps the sphere
    /// puts over the target's holes underneath; 0 for a closed target.
    #[serde(default)]
    pub shape_past_boundary: f64,
    /// `signal_rms_on_shape` over that area (the error against the values
    /// on the rim); `None` as `signal_rms` or without that area.
    #[serde(default)]
    pub signal_rms_past_boundary: Option<f64>,
    /// `signal_roughness_beyond_1pct` over that area.
    #[serde(default)]
    pub signal_roughness_past_boundary: Option<f64>,
    /// The target signal's range (max − min), in its units (0 without one).
    pub signal_range: f64,
    /// With several signal channels, each channel's signal error (the
    /// fields above are the first channel's); empty with one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub channels: Vec<ChannelQuality>,
}

/// One channel's signal error: [`Quality`]'s signal fields, measured on
/// that channel alone (each a fraction of that channel's range).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[allow(missing_docs)]
pub struct ChannelQuality {
    pub signal_rms: Option<f64>,
    pub signal_p99: Option<f64>,
    pub signal_rms_within_1pct: Option<f64>,
    pub signal_rms_beyond_1pct: Option<f64>,
    pub signal_roughness: Option<f64>,
    pub signal_rms_on_shape: Option<f64>,
    pub signal_rms_on_shape_beyond_1pct: Option<f64>,
    pub signal_roughness_beyond_1pct: Option<f64>,
    pub signal_rms_past_boundary: Option<f64>,
    pub signal_roughness_past_boundary: Option<f64>,
    pub signal_range: f64,
}

impl Quality {
    /// One line for reports: percentages of the diagonal and of the range.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "mean distance {:.3}% of the diagonal (95th percentile {:.3}%, max {:.3}%), {:.1}% of the target within 1%",
            100.0 * self.mean_distance,
            100.0 * self.p95_distance,
            100.0 * self.max_distance,
            100.0 * self.target_within_1pct
        );
        if let Some(e) = self.signal_rms {
            s.push_str(&format!(", signal error {:.2}% of its range (rms", 100.0 * e));
            let part = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.2}%", 100.0 * v));
            s.push_str(&format!(
                "; {} within 1%, {} beyond)",
                part(self.signal_rms_within_1pct),
                part(self.signal_rms_beyond_1pct)
            ));
            if let Some(p) = self.signal_p99 {
                s.push_str(&format!(", {:.2}% (99th percentile)", 100.0 * p));
            }
        }
        if let Some(e) = self.signal_rms_on_shape {
            s.push_str(&format!(", {:.2}% from the shape's side", 100.0 * e));
            let mut parts = Vec::new();
            if let Some(b) = self.signal_rms_on_shape_beyond_1pct {
                parts.push(format!("{:.2}% on its {:.1}% beyond 1%", 100.0 * b, 100.0 * self.shape_beyond_1pct));
            }
            if let Some(b) = self.signal_rms_past_boundary {
                parts.push(format!(
                    "{:.2}% on its {:.1}% past the target's boundary",
                    100.0 * b,
                    100.0 * self.shape_past_boundary
                ));
            }
            if !parts.is_empty() {
                s.push_str(&format!(" ({})", parts.join("; ")));
            }
        }
        for (c, q) in self.channels.iter().enumerate().skip(1) {
            if let Some(e) = q.signal_rms {
                s.push_str(&format!(", channel {}: signal error {:.2}%", c + 1, 100.0 * e));
                if let Some(p) = q.signal_p99 {
                    s.push_str(&format!(" ({:.2}% 99th percentile)", 100.0 * p));
                }
            }
        }
        if let Some(r) = self.signal_roughness {
            s.push_str(&format!(", signal roughness {r:.2} of the target's"));
            let parts: Vec<String> = [
                (self.signal_roughness_beyond_1pct, "beyond 1%"),
                (self.signal_roughness_past_boundary, "past the boundary"),
            ]
            .into_iter()
            .filter_map(|(v, at)| v.map(|v| format!("{v:.2} {at}")))
            .collect();
            if !parts.is_empty() {
                s.push_str(&format!(" ({})", parts.join(", ")));
            }
        }
        s
    }
}

/// Area-weighted samples of a shape: positions (3-D, z = 0 in the plane),
/// weights, and for each its cell and barycentric coordinates.
struct Samples {
    points: Vec<[f64; 3]>,
    weights: Vec<f64>,
    cells: Vec<usize>,
    bary: Vec<[f64; 3]>,
}

fn point3(shape: &FShape, v: usize) -> [f64; 3] {
    let p = shape.point(v);
    [p[0], p[1], if shape.dim() == 3 { p[2] } else { 0.0 }]
}

fn corners(shape: &FShape, c: usize) -> [[f64; 3]; 3] {
    let k = shape.kind().n_corners();
    let ids = &shape.cells()[c * k..(c + 1) * k];
    let a = point3(shape, ids[0]);
    let b = point3(shape, ids[1]);
    [a, b, if k == 3 { point3(shape, ids[2]) } else { b }]
}

fn combine(p: &[[f64; 3]; 3], w: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|k| w[0] * p[0][k] + w[1] * p[1][k] + w[2] * p[2][k])
}

fn samples(shape: &FShape) -> Samples {
    let vol = shape.cell_volumes();
    let pattern: &[[f64; 3]] = match shape.kind() {
        CellKind::Triangle => &[
            [4.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0],
            [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0],
            [1.0 / 6.0, 1.0 / 6.0, 4.0 / 6.0],
            [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
        ],
        CellKind::Segment => &[[0.75, 0.25, 0.0], [0.25, 0.75, 0.0]],
    };
    let mut s = Samples { points: Vec::new(), weights: Vec::new(), cells: Vec::new(), bary: Vec::new() };
    for (c, &v) in vol.iter().enumerate() {
        let p = corners(shape, c);
        for w in pattern {
            s.points.push(combine(&p, *w));
            s.weights.push(v / pattern.len() as f64);
            s.cells.push(c);
            s.bary.push(*w);
        }
    }
    s
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Barycentric coordinates of the point of segment [a, b] closest to p.
fn closest_on_segment(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    let t = if len2 > 0.0 { (dot(sub(p, a), ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    [1.0 - t, t, 0.0]
}

/// Barycentric coordinates of the point of triangle abc closest to p
/// (Ericson, Real-Time Collision Detection, 5.1.5: Voronoi regions of the
/// vertices, then of the edges, then the face).
fn closest_on_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = va + vb + vc;
    if denom.abs() <= f64::MIN_POSITIVE {
        // A degenerate triangle: its closest point lies on an edge.
        let (e0, e1, e2) = (closest_on_segment(p, a, b), closest_on_segment(p, b, c), closest_on_segment(p, c, a));
        let candidates = [[e0[0], e0[1], 0.0], [0.0, e1[0], e1[1]], [e2[1], 0.0, e2[0]]];
        let d = |w: &[f64; 3]| {
            let q = sub(p, combine(&[a, b, c], *w));
            dot(q, q)
        };
        return candidates.into_iter().min_by(|x, y| d(x).total_cmp(&d(y))).expect("three edges");
    }
    let (v, w) = (vb / denom, vc / denom);
    [1.0 - v - w, v, w]
}

/// The exact closest point of a shape to query points.
pub struct ClosestPoints<'a> {
    shape: &'a FShape,
    /// The cells grouped by their reach (the largest distance from a
    /// cell's centre to one of its corners) in classes whose reaches
    /// differ by at most a factor 2, so that a few long slivers do not
    /// widen the search around every query.
    classes: Vec<ReachClass>,
}

/// Cells of similar reach: a k-d tree of their centres (items index
/// `cells`) and the largest reach among them.
struct ReachClass {
    tree: ImmutableKdTree<f64, 3>,
    cells: Vec<usize>,
    reach: f64,
}
/// The closest point of a shape to one query point: its squared distance,
/// cell and barycentric coordinates in that cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// |q − closest point|.
    pub distance: f64,
    /// The cell holding the closest point.
    pub cell: usize,
    /// Its barycentric coordinates (the third is 0 for a segment).
    pub bary: [f64; 3],
}

impl<'a> ClosestPoints<'a> {
    /// k-d trees of `shape`'s cell centres, one per class of reach.
    pub fn new(shape: &'a FShape) -> Result<Self, MatchError> {
        if shape.n_cells() == 0 {
            return Err(MatchError::Degenerate("a shape without cells has no closest points".into()));
        }
        let k = shape.kind().n_corners();
        let (mut centres, mut reaches) = (Vec::with_capacity(shape.n_cells()), Vec::with_capacity(shape.n_cells()));
        for c in 0..shape.n_cells() {
            let p = corners(shape, c);
            let centre = if k == 3 { combine(&p, [1.0 / 3.0; 3]) } else { combine(&p, [0.5, 0.5, 0.0]) };
            let reach = p[..k].iter().map(|q| dot(sub(*q, centre), sub(*q, centre)).sqrt()).fold(0.0, f64::max);
            centres.push(centre);
            reaches.push(reach);
        }
        // Class j holds the reaches in (2^(j−1) r₀, 2^j r₀], class 0 those
        // up to r₀, the smallest positive reach.
        let r0 = reaches.iter().copied().filter(|&r| r > 0.0).fold(f64::INFINITY, f64::min);
        let class_of = |r: f64| if r <= r0 { 0 } else { ((r / r0).log2().ceil() as usize).min(1100) };
        let mut members: Vec<Vec<usize>> = Vec::new();
        for (c, &r) in reaches.iter().enumerate() {
            let j = class_of(r);
            if members.len() <= j {
                members.resize(j + 1, Vec::new());
            }
            members[j].push(c);
        }
        let mut classes = Vec::new();
        for cells in members.into_iter().filter(|m| !m.is_empty()) {
            let points: Vec<[f64; 3]> = cells.iter().map(|&c| centres[c]).collect();
            let tree = ImmutableKdTree::new_from_slice(&points)
                .map_err(|e| MatchError::Degenerate(format!("closest points: {e:?}")))?;
            let reach = cells.iter().map(|&c| reaches[c]).fold(0.0, f64::max);
            classes.push(ReachClass { tree, cells, reach });
        }
        Ok(ClosestPoints { shape, classes })
    }

    fn to_cell(&self, q: [f64; 3], c: usize) -> Closest {
        let p = corners(self.shape, c);
        let bary = if self.shape.kind() == CellKind::Triangle {
            closest_on_triangle(q, p[0], p[1], p[2])
        } else {
            closest_on_segment(q, p[0], p[1])
        };
        let d = sub(q, combine(&p, bary));
        Closest { distance: dot(d, d).sqrt(), cell: c, bary }
    }

    /// The closest point of the shape to `q` (3-D; z = 0 for planar
    /// shapes). Exact: the nearest cell centre of each class bounds the
    /// distance, and every cell that could be closer has its centre within
    /// that bound plus its class's largest centre-to-corner distance. Ties
    /// go to the lower cell index.
    pub fn closest(&self, q: [f64; 3]) -> Closest {
        let better = |t: &Closest, best: &Closest| {
            t.distance < best.distance || (t.distance == best.distance && t.cell < best.cell)
        };
        let nearest = |class: &ReachClass| {
            let first = class.tree.query(&q).nearest_one::<SquaredEuclidean<f64>>().execute();
            self.to_cell(q, class.cells[first.item as usize])
        };
        // `new` makes at least one class.
        let mut best = nearest(&self.classes[0]);
        for class in &self.classes[1..] {
            let t = nearest(class);
            if better(&t, &best) {
                best = t;
            }
        }
        let mut candidates: Vec<usize> = Vec::new();
        for class in &self.classes {
            let r = best.distance + class.reach;
            candidates.clear();
            class
                .tree
                .query(&q)
                .within::<SquaredEuclidean<f64>>(r * r * (1.0 + 1e-12) + f64::MIN_POSITIVE)
                .unsorted()
                .visit(|h| candidates.push(class.cells[h.item as usize]));
            for &c in &candidates {
                let t = self.to_cell(q, c);
                if better(&t, &best) {
                    best = t;
                }
            }
        }
        best
    }
}

/// Channel `c` of the signal interpolated in `cell` at `bary`.
fn signal_at(shape: &FShape, c: usize, cell: usize, bary: [f64; 3]) -> Option<f64> {
    let (f, k) = (shape.signal()?, shape.n_channels());
    let n = shape.kind().n_corners();
    let ids = &shape.cells()[cell * n..(cell + 1) * n];
    Some(ids.iter().zip(bary).map(|(&v, w)| w * f[v * k + c]).sum())
}

/// (∫ |∇f|²)^½ over the shape for the P1 interpolant f of its signal:
/// per triangle, area × dfᵀ G⁻¹ df with G the Gram matrix of two edges and
/// df the value differences along them; per segment (f_b − f_a)²/length.
/// Cells of zero volume carry no gradient and are skipped. `None` without
/// a signal, and with several channels (one seminorm per channel is not
/// computed yet).
pub fn dirichlet_seminorm(shape: &FShape) -> Option<f64> {
    if shape.n_channels() > 1 {
        return None;
    }
    Some(dirichlet_energies(shape, 0)?.iter().sum::<f64>().sqrt())
}

/// ∫_c |∇f|² of channel `channel` on each cell c (see [`dirichlet_seminorm`]).
fn dirichlet_energies(shape: &FShape, channel: usize) -> Option<Vec<f64>> {
    let (signal, channels) = (shape.signal()?, shape.n_channels());
    let f = |v: usize| signal[v * channels + channel];
    let k = shape.kind().n_corners();
    let energy = |(c, ids): (usize, &[usize])| {
        let p = corners(shape, c);
        let (e1, d1) = (sub(p[1], p[0]), f(ids[1]) - f(ids[0]));
        if k == 2 {
            let len = dot(e1, e1).sqrt();
            return if len > 0.0 { d1 * d1 / len } else { 0.0 };
        }
        let (e2, d2) = (sub(p[2], p[0]), f(ids[2]) - f(ids[0]));
        let (g11, g12, g22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
        let det = g11 * g22 - g12 * g12;
        // dfᵀ G⁻¹ df × area, area = ½√det.
        if det > 0.0 { (g22 * d1 * d1 - 2.0 * g12 * d1 * d2 + g11 * d2 * d2) / det * 0.5 * det.sqrt() } else { 0.0 }
    };
    // A cell with a masked corner (NaN: no value) carries no gradient.
    Some(shape.cells().chunks_exact(k).enumerate().map(energy).map(|e| if e.is_finite() { e } else { 0.0 }).collect())
}

/// Whether a closest point of `target` lies on its boundary (an edge of a
/// surface used by one triangle, or one of its vertices; an end of a
/// curve) and off the query point: the query lies past the target's edge,
/// e.g. over one of its holes.
fn past_boundary(target: &FShape) -> impl Fn(&Closest) -> bool + '_ {
    let facets = target.topology().boundary_facets;
    let vertices: HashSet<usize> = facets.iter().flatten().copied().collect();
    let edges: HashSet<[usize; 2]> = facets.iter().map(|&[a, b]| [a.min(b), a.max(b)]).collect();
    let k = target.kind().n_corners();
    move |c: &Closest| {
        let ids = &target.cells()[c.cell * k..(c.cell + 1) * k];
        let mut on = (0..k).filter(|&j| c.bary[j] > 0.0).map(|j| ids[j]);
        c.distance > 0.0
            && match (on.next(), on.next(), on.next()) {
                (Some(v), None, _) => vertices.contains(&v),
                (Some(a), Some(b), None) if k == 3 => edges.contains(&[a.min(b), a.max(b)]),
                _ => false,
            }
    }
}

/// The weighted `q`-quantile of values with weights.
fn quantile(mut pairs: Vec<(f64, f64)>, q: f64) -> f64 {
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = pairs.iter().map(|p| p.1).sum();
    let mut acc = 0.0;
    for (v, w) in &pairs {
        acc += w;
        if acc >= q * total {
            return *v;
        }
    }
    pairs.last().map_or(0.0, |p| p.0)
}

/// How close `shape` is to `target` (module docs). Deterministic: samples
/// are evaluated in parallel but summed in order.
pub fn quality(shape: &FShape, target: &FShape) -> Result<Quality, MatchError> {
    if shape.dim() != target.dim() || shape.kind() != target.kind() {
        return Err(MatchError::Kinds("quality: the matched shape and the target differ".into()));
    }
    if shape.signal().is_some() && target.signal().is_some() && shape.n_channels() != target.n_channels() {
        return Err(MatchError::InvalidInput(format!(
            "quality: the matched shape carries {} signal channels, the target {}",
            shape.n_channels(),
            target.n_channels()
        )));
    }
    let diagonal = target.bounding_box().diagonal();
    if !(diagonal > 0.0 && diagonal.is_finite()) {
        return Err(MatchError::Degenerate(format!("quality: the target's bounding-box diagonal is {diagonal}")));
    }
    let (to_target, to_shape) = (ClosestPoints::new(target)?, ClosestPoints::new(shape)?);
    let (xs, ys) = (samples(shape), samples(target));
    let dx: Vec<Closest> = xs.points.par_iter().map(|p| to_target.closest(*p)).collect();
    let dy: Vec<Closest> = ys.points.par_iter().map(|p| to_shape.closest(*p)).collect();
    let (wx, wy): (f64, f64) = (xs.weights.iter().sum(), ys.weights.iter().sum());
    if !(wx > 0.0 && wy > 0.0) {
        return Err(MatchError::Degenerate("quality: a shape has no area (or length)".into()));
    }
    let mean = |d: &[Closest], w: &[f64], total: f64| d.iter().zip(w).map(|(c, w)| c.distance * w).sum::<f64>() / total;
    let mean_distance = 0.5 * (mean(&dx, &xs.weights, wx) + mean(&dy, &ys.weights, wy)) / diagonal;
    let pooled: Vec<(f64, f64)> = dx
        .iter()
        .zip(&xs.weights)
        .map(|(c, w)| (c.distance, 0.5 * w / wx))
        .chain(dy.iter().zip(&ys.weights).map(|(c, w)| (c.distance, 0.5 * w / wy)))
        .collect();
    let max_distance = pooled.iter().map(|p| p.0).fold(0.0, f64::max) / diagonal;
    let p95_distance = quantile(pooled, 0.95) / diagonal;
    let sides = Sides { diagonal, xs, ys, dx, dy, wx, wy };
    let k = shape.n_channels().max(target.n_channels()).max(1);
    let (first, shape_beyond_1pct, shape_past_boundary) = signal_quality(shape, target, 0, &sides);
    let channels = if k > 1 {
        std::iter::once(first).chain((1..k).map(|c| signal_quality(shape, target, c, &sides).0)).collect()
    } else {
        Vec::new()
    };
    let near = |c: &Closest| c.distance <= 0.01 * diagonal;
    let within = sides.dy.iter().zip(&sides.ys.weights).filter(|(c, _)| near(c)).fold(0.0, |a, (_, w)| a + w);
    Ok(Quality {
        diagonal,
        mean_distance,
        p95_distance,
        max_distance,
        target_within_1pct: within / wy,
        signal_rms: first.signal_rms,
        signal_p99: first.signal_p99,
        signal_rms_within_1pct: first.signal_rms_within_1pct,
        signal_rms_beyond_1pct: first.signal_rms_beyond_1pct,
        signal_roughness: first.signal_roughness,
        signal_rms_on_shape: first.signal_rms_on_shape,
        signal_rms_on_shape_beyond_1pct: first.signal_rms_on_shape_beyond_1pct,
        shape_beyond_1pct,
        signal_roughness_beyond_1pct: first.signal_roughness_beyond_1pct,
        shape_past_boundary,
        signal_rms_past_boundary: first.signal_rms_past_boundary,
        signal_roughness_past_boundary: first.signal_roughness_past_boundary,
        signal_range: first.signal_range,
        channels,
    })
}

/// Both shapes' samples and their closest points on the other: what
/// every channel's signal error is measured on.
struct Sides {
    diagonal: f64,
    xs: Samples,
    ys: Samples,
    dx: Vec<Closest>,
    dy: Vec<Closest>,
    wx: f64,
    wy: f64,
}

/// The signal error of channel `channel` (module docs), and the shares of the
/// shape's area beyond 1 % and past the target's boundary.
fn signal_quality(shape: &FShape, target: &FShape, channel: usize, sides: &Sides) -> (ChannelQuality, f64, f64) {
    let Sides { diagonal, xs, ys, dx, dy, wx, wy } = sides;
    let diagonal = *diagonal;
    let k = target.n_channels().max(1);
    let range = target.signal().map_or(0.0, |f| {
        let (lo, hi) = f
            .iter()
            .skip(channel)
            .step_by(k)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
        if hi >= lo { hi - lo } else { 0.0 }
    });
    let near = |c: &Closest| c.distance <= 0.01 * diagonal;
    let (mut signal_rms, mut signal_p99, mut signal_rms_within_1pct, mut signal_rms_beyond_1pct) =
        (None, None, None, None);
    if range > 0.0 && shape.signal().is_some() {
        let errors: Vec<(f64, f64)> = dy
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let ft = signal_at(target, channel, ys.cells[i], ys.bary[i]).unwrap_or(0.0);
                let fs = signal_at(shape, channel, c.cell, c.bary).unwrap_or(0.0);
                ((fs - ft).abs(), ys.weights[i])
            })
            // A masked cell on either side has no value (NaN): not counted.
            .map(|(e, w)| if e.is_finite() { (e, w) } else { (0.0, 0.0) })
            .collect();
        // The rms over the samples `keep` selects, None if they have no area.
        let rms = |keep: &dyn Fn(&Closest) -> bool| {
            let (sum, area) = errors
                .iter()
                .zip(dy)
                .filter(|(_, c)| keep(c))
                .fold((0.0, 0.0), |(s, a), ((e, w), _)| (s + w * e * e, a + w));
            (area > 0.0).then(|| (sum / area).sqrt() / range)
        };
        signal_rms = rms(&|_| true);
        signal_rms_within_1pct = rms(&|c| near(c));
        signal_rms_beyond_1pct = rms(&|c| !near(c));
        signal_p99 = Some(quantile(errors, 0.99) / range);
    }
    let energies = dirichlet_energies(shape, channel);
    // ∫|∇f|² over the whole target, None without a signal or if constant.
    let target_energy = dirichlet_energies(target, channel).map(|e| e.iter().sum::<f64>()).filter(|e| *e > 0.0);
    let signal_roughness = match (&energies, target_energy) {
        (Some(a), Some(b)) => Some((a.iter().sum::<f64>() / b).sqrt()),
        _ => None,
    };
    // The shape's side: its samples' errors against the target's closest
    // points, over the whole shape and over two regions of it.
    let shape_errors: Option<Vec<f64>> = (range > 0.0)
        .then(|| {
            dx.iter()
                .enumerate()
                .map(|(i, c)| {
                    Some(
                        signal_at(shape, channel, xs.cells[i], xs.bary[i])?
                            - signal_at(target, channel, c.cell, c.bary)?,
                    )
                })
                .collect()
        })
        .flatten();
    let samples_per_cell = xs.points.len() / shape.n_cells();
    let target_density = target_energy.map(|e| e / *wy);
    // (share of the shape's area, signal rms, roughness) over the samples
    // `keep` selects (each sample weighs its share of its cell's area);
    // each cell's energy counts in proportion to its samples there.
    let region = |keep: &dyn Fn(&Closest) -> bool| {
        let kept: Vec<bool> = dx.iter().map(keep).collect();
        // Folded from +0: an empty f64 sum is −0, which JSON would show.
        let area = kept.iter().zip(&xs.weights).filter(|(k, _)| **k).fold(0.0, |a, (_, w)| a + w);
        let rms = shape_errors
            .as_ref()
            .filter(|_| area > 0.0)
            .map(|e| {
                // Masked samples (NaN: no value on one side) are left out.
                let (sum, valued) = e
                    .iter()
                    .zip(&xs.weights)
                    .zip(&kept)
                    .filter(|((e, _), k)| **k && e.is_finite())
                    .fold((0.0, 0.0), |(s, a), ((e, w), _)| (s + w * e * e, a + w));
                (sum / valued).sqrt() / range
            })
            .filter(|v: &f64| v.is_finite());
        let roughness = match (&energies, target_density) {
            (Some(energies), Some(density)) if area > 0.0 => {
                let share = kept.chunks_exact(samples_per_cell).map(|k| k.iter().filter(|k| **k).count() as f64);
                let energy: f64 = energies.iter().zip(share).map(|(e, n)| e * n / samples_per_cell as f64).sum();
                Some((energy / area / density).sqrt())
            }
            _ => None,
        };
        (area / *wx, rms, roughness)
    };
    let (_, signal_rms_on_shape, _) = region(&|_| true);
    let (shape_beyond_1pct, signal_rms_on_shape_beyond_1pct, signal_roughness_beyond_1pct) = region(&|c| !near(c));
    let past = past_boundary(target);
    let (shape_past_boundary, signal_rms_past_boundary, signal_roughness_past_boundary) = region(&|c| past(c));
    (
        ChannelQuality {
            signal_rms,
            signal_p99,
            signal_rms_within_1pct,
            signal_rms_beyond_1pct,
            signal_roughness,
            signal_rms_on_shape,
            signal_rms_on_shape_beyond_1pct,
            signal_roughness_beyond_1pct,
            signal_rms_past_boundary,
            signal_roughness_past_boundary,
            signal_range: range,
        },
        shape_beyond_1pct,
        shape_past_boundary,
    )
}
