//! CIFTI-2 dense files (`.dscalar.nii`, HCP's file for maps; also
//! `.dtseries.nii`), after the CIFTI-2 standard (2014) and nibabel's
//! `cifti2` module.
//!
//! A CIFTI-2 file is a NIfTI-2 header (540 bytes), an extension of code 32
//! holding the CIFTI XML, and a matrix whose one dimension runs over
//! *brain models* (the vertices of a surface structure such as
//! `CORTEX_LEFT`, usually without its medial wall, and voxels of
//! subcortical structures) and whose other runs over maps (a dscalar's
//! named maps, a dtseries' time points). The matrix is stored as NIfTI
//! stores arrays, first index fastest: element (i, j) of CIFTI dimensions
//! 0 and 1 is at `i + j × len₀`.
//!
//! fshape reads one map of one surface structure and expands it to the
//! whole surface, NaN at the vertices the structure leaves out
//! ([`Cifti::surface`]); reads a dense label file's (`.dlabel.nii`, HCP's
//! file for parcellations: a label table per map, the keys stored as
//! numbers) map of a structure as a parcellation ([`Cifti::parcellation`]);
//! and writes a map of a structure back into a copy
//! of the file, every other byte (other structures, other maps, the header
//! and the XML) kept ([`Cifti::with_surface`]). Values come out of the
//! file's type as `f64`, scaled by `scl_slope`/`scl_inter` when set.

use std::ops::Range;

use quick_xml::events::Event;

use super::gifti::DataType;
use super::parcellation::{Parcellation, Region};
use super::{Location, ParseError, ParseErrorKind};

/// The NIfTI-2 header's size, which its first four bytes hold.
const HEADER: usize = 540;
/// The extension code of CIFTI's XML.
const CIFTI_EXTENSION: i32 = 32;

/// Whether data begins with a NIfTI-2 header (either byte order).
pub fn is_nifti2(data: &[u8]) -> bool {
    data.starts_with(&540i32.to_le_bytes()) || data.starts_with(&540i32.to_be_bytes())
}

/// A surface structure's brain model.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BrainModel {
    /// The structure, without the `CIFTI_STRUCTURE_` prefix (`CORTEX_LEFT`).
    pub structure: String,
    /// Its first row along the brain-model dimension.
    pub offset: usize,
    /// Its vertex count in the file.
    pub count: usize,
    /// The surface's vertex count (`SurfaceNumberOfVertices`); `None` for
    /// a voxel model.
    pub surface_vertices: Option<usize>,
    /// The surface vertex of each row (empty for a voxel model).
    pub vertices: Vec<usize>,
}

/// A parsed CIFTI-2 dense file. It keeps the file's bytes, for reading a
/// map on demand and for writing one back.
#[derive(Clone, Debug)]
pub struct Cifti {
    /// The names of the maps (a dscalar's `MapName`s; a series' points
    /// numbered from 1).
    pub maps: Vec<String>,
    /// The brain models, in file order.
    pub models: Vec<BrainModel>,
    /// A label file's tables, one per map (`None`: a file of values).
    pub labels: Option<Vec<Vec<Region>>>,
    bytes: Vec<u8>,
    big_endian: bool,
    data_type: DataType,
    /// Where the matrix's values are.
    data: Range<usize>,
    /// Lengths of CIFTI dimensions 0 and 1.
    lens: [usize; 2],
    /// Which CIFTI dimension runs over brain models.
    brain_dim: usize,
    scale: (f64, f64),
}

fn err(at: usize, kind: ParseErrorKind) -> ParseError {
    ParseError { at: Location::Byte(at), kind }
}

fn bad(expected: &'static str, found: impl ToString) -> ParseErrorKind {
    ParseErrorKind::BadToken { expected, found: found.to_string() }
}

