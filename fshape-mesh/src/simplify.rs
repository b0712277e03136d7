//! Mesh simplification that carries the signal: any triangulated surface
//! (or flat triangulated domain) down to a vertex count, for the coarse
//! stages of a registration.
//!
//! Half-edge collapses (a vertex u merged into a neighbour v, which keeps
//! its position and signal), chosen cheapest first by a quadric error
//! (Garland & Heckbert 1997), as in meshoptimizer's simplifier. Keeping
//! the fine mesh's vertices means the coarse surface's vertices lie on the
//! fine one and carry their own signal values: nothing is interpolated. The
//! error of moving u to v is Q_u(x_v, f_v), with Q_u the sum over the faces
//! merged into u so far of
//!
//! - the squared distance to the face's plane (the geometric quadric),
//! - for each signal channel (map), the squared difference between the
//!   signal and the face's linear signal, s − g·x − c (Hoppe 1999's
//!   attribute quadric), weighted so that one standard deviation of the
//!   map costs as much as a distance of 1 % of the bounding-box diagonal
//!   ([`SimplifyOptions::signal_weight`]); each map is weighed so, and a
//!   constant map adds nothing,
//! - a small isotropic term |x − x_f|² (a hundredth of the plane's), which
//!   in flat regions prefers short edges and keeps triangles even,
//!
//! each times the face's area, and on each boundary edge a plane through
//! it perpendicular to its face, which keeps the outline.
//!
//! A collapse is refused if it would make the surface non-manifold (the
//! link condition: u and v share exactly the neighbours of the faces on
//! their edge), turn a face over or nearly flatten one (its normal would
//! turn by more than 90°, or its quality 4√3·area/Σ edge² fall below
//! [`MIN_QUALITY`] and below what it was), leave a boundary (a boundary
//! vertex only collapses along a boundary edge), or close a hole or a
//! triangular hole (a boundary loop of three edges).
//! The queue is ordered by (error, u, v), so the result is the same on
//! every run. Unused vertices are dropped.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::{CellKind, FShape, ShapeError};

/// The lowest triangle quality (4√3·area/Σ edge², 1 for an equilateral
/// triangle) a collapse may create, unless the face it moves was worse.
pub const MIN_QUALITY: f64 = 0.05;

/// Weight of the isotropic term against the plane quadric.
const ISOTROPIC: f64 = 0.01;

/// Weight of a boundary edge's plane, per squared edge length.
const BOUNDARY: f64 = 10.0;

/// How the simplifier weighs the signal against the geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimplifyOptions {
    /// One standard deviation of the signal costs as much as a distance
    /// of `signal_weight` × 1 % of the bounding-box diagonal (default 1;
    /// 0 ignores the signal).
    pub signal_weight: f64,
}

impl Default for SimplifyOptions {
    fn default() -> Self {
        SimplifyOptions { signal_weight: 1.0 }
    }
}

/// A simplified mesh and where its vertices come from.
#[derive(Clone, Debug, PartialEq)]
pub struct Simplified {
    /// The coarse mesh: a subset of the vertices (with their signal
    /// values) and new triangles over them.
    pub shape: FShape,
    /// `kept[i]` is the fine mesh's index of the coarse vertex i
    /// (increasing).
    pub kept: Vec<usize>,
}

/// Why a mesh could not be simplified.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SimplifyError {
    /// Only triangle meshes are simplified.
    #[error("only triangle meshes can be simplified, this one has {kind} cells")]
    NotTriangles {
        /// The cells' kind.
        kind: &'static str,
    },
    /// Fewer vertices than a surface can have were asked for.
    #[error("a simplified surface needs at least 4 vertices, {requested} were asked for")]
    TooFew {
        /// The count asked for.
        requested: usize,
    },
    /// The options are out of range.
    #[error("signal_weight must be finite and non-negative, got {weight}")]
    SignalWeight {
        /// The weight given.
        weight: f64,
    },
    /// The coarse mesh could not be built (a bug if it happens).
    #[error(transparent)]
    Shape(#[from] ShapeError),
}

/// A symmetric 5 × 5 quadric over (x, y, z, s, 1): the error of a point v
/// is [v; 1]ᵀ M [v; 1]. Stored as the upper triangle, row by row.
#[derive(Clone, Copy, Debug, Default)]
struct Quadric([f64; 15]);

