//! Validation: every problem of an fshape with its index, split into errors
//! (nothing can be computed) and warnings (computations are defined), and
//! the usual repairs.

use std::fmt;

use crate::cell::{CellKind, Facet};

/// Whether a problem blocks computation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Severity {
    /// Nothing can be computed on the shape until it is fixed.
    Error,
    /// Computations are defined; the result may not be what was meant.
    Warning,
}

/// Cells whose volume is at most this fraction of diag^d (diag = bounding
/// box diagonal) count as zero-volume: below it the cell's normal is noise.
pub const ZERO_VOLUME_REL: f64 = 1e-12;

/// One problem of an fshape, naming where it is.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Finding {
    /// A coordinate is NaN or infinite. Error.
    NonFiniteCoordinate {
        /// Vertex index.
        vertex: usize,
    },
    /// A signal value is NaN or infinite (a missing value). Error: fill or
    /// drop missing values before building the shape.
    NonFiniteSignal {
        /// Vertex index.
        vertex: usize,
    },
    /// A mask value is not a number in [0, 1]. Error.
    MaskValue {
        /// Vertex index.
        vertex: usize,
        /// The value.
        value: f64,
    },
    /// The mask does not have one value per vertex. Error.
    MaskLength {
        /// Number of vertices.
        expected: usize,
        /// Number of mask values.
        found: usize,
    },
    /// The signal does not have one value per vertex and channel. Error.
    SignalLength {
        /// Number of vertices times the number of channels.
        expected: usize,
        /// Number of signal values.
        found: usize,
    },
    /// A cell refers to a vertex that does not exist. Error.
    IndexOutOfRange {
        /// Cell index.
        cell: usize,
        /// The offending vertex index.
        index: usize,
        /// Number of vertices.
        n_vertices: usize,
    },
    /// A cell uses the same vertex twice. Error.
    RepeatedIndex {
        /// Cell index.
        cell: usize,
        /// The repeated vertex.
        vertex: usize,
    },
    /// A cell has (numerically) zero volume: it carries no mass in the
    /// signal norms and data terms, and has no normal. Warning; repair:
    /// drop zero-volume cells.
    ZeroVolumeCell {
        /// Cell index.
        cell: usize,
        /// Its volume.
        volume: f64,
    },
    /// A cell uses the same vertices as an earlier one. Warning; repair:
    /// drop duplicate cells.
    DuplicateCell {
        /// Cell index.
        cell: usize,
        /// The earlier cell with the same vertices.
        first: usize,
        /// Whether both have the same orientation.
        same_orientation: bool,
    },
    /// No cell uses this vertex: it carries no mass. Warning; repair: drop
    /// unused vertices.
    UnusedVertex {
        /// Vertex index.
        vertex: usize,
    },
    /// More than two cells share this facet (edge of a surface, vertex of a
    /// curve). Warning.
    NonManifoldFacet {
        /// The facet (for a curve both entries are the vertex).
        facet: Facet,
        /// Number of cells sharing it.
        cells: usize,
    },
    /// Two cells traverse this directed facet the same way, so their normals
    /// (tangents) disagree. Warning: oriented data terms (currents) then see
    /// cancellations.
    InconsistentOrientation {
        /// The directed edge `[a, b]` used twice (for a curve both entries
        /// are the vertex).
        facet: Facet,
    },
    /// The shape has a boundary. Warning (informational): boundaries are
    /// normal for open surfaces, curves and image domains.
    Boundary {
        /// Number of boundary facets.
        facets: usize,
        /// Number of boundary loops (surfaces) or end points (curves).
        loops: usize,
    },
}

impl Finding {
    /// Whether the problem blocks computation.
    pub fn severity(&self) -> Severity {
        match self {
            Finding::NonFiniteCoordinate { .. }
            | Finding::NonFiniteSignal { .. }
            | Finding::SignalLength { .. }
            | Finding::MaskValue { .. }
            | Finding::MaskLength { .. }
            | Finding::IndexOutOfRange { .. }
            | Finding::RepeatedIndex { .. } => Severity::Error,
            _ => Severity::Warning,
        }
    }

