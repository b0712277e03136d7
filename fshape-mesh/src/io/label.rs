//! FreeSurfer label files (`lh.cortex.label`): a region of a surface as the
//! list of its vertices, each with its coordinates and a value, in text:
//!
//! ```text
//! #!ascii label  , from subject fsaverage vox2ras=TkReg
//! 3
//! 12  -35.1  -20.5  61.0  0.000000
//! ...
//! ```
//!
//! (a comment line, the count, then one line per vertex: index from 0,
//! x, y, z, value), as FreeSurfer's `read_label.m` and nibabel's
//! `read_label` read it. fshape uses a label as a mask: its vertices 1,
//! the others 0 ([`Label::mask`]).

use std::path::Path;

use super::cursor::{Cursor, lossy};
use super::{Location, ParseError, ParseErrorKind, ReadError, WriteError};

/// A parsed label.
#[derive(Clone, Debug, PartialEq)]
pub struct Label {
    /// The vertices, as listed (indices from 0).
    pub vertices: Vec<usize>,
    /// Their coordinates (3 per vertex).
    pub points: Vec<f64>,
    /// Their values (FreeSurfer's statistic column, often 0).
    pub values: Vec<f64>,
}

impl Label {
    /// The mask of a surface of `n_vertices` vertices: 1 at the label's
    /// vertices, 0 elsewhere. A vertex beyond the surface is an error
    /// naming it (a label of another surface).
    pub fn mask(&self, n_vertices: usize) -> Result<Vec<f64>, ParseError> {
        let mut m = vec![0.0; n_vertices];
        for (k, &v) in self.vertices.iter().enumerate() {
            if v >= n_vertices {
                return Err(ParseError {
                    at: Location::Line(k + 3),
                    kind: ParseErrorKind::CountMismatch {
                        what: "a label vertex against the surface's vertex count (a label of another surface?)",
                        expected: n_vertices as u64,
                        found: v as u64,
                    },
                });
            }
            m[v] = 1.0;
        }
        Ok(m)
    }
}

/// Parses a label file's text. Errors name the line.
pub fn parse_label(data: &[u8]) -> Result<Label, ParseError> {
    let mut cur = Cursor::new(data);
    if cur.line().is_none() {
        return Err(cur.error(ParseErrorKind::Missing { what: "the label's comment line" }));
    }
    let at = cur.mark();
    let count = cur.i64_token("the label's vertex count")?;
    let count = usize::try_from(count).map_err(|_| ParseError {
        at,
        kind: ParseErrorKind::BadToken { expected: "a non-negative vertex count", found: count.to_string() },
    })?;
    super::source::check_values(count as u64, "label vertices").map_err(|kind| ParseError { at, kind })?;
    // A vertex line holds at least five numbers and their separators.
    if count.saturating_mul(10) > cur.remaining() + 1 {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::Truncated {
                what: "label vertices",
                claimed: count as u64,
                available: cur.remaining(),
            },
        });
    }
    let mut label = Label {
        vertices: Vec::with_capacity(count),
        points: Vec::with_capacity(3 * count),
        values: Vec::with_capacity(count),
    };
    cur.line();
    for _ in 0..count {
        let at = cur.mark();
        let Some(line) = cur.text_line("a label vertex line")? else {
            return Err(ParseError { at, kind: ParseErrorKind::Eof { expected: "a label vertex line" } });
        };
        let fields: Vec<&str> = line.split_ascii_whitespace().collect();
        let bad =
            |expected| ParseError { at, kind: ParseErrorKind::BadToken { expected, found: lossy(line.as_bytes()) } };
        let [v, x, y, z, value] = fields[..] else {
            return Err(bad("five fields: vertex x y z value"));
        };
        label.vertices.push(v.parse::<usize>().map_err(|_| bad("a vertex index (a whole number from 0)"))?);
        for t in [x, y, z] {
            label
                .points
                .push(t.parse::<f64>().ok().filter(|c| c.is_finite()).ok_or_else(|| bad("finite coordinates"))?);
        }
        label.values.push(value.parse::<f64>().map_err(|_| bad("a number as the value"))?);
    }
    Ok(label)
}

/// Reads a label file (optionally gzipped), within the reading limits.
pub fn read_label(path: &Path) -> Result<Label, ReadError> {
    let data = super::source::open(path, super::Expect::Text)?.read_all(path)?;
    parse_label(&data).map_err(|source| ReadError::Parse { path: path.into(), source })
}

/// A label's text, as FreeSurfer writes it (`subject` names the surface's
/// subject in the comment line).
pub fn label_text(label: &Label, subject: &str) -> String {
    let mut s = format!("#!ascii label  , from subject {subject} vox2ras=TkReg\n{}\n", label.vertices.len());
    for (k, v) in label.vertices.iter().enumerate() {
        let p = &label.points[3 * k..3 * k + 3];
        s.push_str(&format!("{v} {} {} {} {}\n", p[0], p[1], p[2], label.values[k]));
    }
    s
}

/// Writes a label file atomically (gzipped when the name ends in `.gz`).
pub fn write_label(path: &Path, label: &Label, subject: &str) -> Result<(), WriteError> {
    let gz = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    super::write_atomic(path, label_text(label, subject).as_bytes(), gz)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_label_reads_writes_back_and_becomes_a_mask() {
        let text = "#!ascii label  , from subject fsaverage vox2ras=TkReg\n3\n\
                    2  -35.100  -20.500  61.000 0.000000\n0 1 2 3 0.5\n4 0 0 0 1e-3\n";
        let l = parse_label(text.as_bytes()).unwrap();
        assert_eq!(l.vertices, [2, 0, 4]);
        assert_eq!(l.points[..3], [-35.1, -20.5, 61.0]);
        assert_eq!(l.values, [0.0, 0.5, 1e-3]);
        assert_eq!(parse_label(label_text(&l, "s").as_bytes()).unwrap(), l);
        assert_eq!(l.mask(6).unwrap(), [1.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
        let e = l.mask(4).unwrap_err();
        assert_eq!(e.at, Location::Line(5), "{e}");
    }

    #[test]
    fn bad_labels_are_located() {
        for (text, line, says) in [
            ("# c\nx\n", 2, "vertex count"),
            ("# c\n-1\n", 2, "non-negative"),
            ("# c\n1000000\n0 0 0 0 0\n", 2, "claims 1000000"),
            ("# c\n2\n0 0 0 0 0\n1 0 0 0 0 7\n", 4, "five fields"),
            ("# c\n2\n0 0 0 0 0\n-1 0 0 0 0\n", 4, "vertex index"),
            ("# c\n2\n0 0 0 0 0\n1 0 nan 0 0\n", 4, "finite coordinates"),
        ] {
            let e = parse_label(text.as_bytes()).unwrap_err();
            assert_eq!(e.at, Location::Line(line), "{text:?}: {e}");
            assert!(e.to_string().contains(says), "{text:?}: {e}");
        }
    }
}
