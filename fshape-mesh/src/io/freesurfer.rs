//! FreeSurfer's binary files: triangle surfaces (`lh.pial`, `lh.white`, …),
//! per-vertex "curv" files (`lh.thickness`, `lh.curv`, `lh.sulc`, …),
//! MGH/MGZ volumes holding one value per vertex (`lh.thickness.mgh`) and
//! annotations (`lh.aparc.annot`, a parcellation).
//!
//! FreeSurfer names carry no extension, so the surface and curv readers are
//! chosen by their magic bytes (`FF FF FE` and `FF FF FF`); MGH has none
//! (it starts with the version, 1) and is chosen by `.mgh`/`.mgz`. All
//! three are big endian and store single-precision floats: values written
//! here are rounded to `f32`.
//!
//! Written from FreeSurfer's own description (`utils/mrisurf_io.cpp`,
//! `read_surf.m`, `read_curv.m`, `load_mgh.m`) rather than with the
//! `neuroformats` crate: that crate reads from a path through its own file
//! handling (so it cannot be fuzzed on bytes, nor read a gzipped file the
//! way every other fshape reader does), reports errors without a byte
//! offset and sizes its arrays from the header's counts before checking
//! that the file holds them. Each format here is a header and a few arrays.

use std::io::{self, Write};

use super::cursor::Cursor;
use super::parcellation::{Parcellation, Region};
use super::{ParseError, ParseErrorKind, RawMesh};
use crate::shape::{CellKind, FShape};

/// The first three bytes of a triangle surface file.
pub const SURFACE_MAGIC: [u8; 3] = [0xff, 0xff, 0xfe];
/// The first three bytes of a "new" curv file.
pub const CURV_MAGIC: [u8; 3] = [0xff, 0xff, 0xff];
/// The MGH header is this long; the data follow it.
const MGH_HEADER: usize = 284;

fn be_i32(cur: &mut Cursor, what: &'static str) -> Result<i32, ParseError> {
    let b = cur.take(4, what)?;
    Ok(i32::from_be_bytes([b[0], b[1], b[2], b[3]]))
}

/// A count from the header: not negative, and at most what the rest of the
/// file can hold at `bytes_each` bytes a record (checked before anything is
/// allocated).
fn count(cur: &mut Cursor, what: &'static str, bytes_each: usize) -> Result<usize, ParseError> {
    let at = cur.at();
    let n = be_i32(cur, what)?;
    let n = usize::try_from(n).map_err(|_| ParseError {
        at,
        kind: ParseErrorKind::BadToken { expected: "a non-negative count", found: n.to_string() },
    })?;
    super::source::check_values(n as u64, what).map_err(|kind| ParseError { at, kind })?;
    if n.saturating_mul(bytes_each) > cur.remaining() {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::Truncated { what, claimed: n as u64, available: cur.remaining() },
        });
    }
    Ok(n)
}

/// A count as the formats store it (`i32`).
fn i32_count(n: usize) -> io::Result<i32> {
    i32::try_from(n).map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "more than i32::MAX items"))
}

fn f32s(cur: &mut Cursor, n: usize, what: &'static str) -> Result<Vec<f64>, ParseError> {
    let b = cur.take(4 * n, what)?;
    Ok(b.chunks_exact(4).map(|c| f64::from(f32::from_be_bytes([c[0], c[1], c[2], c[3]]))).collect())
}

fn magic(cur: &mut Cursor, want: [u8; 3], expected: &'static str) -> Result<(), ParseError> {
    let at = cur.at();
    let m = cur.take(3, expected)?;
    if m != want {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::BadToken { expected, found: format!("{:02x} {:02x} {:02x}", m[0], m[1], m[2]) },
        });
    }
    Ok(())
}

