//! VTK legacy POLYDATA, ASCII and binary (big endian), versions 2.0–5.1.
//!
//! Read: `POINTS`; cells from `POLYGONS` (triangles), `TRIANGLE_STRIPS`
//! (split into triangles) or `LINES` (polylines split into segments), in the
//! classic count-prefixed layout or the 5.1 `OFFSETS`/`CONNECTIVITY` layout;
//! `VERTICES` are ignored. The signal is the `POINT_DATA` array (`SCALARS`
//! with one component, or a one-component `FIELD` array) with the caller's
//! name (default `signal`); an array named `mask` is a masked shape's mask.
//! Other attributes and all `CELL_DATA` are skipped.
//!
//! Write: version 4.2 (what fshapesTk and ParaView exchange), `double`
//! points, `int` cells, `SCALARS signal double 1` (NaN where masked) and a
//! masked shape's `SCALARS mask double 1`. A planar shape gets
//! z = 0 and the title `fshape planar`, which this reader honours.

use std::io::{self, Write};

use super::cursor::{Cursor, lossy};
use super::{Encoding, ParseError, ParseErrorKind, RawMesh};
use crate::shape::{CellKind, FShape};

/// The title line that marks a planar (2-D) shape written with z = 0.
pub const PLANAR_TITLE: &str = "fshape planar";

/// Byte size of a VTK data type name, or `None` if unknown. `bit` arrays
/// are not supported.
fn type_size(name: &str) -> Option<usize> {
    Some(match name {
        "unsigned_char" | "char" => 1,
        "unsigned_short" | "short" => 2,
        "unsigned_int" | "int" | "float" => 4,
        "unsigned_long" | "long" | "double" | "vtktypeint64" | "vtktypeuint64" | "vtkIdType" => 8,
        _ => return None,
    })
}

struct Reader<'a> {
    cur: Cursor<'a>,
    binary: bool,
    /// Where the last keyword line started: errors about its words point there.
    line_at: super::Location,
}

impl<'a> Reader<'a> {
    /// An error about the last keyword line.
    fn bad(&self, expected: &'static str, found: &str) -> ParseError {
        self.line_error(ParseErrorKind::BadToken { expected, found: lossy(found.as_bytes()) })
    }

    fn line_error(&self, kind: ParseErrorKind) -> ParseError {
        ParseError { at: self.line_at, kind }
    }

    /// The next non-empty line, split into words; `None` at the end.
    fn keyword_line(&mut self) -> Result<Option<Vec<&'a str>>, ParseError> {
        loop {
            self.line_at = self.cur.mark();
            let Some(line) = self.cur.text_line("a VTK keyword line")? else {
                break;
            };
            let words: Vec<&str> = line.split_whitespace().collect();
            if !words.is_empty() {
                return Ok(Some(words));
            }
        }
        Ok(None)
    }

    fn count(&self, word: Option<&&str>, expected: &'static str) -> Result<u64, ParseError> {
        let w = word.copied().unwrap_or("");
        w.parse::<u64>().map_err(|_| self.bad(expected, w))
    }

    fn dtype<'w>(&self, word: Option<&&'w str>) -> Result<(&'w str, usize), ParseError> {
        let w = word.copied().unwrap_or("");
        match type_size(w) {
            Some(s) => Ok((w, s)),
            None => {
                Err(self.line_error(ParseErrorKind::Unsupported { what: "VTK data type", found: lossy(w.as_bytes()) }))
            }
        }
    }

    /// Refuses a count whose data cannot fit in the rest of the file.
    fn check_room(&self, n: u64, bytes_each: usize) -> Result<usize, ParseError> {
        super::source::check_values(n, "values").map_err(|kind| self.line_error(kind))?;
        let min = if self.binary { bytes_each as u64 } else { 2 };
        if n.saturating_mul(min) > self.cur.remaining() as u64 + 1 {
            return Err(self.line_error(ParseErrorKind::Truncated {
                what: "values",
                claimed: n,
                available: self.cur.remaining(),
            }));
        }
        Ok(n as usize)
    }

    /// Reads `n` numbers of type `ty` as f64.
    fn numbers(&mut self, n: u64, ty: (&str, usize), what: &'static str) -> Result<Vec<f64>, ParseError> {
        let n = self.check_room(n, ty.1)?;
        let mut out = Vec::with_capacity(n);
        if !self.binary {
            for _ in 0..n {
                out.push(self.cur.f64_token(what)?);
            }
            return Ok(out);
        }
        let bytes = self.cur.take(n * ty.1, what)?;
        for b in bytes.chunks_exact(ty.1) {
            out.push(match (ty.0, b.len()) {
                ("float", _) => f32::from_be_bytes(b.try_into().expect("4 bytes")) as f64,
                ("double", _) => f64::from_be_bytes(b.try_into().expect("8 bytes")),
                ("unsigned_char", _) => b[0] as f64,
                ("char", _) => b[0] as i8 as f64,
                ("short", _) => i16::from_be_bytes(b.try_into().expect("2 bytes")) as f64,
                ("unsigned_short", _) => u16::from_be_bytes(b.try_into().expect("2 bytes")) as f64,
                ("int", _) => i32::from_be_bytes(b.try_into().expect("4 bytes")) as f64,
                ("unsigned_int", _) => u32::from_be_bytes(b.try_into().expect("4 bytes")) as f64,
                ("vtktypeuint64" | "unsigned_long", _) => u64::from_be_bytes(b.try_into().expect("8 bytes")) as f64,
                _ => i64::from_be_bytes(b.try_into().expect("8 bytes")) as f64,
            });
        }
        self.cur.skip_newline();
        Ok(out)
    }

    /// Reads `n` integers (cell sizes, indices, offsets).
    fn integers(&mut self, n: u64, ty: (&str, usize), what: &'static str) -> Result<Vec<i64>, ParseError> {
        let at = self.cur.mark();
        let vals = self.numbers(n, ty, what)?;
        vals.iter()
            .map(|&v| {
                if v.fract() == 0.0 && v.abs() < 9.0e15 {
                    Ok(v as i64)
                } else {
                    Err(ParseError { at, kind: ParseErrorKind::BadToken { expected: what, found: v.to_string() } })
                }
            })
            .collect()
    }
}

