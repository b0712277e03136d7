//! Stanford PLY: ASCII, binary little endian and binary big endian.
//!
//! Read: vertex properties `x`, `y` (required), `z` (optional: without it the
//! shape is planar), and the signal from the property the caller names
//! (default `signal`); every other vertex property (`confidence`,
//! `intensity`, normals, colours) is skipped. Cells come from the `face`
//! element's list property `vertex_indices` or `vertex_index` (triangles;
//! two-vertex faces make a curve) or, when there is no face, from an `edge`
//! element's `vertex1`, `vertex2` (a curve). Other elements are skipped.
//!
//! Write: `double` coordinates, signal and mask (a masked shape's), `list uchar int vertex_indices`
//! faces (or an `edge` element for curves). A planar shape is written with
//! z = 0 and the header comment `fshape planar`, which this reader honours.
//! MeshLab and ParaView read these files.

use std::io::{self, Write};

use super::cursor::{Cursor, lossy};
use super::{Encoding, ParseError, ParseErrorKind, RawMesh};
use crate::shape::{CellKind, FShape};

/// The comment that marks a planar (2-D) shape written with z = 0.
pub const PLANAR_COMMENT: &str = "fshape planar";

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Scalar(Scalar),
    List(Scalar, Scalar),
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    /// The fewest bytes one record can take, to bound counts before
    /// allocating: binary sizes, or two bytes ("0 ") per token in ASCII.
    fn min_record_bytes(&self, ascii: bool) -> usize {
        let per = |k: &Kind| match (k, ascii) {
            (_, true) => 2,
            (Kind::Scalar(s), false) => s.size(),
            (Kind::List(c, _), false) => c.size(),
        };
        self.props.iter().map(|p| per(&p.kind)).sum::<usize>().max(1)
    }

    fn find(&self, name: &str) -> Option<usize> {
        self.props.iter().position(|p| p.name == name)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Body {
    Ascii,
    Little,
    Big,
}

struct Header {
    body: Body,
    elements: Vec<Element>,
    planar: bool,
}

fn bad(cur: &Cursor, expected: &'static str, found: &str) -> ParseError {
    cur.error(ParseErrorKind::BadToken { expected, found: lossy(found.as_bytes()) })
}

fn parse_header(cur: &mut Cursor) -> Result<Header, ParseError> {
    let first = cur.text_line("`ply`")?;
    if first.map(str::trim_end) != Some("ply") {
        let found = lossy(first.unwrap_or("").as_bytes());
        return Err(ParseError {
            at: super::Location::Line(1),
            kind: ParseErrorKind::BadToken { expected: "the magic line `ply`", found },
        });
    }
    let mut header = Header { body: Body::Ascii, elements: Vec::new(), planar: false };
    let mut format_seen = false;
    loop {
        let Some(line) = cur.text_line("a header line")? else {
            return Err(cur.error(ParseErrorKind::Missing { what: "`end_header`" }));
        };
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            ["comment", rest @ ..] => header.planar |= rest.join(" ") == PLANAR_COMMENT,
            ["obj_info", ..] | [] => {}
            ["format", fmt, version] => {
                header.body = match *fmt {
                    "ascii" => Body::Ascii,
                    "binary_little_endian" => Body::Little,
                    "binary_big_endian" => Body::Big,
                    _ => return Err(bad_line(cur, "PLY format", fmt)),
                };
                if !version.starts_with('1') {
                    return Err(bad_line(cur, "PLY version", version));
                }
                format_seen = true;
            }
            ["element", name, count] => {
                let count = count.parse::<u64>().map_err(|_| bad_prev(cur, "an element count", count))?;
                header.elements.push(Element { name: name.to_string(), count, props: Vec::new() });
            }
            ["property", rest @ ..] => {
                let el =
                    header.elements.last_mut().ok_or_else(|| bad_prev(cur, "`element` before `property`", line))?;
                let prop = match rest {
                    ["list", c, i, name] => {
                        let c = Scalar::parse(c)
                            .filter(|c| !c.is_float())
                            .ok_or_else(|| bad_prev(cur, "an integer list count type", c))?;
                        let i = Scalar::parse(i).ok_or_else(|| bad_prev(cur, "a PLY scalar type", i))?;
                        Property { name: name.to_string(), kind: Kind::List(c, i) }
                    }
                    [t, name] => {
                        let t = Scalar::parse(t).ok_or_else(|| bad_prev(cur, "a PLY scalar type", t))?;
                        Property { name: name.to_string(), kind: Kind::Scalar(t) }
                    }
                    _ => {
                        return Err(bad_prev(cur, "`property TYPE NAME` or `property list TYPE TYPE NAME`", line));
                    }
                };
                el.props.push(prop);
            }
            _ => return Err(bad_prev(cur, "a PLY header line", line)),
        }
    }
    if !format_seen {
        return Err(cur.error(ParseErrorKind::Missing { what: "the `format` line" }));
    }
    Ok(header)
}

