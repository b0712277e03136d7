//! Wavefront OBJ: `v` positions and `f` triangles (or `l` polylines), in
//! file order.
//!
//! Written by hand rather than with tobj because tobj renumbers vertices by
//! first use and drops unused ones (its `export_faces` index map): a
//! per-vertex signal CSV would no longer line up with the vertices, and the
//! unused vertices a user should be warned about would vanish silently. tobj
//! stays in the tests as an independent reader of the same files.
//!
//! Read: `v x y z` (extra values such as colours ignored), `f a b c` with
//! `i`, `i/t`, `i//n` or `i/t/n` references, 1-based or negative (relative);
//! `l` polylines become segments. Faces with more than three vertices are
//! refused (triangulate first). Every other statement is skipped. OBJ has no
//! per-vertex scalar, so read a signal from a CSV file.

use std::io::{self, Write};

use super::cursor::{Cursor, lossy, parse_f64};
use super::{ParseError, ParseErrorKind, RawMesh};
use crate::shape::{CellKind, FShape};

/// The comment that marks a planar (2-D) shape written with z = 0.
pub const PLANAR_COMMENT: &str = "# fshape planar";

/// Parses OBJ data.
pub(crate) fn parse(data: &[u8]) -> Result<RawMesh, ParseError> {
    let mut cur = Cursor::new(data);
    let mut raw = RawMesh { dim: 3, ..RawMesh::default() };
    let mut planar = false;
    let mut n_cells = 0;
    loop {
        let at = cur.at();
        let Some(line) = cur.text_line("an OBJ statement")? else {
            break;
        };
        let err = |kind| ParseError { at, kind };
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                for _ in 0..3 {
                    let w = words
                        .next()
                        .ok_or_else(|| err(ParseErrorKind::Eof { expected: "three vertex coordinates" }))?;
                    let x = parse_f64(w.as_bytes()).ok_or_else(|| {
                        err(ParseErrorKind::BadToken { expected: "a coordinate", found: lossy(w.as_bytes()) })
                    })?;
                    raw.points.push(x);
                }
            }
            Some(kw @ ("f" | "l")) => {
                let size = if kw == "f" { 3 } else { 2 };
                let refs: Vec<&str> = words.collect();
                if kw == "f" && refs.len() != 3 {
                    return Err(err(ParseErrorKind::CellSize { cell: n_cells, found: refs.len() }));
                }
                if kw == "l" && refs.len() < 2 {
                    return Err(err(ParseErrorKind::Eof { expected: "at least two vertices after `l`" }));
                }
                match raw.cell_size {
                    None => raw.cell_size = Some(size),
                    Some(s) if s != size => {
                        return Err(err(ParseErrorKind::MixedCellSizes { cell: n_cells, found: size, expected: s }));
                    }
                    _ => {}
                }
                let n_vertices = raw.points.len() / 3;
                let ids = refs
                    .iter()
                    .map(|r| vertex_ref(r, n_vertices, n_cells))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(err)?;
                if kw == "f" {
                    raw.cells.extend_from_slice(&ids);
                    n_cells += 1;
                } else {
                    for w in ids.windows(2) {
                        raw.cells.extend_from_slice(w);
                        n_cells += 1;
                    }
                }
            }
            Some("#") => planar |= line.trim() == PLANAR_COMMENT,
            _ => {}
        }
    }
    if planar && raw.points.chunks_exact(3).all(|p| p[2] == 0.0) {
        raw.points = raw.points.chunks_exact(3).flat_map(|p| [p[0], p[1]]).collect();
        raw.dim = 2;
    }
    Ok(raw)
}

/// The 0-based vertex of a face reference `i[/t[/n]]`.
fn vertex_ref(r: &str, n_vertices: usize, cell: usize) -> Result<usize, ParseErrorKind> {
    let head = r.split('/').next().unwrap_or("");
    let bad = || ParseErrorKind::BadToken {
        expected: "a vertex reference (1-based, or negative for relative)",
        found: lossy(r.as_bytes()),
    };
    let i: i64 = head.parse().map_err(|_| bad())?;
    match i {
        0 => Err(bad()),
        i if i > 0 => Ok(i as usize - 1),
        // -1 is the last vertex defined so far.
        i => usize::try_from(n_vertices as i64 + i).map_err(|_| ParseErrorKind::NegativeIndex { cell, value: i }),
    }
}

/// Writes `shape` as OBJ (geometry only; the signal is not written).
pub fn write(w: &mut impl Write, shape: &FShape) -> io::Result<()> {
    writeln!(w, "# written by fshape-mesh")?;
    if shape.dim() == 2 {
        writeln!(w, "{PLANAR_COMMENT}")?;
    }
    for v in 0..shape.n_vertices() {
        let p = shape.point(v);
        let z = if shape.dim() == 3 { p[2] } else { 0.0 };
        writeln!(w, "v {:e} {:e} {:e}", p[0], p[1], z)?;
    }
    let kw = if shape.kind() == CellKind::Triangle { "f" } else { "l" };
    for c in shape.cell_iter() {
        let ids: Vec<String> = c.iter().map(|v| (v + 1).to_string()).collect();
        writeln!(w, "{kw} {}", ids.join(" "))?;
    }
    Ok(())
}