impl Cifti {
    /// Parses a CIFTI-2 file. Errors name the byte (the XML's errors, the
    /// byte where the XML starts, with what the XML holds wrong).
    pub fn parse(bytes: Vec<u8>) -> Result<Cifti, ParseError> {
        if bytes.len() < HEADER + 4 {
            return Err(err(bytes.len(), ParseErrorKind::Eof { expected: "a NIfTI-2 header and extension flag" }));
        }
        let big_endian = if bytes.starts_with(&540i32.to_le_bytes()) {
            false
        } else if bytes.starts_with(&540i32.to_be_bytes()) {
            true
        } else if bytes.starts_with(&348i32.to_le_bytes()) || bytes.starts_with(&348i32.to_be_bytes()) {
            return Err(err(
                0,
                ParseErrorKind::Unsupported { what: "NIfTI-1 file (CIFTI-2 is NIfTI-2)", found: "348".into() },
            ));
        } else {
            return Err(err(0, bad("a NIfTI-2 header (its size, 540)", format!("{:02x?}", &bytes[..4]))));
        };
        let b = &bytes;
        let arr = |at: usize| -> [u8; 8] { b[at..at + 8].try_into().expect("8 bytes") };
        let i64_at = |at: usize| if big_endian { i64::from_be_bytes(arr(at)) } else { i64::from_le_bytes(arr(at)) };
        let f64_at = |at: usize| if big_endian { f64::from_be_bytes(arr(at)) } else { f64::from_le_bytes(arr(at)) };
        let i32_at = |at: usize| {
            let a = b[at..at + 4].try_into().expect("4 bytes");
            if big_endian { i32::from_be_bytes(a) } else { i32::from_le_bytes(a) }
        };
        if &b[4..8] != b"n+2\0" {
            return Err(err(4, bad("the NIfTI-2 single-file magic n+2", super::cursor::lossy(&b[4..8]))));
        }
        let code =
            i32::from(if big_endian { i16::from_be_bytes([b[12], b[13]]) } else { i16::from_le_bytes([b[12], b[13]]) });
        let data_type = DataType::from_code(code)
            .ok_or_else(|| err(12, ParseErrorKind::Unsupported { what: "NIfTI data type", found: code.to_string() }))?;
        let dims: Vec<i64> = (0..8).map(|k| i64_at(16 + 8 * k)).collect();
        if dims[0] != 6 || dims[1..5].iter().any(|&d| d != 1) {
            return Err(err(16, bad("CIFTI dimensions (6 dimensions, the first four 1)", format!("{dims:?}"))));
        }
        let len = |k: usize| {
            usize::try_from(dims[k])
                .ok()
                .filter(|&d| d > 0)
                .ok_or_else(|| err(16 + 8 * k, bad("a positive matrix dimension", dims[k])))
        };
        let lens = [len(5)?, len(6)?];
        let vox_offset = usize::try_from(i64_at(168)).map_err(|_| err(168, bad("a data offset", i64_at(168))))?;
        let (slope, inter) = (f64_at(176), f64_at(184));
        let scale = if slope == 0.0 || !slope.is_finite() || !inter.is_finite() { (1.0, 0.0) } else { (slope, inter) };
        // The extensions: a flag, then (size, code, content) records.
        if b[HEADER] == 0 {
            return Err(err(HEADER, ParseErrorKind::Missing { what: "the CIFTI extension (the header has none)" }));
        }
        let mut at = HEADER + 4;
        let xml = loop {
            if at + 8 > vox_offset.min(b.len()) {
                return Err(err(at, ParseErrorKind::Missing { what: "a CIFTI extension (code 32) before the data" }));
            }
            let (size, code) = (i32_at(at), i32_at(at + 4));
            let size = usize::try_from(size)
                .ok()
                .filter(|&s| s >= 8 && at + s <= b.len())
                .ok_or_else(|| err(at, bad("an extension size within the file", size)))?;
            if code == CIFTI_EXTENSION {
                break at + 8..at + size;
            }
            at += size;
        };
        let xml_start = xml.start;
        let Parsed { maps, models, brain_dim, labels } =
            parse_xml(&b[xml], lens).map_err(|kind| err(xml_start, kind))?;
        let n = lens[0].checked_mul(lens[1]).ok_or_else(|| err(16, bad("a matrix that fits in memory", "")))?;
        super::source::check_values(n as u64, "matrix values").map_err(|k| err(16, k))?;
        let want = n.saturating_mul(data_type.size());
        if vox_offset > b.len() || b.len() - vox_offset < want {
            return Err(err(
                168,
                ParseErrorKind::Truncated {
                    what: "matrix values",
                    claimed: n as u64,
                    available: b.len().saturating_sub(vox_offset),
                },
            ));
        }
        Ok(Cifti {
            maps,
            models,
            labels,
            big_endian,
            data_type,
            data: vox_offset..vox_offset + want,
            lens,
            brain_dim,
            scale,
            bytes,
        })
    }

    /// The file's size in bytes.
    pub fn size(&self) -> usize {
        self.bytes.len()
    }