/// An error about the line just consumed.
fn bad_prev(cur: &Cursor, expected: &'static str, found: &str) -> ParseError {
    let mut e = bad(cur, expected, found);
    if let super::Location::Line(l) = e.at {
        e.at = super::Location::Line(l - 1);
    }
    e
}

fn bad_line(cur: &Cursor, what: &'static str, found: &str) -> ParseError {
    let mut e = bad_prev(cur, "", found);
    e.kind = ParseErrorKind::Unsupported { what, found: lossy(found.as_bytes()) };
    e
}

/// Reads one scalar of the body.
fn scalar(cur: &mut Cursor, body: Body, t: Scalar, expected: &'static str) -> Result<f64, ParseError> {
    if body == Body::Ascii {
        return if t.is_float() { cur.f64_token(expected) } else { cur.i64_token(expected).map(|v| v as f64) };
    }
    let b = cur.take(t.size(), expected)?;
    macro_rules! num {
        ($ty:ty) => {{
            let a = b.try_into().expect("take returned the requested size");
            (if body == Body::Little { <$ty>::from_le_bytes(a) } else { <$ty>::from_be_bytes(a) }) as f64
        }};
    }
    Ok(match t {
        Scalar::I8 => b[0] as i8 as f64,
        Scalar::U8 => b[0] as f64,
        Scalar::I16 => num!(i16),
        Scalar::U16 => num!(u16),
        Scalar::I32 => num!(i32),
        Scalar::U32 => num!(u32),
        Scalar::F32 => num!(f32),
        Scalar::F64 => num!(f64),
    })
}

/// A list length or vertex index: an integer (a float item that is integral is
/// accepted, as some writers use float lists).
fn index(cur: &mut Cursor, body: Body, t: Scalar, expected: &'static str) -> Result<i64, ParseError> {
    let at = cur.mark();
    let v = if body == Body::Ascii && !t.is_float() {
        cur.i64_token(expected)? as f64
    } else {
        scalar(cur, body, t, expected)?
    };
    if v.fract() != 0.0 || !v.is_finite() || v.abs() > 9.0e15 {
        return Err(ParseError { at, kind: ParseErrorKind::BadToken { expected, found: v.to_string() } });
    }
    Ok(v as i64)
}

fn check_count(cur: &Cursor, el: &Element, body: Body) -> Result<(), ParseError> {
    super::source::check_values(el.count, if el.name == "vertex" { "vertices" } else { "records" })
        .map_err(|kind| cur.error(kind))?;
    let min = el.min_record_bytes(body == Body::Ascii) as u64;
    // An ASCII last record needs no trailing separator: allow one byte slack.
    if el.count.saturating_mul(min) > cur.remaining() as u64 + 1 {
        return Err(cur.error(ParseErrorKind::Truncated {
            what: if el.name == "vertex" { "vertices" } else { "records" },
            claimed: el.count,
            available: cur.remaining(),
        }));
    }
    Ok(())
}

/// Parses PLY data; `signal_name` selects the vertex property read as the
/// signal (absent property: no signal).
pub(crate) fn parse(data: &[u8], signal_name: &str) -> Result<RawMesh, ParseError> {
    let mut cur = Cursor::new(data);
    let header = parse_header(&mut cur)?;
    cur.binary = header.body != Body::Ascii;
    let mut raw = RawMesh { dim: 3, ..RawMesh::default() };
    let mut edges = Vec::new();
    let mut faces_seen = false;
    let vertex = header
        .elements
        .iter()
        .find(|e| e.name == "vertex")
        .ok_or_else(|| cur.error(ParseErrorKind::Missing { what: "element `vertex`" }))?;
    raw.scalars = vertex.props.iter().filter(|p| matches!(p.kind, Kind::Scalar(_))).map(|p| p.name.clone()).collect();
    for el in &header.elements {
        check_count(&cur, el, header.body)?;
        match el.name.as_str() {
            "vertex" => read_vertices(&mut cur, header.body, el, signal_name, &mut raw)?,
            "face" => {
                faces_seen = true;
                read_faces(&mut cur, header.body, el, &mut raw)?;
            }
            "edge" => edges = read_edges(&mut cur, header.body, el)?,
            _ => skip(&mut cur, header.body, el)?,
        }
    }
    if !faces_seen && !edges.is_empty() {
        raw.cell_size = Some(2);
        raw.cells = edges;
    }
    if header.planar && raw.dim == 3 && raw.points.chunks_exact(3).all(|p| p[2] == 0.0) {
        raw.points = raw.points.chunks_exact(3).flat_map(|p| [p[0], p[1]]).collect();
        raw.dim = 2;
    }
    Ok(raw)
}

