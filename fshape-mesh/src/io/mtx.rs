//! MatrixMarket coordinate files of symmetric sparse matrices (the lower
//! triangle, as stored in compressed sparse columns).

use std::path::Path;

use super::{WriteError, write_atomic};

/// The text of a symmetric `n × n` matrix given by its lower triangle in
/// compressed sparse columns (`col_ptr` of length n + 1, `row_idx` and
/// `values` of length nnz, every row index ≥ its column), with a comment
/// line. Indices are written 1-based, values in `{:e}` form.
///
/// ```
/// let text = fshape_mesh::io::mtx::symmetric_lower(2, &[0, 2, 3], &[0, 1, 1], &[2.0, -1.0, 2.0], "a test");
/// assert_eq!(text, "%%MatrixMarket matrix coordinate real symmetric\n% a test\n2 2 3\n1 1 2e0\n2 1 -1e0\n2 2 2e0\n");
/// ```
///
/// # Panics
///
/// If the arrays do not describe such a matrix (a caller's bug).
#[track_caller]
pub fn symmetric_lower(n: usize, col_ptr: &[usize], row_idx: &[usize], values: &[f64], comment: &str) -> String {
    assert!(col_ptr.len() == n + 1 && row_idx.len() == values.len() && col_ptr[n] == values.len());
    let mut text = String::from("%%MatrixMarket matrix coordinate real symmetric\n");
    for line in comment.lines() {
        text.push_str(&format!("% {line}\n"));
    }
    text.push_str(&format!("{n} {n} {}\n", values.len()));
    for c in 0..n {
        for e in col_ptr[c]..col_ptr[c + 1] {
            assert!(row_idx[e] >= c && row_idx[e] < n, "entry {e} is not in the lower triangle");
            text.push_str(&format!("{} {} {:e}\n", row_idx[e] + 1, c + 1, values[e]));
        }
    }
    text
}

/// Writes [`symmetric_lower`] to `path` atomically.
#[track_caller]
pub fn write_symmetric_lower(
    path: &Path,
    n: usize,
    col_ptr: &[usize],
    row_idx: &[usize],
    values: &[f64],
    comment: &str,
) -> Result<(), WriteError> {
    write_atomic(path, symmetric_lower(n, col_ptr, row_idx, values, comment).as_bytes(), false)
}
