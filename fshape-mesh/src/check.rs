//! The whole validation of an fshape (its cells, duplicates, topology)
//! and the usual repairs, over the finding types of [`crate::validate`].

use crate::shape::FShape;
use crate::validate::{Finding, RepairLog, Repairs, Validation, ZERO_VOLUME_REL, blocking_problems, cell_key};

impl FShape {
    /// Every problem of the shape, blocking or not (see [`Validation`]).
    pub fn validate(&self) -> Validation {
        validate(self)
    }
}

fn validate(shape: &FShape) -> Validation {
    let mut problems = blocking_problems(
        shape.dim(),
        shape.kind(),
        shape.points(),
        shape.cells(),
        shape.signal(),
        shape.n_channels(),
        shape.mask(),
    );
    let d = shape.kind().dim() as i32;
    let tol = ZERO_VOLUME_REL * shape.bounding_box().diagonal().powi(d);
    for t in 0..shape.n_cells() {
        let volume = shape.cell_volume(t);
        if volume <= tol {
            problems.push(Finding::ZeroVolumeCell { cell: t, volume });
        }
    }
    problems.extend(duplicate_cells(shape));
    let topo = shape.topology();
    for (vertex, c) in topo.vertex_component.iter().enumerate() {
        if c.is_none() {
            problems.push(Finding::UnusedVertex { vertex });
        }
    }
    for &(facet, cells) in &topo.nonmanifold_facets {
        problems.push(Finding::NonManifoldFacet { facet, cells });
    }
    for &facet in &topo.misoriented_facets {
        problems.push(Finding::InconsistentOrientation { facet });
    }
    if !topo.is_closed() {
        problems.push(Finding::Boundary { facets: topo.boundary_facets.len(), loops: topo.n_boundary_loops });
    }
    Validation { problems }
}

/// Cells that repeat the vertex set of an earlier cell. A repeat is "same
/// orientation" when an earlier copy has its orientation (and `first` is
/// that copy), "opposite" otherwise (and `first` is the earliest copy): the
/// counts are then the same as counting distinct oriented cells.
fn duplicate_cells(shape: &FShape) -> Vec<Finding> {
    let mut keyed: Vec<([usize; 3], usize, bool)> = shape
        .cell_iter()
        .enumerate()
        .map(|(t, c)| {
            let (k, o) = cell_key(c);
            (k, t, o)
        })
        .collect();
    keyed.sort_unstable();
    let mut out = Vec::new();
    for group in keyed.chunk_by(|a, b| a.0 == b.0) {
        // Sorted by cell index within the group.
        for (i, &(_, cell, o)) in group.iter().enumerate().skip(1) {
            let same = group[..i].iter().find(|g| g.2 == o);
            let first = same.map_or(group[0].1, |g| g.1);
            out.push(Finding::DuplicateCell { cell, first, same_orientation: same.is_some() });
        }
    }
    out.sort_unstable_by_key(|p| match p {
        Finding::DuplicateCell { cell, .. } => *cell,
        _ => 0,
    });
    out
}

impl FShape {
    /// A copy with the chosen repairs applied, and what was removed. Cells
    /// are dropped first, so vertices used only by dropped cells become
    /// unused and are dropped too when `drop_unused_vertices` is set.
    pub fn repaired(&self, repairs: Repairs) -> (FShape, RepairLog) {
        let mut drop_cell = vec![false; self.n_cells()];
        for p in validate(self).problems {
            match p {
                Finding::ZeroVolumeCell { cell, .. } if repairs.drop_zero_volume_cells => drop_cell[cell] = true,
                Finding::DuplicateCell { cell, .. } if repairs.drop_duplicate_cells => drop_cell[cell] = true,
                _ => {}
            }
        }
        let mut log = RepairLog::default();
        let mut used = vec![!repairs.drop_unused_vertices; self.n_vertices()];
        let mut kept_cells = Vec::new();
        for (t, c) in self.cell_iter().enumerate() {
            if drop_cell[t] {
                log.dropped_cells.push(t);
            } else {
                kept_cells.extend_from_slice(c);
                c.iter().for_each(|&v| used[v] = true);
            }
        }
        let mut next = 0;
        log.vertex_map = used
            .iter()
            .map(|&u| {
                u.then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect();
        log.dropped_vertices = (0..self.n_vertices()).filter(|&v| !used[v]).collect();
        let n = self.dim();
        let points: Vec<f64> =
            (0..self.n_vertices()).filter(|&v| used[v]).flat_map(|v| self.point(v).to_vec()).collect();
        let cells = kept_cells.iter().map(|&v| log.vertex_map[v].unwrap_or(usize::MAX)).collect();
        let k = self.n_channels();
        let signal = self.signal().map(|f| {
            (0..self.n_vertices()).filter(|&v| used[v]).flat_map(|v| f[v * k..(v + 1) * k].to_vec()).collect()
        });
        let mask = self.mask().map(|m| (0..m.len()).filter(|&v| used[v]).map(|v| m[v]).collect());
        debug_assert_eq!(points.len() % n, 0);
        let shape = FShape::try_new(n, self.kind(), points, cells, None)
            .and_then(|s| s.with_signals_and_mask(signal, k, mask))
            .expect("repairs of a valid shape keep it valid");
        (shape, log)
    }
}