fn read_vertices(
    cur: &mut Cursor,
    body: Body,
    el: &Element,
    signal_name: &str,
    raw: &mut RawMesh,
) -> Result<(), ParseError> {
    let missing = |what| cur.error(ParseErrorKind::Missing { what });
    let x = el.find("x").ok_or_else(|| missing("vertex property `x`"))?;
    let y = el.find("y").ok_or_else(|| missing("vertex property `y`"))?;
    let z = el.find("z");
    let s = super::channel_columns(signal_name, |name| {
        el.find(name).filter(|&i| matches!(el.props[i].kind, Kind::Scalar(_)))
    });
    // fshape writes a masked shape's mask as the property `mask`.
    let m = el.find("mask").filter(|&i| matches!(el.props[i].kind, Kind::Scalar(_)) && signal_name != "mask");
    raw.dim = if z.is_some() { 3 } else { 2 };
    let n = el.count as usize;
    raw.points = Vec::with_capacity(n * raw.dim);
    let mut signal = (!s.is_empty()).then(|| Vec::with_capacity(n.saturating_mul(s.len())));
    let mut mask = m.map(|_| Vec::with_capacity(n));
    let mut vals = vec![0.0; el.props.len()];
    for _ in 0..n {
        for (k, p) in el.props.iter().enumerate() {
            vals[k] = match p.kind {
                Kind::Scalar(t) => scalar(cur, body, t, "a vertex property value")?,
                Kind::List(c, t) => {
                    let len = index(cur, body, c, "a list length")?;
                    for _ in 0..len {
                        scalar(cur, body, t, "a list item")?;
                    }
                    0.0
                }
            };
        }
        raw.points.extend_from_slice(&[vals[x], vals[y]]);
        if let Some(z) = z {
            raw.points.push(vals[z]);
        }
        if let Some(sig) = signal.as_mut() {
            sig.extend(s.iter().map(|&s| vals[s]));
        }
        if let (Some(mask), Some(m)) = (mask.as_mut(), m) {
            mask.push(vals[m]);
        }
    }
    raw.signal = signal;
    raw.channels = s.len();
    raw.mask = mask;
    Ok(())
}