/// One cell section, as a flat list of cells (each a list of point ids).
struct CellBlock {
    keyword: &'static str,
    cells: Vec<Vec<i64>>,
}

fn read_cells(r: &mut Reader, words: &[&str], version5: bool, keyword: &'static str) -> Result<CellBlock, ParseError> {
    let n = r.count(words.get(1), "a cell count")?;
    let size = r.count(words.get(2), "a cell list size")?;
    let mut cells = Vec::new();
    if version5 {
        let offsets = read_array_line(r, "OFFSETS", n)?;
        let conn = read_array_line(r, "CONNECTIVITY", size)?;
        for w in offsets.windows(2) {
            let (a, b) = (w[0], w[1]);
            if a < 0 || b < a || b as usize > conn.len() {
                return Err(r.bad("non-decreasing cell offsets within the connectivity", &format!("{a}..{b}")));
            }
            cells.push(conn[a as usize..b as usize].to_vec());
        }
    } else {
        let flat = r.integers(size, ("int", 4), "a cell list entry")?;
        let mut i = 0;
        while i < flat.len() {
            let k = flat[i];
            if k < 0 || i + 1 + k as usize > flat.len() {
                return Err(r.bad("a cell size that fits in the cell list", &k.to_string()));
            }
            cells.push(flat[i + 1..i + 1 + k as usize].to_vec());
            i += 1 + k as usize;
        }
        if cells.len() as u64 != n {
            return Err(r.cur.error(ParseErrorKind::CountMismatch {
                what: "cells in the cell list",
                expected: n,
                found: cells.len() as u64,
            }));
        }
    }
    Ok(CellBlock { keyword, cells })
}

fn read_array_line(r: &mut Reader, name: &'static str, n: u64) -> Result<Vec<i64>, ParseError> {
    let words = r
        .keyword_line()?
        .ok_or_else(|| r.cur.error(ParseErrorKind::Missing { what: "OFFSETS/CONNECTIVITY arrays" }))?;
    if words.first() != Some(&name) {
        return Err(r.bad(
            if name == "OFFSETS" { "`OFFSETS type`" } else { "`CONNECTIVITY type`" },
            words.first().unwrap_or(&""),
        ));
    }
    let ty = r.dtype(words.get(1))?;
    r.integers(n, ty, "a cell array entry")
}

