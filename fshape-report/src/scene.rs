//! What the viewer shows: scenes of meshes (frames under a slider, a
//! companion beside), their arrays packed as base64 of gzip-compressed
//! float32 and uint32, large surfaces simplified for display, and a scene
//! per map of shapes that carry several.

use std::io::Write;

use base64::Engine;
use fshape_mesh::{CellKind, FShape};
use serde::Serialize;

use crate::{ReportError, Result};

/// Vertices above which a surface is simplified for display.
pub const DISPLAY_VERTICES: usize = 40_000;

fn gzip_base64(bytes: &[u8]) -> String {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing to memory cannot fail.
    enc.write_all(bytes).expect("in memory");
    base64::engine::general_purpose::STANDARD.encode(enc.finish().expect("in memory"))
}

fn packed_f32(values: impl Iterator<Item = f64>) -> String {
    let bytes: Vec<u8> = values.flat_map(|v| (v as f32).to_le_bytes()).collect();
    gzip_base64(&bytes)
}

/// One mesh for the viewer: cells, positions (three per vertex) and
/// signals, per frame.
#[derive(Serialize)]
struct MeshData {
    kind: &'static str,
    planar: bool,
    cells: String,
    frames: Vec<String>,
    signals: Option<Vec<String>>,
}

/// What the viewer shows at a time: a mesh whose frames the slider moves
/// through (interpolating between them), and a second mesh beside it or
/// overlaid (the target).
#[derive(Serialize)]
pub struct Scene {
    name: String,
    labels: Vec<String>,
    note: Option<String>,
    mesh: MeshData,
    companion: Option<MeshData>,
    /// What the companion is ("target", "subject").
    companion_name: String,
    range: Option<[f64; 2]>,
    /// The mesh's and the companion's frames and cells are the scene
    /// before's (another map of the same shapes): they are not repeated.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    same_geometry: bool,
}

/// `frames` (one mesh, the same cells) with the simplification applied,
/// if any: the kept vertices of the first frame and its coarse cells.
fn mesh_data(frames: &[&FShape]) -> Result<(MeshData, Option<usize>)> {
    mesh_data_within(frames, DISPLAY_VERTICES)
}

/// [`mesh_data`] with the display limit given.
fn mesh_data_within(frames: &[&FShape], limit: usize) -> Result<(MeshData, Option<usize>)> {
    let first = frames[0];
    let (cells, kept): (Vec<usize>, Option<Vec<usize>>) =
        if first.n_vertices() > limit && first.kind() == CellKind::Triangle {
            let s = first.simplified(limit)?;
            (s.shape.cells().iter().map(|&c| s.kept[c]).collect(), Some(s.kept))
        } else {
            (first.cells().to_vec(), None)
        };
    // Renumber to the kept vertices (all of them when not simplified).
    let order: Vec<usize> = kept.clone().unwrap_or_else(|| (0..first.n_vertices()).collect());
    let mut index = vec![u32::MAX; first.n_vertices()];
    for (k, &v) in order.iter().enumerate() {
        index[v] = k as u32;
    }
    let cell_bytes: Vec<u8> = cells.iter().flat_map(|&v| index[v].to_le_bytes()).collect();
    let d = first.dim();
    let mut positions = Vec::new();
    let mut signals = Vec::new();
    for f in frames {
        positions.push(packed_f32(order.iter().flat_map(|&v| {
            let p = f.point(v);
            [p[0], p[1], if d == 3 { p[2] } else { 0.0 }]
        })));
        // Several channels: the first is shown.
        if let Some(s) = f.channel(0) {
            signals.push(packed_f32(order.iter().map(|&v| s[v])));
        }
    }
    let data = MeshData {
        kind: if first.kind() == CellKind::Triangle { "triangle" } else { "segment" },
        planar: d == 2,
        cells: gzip_base64(&cell_bytes),
        frames: positions,
        signals: (signals.len() == frames.len()).then_some(signals),
    };
    Ok((data, kept.map(|k| k.len())))
}

/// A scene: `frames` under the slider (labelled), `companion` (named, as
/// "target") beside. The colour range spans the first frame's and the
/// companion's signals.
pub fn scene(name: &str, frames: &[&FShape], labels: Vec<String>, companion: Option<(&str, &FShape)>) -> Result<Scene> {
    let (companion_name, companion) = match companion {
        Some((n, c)) => (n.to_string(), Some(c)),
        None => (String::new(), None),
    };
    if frames.is_empty() {
        return Err(ReportError::NoFrames { scene: name.to_string() });
    }
    let (mesh, simplified) = mesh_data(frames)?;
    let (companion_data, companion_simplified) = match companion {
        Some(c) => {
            let (m, s) = mesh_data(&[c])?;
            (Some(m), s)
        }
        None => (None, None),
    };
    let mut notes = Vec::new();
    if let Some(k) = simplified {
        notes.push(format!(
            "shown simplified from {} to {k} vertices (the files hold every vertex)",
            frames[0].n_vertices()
        ));
    }
    if let (Some(k), Some(c)) = (companion_simplified, companion) {
        notes.push(format!("the {companion_name} is shown simplified from {} to {k} vertices", c.n_vertices()));
    }
    if frames[0].n_channels() > 1 {
        notes.push(format!(
            "the colours show the first of its {} signal channels (the files hold each)",
            frames[0].n_channels()
        ));
    }
    let values = frames[0].channel(0).into_iter().chain(companion.and_then(|c| c.channel(0))).flatten();
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    Ok(Scene {
        name: name.to_string(),
        labels,
        note: (!notes.is_empty()).then(|| format!("{}.", notes.join("; "))),
        mesh,
        companion: companion_data,
        companion_name,
        range: (lo < hi).then_some([lo, hi]),
        same_geometry: false,
    })
}

