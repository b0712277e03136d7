//! GIfTI (`.gii`: `.surf.gii` geometry, `.shape.gii`/`.func.gii`
//! per-vertex data), after the GIfTI 1.0 format description.
//!
//! A file is XML: a `GIFTI` element holding `DataArray`s, each with an
//! intent (POINTSET for coordinates, TRIANGLE for faces, SHAPE and others
//! for data), a data type, dimensions, an index order, an encoding and a
//! byte order. This reader takes every encoding of the format but external
//! files (`ASCII`, `Base64Binary`, `GZipBase64Binary`, whose compression is
//! zlib), both byte orders, both index orders, intents by name or number,
//! and every NIfTI integer and float type. Errors name the line of the XML;
//! decompression never produces more bytes than the array's dimensions
//! call for, so a header's claims cannot make the reader allocate beyond
//! what the file holds.
//!
//! The writer stores coordinates and data as `FLOAT32` and faces as
//! `INT32`, the types the format allows and every GIfTI reader takes, so
//! values written here are rounded to single precision.

use std::fmt::Write as _;
use std::io::{self, Read, Write};
use std::path::Path;

use base64::Engine;
use quick_xml::events::Event;

use super::parcellation::{Parcellation, Region};
use super::{Location, ParseError, ParseErrorKind, RawMesh};
use crate::shape::{CellKind, FShape};

/// NIfTI intent codes (the ones GIfTI names, with their numbers).
pub mod intent {
    /// No intent.
    pub const NONE: i32 = 0;
    /// Per-vertex labels.
    pub const LABEL: i32 = 1002;
    /// Per-vertex vectors.
    pub const VECTOR: i32 = 1007;
    /// Vertex coordinates.
    pub const POINTSET: i32 = 1008;
    /// Triangles (vertex indices).
    pub const TRIANGLE: i32 = 1009;
    /// A time series.
    pub const TIME_SERIES: i32 = 2001;
    /// Vertex indices of sparse data.
    pub const NODE_INDEX: i32 = 2002;
    /// Per-vertex shape measurements (thickness, curvature, …).
    pub const SHAPE: i32 = 2005;
}

const INTENTS: &[(&str, i32)] = &[
    ("NONE", 0),
    ("CORREL", 2),
    ("TTEST", 3),
    ("FTEST", 4),
    ("ZSCORE", 5),
    ("CHISQ", 6),
    ("BETA", 7),
    ("BINOM", 8),
    ("GAMMA", 9),
    ("POISSON", 10),
    ("NORMAL", 11),
    ("FTEST_NONC", 12),
    ("CHISQ_NONC", 13),
    ("LOGISTIC", 14),
    ("LAPLACE", 15),
    ("UNIFORM", 16),
    ("TTEST_NONC", 17),
    ("WEIBULL", 18),
    ("CHI", 19),
    ("INVGAUSS", 20),
    ("EXTVAL", 21),
    ("PVAL", 22),
    ("LOGPVAL", 23),
    ("LOG10PVAL", 24),
    ("ESTIMATE", 1001),
    ("LABEL", 1002),
    ("NEURONAME", 1003),
    ("GENMATRIX", 1004),
    ("SYMMATRIX", 1005),
    ("DISPVECT", 1006),
    ("VECTOR", 1007),
    ("POINTSET", 1008),
    ("TRIANGLE", 1009),
    ("QUATERNION", 1010),
    ("DIMLESS", 1011),
    ("TIME_SERIES", 2001),
    ("NODE_INDEX", 2002),
    ("RGB_VECTOR", 2003),
    ("RGBA_VECTOR", 2004),
    ("SHAPE", 2005),
];

/// The name of an intent code (`NIFTI_INTENT_POINTSET`), or its number.
pub fn intent_name(code: i32) -> String {
    match INTENTS.iter().find(|(_, c)| *c == code) {
        Some((n, _)) => format!("NIFTI_INTENT_{n}"),
        None => code.to_string(),
    }
}

fn parse_intent(s: &str) -> Option<i32> {
    let s = s.trim();
    if let Ok(code) = s.parse::<i32>() {
        return Some(code);
    }
    let n = s.strip_prefix("NIFTI_INTENT_").unwrap_or(s);
    INTENTS.iter().find(|(name, _)| name.eq_ignore_ascii_case(n)).map(|(_, c)| *c)
}

/// The element types of a data array (NIfTI's names).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum DataType {
    /// `NIFTI_TYPE_UINT8`
    U8,
    /// `NIFTI_TYPE_INT8`
    I8,
    /// `NIFTI_TYPE_INT16`
    I16,
    /// `NIFTI_TYPE_UINT16`
    U16,
    /// `NIFTI_TYPE_INT32`
    I32,
    /// `NIFTI_TYPE_UINT32`
    U32,
    /// `NIFTI_TYPE_INT64`
    I64,
    /// `NIFTI_TYPE_UINT64`
    U64,
    /// `NIFTI_TYPE_FLOAT32`
    F32,
    /// `NIFTI_TYPE_FLOAT64`
    F64,
}

const TYPES: &[(DataType, &str, i32, usize)] = &[
    (DataType::U8, "UINT8", 2, 1),
    (DataType::I16, "INT16", 4, 2),
    (DataType::I32, "INT32", 8, 4),
    (DataType::F32, "FLOAT32", 16, 4),
    (DataType::F64, "FLOAT64", 64, 8),
    (DataType::I8, "INT8", 256, 1),
    (DataType::U16, "UINT16", 512, 2),
    (DataType::U32, "UINT32", 768, 4),
    (DataType::I64, "INT64", 1024, 8),
    (DataType::U64, "UINT64", 1280, 8),
];