/// Reads the attributes of a `POINT_DATA` or `CELL_DATA` block of `n`
/// tuples; returns one-component arrays by name when `keep`.
fn read_attributes<'a>(
    r: &mut Reader<'a>,
    n: u64,
    keep: bool,
    out: &mut Vec<(String, Vec<f64>)>,
) -> Result<Option<Vec<&'a str>>, ParseError> {
    loop {
        let Some(words) = r.keyword_line()? else {
            return Ok(None);
        };
        let name = words.get(1).copied().unwrap_or("").to_string();
        match words[0] {
            "SCALARS" => {
                let ty = r.dtype(words.get(2))?;
                let ncomp = match words.get(3) {
                    Some(c) => r.count(Some(c), "a component count")?,
                    None => 1,
                };
                let lut = r.keyword_line()?.unwrap_or_default();
                if lut.first() != Some(&"LOOKUP_TABLE") {
                    return Err(r.bad("`LOOKUP_TABLE name` after SCALARS", &lut.join(" ")));
                }
                let vals = r.numbers(n.saturating_mul(ncomp), ty, "a scalar value")?;
                if keep && ncomp == 1 {
                    out.push((name, vals));
                }
            }
            "LOOKUP_TABLE" => {
                let size = r.count(words.get(2), "a lookup table size")?;
                let cbytes = if r.binary { 1 } else { 4 };
                r.numbers(size.saturating_mul(4), ("unsigned_char", cbytes), "a lookup table entry")?;
            }
            "VECTORS" | "NORMALS" => {
                let ty = r.dtype(words.get(2))?;
                r.numbers(n.saturating_mul(3), ty, "a vector component")?;
            }
            "TENSORS" => {
                let ty = r.dtype(words.get(2))?;
                r.numbers(n.saturating_mul(9), ty, "a tensor component")?;
            }
            "TEXTURE_COORDINATES" => {
                let dim = r.count(words.get(2), "a texture dimension")?;
                let ty = r.dtype(words.get(3))?;
                r.numbers(n.saturating_mul(dim), ty, "a texture coordinate")?;
            }
            "COLOR_SCALARS" => {
                let k = r.count(words.get(2), "a colour component count")?;
                let ty = if r.binary { ("unsigned_char", 1) } else { ("float", 4) };
                r.numbers(n.saturating_mul(k), ty, "a colour component")?;
            }
            "FIELD" => {
                let arrays = r.count(words.get(2), "a field array count")?;
                for _ in 0..arrays {
                    let w = r
                        .keyword_line()?
                        .ok_or_else(|| r.cur.error(ParseErrorKind::Eof { expected: "a field array header" }))?;
                    let ncomp = r.count(w.get(1), "a component count")?;
                    let ntup = r.count(w.get(2), "a tuple count")?;
                    let ty = r.dtype(w.get(3))?;
                    let vals = r.numbers(ncomp.saturating_mul(ntup), ty, "a field value")?;
                    if keep && ncomp == 1 && ntup == n {
                        out.push((w[0].to_string(), vals));
                    }
                }
            }
            "METADATA" => skip_metadata(r)?,
            _ => return Ok(Some(words)),
        }
    }
}

fn skip_metadata(r: &mut Reader) -> Result<(), ParseError> {
    while let Some(line) = r.cur.text_line("metadata")? {
        if line.trim().is_empty() {
            break;
        }
    }
    Ok(())
}