fn read_faces(cur: &mut Cursor, body: Body, el: &Element, raw: &mut RawMesh) -> Result<(), ParseError> {
    let li = el
        .find("vertex_indices")
        .or_else(|| el.find("vertex_index"))
        .filter(|&i| matches!(el.props[i].kind, Kind::List(..)))
        .ok_or_else(|| {
            cur.error(ParseErrorKind::Missing { what: "face list property `vertex_indices` or `vertex_index`" })
        })?;
    raw.cells = Vec::with_capacity(el.count as usize * 3);
    for cell in 0..el.count as usize {
        for (k, p) in el.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(t) => {
                    scalar(cur, body, t, "a face property value")?;
                }
                Kind::List(c, t) => {
                    let at = cur.mark();
                    let len = index(cur, body, c, "a face's vertex count")?;
                    if k == li {
                        let len = check_cell_size(raw, cell, len).map_err(|kind| ParseError { at, kind })?;
                        for _ in 0..len {
                            let at = cur.mark();
                            let v = index(cur, body, t, "a vertex index")?;
                            let v = usize::try_from(v).map_err(|_| ParseError {
                                at,
                                kind: ParseErrorKind::NegativeIndex { cell, value: v },
                            })?;
                            raw.cells.push(v);
                        }
                    } else {
                        for _ in 0..len {
                            scalar(cur, body, t, "a list item")?;
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

fn check_cell_size(raw: &mut RawMesh, cell: usize, len: i64) -> Result<usize, ParseErrorKind> {
    let found = usize::try_from(len).unwrap_or(usize::MAX);
    if found != 2 && found != 3 {
        return Err(ParseErrorKind::CellSize { cell, found: len.max(0) as usize });
    }
    match raw.cell_size {
        None => raw.cell_size = Some(found),
        Some(expected) if expected != found => {
            return Err(ParseErrorKind::MixedCellSizes { cell, found, expected });
        }
        Some(_) => {}
    }
    Ok(found)
}

fn read_edges(cur: &mut Cursor, body: Body, el: &Element) -> Result<Vec<usize>, ParseError> {
    let (a, b) = match (el.find("vertex1"), el.find("vertex2")) {
        (Some(a), Some(b)) => (a, b),
        _ => {
            return Err(cur.error(ParseErrorKind::Missing { what: "edge properties `vertex1` and `vertex2`" }));
        }
    };
    let mut out = Vec::with_capacity(el.count as usize * 2);
    let mut vals = vec![0i64; el.props.len()];
    for cell in 0..el.count as usize {
        let at = cur.mark();
        for (k, p) in el.props.iter().enumerate() {
            vals[k] = match p.kind {
                Kind::Scalar(t) => index(cur, body, t, "an edge property value")?,
                Kind::List(c, t) => {
                    let len = index(cur, body, c, "a list length")?;
                    for _ in 0..len {
                        scalar(cur, body, t, "a list item")?;
                    }
                    0
                }
            };
        }
        for v in [vals[a], vals[b]] {
            out.push(
                usize::try_from(v)
                    .map_err(|_| ParseError { at, kind: ParseErrorKind::NegativeIndex { cell, value: v } })?,
            );
        }
    }
    Ok(out)
}

fn skip(cur: &mut Cursor, body: Body, el: &Element) -> Result<(), ParseError> {
    for _ in 0..el.count {
        for p in &el.props {
            match p.kind {
                Kind::Scalar(t) => {
                    scalar(cur, body, t, "a property value")?;
                }
                Kind::List(c, t) => {
                    let len = index(cur, body, c, "a list length")?;
                    for _ in 0..len {
                        scalar(cur, body, t, "a list item")?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Writes `shape` as PLY with `double` coordinates (and signal: a
/// property per channel, `signal`, `signal_2`, …).
pub fn write(w: &mut impl Write, shape: &FShape, encoding: Encoding) -> io::Result<()> {
    let fmt = match encoding {
        Encoding::Ascii => "ascii",
        Encoding::Binary => "binary_little_endian",
    };
    writeln!(w, "ply\nformat {fmt} 1.0\ncomment written by fshape-mesh")?;
    if shape.dim() == 2 {
        writeln!(w, "comment {PLANAR_COMMENT}")?;
    }
    writeln!(w, "element vertex {}", shape.n_vertices())?;
    writeln!(w, "property double x\nproperty double y\nproperty double z")?;
    let k = if shape.signal().is_some() { shape.n_channels().max(1) } else { 0 };
    for c in 0..k {
        writeln!(w, "property double {}", super::channel_name(super::DEFAULT_SIGNAL_NAME, c))?;
    }
    if shape.mask().is_some() {
        writeln!(w, "property double mask")?;
    }
    match shape.kind() {
        CellKind::Triangle => writeln!(w, "element face {}\nproperty list uchar int vertex_indices", shape.n_cells())?,
        CellKind::Segment => {
            writeln!(w, "element edge {}\nproperty int vertex1\nproperty int vertex2", shape.n_cells())?
        }
    }
    writeln!(w, "end_header")?;
    let ascii = encoding == Encoding::Ascii;
    for v in 0..shape.n_vertices() {
        let p = shape.point(v);
        let z = if shape.dim() == 3 { p[2] } else { 0.0 };
        let vals = [p[0], p[1], z];
        let sig = shape.signal().map_or(&[][..], |f| &f[v * k..(v + 1) * k]);
        let mask = shape.mask().map(|m| m[v]);
        if ascii {
            write!(w, "{:e} {:e} {:e}", vals[0], vals[1], vals[2])?;
            for s in sig.iter().chain(&mask) {
                write!(w, " {s:e}")?;
            }
            writeln!(w)?;
        } else {
            for x in vals.iter().chain(sig).chain(mask.as_ref()) {
                w.write_all(&x.to_le_bytes())?;
            }
        }
    }
    for c in shape.cell_iter() {
        let idx = |v: usize| i32::try_from(v).map_err(|_| io::Error::other("vertex index exceeds the PLY int range"));
        match (ascii, shape.kind()) {
            (true, CellKind::Triangle) => writeln!(w, "3 {} {} {}", c[0], c[1], c[2])?,
            (true, CellKind::Segment) => writeln!(w, "{} {}", c[0], c[1])?,
            (false, kind) => {
                if kind == CellKind::Triangle {
                    w.write_all(&[3u8])?;
                }
                for &v in c {
                    w.write_all(&idx(v)?.to_le_bytes())?;
                }
            }
        }
    }
    Ok(())
}
