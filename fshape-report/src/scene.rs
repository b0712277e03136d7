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

/// The vertices and cells a mesh is shown with: all of them, or, above
/// the display limit, the first frame simplified (every map weighed).
struct Shown {
    cells: Vec<usize>,
    /// The kept vertices, in order (`None`: every vertex).
    kept: Option<Vec<usize>>,
}

fn shown(first: &FShape, limit: usize) -> Result<Shown> {
    Ok(if first.n_vertices() > limit && first.kind() == CellKind::Triangle {
        let s = first.simplified(limit)?;
        Shown { cells: s.shape.cells().iter().map(|&c| s.kept[c]).collect(), kept: Some(s.kept) }
    } else {
        Shown { cells: first.cells().to_vec(), kept: None }
    })
}

/// `frames` (one mesh, the same cells) with the simplification applied,
/// if any: the kept vertices of the first frame and its coarse cells.
#[cfg(test)]
fn mesh_data_within(frames: &[&FShape], limit: usize) -> Result<(MeshData, Option<usize>)> {
    let s = shown(frames[0], limit)?;
    Ok((mesh_data_shown(frames, 0, &s, true), s.kept.map(|k| k.len())))
}

/// `frames` at the vertices and cells `shown` says, with their map
/// `channel`; without `geometry`, the map alone (no cells, no positions).
fn mesh_data_shown(frames: &[&FShape], channel: usize, shown: &Shown, geometry: bool) -> MeshData {
    let first = frames[0];
    // Renumber to the kept vertices (all of them when not simplified).
    let order: Vec<usize> = shown.kept.clone().unwrap_or_else(|| (0..first.n_vertices()).collect());
    let mut index = vec![u32::MAX; first.n_vertices()];
    for (k, &v) in order.iter().enumerate() {
        index[v] = k as u32;
    }
    let d = first.dim();
    let cells = if geometry {
        gzip_base64(&shown.cells.iter().flat_map(|&v| index[v].to_le_bytes()).collect::<Vec<u8>>())
    } else {
        String::new()
    };
    let mut positions = Vec::new();
    let mut signals = Vec::new();
    for f in frames {
        if geometry {
            positions.push(packed_f32(order.iter().flat_map(|&v| {
                let p = f.point(v);
                [p[0], p[1], if d == 3 { p[2] } else { 0.0 }]
            })));
        }
        if let Some(s) = f.channel(channel) {
            signals.push(packed_f32(order.iter().map(|&v| s[v])));
        }
    }
    MeshData {
        kind: if first.kind() == CellKind::Triangle { "triangle" } else { "segment" },
        planar: d == 2,
        cells,
        frames: positions,
        signals: (signals.len() == frames.len()).then_some(signals),
    }
}

/// A scene: `frames` under the slider (labelled), `companion` (named, as
/// "target") beside. The colour range spans the first frame's and the
/// companion's signals.
pub fn scene(name: &str, frames: &[&FShape], labels: Vec<String>, companion: Option<(&str, &FShape)>) -> Result<Scene> {
    let first = frames.first().ok_or_else(|| ReportError::NoFrames { scene: name.to_string() })?;
    let mesh = shown(first, DISPLAY_VERTICES)?;
    let other = companion.map(|(_, c)| shown(c, DISPLAY_VERTICES)).transpose()?;
    Ok(scene_shown(name, frames, labels, companion, 0, (&mesh, other.as_ref()), Role::Only))
}

/// A scene's place among the scenes of several maps.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    /// The one scene of a shape (its first map shown).
    Only,
    /// The first of a scene per map: it holds the geometry.
    First,
    /// A later one: its map only, the first's frames and cells shared.
    Other,
}