/// Parses VTK legacy POLYDATA; `signal_name` selects the point-data array
/// read as the signal (absent: no signal).
pub(crate) fn parse(data: &[u8], signal_name: &str) -> Result<RawMesh, ParseError> {
    let mut r = Reader { cur: Cursor::new(data), binary: false, line_at: super::Location::Line(1) };
    let first = r.cur.text_line("`# vtk DataFile Version x.y`")?.unwrap_or("");
    let version = first
        .strip_prefix("# vtk DataFile Version ")
        .and_then(|v| v.trim().split('.').next()?.parse::<u32>().ok())
        .ok_or_else(|| ParseError {
            at: super::Location::Line(1),
            kind: ParseErrorKind::BadToken { expected: "`# vtk DataFile Version x.y`", found: lossy(first.as_bytes()) },
        })?;
    let title = r.cur.text_line("a title line")?.unwrap_or("").trim().to_string();
    r.line_at = r.cur.at();
    let enc = r.cur.text_line("ASCII or BINARY")?.unwrap_or("").trim().to_ascii_uppercase();
    r.binary = match enc.as_str() {
        "ASCII" => false,
        "BINARY" => true,
        _ => return Err(r.bad("ASCII or BINARY", &enc)),
    };
    r.cur.binary = r.binary;
    let ds = r.keyword_line()?.unwrap_or_default();
    if ds.first() != Some(&"DATASET") || ds.get(1) != Some(&"POLYDATA") {
        return Err(r.line_error(ParseErrorKind::Unsupported {
            what: "VTK dataset (fshape reads DATASET POLYDATA)",
            found: ds.join(" "),
        }));
    }
    let mut points: Option<Vec<f64>> = None;
    let mut blocks: Vec<CellBlock> = Vec::new();
    let mut arrays = Vec::new();
    let mut pending = r.keyword_line()?;
    while let Some(words) = pending.take() {
        match words[0] {
            "POINTS" => {
                let n = r.count(words.get(1), "a point count")?;
                let ty = r.dtype(words.get(2))?;
                points = Some(r.numbers(n.saturating_mul(3), ty, "a point coordinate")?);
            }
            "POLYGONS" => blocks.push(read_cells(&mut r, &words, version >= 5, "POLYGONS")?),
            "TRIANGLE_STRIPS" => blocks.push(read_cells(&mut r, &words, version >= 5, "TRIANGLE_STRIPS")?),
            "LINES" => blocks.push(read_cells(&mut r, &words, version >= 5, "LINES")?),
            "VERTICES" => {
                read_cells(&mut r, &words, version >= 5, "VERTICES")?;
            }
            "METADATA" => skip_metadata(&mut r)?,
            "POINT_DATA" | "CELL_DATA" => {
                let n = r.count(words.get(1), "a tuple count")?;
                let keep = words[0] == "POINT_DATA";
                if keep {
                    let np = points.as_ref().map_or(0, |p| p.len() as u64 / 3);
                    if n != np {
                        return Err(r.line_error(ParseErrorKind::CountMismatch {
                            what: "POINT_DATA tuples (one per point)",
                            expected: np,
                            found: n,
                        }));
                    }
                }
                pending = read_attributes(&mut r, n, keep, &mut arrays)?;
                continue;
            }
            other => {
                return Err(r.line_error(ParseErrorKind::Unsupported {
                    what: "VTK POLYDATA section",
                    found: lossy(other.as_bytes()),
                }));
            }
        }
        pending = r.keyword_line()?;
    }
    let points = points.ok_or_else(|| r.cur.error(ParseErrorKind::Missing { what: "POINTS" }))?;
    let mut raw = RawMesh { dim: 3, points, ..RawMesh::default() };
    fill_cells(&mut raw, blocks).map_err(|kind| r.cur.error(kind))?;
    raw.scalars = arrays.iter().map(|a| a.0.clone()).collect();
    if signal_name != "mask" {
        raw.mask = arrays.iter().find(|a| a.0 == "mask").map(|a| a.1.clone());
    }
    let channels = super::channel_columns(signal_name, |name| arrays.iter().position(|a| a.0 == name));
    raw.channels = channels.len();
    raw.signal = match channels[..] {
        [] => None,
        [one] => Some(arrays.swap_remove(one).1),
        _ => Some(super::interleave(&channels.iter().map(|&c| std::mem::take(&mut arrays[c].1)).collect::<Vec<_>>())),
    };
    if title == PLANAR_TITLE && raw.points.chunks_exact(3).all(|p| p[2] == 0.0) {
        raw.points = raw.points.chunks_exact(3).flat_map(|p| [p[0], p[1]]).collect();
        raw.dim = 2;
    }
    Ok(raw)
}

fn fill_cells(raw: &mut RawMesh, blocks: Vec<CellBlock>) -> Result<(), ParseErrorKind> {
    let has_tri = blocks.iter().any(|b| b.keyword != "LINES" && !b.cells.is_empty());
    let has_lines = blocks.iter().any(|b| b.keyword == "LINES" && !b.cells.is_empty());
    if has_tri && has_lines {
        return Err(ParseErrorKind::MixedCellSizes { cell: 0, found: 2, expected: 3 });
    }
    raw.cell_size = Some(if has_lines { 2 } else { 3 });
    let mut cell = 0;
    for b in blocks {
        for c in b.cells {
            let ids: Vec<usize> = c
                .iter()
                .map(|&v| usize::try_from(v).map_err(|_| ParseErrorKind::NegativeIndex { cell, value: v }))
                .collect::<Result<_, _>>()?;
            match b.keyword {
                "POLYGONS" if ids.len() == 3 => raw.cells.extend_from_slice(&ids),
                "POLYGONS" => {
                    return Err(ParseErrorKind::CellSize { cell, found: ids.len() });
                }
                "TRIANGLE_STRIPS" => {
                    for (k, w) in ids.windows(3).enumerate() {
                        // Every other triangle of a strip is flipped to keep
                        // one orientation.
                        let t = if k % 2 == 0 { [w[0], w[1], w[2]] } else { [w[1], w[0], w[2]] };
                        raw.cells.extend_from_slice(&t);
                    }
                }
                _ => {
                    for w in ids.windows(2) {
                        raw.cells.extend_from_slice(w);
                    }
                }
            }
            cell += 1;
        }
    }
    Ok(())
}