    /// The surface structure named `structure` (`CORTEX_LEFT`, with or
    /// without the `CIFTI_STRUCTURE_` prefix).
    pub fn model(&self, structure: &str) -> Result<&BrainModel, ParseErrorKind> {
        let name = structure.strip_prefix("CIFTI_STRUCTURE_").unwrap_or(structure);
        self.models.iter().find(|m| m.structure == name && m.surface_vertices.is_some()).ok_or_else(|| {
            ParseErrorKind::UnknownName {
                what: "surface structure",
                name: name.to_string(),
                available: self
                    .models
                    .iter()
                    .filter(|m| m.surface_vertices.is_some())
                    .map(|m| m.structure.clone())
                    .collect(),
            }
        })
    }

    /// The map named `map` (a name, or its number counting from 1 as
    /// Workbench's `-column` does); `None` when the file has one map.
    pub fn map_index(&self, map: Option<&str>) -> Result<usize, ParseErrorKind> {
        let unknown = |name: &str| ParseErrorKind::UnknownName {
            what: "map",
            name: name.to_string(),
            available: self.maps.clone(),
        };
        match map {
            None if self.maps.len() == 1 => Ok(0),
            None => Err(ParseErrorKind::NotChosen {
                what: "map (the file has several)",
                syntax: "FILE:STRUCTURE:MAP, MAP a name or a number from 1",
                available: self.maps.clone(),
            }),
            Some(m) => self
                .maps
                .iter()
                .position(|n| n == m)
                .or_else(|| m.parse::<usize>().ok().filter(|&k| (1..=self.maps.len()).contains(&k)).map(|k| k - 1))
                .ok_or_else(|| unknown(m)),
        }
    }

    /// The byte range of element (map, brain-model row).
    fn element(&self, map: usize, row: usize) -> usize {
        let (i, j) = if self.brain_dim == 1 { (map, row) } else { (row, map) };
        self.data.start + (i + j * self.lens[0]) * self.data_type.size()
    }

    /// A map of a surface structure on the whole surface of `n_vertices`
    /// vertices: the file's value at each vertex of the structure, NaN at
    /// the others. A structure of another vertex count is refused (the
    /// map of another surface).
    pub fn surface(&self, structure: &str, map: Option<&str>, n_vertices: usize) -> Result<Vec<f64>, ParseErrorKind> {
        let model = self.model(structure)?;
        let map = self.map_index(map)?;
        self.check_vertices(model, n_vertices)?;
        let mut out = vec![f64::NAN; n_vertices];
        let size = self.data_type.size();
        for (r, &v) in model.vertices.iter().enumerate() {
            let at = self.element(map, model.offset + r);
            let x = self.data_type.decode(&self.bytes[at..at + size], self.big_endian);
            out[v] = x * self.scale.0 + self.scale.1;
        }
        Ok(out)
    }