/// [`scene`] of map `channel`, shown as `shown` says (the mesh's and the
/// companion's), in its `role`.
fn scene_shown(
    name: &str,
    frames: &[&FShape],
    labels: Vec<String>,
    companion: Option<(&str, &FShape)>,
    channel: usize,
    shown: (&Shown, Option<&Shown>),
    role: Role,
) -> Scene {
    let (companion_name, companion) = match companion {
        Some((n, c)) => (n.to_string(), Some(c)),
        None => (String::new(), None),
    };
    let geometry = role != Role::Other;
    let mesh = mesh_data_shown(frames, channel, shown.0, geometry);
    let companion_data = companion.zip(shown.1).map(|(c, s)| mesh_data_shown(&[c], channel, s, geometry));
    let mut notes = Vec::new();
    if let Some(k) = &shown.0.kept {
        notes.push(format!(
            "shown simplified from {} to {} vertices (the files hold every vertex)",
            frames[0].n_vertices(),
            k.len()
        ));
    }
    if let (Some(k), Some(c)) = (shown.1.and_then(|s| s.kept.as_ref()), companion) {
        notes.push(format!("the {companion_name} is shown simplified from {} to {} vertices", c.n_vertices(), k.len()));
    }
    if frames[0].n_channels() > 1 && role == Role::Only {
        notes.push(format!(
            "the colours show the first of its {} signal channels (the files hold each)",
            frames[0].n_channels()
        ));
    }
    let values = frames[0].channel(channel).into_iter().chain(companion.and_then(|c| c.channel(channel))).flatten();
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    Scene {
        name: name.to_string(),
        labels,
        note: (!notes.is_empty()).then(|| format!("{}.", notes.join("; "))),
        mesh,
        companion: companion_data,
        companion_name,
        range: (lo < hi).then_some([lo, hi]),
        same_geometry: role == Role::Other,
    }
}

/// A scene per map of `frames` (and of the companion), named by `name(c)`,
/// for the viewer's picker. The first holds the geometry; each other holds
/// its map only, at the same vertices, and shares the first's frames and
/// cells, so that k maps cost one geometry in the page.
pub(crate) fn map_scenes(
    name: impl Fn(usize) -> String,
    frames: &[&FShape],
    labels: &[String],
    companion: Option<(&str, &FShape)>,
) -> Result<Vec<Scene>> {
    map_scenes_within(name, frames, labels, companion, DISPLAY_VERTICES)
}

/// [`map_scenes`] with the display limit given: one simplification for
/// every map (the first frame's, weighing them all).
fn map_scenes_within(
    name: impl Fn(usize) -> String,
    frames: &[&FShape],
    labels: &[String],
    companion: Option<(&str, &FShape)>,
    limit: usize,
) -> Result<Vec<Scene>> {
    let first = frames.first().ok_or_else(|| ReportError::NoFrames { scene: name(0) })?;
    let k = first.n_channels().max(1);
    let mesh = shown(first, limit)?;
    let other = companion.map(|(_, c)| shown(c, limit)).transpose()?;
    Ok((0..k)
        .map(|c| {
            let role = if c == 0 { Role::First } else { Role::Other };
            scene_shown(&name(c), frames, labels.to_vec(), companion, c, (&mesh, other.as_ref()), role)
        })
        .collect())
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
        // Simplified for display: every map at the same kept vertices (the
        // second map's values are those of its own vertices there).
        let scenes = map_scenes_within(|c| format!("map {c}"), &[&two], &["a".into()], None, 500).unwrap();
        let kept = shown(&two, 500).unwrap().kept.expect("simplified");
        assert_eq!(floats(&scenes[0].mesh.frames[0]).len(), 3 * kept.len());
        for (c, sc) in scenes.iter().enumerate() {
            let values = floats(&sc.mesh.signals.as_ref().unwrap()[0]);
            let want: Vec<f32> = kept.iter().map(|&v| two.channel(c).unwrap()[v] as f32).collect();
            assert_eq!(values, want, "map {c}");
        }
        assert!(scenes[1].note.as_deref().is_some_and(|n| n.contains("simplified") && !n.contains("first of its")));
    }
}