impl DataType {
    fn entry(self) -> &'static (DataType, &'static str, i32, usize) {
        TYPES.iter().find(|t| t.0 == self).expect("every type is in the table")
    }

    /// The NIfTI name, `NIFTI_TYPE_FLOAT32` …
    pub fn name(self) -> String {
        format!("NIFTI_TYPE_{}", self.entry().1)
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        self.entry().3
    }

    fn parse(s: &str) -> Option<DataType> {
        let s = s.trim();
        let n = s.strip_prefix("NIFTI_TYPE_").unwrap_or(s);
        TYPES.iter().find(|t| t.1.eq_ignore_ascii_case(n) || s.parse() == Ok(t.2)).map(|t| t.0)
    }

    /// Whether `x` is a value of this type (any number for the floats).
    fn holds(self, x: f64) -> bool {
        let (lo, hi) = match self {
            DataType::F32 | DataType::F64 => return true,
            DataType::U8 => (0.0, f64::from(u8::MAX)),
            DataType::I8 => (f64::from(i8::MIN), f64::from(i8::MAX)),
            DataType::I16 => (f64::from(i16::MIN), f64::from(i16::MAX)),
            DataType::U16 => (0.0, f64::from(u16::MAX)),
            DataType::I32 => (f64::from(i32::MIN), f64::from(i32::MAX)),
            DataType::U32 => (0.0, f64::from(u32::MAX)),
            DataType::I64 => (-9.223_372_036_854_776e18, 9.223_372_036_854_776e18),
            DataType::U64 => (0.0, 1.844_674_407_370_955_2e19),
        };
        x.fract() == 0.0 && (lo..=hi).contains(&x)
    }

    /// The type of a NIfTI `datatype` code (`16` is `FLOAT32`).
    pub(crate) fn from_code(code: i32) -> Option<DataType> {
        TYPES.iter().find(|t| t.2 == code).map(|t| t.0)
    }

    pub(crate) fn is_integer(self) -> bool {
        !matches!(self, DataType::F32 | DataType::F64)
    }

    pub(crate) fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty) => {{
                let a = b.try_into().expect("chunks have the type's size");
                (if big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        match self {
            DataType::U8 => num!(u8),
            DataType::I8 => num!(i8),
            DataType::I16 => num!(i16),
            DataType::U16 => num!(u16),
            DataType::I32 => num!(i32),
            DataType::U32 => num!(u32),
            DataType::I64 => num!(i64),
            DataType::U64 => num!(u64),
            DataType::F32 => num!(f32),
            DataType::F64 => num!(f64),
        }
    }

    pub(crate) fn encode(self, v: f64, big: bool, out: &mut Vec<u8>) {
        macro_rules! num {
            ($t:ty) => {{
                let x = v as $t;
                out.extend_from_slice(&if big { x.to_be_bytes() } else { x.to_le_bytes() });
            }};
        }
        match self {
            DataType::U8 => num!(u8),
            DataType::I8 => num!(i8),
            DataType::I16 => num!(i16),
            DataType::U16 => num!(u16),
            DataType::I32 => num!(i32),
            DataType::U32 => num!(u32),
            DataType::I64 => num!(i64),
            DataType::U64 => num!(u64),
            DataType::F32 => num!(f32),
            DataType::F64 => num!(f64),
        }
    }
}

/// How a data array's values are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GiftiEncoding {
    /// Numbers as text.
    Ascii,
    /// Raw bytes in base64.
    Base64,
    /// zlib-compressed bytes in base64 (`GZipBase64Binary`; nibabel's default).
    #[default]
    GzipBase64,
}

impl GiftiEncoding {
    fn name(self) -> &'static str {
        match self {
            GiftiEncoding::Ascii => "ASCII",
            GiftiEncoding::Base64 => "Base64Binary",
            GiftiEncoding::GzipBase64 => "GZipBase64Binary",
        }
    }
}

/// Options of the writer: the encoding, the byte order of binary data and
/// the index order of 2-D arrays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriteOptions {
    /// The encoding of every array.
    pub encoding: GiftiEncoding,
    /// Big-endian binary data (little endian otherwise).
    pub big_endian: bool,
    /// Column-major arrays (row-major otherwise).
    pub column_major: bool,
}

/// One data array.
#[derive(Clone, Debug, PartialEq)]
pub struct DataArray {
    /// The NIfTI intent code ([`intent`]).
    pub intent: i32,
    /// The element type in the file.
    pub data_type: DataType,
    /// The dimensions (`Dim0`, `Dim1`, …).
    pub dims: Vec<usize>,
    /// The values in row-major order (converted if the file was column
    /// major), as `f64`.
    pub values: Vec<f64>,
    /// The array's metadata, in file order.
    pub meta: Vec<(String, String)>,
}

impl DataArray {
    /// The array's `Name` metadata, if any.
    pub fn name(&self) -> Option<&str> {
        self.meta.iter().find(|(k, _)| k == "Name").map(|(_, v)| v.as_str())
    }

    /// Whether the array holds one value per vertex of an `n`-vertex mesh
    /// (dimensions `[n]` or `[n, 1]`) and is not geometry.
    fn per_vertex(&self, n: Option<usize>) -> bool {
        let len = match self.dims[..] {
            [a] | [a, 1] => a,
            _ => return false,
        };
        self.intent != intent::POINTSET && self.intent != intent::TRIANGLE && n.is_none_or(|n| n == len)
    }

    fn label(&self, k: usize) -> String {
        match self.name() {
            Some(n) => n.to_string(),
            None => format!("array {k} ({})", intent_name(self.intent)),
        }
    }
}

/// A parsed GIfTI file: its data arrays in file order, and its label
/// table (the names of a label array's keys).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gifti {
    /// The data arrays.
    pub arrays: Vec<DataArray>,
    /// The `LabelTable`'s labels, in file order.
    pub labels: Vec<Region>,
}

/// A `Label` of the label table: its key and colour (its name is the
/// element's text).
fn label_attributes(e: &quick_xml::events::BytesStart) -> Result<Region, ParseErrorKind> {
    let mut r = Region { key: 0, name: String::new(), rgba: [0.0; 4] };
    let mut key = None;
    for a in e.attributes() {
        let a = a.map_err(|e| bad("a well-formed attribute", &e.to_string()))?;
        let value = a
            .normalized_value(quick_xml::XmlVersion::Implicit1_0)
            .map_err(|e| bad("a well-formed attribute value", &e.to_string()))?;
        let v = value.trim();
        let colour =
            || v.parse::<f64>().ok().filter(|c| (0.0..=1.0).contains(c)).ok_or_else(|| bad("a colour in [0, 1]", v));
        match a.key.as_ref() {
            "Key" | "Index" => key = Some(v.parse::<i32>().map_err(|_| bad("a label key (a whole number)", v))?),
            "Red" => r.rgba[0] = colour()?,
            "Green" => r.rgba[1] = colour()?,
            "Blue" => r.rgba[2] = colour()?,
            "Alpha" => r.rgba[3] = colour()?,
            _ => {}
        }
    }
    r.key = key.ok_or(ParseErrorKind::Missing { what: "the Label's Key" })?;
    Ok(r)
}