/// Writes `shape` as VTK legacy POLYDATA, version 4.2.
pub fn write(w: &mut impl Write, shape: &FShape, encoding: Encoding) -> io::Result<()> {
    let ascii = encoding == Encoding::Ascii;
    let title = if shape.dim() == 2 { PLANAR_TITLE } else { "fshape" };
    let enc = if ascii { "ASCII" } else { "BINARY" };
    writeln!(w, "# vtk DataFile Version 4.2\n{title}\n{enc}\nDATASET POLYDATA")?;
    writeln!(w, "POINTS {} double", shape.n_vertices())?;
    let put = |w: &mut dyn Write, vals: &[f64]| -> io::Result<()> {
        if ascii {
            let line: Vec<String> = vals.iter().map(|x| format!("{x:e}")).collect();
            writeln!(w, "{}", line.join(" "))
        } else {
            vals.iter().try_for_each(|x| w.write_all(&x.to_be_bytes()))
        }
    };
    for v in 0..shape.n_vertices() {
        let p = shape.point(v);
        put(w, &[p[0], p[1], if shape.dim() == 3 { p[2] } else { 0.0 }])?;
    }
    if !ascii {
        writeln!(w)?;
    }
    let k = shape.kind().n_corners();
    let keyword = if shape.kind() == CellKind::Triangle { "POLYGONS" } else { "LINES" };
    writeln!(w, "{keyword} {} {}", shape.n_cells(), shape.n_cells() * (k + 1))?;
    for c in shape.cell_iter() {
        let ids: Vec<i32> = std::iter::once(Ok(k as i32))
            .chain(
                c.iter()
                    .map(|&v| i32::try_from(v).map_err(|_| io::Error::other("vertex index exceeds the VTK int range"))),
            )
            .collect::<io::Result<_>>()?;
        if ascii {
            let line: Vec<String> = ids.iter().map(i32::to_string).collect();
            writeln!(w, "{}", line.join(" "))?;
        } else {
            ids.iter().try_for_each(|x| w.write_all(&x.to_be_bytes()))?;
        }
    }
    if !ascii {
        writeln!(w)?;
    }
    let mut fields: Vec<(String, Vec<f64>)> =
        (0..shape.n_channels()).filter_map(|c| Some((super::channel_name("signal", c), shape.channel(c)?))).collect();
    fields.extend(shape.mask().map(|m| ("mask".to_string(), m.to_vec())));
    for (k, (name, values)) in fields.iter().enumerate() {
        if k == 0 {
            writeln!(w, "POINT_DATA {}", shape.n_vertices())?;
        }
        writeln!(w, "SCALARS {name} double 1\nLOOKUP_TABLE default")?;
        for &x in values {
            put(w, &[x])?;
        }
        if !ascii {
            writeln!(w)?;
        }
    }
    Ok(())
}

