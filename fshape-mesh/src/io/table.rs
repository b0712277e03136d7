//! The small tables users write by hand or export from a spreadsheet:
//! covariates, batch pairs, atlas subject lists. Read through the `csv`
//! crate (quoted fields, doubled quotes, CRLF), with what people's files
//! hold accepted: a UTF-8 byte-order mark, `#` comment lines, blank lines,
//! cells padded with spaces, and tabs as separators when the first line
//! has tabs and no commas outside quotes. Errors name the line and column.
//!
//! ```
//! use fshape_mesh::io::table::parse_table;
//! let t = parse_table("\u{feff}subject,name\r\n# a comment\r\n1,\"Smith, J\"\r\n".as_bytes())?;
//! assert_eq!(t[1].fields, ["1", "Smith, J"]);
//! assert_eq!(t[1].line, 3);
//! # Ok::<(), fshape_mesh::io::ParseError>(())
//! ```

use std::borrow::Cow;
use std::path::Path;

use super::{Location, ParseError, ParseErrorKind, ReadError, WriteError};

/// One row of a table, with its line in the file (from 1).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Record {
    /// The line the row starts on.
    pub line: usize,
    /// Its cells, trimmed of surrounding spaces.
    pub fields: Vec<String>,
}

/// The separator of a table: a tab when its first row has a tab and no
/// comma outside quotes, else a comma.
fn delimiter(text: &[u8]) -> u8 {
    let first = text
        .split(|&b| b == b'\n')
        .map(<[u8]>::trim_ascii)
        .find(|l| !l.is_empty() && !l.starts_with(b"#"))
        .unwrap_or_default();
    let (mut quoted, mut commas, mut tabs) = (false, 0, 0);
    for &b in first {
        match b {
            b'"' => quoted = !quoted,
            b',' if !quoted => commas += 1,
            b'\t' if !quoted => tabs += 1,
            _ => {}
        }
    }
    if commas == 0 && tabs > 0 { b'\t' } else { b',' }
}

/// Parses a table: every non-blank, non-comment row, header included.
///
/// A row is one line: each line is parsed by the `csv` crate on its own,
/// which keeps line numbers exact (the crate's own positions skip comment
/// and blank lines) and refuses a quote left open instead of reading the
/// rest of the file into one cell.
pub fn parse_table(data: &[u8]) -> Result<Vec<Record>, ParseError> {
    let data = data.strip_prefix(b"\xef\xbb\xbf").unwrap_or(data);
    let delimiter = delimiter(data);
    let mut rows = Vec::new();
    let mut record = csv::ByteRecord::new();
    for (k, raw) in data.split(|&b| b == b'\n').enumerate() {
        let line = k + 1;
        let text = raw.trim_ascii();
        if text.is_empty() || text.starts_with(b"#") {
            continue;
        }
        let at = Location::Line(line);
        if text.iter().filter(|&&b| b == b'"').count() % 2 == 1 {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::BadToken {
                    expected: "quotes in pairs (a quote inside a quoted cell is written \"\")",
                    found: super::cursor::lossy(text),
                },
            });
        }
        let mut reader =
            csv::ReaderBuilder::new().has_headers(false).trim(csv::Trim::All).delimiter(delimiter).from_reader(text);
        // A line without an open quote is one record (reading a slice
        // cannot fail); a second one means a bare carriage return.
        if !reader.read_byte_record(&mut record).unwrap_or(false) {
            continue;
        }
        if reader.read_byte_record(&mut csv::ByteRecord::new()).unwrap_or(false) {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::BadToken {
                    expected: "one row per line (a carriage return inside a line?)",
                    found: super::cursor::lossy(text),
                },
            });
        }
        let mut fields = Vec::with_capacity(record.len());
        for (k, f) in record.iter().enumerate() {
            let text = std::str::from_utf8(f).map_err(|_| ParseError {
                at,
                kind: ParseErrorKind::BadToken {
                    expected: "UTF-8 text",
                    found: format!("column {}: {}", k + 1, super::cursor::lossy(f)),
                },
            })?;
            fields.push(text.to_string());
        }
        rows.push(Record { line, fields });
    }
    Ok(rows)
}

/// Reads a table file (optionally gzipped), within the reading limits.
pub fn read_table(path: &Path) -> Result<Vec<Record>, ReadError> {
    let data = super::source::open(path, super::Expect::Text)?.read_all(path)?;
    parse_table(&data).map_err(|source| ReadError::Parse { path: path.into(), source })
}