/// The parcellation of a label file (`.label.gii`): its one
/// `NIFTI_INTENT_LABEL` array, whose values are keys of the label table.
pub fn parcellation(g: &Gifti) -> Result<Parcellation, ParseError> {
    let at = Location::Line(1);
    let arrays: Vec<&DataArray> = g.arrays.iter().filter(|a| a.intent == intent::LABEL).collect();
    let a = match arrays[..] {
        [a] => a,
        [] => return Err(ParseError { at, kind: ParseErrorKind::Missing { what: "a NIFTI_INTENT_LABEL array" } }),
        _ => {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::Unsupported {
                    what: "label file with several label arrays (fshape reads one)",
                    found: arrays.len().to_string(),
                },
            });
        }
    };
    if !a.per_vertex(None) || !a.data_type.is_integer() {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::BadToken {
                expected: "a label array of one integer per vertex",
                found: format!("{:?} of {}", a.dims, a.data_type.name()),
            },
        });
    }
    // Integer arrays hold whole numbers of their type; keys are 32-bit.
    let keys = a
        .values
        .iter()
        .map(|&v| {
            i32::try_from(v as i64).map_err(|_| ParseError { at, kind: bad("a 32-bit label key", &v.to_string()) })
        })
        .collect::<Result<_, _>>()?;
    Ok(Parcellation { keys, regions: g.labels.clone() })
}

/// An error at byte `offset` of the XML, reported by its line.
fn err_at(data: &[u8], offset: usize, kind: ParseErrorKind) -> ParseError {
    let line = 1 + data[..offset.min(data.len())].iter().filter(|&&b| b == b'\n').count();
    ParseError { at: Location::Line(line), kind }
}

/// The attributes of a `DataArray` as read, before its data.
#[derive(Default)]
struct Header {
    intent: Option<i32>,
    data_type: Option<DataType>,
    dims: Vec<usize>,
    column_major: bool,
    encoding: Option<String>,
    big_endian: bool,
    meta: Vec<(String, String)>,
    start: usize,
    /// `ExternalFileName` (empty when none) and `ExternalFileOffset`.
    external: (String, u64),
}

fn bad(expected: &'static str, found: &str) -> ParseErrorKind {
    ParseErrorKind::BadToken { expected, found: super::cursor::lossy(found.as_bytes()) }
}

fn header(e: &quick_xml::events::BytesStart, start: usize) -> Result<Header, ParseErrorKind> {
    let mut h = Header { start, ..Header::default() };
    let mut dimensionality = None;
    let mut dims: Vec<Option<usize>> = vec![None; 6];
    for a in e.attributes() {
        let a = a.map_err(|e| bad("a well-formed attribute", &e.to_string()))?;
        let value = a
            .normalized_value(quick_xml::XmlVersion::Implicit1_0)
            .map_err(|e| bad("a well-formed attribute value", &e.to_string()))?;
        let v = value.trim();
        match a.key.as_ref() {
            "Intent" => h.intent = Some(parse_intent(v).ok_or_else(|| bad("a NIfTI intent name or code", v))?),
            "DataType" => h.data_type = Some(DataType::parse(v).ok_or_else(|| bad("a NIfTI data type", v))?),
            "ArrayIndexingOrder" => {
                h.column_major = match v {
                    "RowMajorOrder" => false,
                    "ColumnMajorOrder" => true,
                    _ => return Err(bad("RowMajorOrder or ColumnMajorOrder", v)),
                }
            }
            "Dimensionality" => {
                dimensionality =
                    Some(v.parse::<usize>().ok().filter(|d| (1..=6).contains(d)).ok_or_else(|| bad("1 to 6", v))?)
            }
            // The standard's names, and the GIFTI_ENCODING_* and short
            // names nibabel also reads and some writers use.
            "Encoding" => {
                h.encoding = Some(
                    match v {
                        "GIFTI_ENCODING_ASCII" => "ASCII",
                        "B64BIN" | "GIFTI_ENCODING_B64BIN" => "Base64Binary",
                        "B64GZ" | "GIFTI_ENCODING_B64GZ" => "GZipBase64Binary",
                        "External" | "GIFTI_ENCODING_EXTBIN" => "ExternalFileBinary",
                        other => other,
                    }
                    .to_string(),
                )
            }
            "Endian" => {
                // The GIfTI standard's names, and the GIFTI_ENDIAN_* ones
                // of some writers (nibabel reads both).
                h.big_endian = match v {
                    "BigEndian" | "GIFTI_ENDIAN_BIG" => true,
                    "LittleEndian" | "GIFTI_ENDIAN_LITTLE" => false,
                    _ => return Err(bad("BigEndian or LittleEndian", v)),
                }
            }
            "ExternalFileName" => h.external.0 = v.to_string(),
            "ExternalFileOffset" => {
                h.external.1 = if v.is_empty() { 0 } else { v.parse().map_err(|_| bad("a byte offset", v))? }
            }
            k if k.len() == 4 && k.starts_with("Dim") && (b'0'..=b'5').contains(&k.as_bytes()[3]) => {
                dims[usize::from(k.as_bytes()[3] - b'0')] =
                    Some(v.parse().map_err(|_| bad("a dimension (a count)", v))?);
            }
            _ => {}
        }
    }
    let d = dimensionality.ok_or(ParseErrorKind::Missing { what: "the DataArray's Dimensionality" })?;
    h.dims = dims[..d]
        .iter()
        .map(|x| x.ok_or(ParseErrorKind::Missing { what: "a Dim attribute below the Dimensionality" }))
        .collect::<Result<_, _>>()?;
    if h.intent.is_none() {
        return Err(ParseErrorKind::Missing { what: "the DataArray's Intent" });
    }
    if h.data_type.is_none() {
        return Err(ParseErrorKind::Missing { what: "the DataArray's DataType" });
    }
    Ok(h)
}

