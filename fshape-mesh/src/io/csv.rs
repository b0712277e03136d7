//! Per-vertex signal CSV: one column, a header line (the column name), then
//! one value per vertex in vertex order.
//!
//! `nan` marks a missing value; it is accepted only when the caller says
//! missing values are allowed (they must then be filled before the values
//! become an fshape's signal, which has to be finite).

use std::io::Read;
use std::path::Path;

use super::cursor::{Cursor, lossy, parse_f64};
use super::{Location, ParseError, ParseErrorKind, ReadError, WriteError, write_atomic};

/// A parsed signal column.
#[derive(Clone, Debug, PartialEq)]
pub struct SignalColumn {
    /// The header (column name).
    pub name: String,
    /// One value per data line; NaN for a missing value.
    pub values: Vec<f64>,
}

/// Parses a one-column signal CSV. With `allow_missing` false, a `nan` (or
/// any non-finite value) is an error naming its line.
pub fn parse_signal(data: &[u8], allow_missing: bool) -> Result<SignalColumn, ParseError> {
    parse_signal_from(&mut &data[..], allow_missing, None).map_err(|e| match e {
        StreamError::Parse(e) => e,
        StreamError::Io(e) => unreachable!("reading a slice cannot fail: {e}"),
    })
}

/// Why reading a signal stream failed.
#[derive(Debug)]
pub enum StreamError {
    /// Reading (or decompressing) the bytes failed.
    Io(std::io::Error),
    /// The text is not a signal column.
    Parse(ParseError),
}

/// The longest line a signal CSV may have: a number or a column name.
const MAX_LINE: u64 = 4096;

/// Parses a one-column signal CSV from a stream, one line at a time. With
/// `expected` given, the first value past that count is an error naming
/// both counts, so a runaway stream is not read to its end.
pub fn parse_signal_from(
    r: &mut dyn std::io::BufRead,
    allow_missing: bool,
    expected: Option<usize>,
) -> Result<SignalColumn, StreamError> {
    let mut buf = Vec::new();
    let mut line_no = 0;
    // The next line without its terminator, or None at the end.
    let mut next = |buf: &mut Vec<u8>, line_no: &mut usize| -> Result<Option<Location>, StreamError> {
        buf.clear();
        let mut line = std::io::Read::take(&mut *r, MAX_LINE + 1);
        let n = std::io::BufRead::read_until(&mut line, b'\n', buf).map_err(StreamError::Io)?;
        if n == 0 {
            return Ok(None);
        }
        *line_no += 1;
        let at = Location::Line(*line_no);
        if buf.last() == Some(&b'\n') {
            buf.pop();
        } else if n as u64 > MAX_LINE {
            return Err(StreamError::Parse(ParseError {
                at,
                kind: ParseErrorKind::BadToken { expected: "a line of at most 4096 bytes", found: lossy(buf) },
            }));
        }
        if buf.last() == Some(&b'\r') {
            buf.pop();
        }
        Ok(Some(at))
    };
    let bad = |at, expected, t: &[u8]| {
        StreamError::Parse(ParseError { at, kind: ParseErrorKind::BadToken { expected, found: lossy(t) } })
    };
    let Some(at) = next(&mut buf, &mut line_no)? else {
        return Err(StreamError::Parse(ParseError {
            at: Location::Line(1),
            kind: ParseErrorKind::Missing { what: "the header line (column name)" },
        }));
    };
    let text = std::str::from_utf8(&buf).map_err(|_| bad(at, "a header line", &buf))?;
    let name = text.trim().trim_start_matches('\u{feff}').trim().to_string();
    if name.is_empty() || parse_f64(name.as_bytes()).is_some() {
        return Err(bad(at, "a header line naming the column", name.as_bytes()));
    }
    if name.contains(',') {
        return Err(bad(at, "a single column (no comma)", name.as_bytes()));
    }
    let mut values = Vec::with_capacity(expected.unwrap_or(0));
    let what = if allow_missing {
        "a number or `nan`"
    } else {
        "a finite number (missing values are not accepted here; allowing them, with --allow-missing or allow_missing=True, masks their vertices)"
    };
    while let Some(at) = next(&mut buf, &mut line_no)? {
        let t = buf.trim_ascii();
        if t.is_empty() {
            continue;
        }
        if let Some(n) = expected.filter(|&n| values.len() == n) {
            return Err(StreamError::Parse(ParseError {
                at,
                kind: ParseErrorKind::LongerThanMesh { vertices: n as u64 },
            }));
        }
        let v = parse_f64(t).filter(|v| v.is_finite() || (allow_missing && v.is_nan()));
        values.push(v.ok_or_else(|| bad(at, what, t))?);
    }
    Ok(SignalColumn { name, values })
}