/// Index of (i, j), i ≤ j, in the upper triangle of a 5 × 5 matrix.
const fn at(i: usize, j: usize) -> usize {
    i * 5 - i * (i + 1) / 2 + j
}

impl Quadric {
    /// w·(aᵀ[v; 1])²: a plane (or hyperplane) a = (a_x, a_y, a_z, a_s, a_1).
    fn plane(a: [f64; 5], w: f64) -> Quadric {
        let mut q = [0.0; 15];
        for i in 0..5 {
            for j in i..5 {
                q[at(i, j)] = w * a[i] * a[j];
            }
        }
        Quadric(q)
    }

    /// w·|x − p|² (position only).
    fn point(p: [f64; 3], w: f64) -> Quadric {
        let mut q = [0.0; 15];
        for k in 0..3 {
            q[at(k, k)] = w;
            q[at(k, 4)] = -w * p[k];
        }
        q[at(4, 4)] = w * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        Quadric(q)
    }

    fn add(&mut self, o: &Quadric) {
        for (a, b) in self.0.iter_mut().zip(&o.0) {
            *a += b;
        }
    }

    /// The error at v = (x, y, z, s); clamped at 0 (rounding).
    fn error(&self, v: [f64; 4]) -> f64 {
        let x = [v[0], v[1], v[2], v[3], 1.0];
        let mut e = 0.0;
        for i in 0..5 {
            e += self.0[at(i, i)] * x[i] * x[i];
            for j in i + 1..5 {
                e += 2.0 * self.0[at(i, j)] * x[i] * x[j];
            }
        }
        e.max(0.0)
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Twice the area vector of the triangle (a, b, c).
fn normal(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    cross(sub(b, a), sub(c, a))
}

/// 4√3·area/Σ edge², 1 for an equilateral triangle, 0 for a flat one.
fn quality(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let n = normal(a, b, c);
    let edges = dot(sub(b, a), sub(b, a)) + dot(sub(c, b), sub(c, b)) + dot(sub(a, c), sub(a, c));
    if edges == 0.0 { 0.0 } else { 2.0 * 3f64.sqrt() * dot(n, n).sqrt() / edges }
}

/// A map's values scaled so that one standard deviation is `unit`, over
/// the values there are: a masked vertex's (NaN) counts as the mean, no
/// feature to keep; a constant map is all zeros.
fn scaled_map(f: &[f64], unit: f64) -> Vec<f64> {
    let valued = f.iter().filter(|v| !v.is_nan()).count().max(1) as f64;
    let mean = f.iter().filter(|v| !v.is_nan()).sum::<f64>() / valued;
    let sd = (f.iter().filter(|v| !v.is_nan()).map(|v| (v - mean) * (v - mean)).sum::<f64>() / valued).sqrt();
    let scale = if sd > 0.0 { unit / sd } else { 0.0 };
    f.iter().map(|v| if v.is_nan() { mean * scale } else { v * scale }).collect()
}

/// The attribute quadric of a face p with values s at its corners:
/// area × (s − g·x − c)², s = g·x + c the face's linear signal, g in the
/// face's plane.
fn linear_signal(p: [[f64; 3]; 3], s: [f64; 3], area: f64) -> Quadric {
    let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
    let (d1, d2) = (s[1] - s[0], s[2] - s[0]);
    let (a11, a12, a22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
    let det = a11 * a22 - a12 * a12;
    let (al, be) = ((d1 * a22 - d2 * a12) / det, (d2 * a11 - d1 * a12) / det);
    let g = [al * e1[0] + be * e2[0], al * e1[1] + be * e2[1], al * e1[2] + be * e2[2]];
    let c = s[0] - dot(g, p[0]);
    Quadric::plane([-g[0], -g[1], -g[2], 1.0, -c], area)
}

/// An f64 with a total order, for the queue.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cost(f64);

impl Eq for Cost {}

impl PartialOrd for Cost {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Cost {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// The working mesh.
struct Work {
    x: Vec<[f64; 3]>,
    s: Vec<f64>,
    faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    /// The live faces around each vertex.
    around: Vec<Vec<u32>>,
    alive: Vec<bool>,
    boundary: Vec<bool>,
    /// The geometric quadric plus the first map's.
    q: Vec<Quadric>,
    /// The other maps' values (`extra` per vertex, scaled as `s`).
    s_more: Vec<f64>,
    /// The other maps' quadrics (`extra` per vertex): a map's quadric
    /// holds only its own coordinate, so each is evaluated at its own value.
    q_more: Vec<Quadric>,
    /// The number of maps after the first.
    extra: usize,
    /// Bumped when a vertex's quadric changes: queue entries of older
    /// versions are stale.
    version: Vec<u32>,
}

impl Work {
    fn point(&self, v: u32) -> [f64; 4] {
        let x = self.x[v as usize];
        [x[0], x[1], x[2], self.s[v as usize]]
    }

    /// The error of moving u to v: u's quadrics at v's position and
    /// values (with one map, exactly the one quadric's error).
    fn cost(&self, u: u32, v: u32) -> f64 {
        let mut e = self.q[u as usize].error(self.point(v));
        let (u, v) = (u as usize, v as usize);
        let x = self.x[v];
        for c in 0..self.extra {
            e += self.q_more[u * self.extra + c].error([x[0], x[1], x[2], self.s_more[v * self.extra + c]]);
        }
        e
    }

    /// The neighbours of u, sorted.
    fn neighbours(&self, u: u32) -> Vec<u32> {
        let mut n: Vec<u32> =
            self.around[u as usize].iter().flat_map(|&f| self.faces[f as usize]).filter(|&w| w != u).collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    /// The faces on edge (u, v).
    fn edge_faces(&self, u: u32, v: u32) -> Vec<u32> {
        self.around[u as usize].iter().copied().filter(|&f| self.faces[f as usize].contains(&v)).collect()
    }

    /// Whether collapsing u into v keeps the mesh a valid manifold with no
    /// face turned over or flattened (module docs).
    fn can_collapse(&self, u: u32, v: u32) -> bool {
        let shared = self.edge_faces(u, v);
        if shared.is_empty() {
            return false;
        }
        let edge_is_boundary = shared.len() == 1;
        if self.boundary[u as usize] && !edge_is_boundary {
            return false;
        }
        // Link condition: the common neighbours are the shared faces' third vertices.
        let (nu, nv) = (self.neighbours(u), self.neighbours(v));
        let common = nu.iter().filter(|w| nv.binary_search(w).is_ok()).count();
        if common != shared.len() {
            return false;
        }
        // Closing a hole of three edges: u's other boundary neighbour is v's.
        if edge_is_boundary {
            let next = |a: u32, not: u32| {
                self.neighbours(a).into_iter().find(|&w| w != not && self.edge_faces(a, w).len() == 1)
            };
            if next(u, v).is_some() && next(u, v) == next(v, u) {
                return false;
            }
        }
        let xv = self.x[v as usize];
        for &f in &self.around[u as usize] {
            let face = self.faces[f as usize];
            if face.contains(&v) {
                continue;
            }
            let p = face.map(|w| self.x[w as usize]);
            let moved = face.map(|w| if w == u { xv } else { self.x[w as usize] });
            let (n0, n1) = (normal(p[0], p[1], p[2]), normal(moved[0], moved[1], moved[2]));
            if dot(n0, n1) <= 0.0 {
                return false;
            }
            let q1 = quality(moved[0], moved[1], moved[2]);
            if q1 < MIN_QUALITY && q1 < quality(p[0], p[1], p[2]) {
                return false;
            }
        }
        true
    }

    /// Merges u into v.
    fn collapse(&mut self, u: u32, v: u32) {
        for f in std::mem::take(&mut self.around[u as usize]) {
            let face = &mut self.faces[f as usize];
            if face.contains(&v) {
                self.face_alive[f as usize] = false;
                for w in *face {
                    if w != u {
                        self.around[w as usize].retain(|&g| g != f);
                    }
                }
            } else {
                for w in face.iter_mut() {
                    if *w == u {
                        *w = v;
                    }
                }
                self.around[v as usize].push(f);
            }
        }
        let qu = self.q[u as usize];
        self.q[v as usize].add(&qu);
        let (u_at, v_at) = (u as usize * self.extra, v as usize * self.extra);
        for c in 0..self.extra {
            let qu = self.q_more[u_at + c];
            self.q_more[v_at + c].add(&qu);
        }
        self.alive[u as usize] = false;
        self.version[v as usize] += 1;
    }
}

impl FShape {
    /// This mesh simplified to `vertices` vertices with the default
    /// options ([`FShape::simplified_with`]).
    pub fn simplified(&self, vertices: usize) -> Result<Simplified, SimplifyError> {
        self.simplified_with(vertices, &SimplifyOptions::default())
    }

    /// This triangle mesh simplified to `vertices` vertices by half-edge
    /// collapses (module docs): the coarse vertices are fine vertices with
    /// their signal values. A mesh already that small is returned as it
    /// is (without unused vertices). Where every remaining collapse would
    /// break the surface the result keeps more vertices than asked.
    ///
    /// ```
    /// use fshape_mesh::generate::icosphere;
    /// let sphere = icosphere(4, 1.0); // 2562 vertices
    /// let coarse = sphere.simplified(300)?;
    /// assert_eq!(coarse.shape.n_vertices(), 300);
    /// assert!(coarse.shape.validate().is_clean());
    /// # Ok::<(), fshape_mesh::SimplifyError>(())
    /// ```
    pub fn simplified_with(&self, vertices: usize, options: &SimplifyOptions) -> Result<Simplified, SimplifyError> {
        if self.kind() != CellKind::Triangle {
            return Err(SimplifyError::NotTriangles { kind: self.kind().name() });
        }
        if vertices < 4 {
            return Err(SimplifyError::TooFew { requested: vertices });
        }
        let w = options.signal_weight;
        if !(w.is_finite() && w >= 0.0) {
            return Err(SimplifyError::SignalWeight { weight: w });
        }
        let mut work = self.work(w);
        let mut left = work.around.iter().filter(|a| !a.is_empty()).count();
        let mut queue = BinaryHeap::new();
        let push = |work: &Work, queue: &mut BinaryHeap<_>, u: u32| {
            for v in work.neighbours(u) {
                let cost = work.cost(u, v);
                queue.push(Reverse((Cost(cost), u, v, work.version[u as usize])));
            }
        };
        for u in 0..work.x.len() as u32 {
            push(&work, &mut queue, u);
        }
        while left > vertices {
            let Some(Reverse((_, u, v, version))) = queue.pop() else { break };
            if !work.alive[u as usize] || !work.alive[v as usize] || version != work.version[u as usize] {
                continue;
            }
            if !work.can_collapse(u, v) {
                continue;
            }
            work.collapse(u, v);
            left -= 1;
            // v's quadric changed: its collapses; and every neighbour may
            // now collapse into v.
            push(&work, &mut queue, v);
            for w in work.neighbours(v) {
                let cost = work.cost(w, v);
                queue.push(Reverse((Cost(cost), w, v, work.version[w as usize])));
            }
        }
        self.coarse_mesh(&work)
    }

    /// The working mesh: positions in 3-D (z = 0 in the plane), the signal
    /// scaled to its weight, adjacency and quadrics.
    fn work(&self, signal_weight: f64) -> Work {
        let (n, dim) = (self.n_vertices(), self.dim());
        let x: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let p = self.point(i);
                [p[0], p[1], if dim == 3 { p[2] } else { 0.0 }]
            })
            .collect();
        // Each map in units where one standard deviation is signal_weight
        // × 1 % of the diagonal, so that its quadric adds to the plane's.
        // The first map's quadric is summed with the geometry's (one map:
        // one quadric, as always); the others have their own.
        let k = self.n_channels().max(1);
        let scaled = |c: usize| match self.channel(c) {
            Some(f) if signal_weight > 0.0 => scaled_map(&f, signal_weight * 0.01 * self.bounding_box().diagonal()),
            _ => vec![0.0; n],
        };
        let s = scaled(0);
        let extra = k - 1;
        let mut s_more = vec![0.0; n * extra];
        for c in 1..k {
            for (i, v) in scaled(c).into_iter().enumerate() {
                s_more[i * extra + c - 1] = v;
            }
        }
        let faces: Vec<[u32; 3]> = self.cell_iter().map(|c| [c[0] as u32, c[1] as u32, c[2] as u32]).collect();
        let mut around = vec![Vec::new(); n];
        for (f, face) in faces.iter().enumerate() {
            for &w in face {
                around[w as usize].push(f as u32);
            }
        }
        let mut q = vec![Quadric::default(); n];
        let mut q_more = vec![Quadric::default(); n * extra];
        // Each undirected edge's faces, to find the boundary.
        let mut edges: Vec<(u32, u32, u32)> = faces
            .iter()
            .enumerate()
            .flat_map(|(f, t)| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]), f as u32)))
            .collect();
        edges.sort_unstable();
        let mut boundary = vec![false; n];
        for t in &faces {
            let p = t.map(|w| x[w as usize]);
            let nrm = normal(p[0], p[1], p[2]);
            let twice = dot(nrm, nrm).sqrt();
            if twice == 0.0 {
                continue;
            }
            let (area, unit) = (0.5 * twice, nrm.map(|c| c / twice));
            let plane = Quadric::plane([unit[0], unit[1], unit[2], 0.0, -dot(unit, p[0])], area);
            let signal = linear_signal(p, t.map(|w| s[w as usize]), area);
            for &w in t {
                let qw = &mut q[w as usize];
                qw.add(&plane);
                qw.add(&signal);
                qw.add(&Quadric::point(x[w as usize], ISOTROPIC * area));
            }
            for c in 0..extra {
                let signal = linear_signal(p, t.map(|w| s_more[w as usize * extra + c]), area);
                for &w in t {
                    q_more[w as usize * extra + c].add(&signal);
                }
            }
        }
        let mut k = 0;
        while k < edges.len() {
            let (a, b, f) = edges[k];
            let count = edges[k..].iter().take_while(|e| e.0 == a && e.1 == b).count();
            if count == 1 {
                boundary[a as usize] = true;
                boundary[b as usize] = true;
                let t = faces[f as usize];
                let p = t.map(|w| x[w as usize]);
                let nrm = normal(p[0], p[1], p[2]);
                let e = sub(x[b as usize], x[a as usize]);
                let m = cross(e, nrm);
                let len = dot(m, m).sqrt();
                if len > 0.0 {
                    let m = m.map(|c| c / len);
                    let wall = Quadric::plane([m[0], m[1], m[2], 0.0, -dot(m, x[a as usize])], BOUNDARY * dot(e, e));
                    q[a as usize].add(&wall);
                    q[b as usize].add(&wall);
                }
            }
            k += count;
        }
        Work {
            x,
            s,
            face_alive: vec![true; faces.len()],
            faces,
            alive: around.iter().map(|a| !a.is_empty()).collect(),
            around,
            boundary,
            q,
            s_more,
            q_more,
            extra,
            version: vec![0; n],
        }
    }