/// Writes `shape` with named per-vertex fields as legacy ASCII VTK
/// POLYDATA (for ParaView: glyphs of the vectors, colours of the scalars),
/// in place of the signal: `vectors` holds `dim` values per vertex (padded
/// to 3 components), `scalars` one value per vertex. Names must be single
/// words (VTK separates by whitespace).
///
/// # Errors
///
/// An array whose length is not the vertex count (times `dim` for a vector
/// field), or a name with whitespace, is an `InvalidInput` error naming it.
pub fn write_point_fields(
    w: &mut impl Write,
    shape: &FShape,
    title: &str,
    vectors: &[(&str, &[f64])],
    scalars: &[(&str, &[f64])],
) -> io::Result<()> {
    let (n, dim) = (shape.n_vertices(), shape.dim());
    let invalid = |m: String| io::Error::new(io::ErrorKind::InvalidInput, m);
    for (name, v, per) in vectors.iter().map(|(a, b)| (a, b, dim)).chain(scalars.iter().map(|(a, b)| (a, b, 1))) {
        if name.is_empty() || name.contains(char::is_whitespace) {
            return Err(invalid(format!("VTK field name {name:?}: must be one word")));
        }
        if v.len() != n * per {
            return Err(invalid(format!("VTK field {name}: {} values for {n} vertices × {per}", v.len())));
        }
    }
    let title: String = title.chars().map(|c| if c == '\n' { ' ' } else { c }).collect();
    let pad = |row: &[f64]| -> String {
        let mut v: Vec<String> = row.iter().map(|c| format!("{c:e}")).collect();
        v.resize(3, "0".into());
        v.join(" ")
    };
    writeln!(w, "# vtk DataFile Version 4.2\n{title}\nASCII\nDATASET POLYDATA\nPOINTS {n} double")?;
    for p in shape.points().chunks_exact(dim) {
        writeln!(w, "{}", pad(p))?;
    }
    let k = shape.kind().n_corners();
    let keyword = if shape.kind() == CellKind::Triangle { "POLYGONS" } else { "LINES" };
    writeln!(w, "{keyword} {} {}", shape.n_cells(), shape.n_cells() * (k + 1))?;
    for c in shape.cell_iter() {
        let ids: Vec<String> = c.iter().map(usize::to_string).collect();
        writeln!(w, "{k} {}", ids.join(" "))?;
    }
    if vectors.is_empty() && scalars.is_empty() {
        return Ok(());
    }
    writeln!(w, "POINT_DATA {n}")?;
    for (name, v) in vectors {
        writeln!(w, "VECTORS {name} double")?;
        for row in v.chunks_exact(dim) {
            writeln!(w, "{}", pad(row))?;
        }
    }
    for (name, v) in scalars {
        writeln!(w, "SCALARS {name} double 1\nLOOKUP_TABLE default")?;
        for x in *v {
            writeln!(w, "{x:e}")?;
        }
    }
    Ok(())
}

/// A ParaView collection (`.pvd`) of time steps: one `(time, file)` per
/// entry, the files relative to the collection.
pub fn collection(entries: &[(f64, &str)]) -> String {
    let mut pvd =
        String::from("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n");
    for (t, file) in entries {
        // Escaped so that an XML reader gives the name back as written
        // (a raw tab or line end in an attribute would read as a space).
        let file = file
            .replace('&', "&amp;")
            .replace('"', "&quot;")
            .replace('<', "&lt;")
            .replace('\t', "&#9;")
            .replace('\n', "&#10;")
            .replace('\r', "&#13;");
        pvd.push_str(&format!("    <DataSet timestep=\"{t}\" part=\"0\" file=\"{file}\"/>\n"));
    }
    pvd.push_str("  </Collection>\n</VTKFile>\n");
    pvd
}

/// The `(time, file)` entries of a ParaView collection, in file order, as
/// [`collection`] writes them (attribute values unescaped by an XML
/// reader, so any file name comes back as written).
pub fn parse_collection(text: &str) -> Result<Vec<(f64, String)>, ParseErrorKind> {
    let bad = |expected: &'static str, found: String| ParseErrorKind::BadToken { expected, found };
    let mut reader = quick_xml::Reader::from_str(text);
    let mut out = Vec::new();
    loop {
        match reader.read_event().map_err(|e| bad("a well-formed .pvd (XML)", e.to_string()))? {
            quick_xml::events::Event::Start(e) | quick_xml::events::Event::Empty(e)
                if e.name().as_ref() == "DataSet" =>
            {
                let (mut time, mut file) = (None, None);
                for a in e.attributes() {
                    let a = a.map_err(|e| bad("a well-formed attribute", e.to_string()))?;
                    let value = a
                        .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                        .map_err(|e| bad("a well-formed attribute value", e.to_string()))?;
                    match a.key.as_ref() {
                        "timestep" => {
                            time =
                                Some(value.trim().parse::<f64>().map_err(|_| bad("a number timestep", value.into()))?)
                        }
                        "file" => file = Some(value.into_owned()),
                        _ => {}
                    }
                }
                match (time, file) {
                    (Some(t), Some(f)) => out.push((t, f)),
                    _ => return Err(ParseErrorKind::Missing { what: "a DataSet's timestep and file" }),
                }
            }
            quick_xml::events::Event::Eof => break,
            _ => {}
        }
    }
    if out.is_empty() {
        return Err(ParseErrorKind::Missing { what: "a DataSet (the collection holds no state)" });
    }
    Ok(out)
}