/// Decodes a `Data` element's text (or the external file's bytes, found
/// in `folder`) into row-major values.
fn decode(h: &Header, text: &str, folder: Option<&Path>) -> Result<Vec<f64>, ParseErrorKind> {
    let data_type = h.data_type.expect("checked in header()");
    let n = h.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).ok_or(ParseErrorKind::BadToken {
        expected: "dimensions whose product fits in memory",
        found: format!("{:?}", h.dims),
    })?;
    super::source::check_values(n as u64, "values in a data array")?;
    let encoding = h.encoding.as_deref().ok_or(ParseErrorKind::Missing { what: "the DataArray's Encoding" })?;
    let mismatch = |found: usize| ParseErrorKind::CountMismatch {
        what: "values in the Data element against the product of the Dim attributes",
        expected: n as u64,
        found: found as u64,
    };
    let values = match encoding {
        "ASCII" => {
            let mut v = Vec::new();
            for t in text.split_ascii_whitespace() {
                if v.len() == n {
                    return Err(mismatch(n + 1 + text.split_ascii_whitespace().skip(n + 1).count()));
                }
                let x = t.parse::<f64>().map_err(|_| bad("a number", t))?;
                // The array's type holds the value: "0.1" in a FLOAT32 array
                // is 0.1f32, and an integer array holds integers in its range.
                if !data_type.holds(x) {
                    return Err(bad("a whole number within the array's integer type", t));
                }
                v.push(if data_type == DataType::F32 { f64::from(x as f32) } else { x });
            }
            if v.len() != n {
                return Err(mismatch(v.len()));
            }
            v
        }
        "Base64Binary" | "GZipBase64Binary" => {
            let compact: Vec<u8> = text.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
            let raw = base64::engine::general_purpose::STANDARD
                .decode(&compact)
                .map_err(|e| ParseErrorKind::BadToken { expected: "base64 data", found: e.to_string() })?;
            let want = n.checked_mul(data_type.size()).ok_or(mismatch(0))?;
            let bytes = if encoding == "GZipBase64Binary" {
                let mut out = Vec::new();
                // zlib, as the format says; gzip streams (some writers' error) too.
                let limit = want as u64 + 1;
                let r = if raw.starts_with(&[0x1f, 0x8b]) {
                    flate2::read::GzDecoder::new(&raw[..]).take(limit).read_to_end(&mut out)
                } else {
                    flate2::read::ZlibDecoder::new(&raw[..]).take(limit).read_to_end(&mut out)
                };
                r.map_err(|e| ParseErrorKind::BadToken {
                    expected: "zlib-compressed data (GZipBase64Binary)",
                    found: e.to_string(),
                })?;
                out
            } else {
                raw
            };
            if bytes.len() != want {
                return Err(ParseErrorKind::CountMismatch {
                    what: "bytes of data against the Dim attributes times the type's size",
                    expected: want as u64,
                    found: bytes.len() as u64,
                });
            }
            bytes.chunks_exact(data_type.size()).map(|c| data_type.decode(c, h.big_endian)).collect()
        }
        "ExternalFileBinary" => {
            let want = n.checked_mul(data_type.size()).ok_or(mismatch(0))?;
            let bytes = external(h, folder, want)?;
            bytes.chunks_exact(data_type.size()).map(|c| data_type.decode(c, h.big_endian)).collect()
        }
        _ => return Err(ParseErrorKind::Unsupported { what: "GIfTI encoding", found: encoding.into() }),
    };
    Ok(if h.column_major { reorder(&values, &h.dims, true) } else { values })
}

/// The `want` raw bytes of an `ExternalFileBinary` array: from its
/// `ExternalFileName`, relative to `folder` (the .gii's), at its
/// `ExternalFileOffset`, as nibabel reads them.
fn external(h: &Header, folder: Option<&Path>, want: usize) -> Result<Vec<u8>, ParseErrorKind> {
    let (name, offset) = &h.external;
    if name.is_empty() {
        return Err(ParseErrorKind::Missing { what: "the ExternalFileName of an ExternalFileBinary array" });
    }
    let Some(folder) = folder else {
        return Err(ParseErrorKind::Unsupported {
            what: "external data file without the .gii's folder (read the .gii by its path)",
            found: name.clone(),
        });
    };
    let limits = super::limits();
    let relative = Path::new(name);
    let inside = relative.components().all(|c| matches!(c, std::path::Component::Normal(_)));
    if !inside && !limits.external_data_anywhere {
        return Err(ParseErrorKind::Unsupported {
            what: "external data file outside the .gii's folder (an absolute name or one with `..`; \
                   set FSHAPE_EXTERNAL_DATA_ANYWHERE=1 to allow it)",
            found: name.clone(),
        });
    }
    let path = folder.join(relative);
    let unreadable = |e: std::io::Error| ParseErrorKind::BadToken {
        expected: "a readable external data file",
        found: format!("{}: {e}", path.display()),
    };
    // Checked by its metadata before it is opened: a FIFO would block the
    // open, a device would be read forever.
    let meta = std::fs::metadata(&path).map_err(unreadable)?;
    if !meta.is_file() {
        return Err(unreadable(std::io::Error::other("not a regular file (a device, a FIFO or a folder)")));
    }
    let end = offset.checked_add(want as u64);
    if end.is_none_or(|end| end > meta.len()) {
        return Err(ParseErrorKind::CountMismatch {
            what: "bytes in the external data file from ExternalFileOffset against the Dim attributes times the type's size",
            expected: want as u64,
            found: meta.len().saturating_sub(*offset),
        });
    }
    let mut file = std::fs::File::open(&path).map_err(unreadable)?;
    std::io::Seek::seek(&mut file, std::io::SeekFrom::Start(*offset)).map_err(unreadable)?;
    let mut bytes = Vec::with_capacity(want);
    file.take(want as u64).read_to_end(&mut bytes).map_err(unreadable)?;
    if bytes.len() != want {
        return Err(ParseErrorKind::CountMismatch {
            what: "bytes in the external data file from ExternalFileOffset against the Dim attributes times the type's size",
            expected: want as u64,
            found: bytes.len() as u64,
        });
    }
    Ok(bytes)
}