/// `s` with map `c` of its signal alone (to show one map of several).
fn one_map(s: &FShape, c: usize) -> Result<FShape> {
    Ok(s.clone().with_signal(s.channel(c))?)
}

/// A scene per map of `frames` (and of the companion), named by `name(c)`,
/// for the viewer's picker. The first holds the geometry; each other holds
/// its map only and shares the first's frames and cells, so that k maps
/// cost one geometry in the page.
pub(crate) fn map_scenes(
    name: impl Fn(usize) -> String,
    frames: &[&FShape],
    labels: &[String],
    companion: Option<(&str, &FShape)>,
) -> Result<Vec<Scene>> {
    let k = frames.first().map_or(1, |f| f.n_channels().max(1));
    (0..k)
        .map(|c| {
            let maps: Vec<FShape> = frames.iter().map(|f| one_map(f, c)).collect::<Result<_>>()?;
            let maps: Vec<&FShape> = maps.iter().collect();
            let other = companion.map(|(n, s)| Ok::<_, ReportError>((n, one_map(s, c)?))).transpose()?;
            let mut sc = scene(&name(c), &maps, labels.to_vec(), other.as_ref().map(|(n, s)| (*n, s)))?;
            if c > 0 {
                sc.same_geometry = true;
                for m in std::iter::once(&mut sc.mesh).chain(sc.companion.as_mut()) {
                    m.cells.clear();
                    m.frames.clear();
                }
            }
            Ok(sc)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;
    fn unpack(b64: &str) -> Vec<u8> {
        let gz = base64::engine::general_purpose::STANDARD.decode(b64).unwrap();
        let mut bytes = Vec::new();
        flate2::read::GzDecoder::new(&gz[..]).read_to_end(&mut bytes).unwrap();
        bytes
    }

    #[test]
    fn a_large_surface_is_shown_simplified_every_frame_at_the_kept_vertices() {
        let sphere = fshape_mesh::generate::icosphere(4, 1.0); // 2562 vertices
        let f: Vec<f64> = sphere.points().chunks_exact(3).map(|p| p[2]).collect();
        let first = sphere.clone().with_signal(Some(f.clone())).unwrap();
        let grown = first.clone().with_points(sphere.points().iter().map(|x| 2.0 * x).collect()).unwrap();
        let (data, kept) = mesh_data_within(&[&first, &grown], 500).unwrap();
        let kept = kept.expect("simplified");
        assert!((400..=600).contains(&kept), "{kept}");
        let cells: Vec<u32> =
            unpack(&data.cells).chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        assert!(cells.iter().all(|&c| (c as usize) < kept));
        let floats = |b64: &str| -> Vec<f32> {
            unpack(b64).chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        let (x0, x1) = (floats(&data.frames[0]), floats(&data.frames[1]));
        assert_eq!(x0.len(), 3 * kept);
        // The same vertices in both frames: the second is the first doubled,
        // each a point of the unit sphere carrying its own z.
        for (a, b) in x0.iter().zip(&x1) {
            assert_eq!(2.0 * a, *b);
        }
        let signal = floats(&data.signals.as_ref().unwrap()[0]);
        for (v, z) in signal.iter().enumerate() {
            assert_eq!(*z, x0[3 * v + 2]);
            let r: f32 = (0..3).map(|k| x0[3 * v + k].powi(2)).sum::<f32>().sqrt();
            assert!((r - 1.0).abs() < 1e-5);
        }
        // Below the limit nothing is simplified.
        let (small, none) = mesh_data_within(&[&first], 10_000).unwrap();
        assert!(none.is_none());
        assert_eq!(floats(&small.frames[0]).len(), 3 * 2562);
    }

    #[test]
    fn each_map_has_a_scene_and_the_maps_share_one_geometry() {
        let sphere = fshape_mesh::generate::icosphere(3, 1.0);
        let f: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [p[0], 10.0 * p[2]]).collect();
        let two = sphere.clone().with_signals(Some(f), 2).unwrap();
        let grown = two.clone().with_points(sphere.points().iter().map(|x| 1.5 * x).collect()).unwrap();
        let scenes =
            map_scenes(|c| format!("map {c}"), &[&two, &grown], &["a".into(), "b".into()], Some(("target", &grown)))
                .unwrap();
        assert_eq!(scenes.len(), 2);
        // The first holds the frames and cells; the second only its map.
        let (first, second) = (&scenes[0], &scenes[1]);
        assert!(!first.same_geometry && first.mesh.frames.len() == 2 && !first.mesh.cells.is_empty());
        assert!(second.same_geometry && second.mesh.frames.is_empty() && second.mesh.cells.is_empty());
        assert!(second.companion.as_ref().is_some_and(|c| c.frames.is_empty() && c.signals.is_some()));
        let floats = |b64: &str| -> Vec<f32> {
            unpack(b64).chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        };
        // Each its own map and its own colour range.
        let x = floats(&first.mesh.frames[0]);
        let m2 = floats(&second.mesh.signals.as_ref().unwrap()[0]);
        for (v, value) in m2.iter().enumerate() {
            assert_eq!(*value, (10.0 * sphere.point(v)[2]) as f32);
            assert_eq!(floats(&first.mesh.signals.as_ref().unwrap()[0])[v], x[3 * v]);
        }
        let range = |s: &Scene| s.range.unwrap();
        assert!(range(second)[1] > 5.0 * range(first)[1], "{:?} {:?}", range(first), range(second));
    }
}
