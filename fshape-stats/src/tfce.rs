//! Threshold-free cluster enhancement on a mesh (Smith & Nichols 2009):
//!
//! ```text
//! TFCE(v) = ∫_0^{s(v)} e(h)^E h^H dh
//! ```
//!
//! where e(h) is the area (length for a curve) of the connected part of
//! {s ≥ h} that contains v, vertices joined by the mesh's edges and each
//! vertex weighing its lumped area. The integral is the sum at h = k·dh,
//! k = 1, 2, … with dh = max s / steps, as FSL and PALM compute it. The
//! defaults E = 1, H = 2 are those of FSL and PALM for surfaces.

use fshape_mesh::FShape;

/// TFCE's parameters.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TfceParams {
    /// Extent exponent E.
    pub extent: f64,
    /// Height exponent H.
    pub height: f64,
    /// Threshold steps from 0 to the map's maximum.
    pub steps: usize,
}

impl Default for TfceParams {
    fn default() -> TfceParams {
        TfceParams { extent: 1.0, height: 2.0, steps: 100 }
    }
}

/// A mesh's vertex graph (its cells' edges) and its vertices' lumped
/// areas: what clusters need.
#[derive(Clone, Debug)]
pub struct MeshGraph {
    offsets: Vec<usize>,
    neighbours: Vec<usize>,
    areas: Vec<f64>,
}