/// Converts between column-major and row-major order (`to_row` says
/// which way).
fn reorder(values: &[f64], dims: &[usize], to_row: bool) -> Vec<f64> {
    if dims.iter().filter(|&&d| d > 1).count() < 2 {
        return values.to_vec();
    }
    let k = dims.len();
    let mut row_stride = vec![1; k];
    let mut col_stride = vec![1; k];
    for i in (0..k - 1).rev() {
        row_stride[i] = row_stride[i + 1] * dims[i + 1];
    }
    for i in 1..k {
        col_stride[i] = col_stride[i - 1] * dims[i - 1];
    }
    let mut out = vec![0.0; values.len()];
    let mut idx = vec![0usize; k];
    for _ in 0..values.len() {
        let r: usize = idx.iter().zip(&row_stride).map(|(a, b)| a * b).sum();
        let c: usize = idx.iter().zip(&col_stride).map(|(a, b)| a * b).sum();
        if to_row {
            out[r] = values[c];
        } else {
            out[c] = values[r];
        }
        for d in (0..k).rev() {
            idx[d] += 1;
            if idx[d] < dims[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    out
}

/// Parses a GIfTI file whose external data files, if any, are in
/// `folder` (the .gii's). Errors name the line.
pub fn parse_in(data: &[u8], folder: Option<&Path>) -> Result<Gifti, ParseError> {
    let xml = std::str::from_utf8(data).map_err(|e| {
        err_at(data, e.valid_up_to(), ParseErrorKind::BadToken { expected: "UTF-8 text", found: e.to_string() })
    })?;
    let mut reader = quick_xml::Reader::from_str(xml);
    let mut arrays = Vec::new();
    let mut stack: Vec<String> = Vec::new();
    let mut text = String::new();
    let mut current: Option<Header> = None;
    let mut data_text: Option<String> = None;
    let (mut md_name, mut md_value) = (None, None);
    let mut declared = None;
    let mut seen_root = false;
    let mut labels = Vec::new();
    let mut label: Option<Region> = None;
    loop {
        let at = reader.buffer_position() as usize;
        let event = reader
            .read_event()
            .map_err(|e| err_at(data, reader.error_position() as usize, bad("well-formed XML", &e.to_string())))?;
        let at_err = |kind| err_at(data, at, kind);
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let empty = matches!(event, Event::Empty(_));
                let name = e.name().as_ref().to_string();
                text.clear();
                if stack.is_empty() {
                    if name != "GIFTI" {
                        return Err(at_err(bad("the GIFTI root element", &name)));
                    }
                    seen_root = true;
                    for a in e.attributes().flatten() {
                        if a.key.as_ref() == "NumberOfDataArrays" {
                            let v = a.value.trim().to_string();
                            declared = Some(v.parse::<usize>().map_err(|_| at_err(bad("a count", &v)))?);
                        }
                    }
                }
                if name == "Label" && stack.last().is_some_and(|p| p == "LabelTable") {
                    let r = label_attributes(e).map_err(at_err)?;
                    if empty {
                        labels.push(r);
                    } else {
                        label = Some(r);
                    }
                }
                if name == "DataArray" {
                    if current.is_some() {
                        return Err(at_err(bad("no DataArray inside a DataArray", &name)));
                    }
                    current = Some(header(e, at).map_err(at_err)?);
                    data_text = None;
                    if empty {
                        let h = current.take().expect("just set");
                        arrays.push(finish(data, h, None, folder)?);
                    }
                }
                if !empty {
                    stack.push(name);
                }
            }
            Event::Text(t) => text.push_str(&t),
            Event::CData(t) => text.push_str(&t),
            Event::GeneralRef(r) => {
                let c = match &*r {
                    "amp" => Some('&'),
                    "lt" => Some('<'),
                    "gt" => Some('>'),
                    "quot" => Some('"'),
                    "apos" => Some('\''),
                    _ => r.resolve_char_ref().ok().flatten(),
                };
                text.push(c.ok_or_else(|| at_err(bad("a known entity", &r)))?);
            }
            Event::End(e) => {
                let name = e.name().as_ref().to_string();
                stack.pop();
                let in_md = stack.last().is_some_and(|p| p == "MD");
                match name.as_str() {
                    "Name" if in_md => md_name = Some(std::mem::take(&mut text)),
                    "Value" if in_md => md_value = Some(std::mem::take(&mut text)),
                    "MD" => {
                        if let (Some(h), Some(k)) = (current.as_mut(), md_name.take()) {
                            h.meta.push((k.trim().to_string(), md_value.take().unwrap_or_default().trim().to_string()));
                        }
                        md_value = None;
                    }
                    "Data" if current.is_some() => data_text = Some(std::mem::take(&mut text)),
                    "Label" if label.is_some() => {
                        let mut r = label.take().expect("checked");
                        r.name = std::mem::take(&mut text).trim().to_string();
                        labels.push(r);
                    }
                    "DataArray" => {
                        let h = current.take().expect("a DataArray end follows its start");
                        arrays.push(finish(data, h, data_text.take(), folder)?);
                    }
                    _ => {}
                }
                text.clear();
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if !seen_root {
        return Err(err_at(data, data.len(), ParseErrorKind::Missing { what: "the GIFTI root element" }));
    }
    if let Some(d) = declared
        && d != arrays.len()
    {
        return Err(err_at(
            data,
            0,
            ParseErrorKind::CountMismatch {
                what: "data arrays against NumberOfDataArrays",
                expected: d as u64,
                found: arrays.len() as u64,
            },
        ));
    }
    Ok(Gifti { arrays, labels })
}

/// Parses a GIfTI file without external data files. Errors name the line.
pub fn parse(data: &[u8]) -> Result<Gifti, ParseError> {
    parse_in(data, None)
}

fn finish(data: &[u8], h: Header, text: Option<String>, folder: Option<&Path>) -> Result<DataArray, ParseError> {
    let values = decode(&h, text.as_deref().unwrap_or(""), folder).map_err(|k| err_at(data, h.start, k))?;
    Ok(DataArray {
        intent: h.intent.expect("checked in header()"),
        data_type: h.data_type.expect("checked in header()"),
        dims: h.dims,
        values,
        meta: h.meta,
    })
}

/// The mesh of a parsed file: its POINTSET (n × 3) and TRIANGLE (m × 3)
/// arrays, and as signal the per-vertex array whose `Name` is
/// `signal_name`, if one is.
pub(crate) fn to_raw(mut g: Gifti, signal_name: &str) -> Result<RawMesh, ParseError> {
    let at = Location::Line(1);
    let find = |code: i32, what: &'static str| -> Result<usize, ParseError> {
        let mut it = g.arrays.iter().enumerate().filter(|(_, a)| a.intent == code);
        let (k, a) = it.next().ok_or(ParseError { at, kind: ParseErrorKind::Missing { what } })?;
        if it.next().is_some() {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::Unsupported {
                    what: "GIfTI file with several arrays of intent",
                    found: intent_name(code),
                },
            });
        }
        if a.dims.len() != 2 || a.dims[1] != 3 {
            return Err(ParseError {
                at,
                kind: ParseErrorKind::BadToken {
                    expected: "dimensions n × 3",
                    found: format!("{:?} for {}", a.dims, intent_name(code)),
                },
            });
        }
        Ok(k)
    };
    let p = find(intent::POINTSET, "a NIFTI_INTENT_POINTSET array (the vertex coordinates)")?;
    let t = find(intent::TRIANGLE, "a NIFTI_INTENT_TRIANGLE array (the faces)")?;
    let tri = &g.arrays[t];
    if !tri.data_type.is_integer() {
        return Err(ParseError {
            at,
            kind: ParseErrorKind::BadToken {
                expected: "an integer type for the triangles",
                found: tri.data_type.name(),
            },
        });
    }
    let mut cells = Vec::with_capacity(tri.values.len());
    for (k, &v) in tri.values.iter().enumerate() {
        if v < 0.0 {
            return Err(ParseError { at, kind: ParseErrorKind::NegativeIndex { cell: k / 3, value: v as i64 } });
        }
        cells.push(v as usize);
    }
    let n = g.arrays[p].dims[0];
    let scalars: Vec<usize> = (0..g.arrays.len()).filter(|&k| g.arrays[k].per_vertex(Some(n))).collect();
    let labels = scalars.iter().map(|&k| g.arrays[k].label(k)).collect();
    let channels = super::channel_columns(signal_name, |name| {
        scalars.iter().find(|&&k| g.arrays[k].name() == Some(name)).copied()
    });
    let mask = scalars.iter().find(|&&k| g.arrays[k].name() == Some("mask") && signal_name != "mask").copied();
    let mask = mask.map(|k| std::mem::take(&mut g.arrays[k].values));
    // The arrays are ours: move the values out rather than copy them.
    Ok(RawMesh {
        dim: 3,
        cell_size: Some(3),
        points: std::mem::take(&mut g.arrays[p].values),
        cells,
        channels: channels.len(),
        signal: match channels[..] {
            [] => None,
            [one] => Some(std::mem::take(&mut g.arrays[one].values)),
            _ => Some(super::interleave(
                &channels.iter().map(|&k| std::mem::take(&mut g.arrays[k].values)).collect::<Vec<_>>(),
            )),
        },
        mask,
        scalars: labels,
    })
}

/// The one per-vertex array of a data file (`.shape.gii`, `.func.gii`) and
/// its name (`Name` metadata, or `signal`).
pub fn signal(g: &Gifti) -> Result<(String, Vec<f64>), ParseError> {
    signal_named(g, None)
}

/// [`signal`], or with `selector` the per-vertex array of that `Name` or
/// number from 1 among the per-vertex arrays (a file of several maps, as
/// `maps.func.gii:myelin` or `maps.func.gii:2`). Several arrays without a
/// selector are refused, naming them.
pub fn signal_named(g: &Gifti, selector: Option<&str>) -> Result<(String, Vec<f64>), ParseError> {
    let at = Location::Line(1);
    let arrays: Vec<(usize, &DataArray)> = g.arrays.iter().enumerate().filter(|(_, a)| a.per_vertex(None)).collect();
    // Listed as they are chosen: by name, else by number from 1.
    let labels = || {
        arrays
            .iter()
            .enumerate()
            .map(|(i, (_, a))| {
                a.name().map_or_else(|| format!("{} ({})", i + 1, intent_name(a.intent)), str::to_string)
            })
            .collect::<Vec<_>>()
    };
    let named =
        |(_, a): &(usize, &DataArray)| (a.name().unwrap_or(super::DEFAULT_SIGNAL_NAME).to_string(), a.values.clone());
    if let Some(sel) = selector {
        let by_name = arrays.iter().find(|(_, a)| a.name() == Some(sel));
        let by_number = || sel.parse::<usize>().ok().and_then(|k| k.checked_sub(1)).and_then(|k| arrays.get(k));
        return by_name.or_else(by_number).map(named).ok_or_else(|| ParseError {
            at,
            kind: ParseErrorKind::UnknownName {
                what: "per-vertex data array",
                name: sel.to_string(),
                available: labels(),
            },
        });
    }
    match arrays[..] {
        [one] => Ok(named(&one)),
        [] => Err(ParseError { at, kind: ParseErrorKind::Missing { what: "a data array of one value per vertex" } }),
        _ => Err(ParseError {
            at,
            kind: ParseErrorKind::NotChosen {
                what: "data array",
                syntax: "FILE:NAME or FILE:NUMBER (from 1)",
                available: labels(),
            },
        }),
    }
}

/// Writes data arrays as a GIfTI file.
pub fn write_arrays(w: &mut impl Write, arrays: &[DataArray], opts: WriteOptions) -> io::Result<()> {
    write_gifti(w, arrays, &[], opts)
}

/// The label file of a parcellation (`.label.gii`), as Workbench and
/// nibabel write one: its keys as a NIFTI_INTENT_LABEL array (`INT32`)
/// and its regions as the label table, keys kept. Vertices in no region
/// (−1) take the key of the table's `???` region when it has one, else
/// key 0 as a transparent `???` when 0 is free (the convention for
/// unassigned vertices), else the largest key plus one.
pub fn label_file(p: &Parcellation) -> (DataArray, Vec<Region>) {
    let mut regions = p.regions.clone();
    let none = if p.keys.contains(&-1) {
        let key = match regions.iter().find(|r| r.name == "???") {
            Some(r) => r.key,
            None => {
                let key = if regions.iter().any(|r| r.key == 0) {
                    regions.iter().map(|r| r.key).max().unwrap_or(0).saturating_add(1)
                } else {
                    0
                };
                regions.insert(0, Region { key, name: "???".into(), rgba: [0.0; 4] });
                key
            }
        };
        Some(key)
    } else {
        None
    };
    let values = p.keys.iter().map(|&k| f64::from(if k == -1 { none.unwrap_or(k) } else { k })).collect();
    let array = DataArray {
        intent: intent::LABEL,
        data_type: DataType::I32,
        dims: vec![p.keys.len()],
        values,
        meta: Vec::new(),
    };
    (array, regions)
}

/// Writes a parcellation as a GIfTI label file ([`label_file`]).
pub fn write_parcellation(w: &mut impl Write, p: &Parcellation, opts: WriteOptions) -> io::Result<()> {
    let (array, regions) = label_file(p);
    write_gifti(w, &[array], &regions, opts)
}

/// A GIfTI file of these arrays and this label table.
fn write_gifti(w: &mut impl Write, arrays: &[DataArray], labels: &[Region], opts: WriteOptions) -> io::Result<()> {
    let mut s = String::new();
    s.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    s.push_str("<!DOCTYPE GIFTI SYSTEM \"http://www.nitrc.org/frs/download.php/115/gifti.dtd\">\n");
    let _ = writeln!(s, "<GIFTI Version=\"1.0\" NumberOfDataArrays=\"{}\">", arrays.len());
    if labels.is_empty() {
        s.push_str("  <MetaData/>\n  <LabelTable/>\n");
    } else {
        s.push_str("  <MetaData/>\n  <LabelTable>\n");
        for r in labels {
            let [red, green, blue, alpha] = r.rgba;
            let _ = writeln!(
                s,
                "    <Label Key=\"{}\" Red=\"{red}\" Green=\"{green}\" Blue=\"{blue}\" Alpha=\"{alpha}\">{}</Label>",
                r.key,
                quick_xml::escape::escape(r.name.as_str())
            );
        }
        s.push_str("  </LabelTable>\n");
    }
    for a in arrays {
        let order = if opts.column_major { "ColumnMajorOrder" } else { "RowMajorOrder" };
        let endian = if opts.big_endian { "BigEndian" } else { "LittleEndian" };
        let _ = write!(
            s,
            "  <DataArray Intent=\"{}\" DataType=\"{}\" ArrayIndexingOrder=\"{order}\" Dimensionality=\"{}\"",
            intent_name(a.intent),
            a.data_type.name(),
            a.dims.len()
        );
        for (k, d) in a.dims.iter().enumerate() {
            let _ = write!(s, " Dim{k}=\"{d}\"");
        }
        let _ = writeln!(
            s,
            " Encoding=\"{}\" Endian=\"{endian}\" ExternalFileName=\"\" ExternalFileOffset=\"\">",
            opts.encoding.name()
        );
        if a.meta.is_empty() {
            s.push_str("    <MetaData/>\n");
        } else {
            s.push_str("    <MetaData>\n");
            for (k, v) in &a.meta {
                let _ = writeln!(
                    s,
                    "      <MD>\n        <Name>{}</Name>\n        <Value>{}</Value>\n      </MD>",
                    quick_xml::escape::escape(k.as_str()),
                    quick_xml::escape::escape(v.as_str())
                );
            }
            s.push_str("    </MetaData>\n");
        }
        let values = if opts.column_major { reorder(&a.values, &a.dims, false) } else { a.values.clone() };
        s.push_str("    <Data>");
        match opts.encoding {
            GiftiEncoding::Ascii => {
                // Row-major 2-D arrays one row a line, as every writer does;
                // column-major ones on a single line: nibabel reads lines as
                // rows whatever the order, and a flat sequence in the
                // declared order, as the format means.
                let per_line = match a.dims[..] {
                    [_, c] if !opts.column_major => c.max(1),
                    _ if opts.column_major => values.len().max(1),
                    _ => 1,
                };
                for (k, v) in values.iter().enumerate() {
                    s.push_str(if k % per_line == 0 { "\n" } else { " " });
                    if a.data_type == DataType::F32 {
                        let _ = write!(s, "{}", *v as f32);
                    } else if a.data_type.is_integer() {
                        let _ = write!(s, "{}", *v as i64);
                    } else {
                        let _ = write!(s, "{v}");
                    }
                }
                s.push('\n');
            }
            GiftiEncoding::Base64 | GiftiEncoding::GzipBase64 => {
                let mut bytes = Vec::with_capacity(values.len() * a.data_type.size());
                for &v in &values {
                    a.data_type.encode(v, opts.big_endian, &mut bytes);
                }
                if opts.encoding == GiftiEncoding::GzipBase64 {
                    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                    z.write_all(&bytes)?;
                    bytes = z.finish()?;
                }
                s.push_str(&base64::engine::general_purpose::STANDARD.encode(&bytes));
            }
        }
        s.push_str("</Data>\n  </DataArray>\n");
    }
    s.push_str("</GIFTI>\n");
    w.write_all(s.as_bytes())
}

/// The data arrays of a surface: POINTSET (`FLOAT32`), TRIANGLE (`INT32`)
/// and, if the shape has a signal, a SHAPE array (`FLOAT32`) per channel
/// named `signal_name`, `signal_name_2`, … ([`super::channel_name`]).
///
/// # Errors
///
/// `InvalidInput` if the shape is not a triangle surface in 3-D.
pub fn surface_arrays(shape: &FShape, signal_name: &str) -> io::Result<Vec<DataArray>> {
    if shape.kind() != CellKind::Triangle || shape.dim() != 3 {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "GIfTI holds triangle surfaces in 3-D; this shape is not one",
        ));
    }
    let (n, m) = (shape.n_vertices(), shape.n_cells());
    let mut arrays = vec![
        DataArray {
            intent: intent::POINTSET,
            data_type: DataType::F32,
            dims: vec![n, 3],
            values: shape.points().to_vec(),
            meta: Vec::new(),
        },
        DataArray {
            intent: intent::TRIANGLE,
            data_type: DataType::I32,
            dims: vec![m, 3],
            values: shape.cells().iter().map(|&v| v as f64).collect(),
            meta: Vec::new(),
        },
    ];
    for c in 0..shape.n_channels() {
        let f = shape.channel(c).unwrap_or_default();
        arrays.push(signal_array(&super::channel_name(signal_name, c), &f));
    }
    if let Some(m) = shape.mask() {
        arrays.push(signal_array("mask", m));
    }
    Ok(arrays)
}