/// One column of a table of several maps ([`super::table`]'s rules:
/// quotes, tabs, `#` comments): a header line naming the columns, then one
/// row per vertex of as many values (`nan` for a missing one); the column chosen by its name or its number
/// from 1 (`maps.csv:myelin`, `maps.csv:2`). Errors name the line.
///
/// ```
/// use fshape_mesh::io::csv::parse_table_column;
/// let c = parse_table_column(b"thickness,myelin\n2.5,1.5\n3,nan\n", "myelin")?;
/// assert_eq!((c.name.as_str(), c.values[0], c.values[1].is_nan()), ("myelin", 1.5, true));
/// assert_eq!(parse_table_column(b"thickness,myelin\n2.5,1.5\n", "1")?.values, [2.5]);
/// assert!(parse_table_column(b"thickness,myelin\n2.5\n", "1").is_err()); // a value short
/// # Ok::<(), fshape_mesh::io::ParseError>(())
/// ```
pub fn parse_table_column(data: &[u8], selector: &str) -> Result<SignalColumn, ParseError> {
    let mut rows = super::table::parse_table(data)?.into_iter();
    let names = rows
        .next()
        .ok_or(ParseError {
            at: Location::Line(1),
            kind: ParseErrorKind::Missing { what: "the header line (column names)" },
        })?
        .fields;
    let by_number = || selector.parse::<usize>().ok().filter(|k| (1..=names.len()).contains(k)).map(|k| k - 1);
    let column = names.iter().position(|n| n == selector).or_else(by_number).ok_or_else(|| ParseError {
        at: Location::Line(1),
        kind: ParseErrorKind::UnknownName { what: "column", name: selector.to_string(), available: names.clone() },
    })?;
    let values = rows
        .map(|row| {
            let at = Location::Line(row.line);
            if row.fields.len() != names.len() {
                return Err(ParseError {
                    at,
                    kind: ParseErrorKind::CountMismatch {
                        what: "values in a row (one per column of the header)",
                        expected: names.len() as u64,
                        found: row.fields.len() as u64,
                    },
                });
            }
            let f = row.fields[column].as_bytes();
            parse_f64(f).filter(|v| !v.is_infinite()).ok_or(ParseError {
                at,
                kind: ParseErrorKind::BadToken { expected: "a number or `nan`", found: lossy(f) },
            })
        })
        .collect::<Result<_, _>>()?;
    Ok(SignalColumn { name: names[column].clone(), values })
}

