//! Connectivity: facets (edges of triangles, end points of segments),
//! boundaries, non-manifold facets, orientation, connected components.

use crate::shape::{CellKind, FShape};

pub use crate::cell::Facet;

/// The connectivity summary of an fshape, from [`FShape::topology`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Topology {
    /// Number of distinct facets (edges of a surface, vertices of a curve).
    pub n_facets: usize,
    /// Facets used by exactly one cell, oriented as in that cell.
    pub boundary_facets: Vec<Facet>,
    /// Facets used by more than two cells, with the number of cells.
    pub nonmanifold_facets: Vec<(Facet, usize)>,
    /// Directed facets used by more than one cell: for a surface, a
    /// half-edge a→b that two cells traverse the same way (so their normals
    /// disagree); for a curve, a vertex that starts (or ends) two segments.
    /// A surface facet is listed as the repeated direction `[a, b]`.
    pub misoriented_facets: Vec<Facet>,
    /// Number of connected components of the used vertices.
    pub n_components: usize,
    /// For each vertex, its component, or `None` for an unused vertex.
    pub vertex_component: Vec<Option<usize>>,
    /// Number of closed boundary loops of a surface (connected components
    /// of the boundary edge graph); for a curve, its number of end points.
    pub n_boundary_loops: usize,
    /// Number of vertices used by at least one cell.
    pub n_used_vertices: usize,
}

impl Topology {
    /// True when no facet lies on a boundary (a closed surface or curve).
    pub fn is_closed(&self) -> bool {
        self.boundary_facets.is_empty()
    }

    /// Euler characteristic V − E + F of the used vertices (surfaces), or
    /// V − E (curves), where `n_cells` is the shape's cell count.
    pub fn euler_characteristic(&self, kind: CellKind, n_cells: usize) -> i64 {
        match kind {
            CellKind::Triangle => self.n_used_vertices as i64 - self.n_facets as i64 + n_cells as i64,
            CellKind::Segment => self.n_used_vertices as i64 - n_cells as i64,
        }
    }
}

/// Union–find with path halving; small enough to keep here rather than pull
/// a crate for it.
pub(crate) struct UnionFind(Vec<usize>);

impl UnionFind {
    pub(crate) fn new(n: usize) -> Self {
        UnionFind((0..n).collect())
    }

    pub(crate) fn find(&mut self, mut i: usize) -> usize {
        while self.0[i] != i {
            self.0[i] = self.0[self.0[i]];
            i = self.0[i];
        }
        i
    }

    pub(crate) fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb)] = ra.min(rb);
        }
    }
}

/// One use of a facet by a cell: its key (sorted), whether the cell
/// traverses it forward, and the facet as the cell sees it.
struct Use {
    key: Facet,
    forward: bool,
    oriented: Facet,
}

fn facet_uses(shape: &FShape) -> Vec<Use> {
    let mut uses = Vec::with_capacity(shape.cells().len());
    for c in shape.cell_iter() {
        match shape.kind() {
            CellKind::Triangle => {
                for (a, b) in [(c[0], c[1]), (c[1], c[2]), (c[2], c[0])] {
                    uses.push(Use { key: [a.min(b), a.max(b)], forward: a < b, oriented: [a, b] });
                }
            }
            CellKind::Segment => {
                uses.push(Use { key: [c[0], c[0]], forward: true, oriented: [c[0], c[0]] });
                uses.push(Use { key: [c[1], c[1]], forward: false, oriented: [c[1], c[1]] });
            }
        }
    }
    uses.sort_unstable_by_key(|u| u.key);
    uses
}

impl FShape {
    /// Computes the connectivity summary in O(T log T).
    pub fn topology(&self) -> Topology {
        let mut topo = Topology::default();
        let uses = facet_uses(self);
        for group in uses.chunk_by(|a, b| a.key == b.key) {
            topo.n_facets += 1;
            match group.len() {
                1 => topo.boundary_facets.push(group[0].oriented),
                2 => {}
                n => topo.nonmanifold_facets.push((group[0].key, n)),
            }
            let forward = group.iter().filter(|u| u.forward).count();
            let [a, b] = group[0].key;
            if forward > 1 {
                topo.misoriented_facets.push([a, b]);
            }
            if group.len() - forward > 1 {
                topo.misoriented_facets.push([b, a]);
            }
        }
        self.fill_components(&mut topo);
        topo.n_boundary_loops = match self.kind() {
            CellKind::Segment => topo.boundary_facets.len(),
            CellKind::Triangle => count_loops(self.n_vertices(), &topo.boundary_facets),
        };
        topo
    }

    fn fill_components(&self, topo: &mut Topology) {
        let n = self.n_vertices();
        let mut uf = UnionFind::new(n);
        let mut used = vec![false; n];
        for c in self.cell_iter() {
            for &v in c {
                used[v] = true;
                uf.union(c[0], v);
            }
        }
        let mut label = vec![usize::MAX; n];
        topo.vertex_component = vec![None; n];
        for v in (0..n).filter(|&v| used[v]) {
            let r = uf.find(v);
            if label[r] == usize::MAX {
                label[r] = topo.n_components;
                topo.n_components += 1;
            }
            topo.vertex_component[v] = Some(label[r]);
            topo.n_used_vertices += 1;
        }
    }
}

fn count_loops(n_vertices: usize, edges: &[Facet]) -> usize {
    let mut uf = UnionFind::new(n_vertices);
    for &[a, b] in edges {
        uf.union(a, b);
    }
    let mut roots: Vec<usize> = edges.iter().map(|e| uf.find(e[0])).collect();
    roots.sort_unstable();
    roots.dedup();
    roots.len()
}