    /// A label file's map of a surface structure as a parcellation of the
    /// whole surface of `n_vertices` vertices: the file's key at each vertex
    /// of the structure, and at the others (the medial wall) the key of the
    /// map's `???` region (Workbench's unlabelled key, 0 in HCP's files),
    /// or −1 (no region) when its table has none. A key that is not an
    /// integer is refused, naming its vertex.
    pub fn parcellation(
        &self,
        structure: &str,
        map: Option<&str>,
        n_vertices: usize,
    ) -> Result<Parcellation, ParseErrorKind> {
        let Some(tables) = &self.labels else {
            return Err(ParseErrorKind::Unsupported {
                what: "CIFTI file as a parcellation (it holds values, not labels: read it as a map)",
                found: "a dense file without label tables".into(),
            });
        };
        let model = self.model(structure)?;
        let m = self.map_index(map)?;
        self.check_vertices(model, n_vertices)?;
        let regions = tables[m].clone();
        let none = regions.iter().find(|r| r.name == "???").map_or(-1, |r| r.key);
        let mut keys = vec![none; n_vertices];
        let size = self.data_type.size();
        for (r, &v) in model.vertices.iter().enumerate() {
            let at = self.element(m, model.offset + r);
            let x = self.data_type.decode(&self.bytes[at..at + size], self.big_endian) * self.scale.0 + self.scale.1;
            if x.fract() != 0.0 || !(f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(&x) {
                return Err(bad("an integer label key", format!("{x} at vertex {v} of {}", model.structure)));
            }
            keys[v] = x as i32;
        }
        Ok(Parcellation { keys, regions })
    }

    /// A structure of another vertex count than the surface's is refused
    /// (the map of another surface).
    fn check_vertices(&self, model: &BrainModel, n_vertices: usize) -> Result<(), ParseErrorKind> {
        let n = model.surface_vertices.expect("a surface model");
        if n != n_vertices {
            return Err(ParseErrorKind::CountMismatch {
                what: "the structure's SurfaceNumberOfVertices against the surface's vertex count (a map of another surface?)",
                expected: n_vertices as u64,
                found: n as u64,
            });
        }
        Ok(())
    }

    /// The file's bytes with one map of a surface structure replaced by
    /// `values` (one per surface vertex; those off the structure are not
    /// stored): every other byte is the file's. The file must store floats
    /// without scaling.
    pub fn with_surface(&self, structure: &str, map: Option<&str>, values: &[f64]) -> Result<Vec<u8>, ParseErrorKind> {
        let model = self.model(structure)?;
        let map = self.map_index(map)?;
        let n = model.surface_vertices.expect("a surface model");
        if values.len() != n {
            return Err(ParseErrorKind::CountMismatch {
                what: "values against the structure's surface vertices",
                expected: n as u64,
                found: values.len() as u64,
            });
        }
        if !matches!(self.data_type, DataType::F32 | DataType::F64) || self.scale != (1.0, 0.0) {
            return Err(ParseErrorKind::Unsupported {
                what: "CIFTI file to write into (fshape writes into unscaled FLOAT32 or FLOAT64 files)",
                found: format!("{} scaled by {:?}", self.data_type.name(), self.scale),
            });
        }
        let mut out = self.bytes.clone();
        let size = self.data_type.size();
        let mut buf = Vec::with_capacity(size);
        for (r, &v) in model.vertices.iter().enumerate() {
            let at = self.element(map, model.offset + r);
            buf.clear();
            self.data_type.encode(values[v], self.big_endian, &mut buf);
            out[at..at + size].copy_from_slice(&buf);
        }
        Ok(out)
    }
}

/// What the CIFTI XML says.
struct Parsed {
    maps: Vec<String>,
    models: Vec<BrainModel>,
    brain_dim: usize,
    labels: Option<Vec<Vec<Region>>>,
}

/// The map names, the brain models, the brain-model dimension and a label
/// file's tables of the CIFTI XML, checked against the matrix's lengths.
fn parse_xml(xml: &[u8], lens: [usize; 2]) -> Result<Parsed, ParseErrorKind> {
    // The extension is padded with NULs (or spaces) to a multiple of 16.
    let end = xml.iter().rposition(|&c| c != 0).map_or(0, |k| k + 1);
    let xml = std::str::from_utf8(&xml[..end]).map_err(|e| bad("UTF-8 XML", e))?;
    let mut reader = quick_xml::Reader::from_str(xml);
    let mut maps = Vec::new();
    let mut models: Vec<BrainModel> = Vec::new();
    let mut brain_dim = None;
    let mut map_dim = None;
    let mut series = None;
    // A label file's tables (one per NamedMap) and the label being read.
    let mut tables: Vec<Vec<Region>> = Vec::new();
    let mut label: Option<(i32, [f64; 4])> = None;
    let mut in_table = false;
    // The dimension the current MatrixIndicesMap applies to, and its type.
    let mut current: Option<(Vec<usize>, String)> = None;
    let mut text = String::new();
    loop {
        let event = reader.read_event().map_err(|e| bad("well-formed CIFTI XML", e))?;
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let empty = matches!(event, Event::Empty(_));
                let mut attrs = Vec::new();
                for a in e.attributes() {
                    let a = a.map_err(|e| bad("a well-formed attribute", e))?;
                    let v = a
                        .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                        .map_err(|e| bad("a well-formed attribute value", e))?;
                    attrs.push((a.key.as_ref().to_string(), v.trim().to_string()));
                }
                let get = |k: &str| attrs.iter().find(|(n, _)| n == k).map(|(_, v)| v.as_str());
                let count = |k: &'static str| -> Result<usize, ParseErrorKind> {
                    let v = get(k).ok_or(ParseErrorKind::Missing { what: k })?;
                    v.parse().map_err(|_| bad("a count", v))
                };
                text.clear();
                match e.name().as_ref() {
                    "MatrixIndicesMap" => {
                        let dims = get("AppliesToMatrixDimension")
                            .ok_or(ParseErrorKind::Missing { what: "AppliesToMatrixDimension" })?;
                        let dims = dims
                            .split(',')
                            .map(|d| d.trim().parse::<usize>().ok().filter(|&d| d < 2))
                            .collect::<Option<Vec<_>>>()
                            .ok_or_else(|| bad("matrix dimensions 0 or 1", dims))?;
                        let kind = get("IndicesMapToDataType")
                            .ok_or(ParseErrorKind::Missing { what: "IndicesMapToDataType" })?
                            .to_string();
                        if kind == "CIFTI_INDEX_TYPE_SERIES" {
                            series = Some(count("NumberOfSeriesPoints")?);
                        }
                        current = Some((dims, kind));
                    }
                    "LabelTable" => {
                        tables.push(Vec::new());
                        in_table = !empty;
                    }
                    "Label" => {
                        if !in_table {
                            return Err(bad("a Label inside a LabelTable", "elsewhere"));
                        }
                        let key = get("Key").ok_or(ParseErrorKind::Missing { what: "a Label's Key" })?;
                        let key = key.parse::<i32>().map_err(|_| bad("an integer label Key", key))?;
                        let mut rgba = [0.0, 0.0, 0.0, 1.0];
                        for (c, name) in rgba.iter_mut().zip(["Red", "Green", "Blue", "Alpha"]) {
                            if let Some(v) = get(name) {
                                *c = v.parse::<f64>().ok().filter(|c| (0.0..=1.0).contains(c)).ok_or_else(|| {
                                    bad("a colour component in [0, 1]", format!("{name}=\"{v}\" of key {key}"))
                                })?;
                            }
                        }
                        if empty {
                            // <Label Key="3" .../>: a region without a name.
                            tables.last_mut().expect("inside a table").push(Region { key, name: String::new(), rgba });
                        } else {
                            label = Some((key, rgba));
                        }
                    }
                    "BrainModel" => {
                        let structure =
                            get("BrainStructure").ok_or(ParseErrorKind::Missing { what: "BrainStructure" })?;
                        let model_type = get("ModelType").unwrap_or("");
                        let surface = model_type.ends_with("SURFACE");
                        models.push(BrainModel {
                            structure: structure.strip_prefix("CIFTI_STRUCTURE_").unwrap_or(structure).to_string(),
                            offset: count("IndexOffset")?,
                            count: count("IndexCount")?,
                            surface_vertices: if surface { Some(count("SurfaceNumberOfVertices")?) } else { None },
                            vertices: Vec::new(),
                        });
                    }
                    _ => {}
                }
            }
            Event::Text(t) => text.push_str(&t),
            Event::CData(t) => text.push_str(&t),
            Event::GeneralRef(r) => {
                let c = match &*r {
                    "amp" => '&',
                    "lt" => '<',
                    "gt" => '>',
                    "quot" => '"',
                    "apos" => '\'',
                    _ => r.resolve_char_ref().ok().flatten().ok_or_else(|| bad("a known entity", &*r))?,
                };
                text.push(c);
            }
            Event::End(e) => {
                match e.name().as_ref() {
                    "MapName" => maps.push(text.trim().to_string()),
                    "Label" => {
                        let (Some((key, rgba)), Some(table)) = (label.take(), tables.last_mut()) else {
                            return Err(bad("a Label inside a LabelTable", "elsewhere"));
                        };
                        table.push(Region { key, name: text.trim().to_string(), rgba });
                    }
                    "LabelTable" => in_table = false,
                    "VertexIndices" => {
                        let Some(m) = models.last_mut().filter(|m| m.surface_vertices.is_some()) else {
                            return Err(bad("VertexIndices inside a surface BrainModel", "elsewhere"));
                        };
                        let n = m.surface_vertices.expect("a surface");
                        for t in text.split_ascii_whitespace() {
                            let v = t.parse::<usize>().ok().filter(|&v| v < n).ok_or_else(|| {
                                bad("a vertex index below SurfaceNumberOfVertices", format!("{t} in {}", m.structure))
                            })?;
                            if m.vertices.len() == m.count {
                                return Err(ParseErrorKind::CountMismatch {
                                    what: "VertexIndices against IndexCount",
                                    expected: m.count as u64,
                                    found: m.count as u64 + 1,
                                });
                            }
                            m.vertices.push(v);
                        }
                        // Each vertex once (a sorted copy: memory as the list's).
                        let mut sorted = m.vertices.clone();
                        sorted.sort_unstable();
                        if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
                            return Err(bad("each vertex once", format!("vertex {} again in {}", w[0], m.structure)));
                        }
                    }
                    "MatrixIndicesMap" => {
                        let (dims, kind) = current.take().expect("an end follows its start");
                        for d in dims {
                            if kind == "CIFTI_INDEX_TYPE_BRAIN_MODELS" {
                                brain_dim = Some(d);
                            } else {
                                map_dim = Some((d, kind.clone()));
                            }
                        }
                    }
                    _ => {}
                }
                text.clear();
            }
            Event::Eof => break,
            _ => {}
        }
    }
    let brain_dim = brain_dim.ok_or(ParseErrorKind::Missing { what: "a brain-model dimension (a dense file)" })?;
    let other = 1 - brain_dim;
    let mut labels = None;
    match map_dim {
        Some((d, kind)) if d == other => {
            if kind == "CIFTI_INDEX_TYPE_LABELS" {
                if series.is_some() {
                    return Err(ParseErrorKind::Unsupported {
                        what: "CIFTI label file with a series as well",
                        found: "CIFTI_INDEX_TYPE_SERIES".into(),
                    });
                }
                if tables.len() != maps.len() {
                    return Err(ParseErrorKind::CountMismatch {
                        what: "label tables against maps (a NamedMap of a label file has both)",
                        expected: maps.len() as u64,
                        found: tables.len() as u64,
                    });
                }
                labels = Some(tables);
            }
        }
        Some((_, kind)) => {
            return Err(ParseErrorKind::Unsupported {
                what: "CIFTI matrix (both dimensions the same kind?)",
                found: kind,
            });
        }
        None => {
            return Err(ParseErrorKind::Unsupported {
                what: "CIFTI matrix (fshape reads dense files: brain models against maps)",
                found: "brain models on both dimensions".into(),
            });
        }
    }
    if let Some(points) = series {
        maps = (1..=points).map(|k| k.to_string()).collect();
    }
    if maps.len() != lens[other] {
        return Err(ParseErrorKind::CountMismatch {
            what: "maps in the XML against the matrix's dimension",
            expected: lens[other] as u64,
            found: maps.len() as u64,
        });
    }
    let mut rows = 0usize;
    for m in &models {
        if m.surface_vertices.is_some() && m.vertices.len() != m.count {
            return Err(ParseErrorKind::CountMismatch {
                what: "VertexIndices against IndexCount",
                expected: m.count as u64,
                found: m.vertices.len() as u64,
            });
        }
        if m.offset != rows {
            return Err(bad(
                "brain models in order, each starting where the last ended",
                format!("{} at {}", m.structure, m.offset),
            ));
        }
        rows = rows.saturating_add(m.count);
    }
    if rows != lens[brain_dim] {
        return Err(ParseErrorKind::CountMismatch {
            what: "brain model rows against the matrix's dimension",
            expected: lens[brain_dim] as u64,
            found: rows as u64,
        });
    }
    Ok(Parsed { maps, models, brain_dim, labels })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// nibabel's file (tests/data/nibabel): two maps, CORTEX_LEFT (10 of
    /// 12 vertices), CORTEX_RIGHT (11 of 12), two thalamus voxels.
    const MAPS: &[u8] = include_bytes!("../../tests/data/nibabel/maps.dscalar.nii");

    fn edited(from: &str, to: &str) -> Vec<u8> {
        // Same length, so the extension's size and the data offset hold.
        assert_eq!(from.len(), to.len());
        let at = MAPS.windows(from.len()).position(|w| w == from.as_bytes()).expect("the fixture has it");
        let mut b = MAPS.to_vec();
        b[at..at + from.len()].copy_from_slice(to.as_bytes());
        b
    }

    #[test]
    fn damaged_files_are_refused_naming_what_is_wrong() {
        let mut nifti1 = MAPS.to_vec();
        nifti1[..4].copy_from_slice(&348i32.to_le_bytes());
        let mut magic = MAPS.to_vec();
        magic[4..8].copy_from_slice(b"ni2\0");
        let mut no_ext = MAPS.to_vec();
        no_ext[540] = 0;
        for (bytes, says) in [
            (MAPS[..500].to_vec(), "NIfTI-2 header"),
            (nifti1, "NIfTI-1 file"),
            (magic, "n+2"),
            (no_ext, "the CIFTI extension"),
            (MAPS[..MAPS.len() - 4].to_vec(), "claims 46 matrix values"),
            (edited("0 1 2 3 4 6 7 8 9 11", "0 1 2 3 4 6 7 8 9 99"), "99 in CORTEX_LEFT"),
            (edited("0 1 2 3 4 6 7 8 9 11", "0 1 2 3 4 6 7 8 9 9 "), "vertex 9 again in CORTEX_LEFT"),
            (
                edited("0 1 2 3 4 6 7 8 9 11", "0 1 2 3 4 6 7 8 9   "),
                "VertexIndices against IndexCount: expected 10, found 9",
            ),
            (edited("IndexOffset=\"10\"", "IndexOffset=\"11\""), "each starting where the last ended"),
            (edited("<MapName>myelin</MapName>", "<MapNime>myelin</MapNime>"), "maps in the XML"),
        ] {
            let e = Cifti::parse(bytes).unwrap_err().to_string();
            assert!(e.contains(says), "{says}: {e}");
        }
    }

    /// nibabel's label file (tests/data/nibabel): maps `parcels` and
    /// `halves`, each with its table, on CORTEX_LEFT and CORTEX_RIGHT.
    const LABELS: &[u8] = include_bytes!("../../tests/data/nibabel/parcels.dlabel.nii");

    #[test]
    fn damaged_label_files_are_refused_naming_what_is_wrong() {
        let edit = |from: &str, to: &str| {
            assert_eq!(from.len(), to.len());
            let at = LABELS.windows(from.len()).position(|w| w == from.as_bytes()).expect("the fixture has it");
            let mut b = LABELS.to_vec();
            b[at..at + from.len()].copy_from_slice(to.as_bytes());
            b
        };
        for (bytes, says) in [
            (edit("Label Key=\"4\"", "Label Key=\"x\""), "an integer label Key"),
            (edit("Green=\"0.75\"", "Green=\"7.50\""), "Green=\"7.50\" of key 9"),
            (edit("<LabelTable><Label Key=\"0\"", "<LabelTible><Label Key=\"0\""), "a Label inside a LabelTable"),
        ] {
            let e = Cifti::parse(bytes).unwrap_err().to_string();
            assert!(e.contains(says), "{says}: {e}");
        }
        // A self-closing label is a region without a name, not dropped.
        let c = Cifti::parse(edit("Alpha=\"0\">???</Label>", "Alpha=\"0\"/>          ")).unwrap();
        let p = c.parcellation("CORTEX_LEFT", Some("parcels"), 12).unwrap();
        let keys: Vec<(i32, &str)> = p.regions.iter().map(|r| (r.key, r.name.as_str())).collect();
        assert_eq!(keys, [(0, ""), (4, "precentral"), (7, "postcentral"), (9, "insula")]);
        // A key that is no integer, named with its vertex.
        let c = Cifti::parse(LABELS.to_vec()).unwrap();
        let mut bytes = LABELS.to_vec();
        let at = c.element(0, 1);
        bytes[at..at + 4].copy_from_slice(&4.5f32.to_le_bytes());
        let e = Cifti::parse(bytes).unwrap().parcellation("CORTEX_LEFT", Some("parcels"), 12).unwrap_err();
        assert!(e.to_string().contains("4.5 at vertex 1 of CORTEX_LEFT"), "{e}");
    }

    #[test]
    fn values_are_read_from_their_place_in_the_matrix() {
        let c = Cifti::parse(MAPS.to_vec()).unwrap();
        assert_eq!(c.maps, ["thickness", "myelin"]);
        let m: Vec<(&str, usize, usize, Option<usize>)> =
            c.models.iter().map(|m| (m.structure.as_str(), m.offset, m.count, m.surface_vertices)).collect();
        assert_eq!(
            m,
            [("CORTEX_LEFT", 0, 10, Some(12)), ("CORTEX_RIGHT", 10, 11, Some(12)), ("THALAMUS_LEFT", 21, 2, None)]
        );
        // The voxels' values (the last two rows) sit after every surface
        // row, map fastest: 7.5, 9.5, 8.5, 10.5 at the end of the file.
        let tail: Vec<f32> =
            MAPS[MAPS.len() - 16..].chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
        assert_eq!(tail, [7.5, 9.5, 8.5, 10.5]);
        assert!(c.model("THALAMUS_LEFT").is_err(), "a voxel model is no surface");
    }
}