/// A per-vertex SHAPE array (`FLOAT32`) named `name`.
pub fn signal_array(name: &str, values: &[f64]) -> DataArray {
    DataArray {
        intent: intent::SHAPE,
        data_type: DataType::F32,
        dims: vec![values.len()],
        values: values.to_vec(),
        meta: vec![("Name".into(), name.into())],
    }
}

/// Writes a surface file (`.gii`, optionally `.gz`) with the writer's
/// options, atomically; the signal, if any, is a SHAPE array named
/// `signal` (NaN where masked), and a masked shape's mask one named
/// `mask`.
pub fn write_file(path: &std::path::Path, shape: &FShape, opts: WriteOptions) -> Result<(), super::WriteError> {
    let io = |source| super::WriteError::Io { path: path.into(), source };
    if super::Format::from_path(path).map(|f| f.0) != Some(super::Format::Gifti) {
        return Err(super::WriteError::UnknownFormat { path: path.into() });
    }
    let mut bytes = Vec::new();
    write_arrays(&mut bytes, &surface_arrays(shape, super::DEFAULT_SIGNAL_NAME).map_err(io)?, opts).map_err(io)?;
    let gz = path.extension().is_some_and(|e| e == "gz");
    super::write_atomic(path, &bytes, gz)
}

/// Writes a surface (and its signal as a SHAPE array named `signal`) with
/// `GZipBase64Binary` data for [`Encoding::Binary`](super::Encoding) and
/// `ASCII` otherwise.
pub fn write(w: &mut impl Write, shape: &FShape, encoding: super::Encoding) -> io::Result<()> {
    let encoding = match encoding {
        super::Encoding::Ascii => GiftiEncoding::Ascii,
        super::Encoding::Binary => GiftiEncoding::GzipBase64,
    };
    write_arrays(
        w,
        &surface_arrays(shape, super::DEFAULT_SIGNAL_NAME)?,
        WriteOptions { encoding, ..WriteOptions::default() },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_array(attrs: &str, data: &str) -> String {
        format!(
            "<?xml version=\"1.0\"?>\n<GIFTI Version=\"1.0\">\n<DataArray {attrs} Encoding=\"ASCII\" \
             Endian=\"LittleEndian\"><Data>{data}</Data></DataArray>\n</GIFTI>\n"
        )
    }

    #[test]
    fn intents_and_types_are_read_by_name_or_number() {
        let g = parse(
            one_array("Intent=\"1008\" DataType=\"16\" Dimensionality=\"2\" Dim0=\"1\" Dim1=\"3\"", "1 2 3").as_bytes(),
        )
        .unwrap();
        assert_eq!((g.arrays[0].intent, g.arrays[0].data_type), (intent::POINTSET, DataType::F32));
        let g = parse(
            one_array(
                "Intent=\"NIFTI_INTENT_SHAPE\" DataType=\"NIFTI_TYPE_UINT8\" Dimensionality=\"1\" Dim0=\"2\"",
                "7 9",
            )
            .as_bytes(),
        )
        .unwrap();
        assert_eq!(
            (g.arrays[0].intent, g.arrays[0].data_type, &g.arrays[0].values[..]),
            (intent::SHAPE, DataType::U8, &[7.0, 9.0][..])
        );
        assert_eq!(intent_name(2005), "NIFTI_INTENT_SHAPE");
        assert_eq!(intent_name(4242), "4242");
    }

    #[test]
    fn column_major_arrays_become_row_major() {
        // A 2 × 3 array [[1, 2, 3], [4, 5, 6]] stored column by column.
        let g = parse(
            one_array(
                "Intent=\"NIFTI_INTENT_NONE\" DataType=\"NIFTI_TYPE_FLOAT32\" ArrayIndexingOrder=\"ColumnMajorOrder\" \
                 Dimensionality=\"2\" Dim0=\"2\" Dim1=\"3\"",
                "1 4 2 5 3 6",
            )
            .as_bytes(),
        )
        .unwrap();
        assert_eq!(g.arrays[0].values, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        // Three dimensions (2 × 2 × 2): element (i, j, k) is at i + 2j + 4k in column order.
        let cm: Vec<f64> = (0..8).map(f64::from).collect();
        let rm = reorder(&cm, &[2, 2, 2], true);
        for (i, j, k) in (0..8).map(|r| (r / 4, (r / 2) % 2, r % 2)) {
            assert_eq!(rm[4 * i + 2 * j + k], (i + 2 * j + 4 * k) as f64);
        }
        assert_eq!(reorder(&rm, &[2, 2, 2], false), cm);
    }

    #[test]
    fn decompression_stops_at_the_size_the_dimensions_call_for() {
        // 1 MB of zeros compresses to about a kilobyte; Dim0 = 4 float32s
        // wants 16 bytes: the reader stops at 17 and reports the mismatch
        // instead of inflating the rest.
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        z.write_all(&vec![0u8; 1 << 20]).unwrap();
        let data = base64::engine::general_purpose::STANDARD.encode(z.finish().unwrap());
        let xml = one_array(
            "Intent=\"NIFTI_INTENT_SHAPE\" DataType=\"NIFTI_TYPE_FLOAT32\" Dimensionality=\"1\" Dim0=\"4\"",
            &data,
        )
        .replace("Encoding=\"ASCII\"", "Encoding=\"GZipBase64Binary\"");
        let e = parse(xml.as_bytes()).unwrap_err();
        assert_eq!(
            e.kind,
            ParseErrorKind::CountMismatch {
                what: "bytes of data against the Dim attributes times the type's size",
                expected: 16,
                found: 17
            }
        );
    }

    #[test]
    fn a_dimension_product_that_overflows_is_an_error() {
        let xml = one_array(
            "Intent=\"NIFTI_INTENT_SHAPE\" DataType=\"NIFTI_TYPE_FLOAT32\" Dimensionality=\"2\" \
             Dim0=\"18446744073709551615\" Dim1=\"2\"",
            "1",
        );
        let e = parse(xml.as_bytes()).unwrap_err();
        assert!(e.to_string().contains("dimensions whose product fits in memory"), "{e}");
    }
}