/// Parses a triangle surface file: the magic, a comment line ("created by
/// …") and an empty line, the vertex and face counts, the coordinates
/// (`f32`) and the faces (`i32`). Whatever follows (volume geometry tags)
/// is ignored. Quad files (FreeSurfer's old format) are refused.
pub(crate) fn parse_surface(data: &[u8]) -> Result<RawMesh, ParseError> {
    let mut cur = Cursor::new(data);
    cur.binary = true;
    if data.starts_with(&[0xff, 0xff, 0xff]) || data.starts_with(&[0xff, 0xff, 0xfd]) {
        return Err(cur.error(ParseErrorKind::Unsupported {
            what: "FreeSurfer surface type",
            found: "quad file (convert it with mris_convert)".into(),
        }));
    }
    magic(&mut cur, SURFACE_MAGIC, "the FreeSurfer triangle-surface magic ff ff fe")?;
    // The comment ends at the first newline; FreeSurfer writes a second one.
    let rest = &data[3..];
    let end = rest
        .iter()
        .position(|&b| b == b'\n')
        .ok_or_else(|| cur.error(ParseErrorKind::Eof { expected: "the comment line after the magic" }))?;
    let mut skip = end + 1;
    if rest.get(skip) == Some(&b'\n') {
        skip += 1;
    }
    cur.take(skip, "the comment line")?;
    // Both counts come before the arrays: check them against what follows both.
    let at_n = cur.at();
    let n = count(&mut cur, "vertices", 0)?;
    let at_m = cur.at();
    let m = count(&mut cur, "triangles", 0)?;
    let remaining = cur.remaining();
    if n.saturating_mul(12) > remaining {
        return Err(ParseError {
            at: at_n,
            kind: ParseErrorKind::Truncated { what: "vertices", claimed: n as u64, available: remaining },
        });
    }
    let available = remaining - 12 * n;
    if m.saturating_mul(12) > available {
        return Err(ParseError {
            at: at_m,
            kind: ParseErrorKind::Truncated { what: "triangles after the vertices", claimed: m as u64, available },
        });
    }
    let points = f32s(&mut cur, 3 * n, "vertex coordinates")?;
    let mut cells = Vec::with_capacity(3 * m);
    for t in 0..m {
        for _ in 0..3 {
            let v = be_i32(&mut cur, "a triangle's vertex index")?;
            cells.push(
                usize::try_from(v)
                    .map_err(|_| cur.error(ParseErrorKind::NegativeIndex { cell: t, value: i64::from(v) }))?,
            );
        }
    }
    Ok(RawMesh { dim: 3, cell_size: Some(3), points, cells, ..RawMesh::default() })
}

/// Writes a triangle surface file (coordinates rounded to `f32`), as
/// FreeSurfer's `MRISwriteTriangularSurface` does.
///
/// # Errors
///
/// `InvalidInput` if the shape is not a triangle surface in 3-D or has more
/// than `i32::MAX` vertices; otherwise the writer's errors.
pub fn write_surface(w: &mut impl Write, shape: &FShape) -> io::Result<()> {
    if shape.kind() != CellKind::Triangle || shape.dim() != 3 {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "FreeSurfer surfaces hold triangles in 3-D; this shape is not one",
        ));
    }
    let mut out = Vec::with_capacity(32 + 12 * (shape.n_vertices() + shape.n_cells()));
    out.extend_from_slice(&SURFACE_MAGIC);
    out.extend_from_slice(b"created by fshape\n\n");
    out.extend_from_slice(&i32_count(shape.n_vertices())?.to_be_bytes());
    out.extend_from_slice(&i32_count(shape.n_cells())?.to_be_bytes());
    for &x in shape.points() {
        out.extend_from_slice(&(x as f32).to_be_bytes());
    }
    for &v in shape.cells() {
        out.extend_from_slice(&i32_count(v)?.to_be_bytes());
    }
    w.write_all(&out)
}

/// Parses a "new" curv file: the magic, the vertex and face counts, the
/// values per vertex (must be 1), then one `f32` per vertex.
pub fn parse_curv(data: &[u8]) -> Result<Vec<f64>, ParseError> {
    let mut cur = Cursor::new(data);
    cur.binary = true;
    magic(&mut cur, CURV_MAGIC, "the FreeSurfer curv magic ff ff ff")?;
    let n = count(&mut cur, "values", 4)?;
    be_i32(&mut cur, "the face count")?;
    let at = cur.at();
    let per = be_i32(&mut cur, "the values per vertex")?;
    if per != 1 {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::Unsupported { what: "values per vertex (fshape reads 1)", found: per.to_string() },
        });
    }
    if 4 * n > cur.remaining() {
        return Err(cur.error(ParseErrorKind::Truncated {
            what: "values",
            claimed: n as u64,
            available: cur.remaining(),
        }));
    }
    f32s(&mut cur, n, "values")
}