/// A cell a spreadsheet would run as a formula (it starts with `=`, `+`,
/// `-`, `@`, a tab or a carriage return, and is not a number), prefixed
/// with `'` so that it shows as text; other cells unchanged.
pub fn neutralise(cell: &str) -> Cow<'_, str> {
    let risky = cell.starts_with(['=', '+', '-', '@', '\t', '\r']);
    if risky && cell.trim().parse::<f64>().is_err() { Cow::Owned(format!("'{cell}")) } else { Cow::Borrowed(cell) }
}

/// The text of a table: comma-separated, text cells quoted, so that
/// [`parse_table`] reads back the same cells (`parse(write(parse(x))) =
/// parse(x)`, the fuzz target `table`'s property), except what a table
/// cannot hold by design: spaces around a cell (trimmed) and line breaks
/// in a cell. With `neutral`, every cell is first [`neutralise`]d
/// (tables for spreadsheets).
pub fn table_text(rows: &[Vec<String>], neutral: bool) -> String {
    let mut out = Vec::new();
    for row in rows {
        // Quoted where needed; a row that would read otherwise (a first
        // cell `#…` is a comment, a leading byte-order mark is dropped, a
        // tab could make the table look tab-separated) has every cell quoted.
        let special =
            row.first().is_some_and(|c| c.starts_with(['#', '\u{feff}'])) || row.iter().any(|c| c.contains('\t'));
        let style = if special { csv::QuoteStyle::Always } else { csv::QuoteStyle::Necessary };
        let mut w = csv::WriterBuilder::new().flexible(true).quote_style(style).from_writer(&mut out);
        let cells = row.iter().map(|c| if neutral { neutralise(c) } else { Cow::Borrowed(c.as_str()) });
        w.write_record(cells.map(|c| c.into_owned())).expect("writing to memory cannot fail");
        w.flush().expect("writing to memory cannot fail");
    }
    String::from_utf8(out).expect("the cells are UTF-8")
}

/// Writes a table atomically ([`table_text`]).
pub fn write_table(path: &Path, rows: &[Vec<String>], neutral: bool) -> Result<(), WriteError> {
    super::write_atomic(path, table_text(rows, neutral).as_bytes(), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cells(t: &str) -> Vec<(usize, Vec<&'static str>)> {
        parse_table(t.as_bytes())
            .unwrap()
            .into_iter()
            .map(|r| (r.line, r.fields.into_iter().map(|f| &*f.leak()).collect()))
            .collect()
    }

    #[test]
    fn lines_are_counted_through_comments_blank_lines_and_crlf() {
        let want = vec![(1, vec!["a", "b"]), (4, vec!["1", "x, y"]), (5, vec!["3", "say \"hi\""])];
        assert_eq!(cells("a,b\n# c\n\n1,\"x, y\"\n3,\"say \"\"hi\"\"\"\n"), want);
        assert_eq!(cells("\u{feff}a,b\r\n# c\r\n  \r\n1,\"x, y\" \r\n3,\"say \"\"hi\"\"\"\r\n"), want);
        assert_eq!(cells("s\tage\n1\t30\n"), vec![(1, vec!["s", "age"]), (2, vec!["1", "30"])]);
        // A quoted header cell with a comma does not make the table comma-separated.
        assert_eq!(cells("s\t\"age, y\"\n1\t30\n")[0].1, ["s", "age, y"]);
    }

    #[test]
    fn an_open_quote_and_bad_utf8_are_located() {
        let e = parse_table(b"a,b\n1,\"x\n2,y\n").unwrap_err();
        assert_eq!(e.at, Location::Line(2), "{e}");
        assert!(e.to_string().contains("quotes in pairs"), "{e}");
        let e = parse_table(b"a,b\n1,\xff\n").unwrap_err();
        assert_eq!(e.at, Location::Line(2), "{e}");
        assert!(e.to_string().contains("column 2"), "{e}");
    }

    #[test]
    fn formulas_are_neutralised_and_numbers_kept() {
        for (cell, out) in
            [("=1+1", "'=1+1"), ("+x", "'+x"), ("@SUM(A1)", "'@SUM(A1)"), ("-1.5", "-1.5"), ("-", "'-"), ("a=b", "a=b")]
        {
            assert_eq!(neutralise(cell), out);
        }
        let rows = vec![vec!["name".to_string(), "value".into()], vec!["=HYPERLINK(\"x\")".into(), "-2e-3".into()]];
        let text = table_text(&rows, true);
        let back = parse_table(text.as_bytes()).unwrap();
        assert_eq!(back[1].fields, ["'=HYPERLINK(\"x\")", "-2e-3"]);
    }
}