impl MeshGraph {
    /// The graph of `shape`'s cells.
    pub fn new(shape: &FShape) -> MeshGraph {
        let n = shape.n_vertices();
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        for cell in shape.cell_iter() {
            for (a, &u) in cell.iter().enumerate() {
                for &v in &cell[a + 1..] {
                    pairs.push((u, v));
                    pairs.push((v, u));
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut offsets = vec![0; n + 1];
        for &(u, _) in &pairs {
            offsets[u + 1] += 1;
        }
        for k in 0..n {
            offsets[k + 1] += offsets[k];
        }
        MeshGraph { offsets, neighbours: pairs.into_iter().map(|(_, v)| v).collect(), areas: shape.vertex_volumes() }
    }

    /// The graph of the vertices `keep` marks, numbered in order among
    /// them: an edge stays when both its ends are kept, each kept vertex
    /// keeps its area. A cluster cannot cross a vertex outside (a masked
    /// medial wall separates what lies on either side of it).
    pub fn restricted(&self, keep: &[bool]) -> MeshGraph {
        assert_eq!(keep.len(), self.len(), "one flag per vertex");
        let mut renumber = vec![usize::MAX; keep.len()];
        let mut count = 0;
        for (v, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
            renumber[v] = count;
            count += 1;
        }
        let (mut offsets, mut neighbours, mut areas) = (vec![0], Vec::new(), Vec::with_capacity(count));
        for v in (0..keep.len()).filter(|&v| keep[v]) {
            neighbours.extend(self.neighbours(v).iter().filter(|&&u| keep[u]).map(|&u| renumber[u]));
            offsets.push(neighbours.len());
            areas.push(self.areas[v]);
        }
        MeshGraph { offsets, neighbours, areas }
    }

    /// Vertices.
    pub fn len(&self) -> usize {
        self.areas.len()
    }

    /// No vertices.
    pub fn is_empty(&self) -> bool {
        self.areas.is_empty()
    }

    fn neighbours(&self, v: usize) -> &[usize] {
        &self.neighbours[self.offsets[v]..self.offsets[v + 1]]
    }
}

fn find(parent: &mut [usize], mut v: usize) -> usize {
    while parent[v] != v {
        parent[v] = parent[parent[v]];
        v = parent[v];
    }
    v
}

/// TFCE of the non-negative part of `s` (negative values count as 0),
/// written to `out`. Thresholds are visited from the highest down; each
/// step adds the vertices reaching it and joins them to their neighbours
/// already in (union–find), so one pass over the sorted vertices serves
/// every threshold.
pub fn tfce(s: &[f64], graph: &MeshGraph, params: TfceParams, out: &mut [f64]) {
    let n = s.len();
    out.fill(0.0);
    let max = s.iter().copied().fold(0.0, f64::max);
    if max <= 0.0 || params.steps == 0 {
        return;
    }
    let dh = max / params.steps as f64;
    let mut order: Vec<usize> = (0..n).filter(|&v| s[v] >= dh).collect();
    order.sort_by(|&a, &b| s[b].total_cmp(&s[a]).then(a.cmp(&b)));
    let mut parent: Vec<usize> = (0..n).collect();
    let mut area: Vec<f64> = graph.areas.clone();
    let mut inside = vec![false; n];
    let mut added = 0;
    for k in (1..=params.steps).rev() {
        let h = k as f64 * dh;
        while added < order.len() && s[order[added]] >= h {
            let v = order[added];
            inside[v] = true;
            for &u in graph.neighbours(v) {
                if inside[u] {
                    let (a, b) = (find(&mut parent, u), find(&mut parent, v));
                    if a != b {
                        let (big, small) = if area[a] >= area[b] { (a, b) } else { (b, a) };
                        parent[small] = big;
                        area[big] += area[small];
                    }
                }
            }
            added += 1;
        }
        let weight = h.powf(params.height) * dh;
        for &v in &order[..added] {
            let root = find(&mut parent, v);
            out[v] += area[root].powf(params.extent) * weight;
        }
    }
}

/// Signed TFCE: the TFCE of s's positive part minus that of its negative
/// part (two-sided t maps).
pub fn tfce_signed(s: &[f64], graph: &MeshGraph, params: TfceParams, out: &mut [f64]) {
    tfce(s, graph, params, out);
    let negative: Vec<f64> = s.iter().map(|v| -v).collect();
    let mut below = vec![0.0; s.len()];
    tfce(&negative, graph, params, &mut below);
    for (o, b) in out.iter_mut().zip(below) {
        *o -= b;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fshape_mesh::generate::{SplitMix64, icosphere};

    /// The obvious TFCE: at every threshold, the clusters found afresh by
    /// a breadth-first search.
    fn tfce_by_search(s: &[f64], graph: &MeshGraph, params: TfceParams) -> Vec<f64> {
        let n = s.len();
        let max = s.iter().copied().fold(0.0, f64::max);
        let dh = max / params.steps as f64;
        let mut out = vec![0.0; n];
        for k in 1..=params.steps {
            let h = k as f64 * dh;
            let mut label = vec![usize::MAX; n];
            for start in 0..n {
                if s[start] < h || label[start] != usize::MAX {
                    continue;
                }
                let (mut members, mut queue) = (vec![start], vec![start]);
                label[start] = start;
                while let Some(v) = queue.pop() {
                    for &u in graph.neighbours(v) {
                        if s[u] >= h && label[u] == usize::MAX {
                            label[u] = start;
                            members.push(u);
                            queue.push(u);
                        }
                    }
                }
                let e: f64 = members.iter().map(|&v| graph.areas[v]).sum();
                for &v in &members {
                    out[v] += e.powf(params.extent) * h.powf(params.height) * dh;
                }
            }
        }
        out
    }

    #[test]
    fn union_find_tfce_matches_the_search_at_every_threshold() {
        let sphere = icosphere(2, 1.0);
        let graph = MeshGraph::new(&sphere);
        let mut rng = SplitMix64(7);
        for trial in 0..5 {
            // Smooth-ish random maps: a few bumps plus noise, some negative.
            let centres: Vec<usize> = (0..3).map(|_| (rng.uniform() * graph.len() as f64) as usize).collect();
            let s: Vec<f64> = (0..graph.len())
                .map(|v| {
                    let p = sphere.point(v);
                    centres
                        .iter()
                        .map(|&c| {
                            let q = sphere.point(c);
                            let d2: f64 = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum();
                            3.0 * (-d2 / 0.3).exp()
                        })
                        .sum::<f64>()
                        + rng.range(-0.5, 0.5)
                })
                .collect();
            let params = TfceParams { extent: [1.0, 0.5][trial % 2], height: 2.0, steps: 50 };
            let mut fast = vec![0.0; s.len()];
            tfce(&s, &graph, params, &mut fast);
            let slow = tfce_by_search(&s, &graph, params);
            for (a, b) in fast.iter().zip(&slow) {
                assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{a} vs {b}");
            }
            assert!(fast.iter().any(|&v| v > 0.0));
        }
    }

    #[test]
    fn a_lone_vertex_gets_its_area_times_the_height_integral() {
        // One vertex at height 1, the rest 0: e = its area at every step,
        // TFCE = a Σ_k (k/K)² / K → a/3 as K grows.
        let sphere = icosphere(1, 1.0);
        let graph = MeshGraph::new(&sphere);
        let mut s = vec![0.0; graph.len()];
        s[5] = 1.0;
        let mut out = vec![0.0; s.len()];
        let steps = 1000;
        tfce(&s, &graph, TfceParams { extent: 1.0, height: 2.0, steps }, &mut out);
        let k = steps as f64;
        let exact = graph.areas[5] * (k + 1.0) * (2.0 * k + 1.0) / (6.0 * k * k);
        assert!((out[5] - exact).abs() < 1e-12 * exact);
        assert!(out.iter().enumerate().all(|(v, &x)| v == 5 || x == 0.0));
    }
}