/// The bytes of a "new" curv file holding `values` (rounded to `f32`);
/// `faces` is the surface's triangle count, which the format records.
///
/// # Errors
///
/// `InvalidInput` if a count exceeds `i32::MAX`.
pub fn curv_bytes(values: &[f64], faces: usize) -> io::Result<Vec<u8>> {
    let mut out = Vec::with_capacity(15 + 4 * values.len());
    out.extend_from_slice(&CURV_MAGIC);
    out.extend_from_slice(&i32_count(values.len())?.to_be_bytes());
    out.extend_from_slice(&i32_count(faces)?.to_be_bytes());
    out.extend_from_slice(&1i32.to_be_bytes());
    for &v in values {
        out.extend_from_slice(&(v as f32).to_be_bytes());
    }
    Ok(out)
}

/// Parses an MGH volume holding one value per vertex: version 1, the
/// dimensions (one of width, height, depth may exceed 1: FreeSurfer stores
/// surface data as n × 1 × 1), one frame, and data of type uchar, short,
/// int or float after the 284-byte header. Optional trailing tags are
/// ignored.
pub fn parse_mgh(data: &[u8]) -> Result<Vec<f64>, ParseError> {
    let mut cur = Cursor::new(data);
    cur.binary = true;
    let at = cur.at();
    let version = be_i32(&mut cur, "the MGH version")?;
    if version != 1 {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::BadToken { expected: "MGH version 1", found: version.to_string() },
        });
    }
    let mut dims = [0usize; 4];
    for (d, what) in dims.iter_mut().zip(["width", "height", "depth", "frames"]) {
        let at = cur.at();
        let v = be_i32(&mut cur, what)?;
        *d = usize::try_from(v).ok().filter(|&v| v > 0).ok_or_else(|| ParseError {
            at,
            kind: ParseErrorKind::BadToken { expected: "a positive dimension", found: v.to_string() },
        })?;
    }
    if dims[3] != 1 {
        return Err(cur.error(ParseErrorKind::Unsupported {
            what: "MGH frame count (fshape reads one frame of per-vertex values)",
            found: dims[3].to_string(),
        }));
    }
    if dims[..3].iter().filter(|&&d| d > 1).count() > 1 {
        return Err(cur.error(ParseErrorKind::Unsupported {
            what: "MGH volume shape (per-vertex data is n × 1 × 1)",
            found: format!("{} × {} × {}", dims[0], dims[1], dims[2]),
        }));
    }
    let n = dims[0] * dims[1] * dims[2];
    let at = cur.at();
    let kind = be_i32(&mut cur, "the data type")?;
    let size = match kind {
        0 => 1,
        1 | 3 => 4,
        4 => 2,
        _ => {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::Unsupported {
                    what: "MGH data type (0 uchar, 1 int, 3 float, 4 short)",
                    found: kind.to_string(),
                },
            });
        }
    };
    if data.len() < MGH_HEADER {
        return Err(cur.error(ParseErrorKind::Eof { expected: "the 284-byte MGH header" }));
    }
    cur.take(MGH_HEADER - 24, "the MGH header")?;
    super::source::check_values(n as u64, "values").map_err(|kind| cur.error(kind))?;
    if n.saturating_mul(size) > cur.remaining() {
        return Err(cur.error(ParseErrorKind::Truncated {
            what: "values",
            claimed: n as u64,
            available: cur.remaining(),
        }));
    }
    let b = cur.take(n * size, "values")?;
    Ok(match kind {
        0 => b.iter().map(|&v| f64::from(v)).collect(),
        1 => b.chunks_exact(4).map(|c| f64::from(i32::from_be_bytes([c[0], c[1], c[2], c[3]]))).collect(),
        3 => b.chunks_exact(4).map(|c| f64::from(f32::from_be_bytes([c[0], c[1], c[2], c[3]]))).collect(),
        _ => b.chunks_exact(2).map(|c| f64::from(i16::from_be_bytes([c[0], c[1]]))).collect(),
    })
}