    /// A short stable name for the kind of problem (used to group reports
    /// and in JSON output).
    pub fn code(&self) -> &'static str {
        match self {
            Finding::NonFiniteCoordinate { .. } => "non_finite_coordinate",
            Finding::NonFiniteSignal { .. } => "non_finite_signal",
            Finding::SignalLength { .. } => "signal_length",
            Finding::MaskValue { .. } => "mask_value",
            Finding::MaskLength { .. } => "mask_length",
            Finding::IndexOutOfRange { .. } => "index_out_of_range",
            Finding::RepeatedIndex { .. } => "repeated_index",
            Finding::ZeroVolumeCell { .. } => "zero_volume_cell",
            Finding::DuplicateCell { .. } => "duplicate_cell",
            Finding::UnusedVertex { .. } => "unused_vertex",
            Finding::NonManifoldFacet { .. } => "non_manifold_facet",
            Finding::InconsistentOrientation { .. } => "inconsistent_orientation",
            Finding::Boundary { .. } => "boundary",
        }
    }
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Finding::NonFiniteCoordinate { vertex } => {
                write!(f, "vertex {vertex} has a NaN or infinite coordinate")
            }
            Finding::NonFiniteSignal { vertex } => {
                write!(f, "vertex {vertex} has a NaN or infinite (missing) signal value")
            }
            Finding::SignalLength { expected, found } => {
                write!(f, "the signal has {found} values where {expected} were expected (one per vertex and channel)")
            }
            Finding::MaskValue { vertex, value } => {
                write!(f, "vertex {vertex} has the mask value {value}; a mask holds weights in [0, 1]")
            }
            Finding::MaskLength { expected, found } => {
                write!(f, "the mask has {found} values for {expected} vertices")
            }
            Finding::IndexOutOfRange { cell, index, n_vertices } => {
                write!(f, "cell {cell} uses vertex {index}, but there are only {n_vertices} vertices")
            }
            Finding::RepeatedIndex { cell, vertex } => {
                write!(f, "cell {cell} uses vertex {vertex} twice")
            }
            Finding::ZeroVolumeCell { cell, volume } => {
                write!(f, "cell {cell} has zero volume ({volume:e})")
            }
            Finding::DuplicateCell { cell, first, same_orientation } => {
                let o = if *same_orientation { "same" } else { "opposite" };
                write!(f, "cell {cell} repeats cell {first} ({o} orientation)")
            }
            Finding::UnusedVertex { vertex } => write!(f, "vertex {vertex} is used by no cell"),
            Finding::NonManifoldFacet { facet, cells } => {
                write!(f, "{} is shared by {cells} cells", facet_name(*facet, false))
            }
            Finding::InconsistentOrientation { facet } => {
                write!(
                    f,
                    "{} is traversed the same way by two cells (inconsistent orientation)",
                    facet_name(*facet, true)
                )
            }
            Finding::Boundary { facets, loops } => {
                write!(f, "{facets} boundary facets in {loops} loops (or curve end points)")
            }
        }
    }
}

fn facet_name([a, b]: Facet, directed: bool) -> String {
    match (a == b, directed) {
        (true, _) => format!("vertex {a}"),
        (false, true) => format!("edge {a}→{b}"),
        (false, false) => format!("edge ({a}, {b})"),
    }
}

/// A one-paragraph summary of a problem list: counts per kind and the first
/// few instances of each.
pub fn summarise(problems: &[Finding]) -> String {
    const SHOWN: usize = 3;
    let mut codes: Vec<&'static str> = problems.iter().map(Finding::code).collect();
    codes.dedup();
    let mut seen = Vec::new();
    let mut parts = Vec::new();
    for code in codes {
        if seen.contains(&code) {
            continue;
        }
        seen.push(code);
        let of_kind: Vec<&Finding> = problems.iter().filter(|p| p.code() == code).collect();
        let shown: Vec<String> = of_kind.iter().take(SHOWN).map(|p| p.to_string()).collect();
        let more = of_kind.len().saturating_sub(SHOWN);
        let tail = if more > 0 { format!("; and {more} more") } else { String::new() };
        parts.push(format!("{} × {code}: {}{tail}", of_kind.len(), shown.join("; ")));
    }
    parts.join(" | ")
}

/// The full validation report of an fshape.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Validation {
    /// Every problem found, errors first, each group in index order.
    pub problems: Vec<Finding>,
}

impl Validation {
    /// The problems that block computation.
    pub fn errors(&self) -> impl Iterator<Item = &Finding> {
        self.problems.iter().filter(|p| p.severity() == Severity::Error)
    }

    /// The problems that allow computation.
    pub fn warnings(&self) -> impl Iterator<Item = &Finding> {
        self.problems.iter().filter(|p| p.severity() == Severity::Warning)
    }

