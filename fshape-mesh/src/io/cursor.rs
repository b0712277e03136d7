//! A byte cursor shared by the hand-written parsers: whitespace-separated
//! tokens with line tracking for text, raw records with byte offsets for
//! binary data.

use super::{Location, ParseError, ParseErrorKind};

pub(crate) struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
    /// 1-based line of `pos`, meaningful while the data is text.
    line: usize,
    /// Report byte offsets rather than lines (inside binary sections).
    pub(crate) binary: bool,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(data: &'a [u8]) -> Self {
        Cursor { data, pos: 0, line: 1, binary: false }
    }

    pub(crate) fn at(&self) -> Location {
        if self.binary { Location::Byte(self.pos) } else { Location::Line(self.line) }
    }

    /// The location of the next token: in text, whitespace is skipped first
    /// so that the line is the token's own.
    pub(crate) fn mark(&mut self) -> Location {
        if !self.binary {
            self.skip_space();
        }
        self.at()
    }

    pub(crate) fn error(&self, kind: ParseErrorKind) -> ParseError {
        ParseError { at: self.at(), kind }
    }

    pub(crate) fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    pub(crate) fn is_eof(&self) -> bool {
        self.pos >= self.data.len()
    }

    /// The next line without its terminator (`\n` or `\r\n`), or `None` at
    /// the end of the data.
    pub(crate) fn line(&mut self) -> Option<&'a [u8]> {
        if self.is_eof() {
            return None;
        }
        let rest = &self.data[self.pos..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        self.line += 1;
        let l = &rest[..end];
        Some(l.strip_suffix(b"\r").unwrap_or(l))
    }

    /// The line as text, or an error if it is not UTF-8.
    pub(crate) fn text_line(&mut self, expected: &'static str) -> Result<Option<&'a str>, ParseError> {
        let at = self.at();
        match self.line() {
            None => Ok(None),
            Some(l) => std::str::from_utf8(l)
                .map(Some)
                .map_err(|_| ParseError { at, kind: ParseErrorKind::BadToken { expected, found: lossy(l) } }),
        }
    }

    /// Skips spaces, tabs and newlines, counting lines.
    pub(crate) fn skip_space(&mut self) {
        while let Some(&b) = self.data.get(self.pos) {
            match b {
                b'\n' => self.line += 1,
                b' ' | b'\t' | b'\r' => {}
                _ => break,
            }
            self.pos += 1;
        }
    }

    /// The next whitespace-separated token.
    pub(crate) fn token(&mut self, expected: &'static str) -> Result<&'a [u8], ParseError> {
        self.skip_space();
        let start = self.pos;
        while self.data.get(self.pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(self.error(ParseErrorKind::Eof { expected }));
        }
        Ok(&self.data[start..self.pos])
    }

    pub(crate) fn f64_token(&mut self, expected: &'static str) -> Result<f64, ParseError> {
        let t = self.token(expected)?;
        parse_f64(t).ok_or_else(|| self.error(ParseErrorKind::BadToken { expected, found: lossy(t) }))
    }

    pub(crate) fn i64_token(&mut self, expected: &'static str) -> Result<i64, ParseError> {
        let t = self.token(expected)?;
        std::str::from_utf8(t)
            .ok()
            .and_then(|s| s.parse::<i64>().ok())
            .ok_or_else(|| self.error(ParseErrorKind::BadToken { expected, found: lossy(t) }))
    }

    /// The next `n` raw bytes.
    pub(crate) fn take(&mut self, n: usize, expected: &'static str) -> Result<&'a [u8], ParseError> {
        if self.remaining() < n {
            return Err(self.error(ParseErrorKind::Eof { expected }));
        }
        self.pos += n;
        Ok(&self.data[self.pos - n..self.pos])
    }

    /// Skips one line terminator if it is next (VTK binary blocks end with one).
    pub(crate) fn skip_newline(&mut self) {
        if self.data.get(self.pos) == Some(&b'\r') {
            self.pos += 1;
        }
        if self.data.get(self.pos) == Some(&b'\n') {
            self.pos += 1;
            self.line += 1;
        }
    }
}

/// Parses a decimal float, accepting `nan`, `inf` and `infinity` in any case
/// (validation reports non-finite values with their index afterwards).
pub(crate) fn parse_f64(t: &[u8]) -> Option<f64> {
    std::str::from_utf8(t).ok()?.parse::<f64>().ok()
}

/// A short printable excerpt of an offending token.
pub(crate) fn lossy(t: &[u8]) -> String {
    let s = String::from_utf8_lossy(&t[..t.len().min(40)]).into_owned();
    if t.len() > 40 { s + "…" } else { s }
}