/// The bytes of an MGH file holding `values` as an n × 1 × 1 float volume
/// of one frame (rounded to `f32`), as FreeSurfer writes surface overlays.
///
/// # Errors
///
/// `InvalidInput` if there are more than `i32::MAX` values.
pub fn mgh_bytes(values: &[f64]) -> io::Result<Vec<u8>> {
    let n = i32_count(values.len())?;
    let mut out = Vec::with_capacity(MGH_HEADER + 4 * values.len());
    for v in [1, n, 1, 1, 1, 3, 0] {
        out.extend_from_slice(&v.to_be_bytes());
    }
    out.extend_from_slice(&0i16.to_be_bytes()); // no RAS geometry
    out.resize(MGH_HEADER, 0);
    for &v in values {
        out.extend_from_slice(&(v as f32).to_be_bytes());
    }
    Ok(out)
}

/// A string of an annotation's colour table: its length (with the final
/// NUL) then its bytes; the NUL and anything after it are dropped.
fn annot_string(cur: &mut Cursor, what: &'static str) -> Result<String, ParseError> {
    let n = count(cur, what, 1)?;
    let b = cur.take(n, what)?;
    let b = b.split(|&c| c == 0).next().unwrap_or(b);
    Ok(super::cursor::lossy(b))
}

/// Parses an annotation (`lh.aparc.annot`), FreeSurfer's parcellation
/// file, as FreeSurfer's `read_annotation.m` and nibabel's `read_annot`
/// read it: the vertex count, a (vertex, value) pair per vertex, where the
/// value packs the region's colour (r + 256 g + 65536 b), then a colour
/// table in the old layout (a positive entry count) or the new one
/// (version −2). Each vertex gets the table row of its colour as key, and
/// −1 when its value is 0 or no row has its colour (nibabel's keys, with
/// `orig_ids=False`). Alpha is 255 minus the table's transparency.
pub fn parse_annot(data: &[u8]) -> Result<Parcellation, ParseError> {
    let mut cur = Cursor::new(data);
    cur.binary = true;
    let n = count(&mut cur, "vertex and value pairs", 8)?;
    let mut values = vec![0i32; n];
    let mut seen = vec![false; n];
    for _ in 0..n {
        let at = cur.at();
        let v = be_i32(&mut cur, "a vertex")?;
        let value = be_i32(&mut cur, "a vertex's annotation value")?;
        let k = usize::try_from(v).ok().filter(|&k| k < n).ok_or_else(|| ParseError {
            at,
            kind: ParseErrorKind::BadToken { expected: "a vertex index below the vertex count", found: v.to_string() },
        })?;
        if std::mem::replace(&mut seen[k], true) {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::BadToken { expected: "each vertex once", found: format!("vertex {k} again") },
            });
        }
        values[k] = value;
    }
    let at = cur.at();
    if be_i32(&mut cur, "the colour table flag")? == 0 {
        return Err(ParseError { at, kind: ParseErrorKind::Missing { what: "the colour table (the flag is 0)" } });
    }
    let at = cur.at();
    let first = be_i32(&mut cur, "the colour table's entry count or version")?;
    // Each entry holds at least a name length and four colour numbers.
    let mut regions = Vec::new();
    // (packed colour, key) of every entry, to look the vertices' values up.
    let mut by_value = Vec::new();
    let mut entry = |cur: &mut Cursor, row: i32| -> Result<(), ParseError> {
        let name = annot_string(cur, "a region name")?;
        let mut c = [0i32; 4];
        for x in &mut c {
            *x = be_i32(cur, "a region colour")?;
        }
        let unit = |v: i32| f64::from(v) / 255.0;
        by_value.push((c[0].wrapping_add(c[1].wrapping_shl(8)).wrapping_add(c[2].wrapping_shl(16)), row));
        regions.push(Region { key: row, name, rgba: [unit(c[0]), unit(c[1]), unit(c[2]), unit(255 - c[3])] });
        Ok(())
    };
    if first > 0 {
        let m = usize::try_from(first).expect("positive");
        if m.saturating_mul(20) > cur.remaining() {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::Truncated {
                    what: "colour table entries",
                    claimed: m as u64,
                    available: cur.remaining(),
                },
            });
        }
        annot_string(&mut cur, "the colour table's file name")?;
        for row in 0..first {
            entry(&mut cur, row)?;
        }
    } else if first == -2 {
        be_i32(&mut cur, "the colour table's largest index")?;
        annot_string(&mut cur, "the colour table's file name")?;
        let m = count(&mut cur, "colour table entries", 24)?;
        for _ in 0..m {
            let at = cur.at();
            let row = be_i32(&mut cur, "a colour table index")?;
            if row < 0 {
                return Err(ParseError {
                    at,
                    kind: ParseErrorKind::BadToken {
                        expected: "a non-negative colour table index",
                        found: row.to_string(),
                    },
                });
            }
            entry(&mut cur, row)?;
        }
    } else {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::Unsupported {
                what: "colour table version (fshape reads the old layout and version -2)",
                found: first.to_string(),
            },
        });
    }
    by_value.sort_unstable();
    let keys = values
        .iter()
        .map(|&v| match by_value.binary_search_by_key(&v, |&(p, _)| p) {
            Ok(i) if v != 0 => by_value[i].1,
            _ => -1,
        })
        .collect();
    Ok(Parcellation { keys, regions })
}