    /// The live vertices (in their order) and faces as an fshape.
    fn coarse_mesh(&self, work: &Work) -> Result<Simplified, SimplifyError> {
        let kept: Vec<usize> = (0..work.x.len()).filter(|&i| work.alive[i]).collect();
        let mut index = vec![usize::MAX; work.x.len()];
        for (new, &old) in kept.iter().enumerate() {
            index[old] = new;
        }
        let points: Vec<f64> = kept.iter().flat_map(|&i| self.point(i).to_vec()).collect();
        let cells: Vec<usize> = work
            .faces
            .iter()
            .zip(&work.face_alive)
            .filter(|(_, alive)| **alive)
            .flat_map(|(t, _)| t.map(|w| index[w as usize]))
            .collect();
        let k = self.n_channels();
        let signal = self.signal().map(|f| kept.iter().flat_map(|&i| f[i * k..(i + 1) * k].to_vec()).collect());
        let mask = self.mask().map(|m| kept.iter().map(|&i| m[i]).collect());
        // The kept vertices keep their values and their mask weights.
        let shape = FShape::try_new(self.dim(), CellKind::Triangle, points, cells, None)?.with_signals_and_mask(
            signal,
            k.max(1),
            mask,
        )?;
        Ok(Simplified { shape, kept })
    }
}