/// Parses a vector-field CSV (momenta, velocities): a header line, then one
/// row of `dim` finite numbers separated by commas per vertex. Returns the
/// rows flat (n × dim). Errors name the line.
///
/// ```
/// use fshape_mesh::io::csv::parse_vectors;
/// let v = parse_vectors(b"p_x,p_y\n1,2\n3,4.5\n", 2)?;
/// assert_eq!(v, [1.0, 2.0, 3.0, 4.5]);
/// assert!(parse_vectors(b"p_x,p_y\n1,2,3\n", 2).is_err()); // three columns
/// // A row of another count says how many each row needs.
/// let e = parse_vectors(b"pf,pf_2,pf_3,pf_4\n1,2,3\n", 4).unwrap_err().to_string();
/// assert!(e.contains("line 2") && e.contains("expected 4 comma-separated numbers"), "{e}");
/// let e = parse_vectors(b"pf\n1,2\n", 1).unwrap_err().to_string();
/// assert!(e.contains("expected 1 number"), "{e}");
/// # Ok::<(), fshape_mesh::io::ParseError>(())
/// ```
pub fn parse_vectors(data: &[u8], dim: usize) -> Result<Vec<f64>, ParseError> {
    let mut cur = Cursor::new(data);
    let header = cur
        .text_line("a header line")?
        .ok_or_else(|| cur.error(ParseErrorKind::Missing { what: "the header line (column names)" }))?;
    let first = header.split(',').next().unwrap_or("").trim();
    if parse_f64(first.as_bytes()).is_some() {
        return Err(ParseError {
            at: super::Location::Line(1),
            kind: ParseErrorKind::BadToken {
                expected: "a header line naming the columns",
                found: lossy(header.as_bytes()),
            },
        });
    }
    let mut out = Vec::new();
    loop {
        let at = cur.at();
        let Some(line) = cur.text_line("a row of numbers")? else {
            break;
        };
        let t = line.trim();
        if t.is_empty() {
            continue;
        }
        let fields: Vec<&str> = t.split(',').map(str::trim).collect();
        let bad = |expected: &'static str| ParseError {
            at,
            kind: ParseErrorKind::BadToken { expected, found: lossy(t.as_bytes()) },
        };
        if fields.len() != dim {
            // The count the caller reads (d coordinates, or k signal maps).
            const COUNTS: [&str; 9] = [
                "no numbers",
                "1 number",
                "2 comma-separated numbers",
                "3 comma-separated numbers",
                "4 comma-separated numbers",
                "5 comma-separated numbers",
                "6 comma-separated numbers",
                "7 comma-separated numbers",
                "8 comma-separated numbers",
            ];
            return Err(bad(COUNTS.get(dim).copied().unwrap_or("as many comma-separated numbers as the header names")));
        }
        for f in fields {
            out.push(parse_f64(f.as_bytes()).filter(|v| v.is_finite()).ok_or_else(|| bad("finite numbers"))?);
        }
    }
    Ok(out)
}

/// Reads a vector-field CSV file (optionally gzipped); see [`parse_vectors`].
pub fn read_vectors(path: &Path, dim: usize) -> Result<Vec<f64>, ReadError> {
    let data = super::source::open(path, super::Expect::Text)?.read_all(path)?;
    parse_vectors(&data, dim).map_err(|source| ReadError::Parse { path: path.into(), source })
}

/// Reads a signal CSV file (optionally gzipped), as a stream.
pub fn read_signal(path: &Path, allow_missing: bool) -> Result<SignalColumn, ReadError> {
    let input = super::source::open(path, super::Expect::Text)?;
    let mut reader = std::io::BufReader::new(std::io::Cursor::new(input.prefix).chain(input.rest));
    parse_signal_from(&mut reader, allow_missing, None).map_err(|e| match e {
        StreamError::Io(source) => ReadError::Io { path: path.into(), source },
        StreamError::Parse(source) => ReadError::Parse { path: path.into(), source },
    })
}

/// Writes a signal CSV atomically, values in Rust's shortest round-trip
/// form (`nan` for NaN).
pub fn write_signal(path: &Path, name: &str, values: &[f64]) -> Result<(), WriteError> {
    let mut s = format!("{name}\n");
    for v in values {
        if v.is_nan() {
            s.push_str("nan\n");
        } else {
            s.push_str(&format!("{v:e}\n"));
        }
    }
    let gz = path.extension().is_some_and(|e| e == "gz");
    write_atomic(path, s.as_bytes(), gz)
}

/// The text of a vector-field CSV: a header of `names` joined by commas,
/// then one row of `names.len()` values per point (Rust's shortest
/// round-trip form), as [`read_vectors`] reads back.
///
/// # Panics
///
/// If `values.len()` is not a multiple of `names.len()` (a caller's bug).
#[track_caller]
pub fn vectors_text(names: &[&str], values: &[f64]) -> String {
    let w = names.len().max(1);
    assert!(values.len().is_multiple_of(w), "{} values do not make rows of {w}", values.len());
    let mut s = names.join(",");
    s.push('\n');
    for row in values.chunks_exact(w) {
        let cells: Vec<String> = row.iter().map(|c| format!("{c}")).collect();
        s.push_str(&cells.join(","));
        s.push('\n');
    }
    s
}

/// Writes a vector-field CSV ([`vectors_text`]) atomically, gzipped when
/// the path ends in `.gz`.
#[track_caller]
pub fn write_vectors(path: &Path, names: &[&str], values: &[f64]) -> Result<(), WriteError> {
    let gz = path.extension().is_some_and(|e| e == "gz");
    write_atomic(path, vectors_text(names, values).as_bytes(), gz)
}