/// The bytes of an annotation as nibabel's `write_annot` writes it (the
/// new colour table layout, version −2): the regions in table order,
/// numbered by their row (0, 1, …, as nibabel numbers them), each one's
/// colour packed into its vertices' values; a vertex whose key is not in
/// the table (−1) gets 0. [`parse_annot`] reads back each vertex's row, so
/// keys 0..n−1 in table order (any annotation read) come back as they
/// were, and other keys (a GIfTI label table's, e.g. 1001…) come back as
/// their rows. A black region's vertices also get 0 and read back as no
/// region (−1), as FreeSurfer reads them (HCP's `???`). Refused: two
/// regions of one colour (their vertices would read back as one region).
pub fn annot_bytes(p: &Parcellation) -> io::Result<Vec<u8>> {
    let invalid = |m: String| io::Error::new(io::ErrorKind::InvalidInput, m);
    let byte = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as i32;
    let mut packed = Vec::with_capacity(p.regions.len());
    for r in &p.regions {
        let value = byte(r.rgba[0]) + (byte(r.rgba[1]) << 8) + (byte(r.rgba[2]) << 16);
        if let Some((_, other)) = packed.iter().find(|(v, _)| *v == value && value != 0) {
            return Err(invalid(format!("annotation: regions {other:?} and {:?} have one colour", r.name)));
        }
        packed.push((value, &r.name));
    }
    let n = i32::try_from(p.keys.len()).map_err(|_| invalid(format!("annotation: {} vertices", p.keys.len())))?;
    let mut out = Vec::with_capacity(8 * p.keys.len() + 64 * p.regions.len() + 64);
    let put = |v: i32, out: &mut Vec<u8>| out.extend_from_slice(&v.to_be_bytes());
    put(n, &mut out);
    for (v, &key) in p.keys.iter().enumerate() {
        let value = p.regions.iter().position(|r| r.key == key).map_or(0, |i| packed[i].0);
        put(v as i32, &mut out);
        put(value, &mut out);
    }
    put(1, &mut out);
    put(-2, &mut out);
    let rows =
        i32::try_from(p.regions.len()).map_err(|_| invalid(format!("annotation: {} regions", p.regions.len())))?;
    put(rows, &mut out);
    let string = |s: &str, out: &mut Vec<u8>| {
        out.extend_from_slice(&(s.len() as i32 + 1).to_be_bytes());
        out.extend_from_slice(s.as_bytes());
        out.push(0);
    };
    string("NOFILE", &mut out);
    put(rows, &mut out);
    for (row, r) in (0..).zip(&p.regions) {
        put(row, &mut out);
        string(&r.name, &mut out);
        for c in [byte(r.rgba[0]), byte(r.rgba[1]), byte(r.rgba[2]), 255 - byte(r.rgba[3])] {
            put(c, &mut out);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::Location;

    fn tetra() -> FShape {
        let p = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        FShape::try_new(3, CellKind::Triangle, p, vec![0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], None).unwrap()
    }

    #[test]
    fn surface_curv_and_mgh_round_trip() {
        let mut bytes = Vec::new();
        write_surface(&mut bytes, &tetra()).unwrap();
        let raw = parse_surface(&bytes).unwrap();
        assert_eq!(raw.points, tetra().points());
        assert_eq!(raw.cells, tetra().cells());
        let v = [0.5, -2.25, 3.0, 1e-3_f32 as f64];
        assert_eq!(parse_curv(&curv_bytes(&v, 4).unwrap()).unwrap(), v);
        assert_eq!(parse_mgh(&mgh_bytes(&v).unwrap()).unwrap(), v);
    }

    #[test]
    fn counts_beyond_the_file_and_bad_magic_are_errors_with_offsets() {
        let mut bytes = Vec::new();
        write_surface(&mut bytes, &tetra()).unwrap();
        let e = parse_surface(&bytes[..bytes.len() - 5]).unwrap_err();
        assert!(
            matches!(e.kind, ParseErrorKind::Truncated { what: "triangles after the vertices", claimed: 4, .. }),
            "{e}"
        );
        let mut huge = bytes.clone();
        huge[22..26].copy_from_slice(&i32::MAX.to_be_bytes()); // the vertex count
        let e = parse_surface(&huge).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("byte 22: the header claims 2147483647 vertices, but only {} bytes follow", bytes.len() - 30)
        );
        // A vertex count that fits the bytes after it but not after the
        // triangle count: the 4 bytes of that count are not vertex data.
        let mut tight = bytes[..30].to_vec();
        tight[22..26].copy_from_slice(&1i32.to_be_bytes());
        tight.extend_from_slice(&[0; 8]);
        let e = parse_surface(&tight).unwrap_err();
        assert!(matches!(e.kind, ParseErrorKind::Truncated { what: "vertices", claimed: 1, available: 8 }), "{e}");
        let e = parse_curv(&bytes).unwrap_err();
        assert_eq!(e.to_string(), "byte 0: expected the FreeSurfer curv magic ff ff ff, found `ff ff fe`");
        let mut c = curv_bytes(&[1.0, 2.0], 0).unwrap();
        c[11..15].copy_from_slice(&3i32.to_be_bytes());
        assert!(parse_curv(&c).unwrap_err().to_string().starts_with("byte 11: unsupported values per vertex"));
        let mut m = mgh_bytes(&[1.0, 2.0]).unwrap();
        m[16..20].copy_from_slice(&2i32.to_be_bytes());
        assert!(parse_mgh(&m).unwrap_err().to_string().contains("frame count"));
        assert!(
            parse_mgh(&mgh_bytes(&[1.0, 2.0]).unwrap()[..290]).unwrap_err().to_string().contains("claims 2 values")
        );
    }

    #[test]
    fn a_negative_face_index_names_its_triangle() {
        let mut bytes = Vec::new();
        write_surface(&mut bytes, &tetra()).unwrap();
        let at = bytes.len() - 4;
        bytes[at..].copy_from_slice(&(-7i32).to_be_bytes());
        let e = parse_surface(&bytes).unwrap_err();
        assert_eq!(e.kind, ParseErrorKind::NegativeIndex { cell: 3, value: -7 });
    }
    /// nibabel's annotation (tests/data/nibabel): 12 vertices, 3 regions.
    const ANNOT: &[u8] = include_bytes!("../../tests/data/nibabel/lh.parcels.annot");

    #[test]
    fn damaged_annotations_are_refused_at_their_byte() {
        let with = |at: usize, v: i32| {
            let mut b = ANNOT.to_vec();
            b[at..at + 4].copy_from_slice(&v.to_be_bytes());
            b
        };
        // Byte 4 + 8k is vertex k's index, then its value; the flag follows the pairs.
        let flag = 4 + 8 * 12;
        for (bytes, at, says) in [
            (ANNOT[..50].to_vec(), 0, "claims 12 vertex and value pairs"),
            (with(4 + 8 * 3, 12), 28, "a vertex index below the vertex count"),
            (with(4 + 8 * 3, 2), 28, "vertex 2 again"),
            (with(flag, 0), flag, "the colour table (the flag is 0)"),
            (with(flag + 4, -3), flag + 4, "colour table version"),
            (with(flag + 4, 1_000_000), flag + 4, "claims 1000000 colour table entries"),
            (ANNOT[..ANNOT.len() - 2].to_vec(), ANNOT.len() - 4, "a region colour"),
        ] {
            let e = parse_annot(&bytes).unwrap_err();
            assert!(e.to_string().contains(says), "{says}: {e}");
            assert_eq!(e.at, Location::Byte(at), "{says}: {e}");
        }
        // A value that is no region's colour is a vertex without a region.
        let p = parse_annot(&with(4 + 8 * 3 + 4, 12345)).unwrap();
        assert_eq!(p.keys[3], -1);
    }
}