    /// Number of problems with the given [`Finding::code`].
    pub fn count(&self, code: &str) -> usize {
        self.problems.iter().filter(|p| p.code() == code).count()
    }

    /// True when there is no problem at all.
    pub fn is_clean(&self) -> bool {
        self.problems.is_empty()
    }
}

impl fmt::Display for Validation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.problems.is_empty() {
            return f.write_str("no problems");
        }
        f.write_str(&summarise(&self.problems))
    }
}

/// The problems that make a shape unusable. Called by [`crate::FShape::try_new`]
/// on raw arrays whose lengths are already consistent.
pub(crate) fn blocking_problems(
    dim: usize,
    kind: CellKind,
    points: &[f64],
    cells: &[usize],
    signal: Option<&[f64]>,
    channels: usize,
    mask: Option<&[f64]>,
) -> Vec<Finding> {
    let n_vertices = points.len() / dim;
    let mut out = Vec::new();
    for (vertex, p) in points.chunks_exact(dim).enumerate() {
        if p.iter().any(|x| !x.is_finite()) {
            out.push(Finding::NonFiniteCoordinate { vertex });
        }
    }
    if let Some(m) = mask {
        if m.len() != n_vertices {
            out.push(Finding::MaskLength { expected: n_vertices, found: m.len() });
        }
        out.extend(
            m.iter()
                .enumerate()
                .filter(|(_, w)| !(0.0..=1.0).contains(*w))
                .map(|(vertex, &value)| Finding::MaskValue { vertex, value }),
        );
    }
    if let Some(f) = signal {
        // `channels` values per vertex, vertex by vertex.
        let k = channels.max(1);
        if f.len() != n_vertices * k {
            out.push(Finding::SignalLength { expected: n_vertices * k, found: f.len() });
        }
        // A masked vertex (weight 0) has no value: anything is accepted there.
        let masked = |v: usize| mask.is_some_and(|m| m.get(v) == Some(&0.0));
        let mut last = None;
        for (i, x) in f.iter().enumerate() {
            let vertex = i / k;
            if !x.is_finite() && !masked(vertex) && last != Some(vertex) {
                out.push(Finding::NonFiniteSignal { vertex });
                last = Some(vertex);
            }
        }
    }
    for (cell, c) in cells.chunks_exact(kind.n_corners()).enumerate() {
        for (i, &index) in c.iter().enumerate() {
            if index >= n_vertices {
                out.push(Finding::IndexOutOfRange { cell, index, n_vertices });
            } else if c[..i].contains(&index) {
                out.push(Finding::RepeatedIndex { cell, vertex: index });
            }
        }
    }
    out
}

/// Sorted corner list and orientation parity of a cell, for duplicate
/// detection.
pub(crate) fn cell_key(c: &[usize]) -> ([usize; 3], bool) {
    match *c {
        [a, b] => ([a.min(b), a.max(b), usize::MAX], a < b),
        [a, b, d] => {
            let mut k = [a, b, d];
            k.sort_unstable();
            // A triangle keeps its orientation under cyclic rotations: it is
            // "even" when, rotated to start at its smallest index, it is sorted.
            let m = c.iter().position(|&v| v == k[0]).unwrap_or(0);
            (k, c[(m + 1) % 3] == k[1])
        }
        _ => ([usize::MAX; 3], true),
    }
}

/// Which repairs [`crate::FShape::repaired`] applies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Repairs {
    /// Remove vertices no cell uses (renumbering the rest, signal kept).
    pub drop_unused_vertices: bool,
    /// Remove cells with zero volume ([`ZERO_VOLUME_REL`]).
    pub drop_zero_volume_cells: bool,
    /// Remove cells that repeat an earlier cell's vertices (whatever their
    /// orientation); the first is kept.
    pub drop_duplicate_cells: bool,
}

impl Repairs {
    /// Every repair.
    pub const ALL: Repairs =
        Repairs { drop_unused_vertices: true, drop_zero_volume_cells: true, drop_duplicate_cells: true };
}

/// What [`crate::FShape::repaired`] removed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RepairLog {
    /// Removed cells (original indices).
    pub dropped_cells: Vec<usize>,
    /// Removed vertices (original indices).
    pub dropped_vertices: Vec<usize>,
    /// For each original vertex, its new index (`None` if removed).
    pub vertex_map: Vec<Option<usize>>,
}
