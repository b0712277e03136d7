//! Per-vertex maps of an atlas's subjects on the template: what a group
//! test compares, vertex by vertex. Subject i's geodesic takes the
//! template (x̄, f̄) to (x_1ⁱ, f_1ⁱ), vertex for vertex, so each map is a
//! function on the template's vertices:
//!
//! - `signal`: f_1ⁱ − f̄, the signal change the metamorphosis carries to
//!   the template's point (the transported signal residual); with several
//!   maps per vertex, one map each (`signal`, `signal_2`, …: a [`Map`]
//!   names which);
//! - `momentum`: p_0ⁱ · n̄ / ā, the initial momentum's normal component per
//!   unit area (the momenta are densities times areas in the discrete
//!   model), n̄ the template's unit normal;
//! - `displacement`: (x_1ⁱ − x̄) · n̄, how far the surface moved along its
//!   normal (outward for a closed surface oriented outward);
//! - `area`: log(a_1ⁱ / ā), the local log area change (log length change
//!   for a curve), with a the lumped vertex areas: tensor-based
//!   morphometry's log Jacobian.
//!
//! Normals exist for surfaces in R³ and curves in the plane; for a planar
//! triangulation (a digit on a square) `momentum` and `displacement` are
//! not defined.

use fshape_mesh::{CellKind, FShape};

use crate::StatsError;

/// A per-vertex map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MapKind {
    /// f_1 − f̄.
    Signal,
    /// p_0 · n̄ / ā.
    Momentum,
    /// (x_1 − x̄) · n̄.
    Displacement,
    /// log(a_1 / ā).
    Area,
}

impl MapKind {
    /// Every kind, in the order of outputs.
    pub const ALL: [MapKind; 4] = [MapKind::Signal, MapKind::Momentum, MapKind::Displacement, MapKind::Area];

    /// Its name in file names and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MapKind::Signal => "signal",
            MapKind::Momentum => "momentum",
            MapKind::Displacement => "displacement",
            MapKind::Area => "area",
        }
    }

    /// The kind a name gives.
    pub fn from_name(name: &str) -> Option<MapKind> {
        MapKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// What the map is, for legends and summaries.
    pub fn describe(self) -> &'static str {
        match self {
            MapKind::Signal => "signal change carried to the template (f1 - f)",
            MapKind::Momentum => "initial momentum's normal component per unit area",
            MapKind::Displacement => "displacement along the template's normal",
            MapKind::Area => "log area change (log Jacobian)",
        }
    }

    /// Whether the template allows this map.
    pub fn available(self, template: &FShape) -> bool {
        match self {
            MapKind::Signal => template.signal().is_some(),
            MapKind::Momentum | MapKind::Displacement => vertex_normals(template).is_some(),
            MapKind::Area => true,
        }
    }
}

/// A map to test: its kind and, for [`MapKind::Signal`], which of the
/// template's maps (0 the first; 0 for the other kinds).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Map {
    /// What the map measures.
    pub kind: MapKind,
    /// The signal map it reads (0 unless `kind` is `Signal`).
    pub channel: usize,
}

impl From<MapKind> for Map {
    fn from(kind: MapKind) -> Map {
        Map { kind, channel: 0 }
    }
}

impl Map {
    /// Its name in file names, summaries and on the command line: the
    /// kind's, the signal's maps after the first as `signal_2`, `signal_3`, …
    /// (as mesh files name a signal's maps).
    pub fn name(self) -> String {
        match self.channel {
            0 => self.kind.name().to_string(),
            c => format!("{}_{}", self.kind.name(), c + 1),
        }
    }

    /// The map a name gives (`signal_2`: the second signal map).
    pub fn from_name(name: &str) -> Option<Map> {
        if let Some(kind) = MapKind::from_name(name) {
            return Some(kind.into());
        }
        let number: usize = name.strip_prefix("signal_")?.parse().ok()?;
        (number >= 2).then_some(Map { kind: MapKind::Signal, channel: number - 1 })
    }

    /// What the map is, for legends and summaries.
    pub fn describe(self) -> String {
        match self.channel {
            0 => self.kind.describe().to_string(),
            c => format!("{}, map {}", self.kind.describe(), c + 1),
        }
    }

    /// Whether the template allows this map (a signal map it carries).
    pub fn available(self, template: &FShape) -> bool {
        match self.kind {
            MapKind::Signal => self.channel < template.n_channels(),
            _ => self.channel == 0 && self.kind.available(template),
        }
    }

    /// Every map the template allows, in the order of outputs: each of its
    /// signal maps, then the geometric ones.
    pub fn every(template: &FShape) -> Vec<Map> {
        let signals = (0..template.n_channels()).map(|channel| Map { kind: MapKind::Signal, channel });
        let geometric = MapKind::ALL.into_iter().filter(|k| *k != MapKind::Signal && k.available(template));
        signals.chain(geometric.map(Map::from)).collect()
    }
}

/// The template's unit vertex normals (area-weighted mean of its cells'
/// normals; for a plane curve its tangents turned by −90°), or `None` when
/// the shape has no normal (planar triangles, space curves). A vertex
/// whose normals cancel gets 0.
pub fn vertex_normals(shape: &FShape) -> Option<Vec<[f64; 3]>> {
    let rotate = match (shape.kind(), shape.dim()) {
        (CellKind::Triangle, 3) => false,
        (CellKind::Segment, 2) => true,
        _ => return None,
    };
    let mut normals = vec![[0.0; 3]; shape.n_vertices()];
    for (t, cell) in shape.cell_iter().enumerate() {
        let c = shape.cell_vector(t);
        let nrm = if rotate { [c[1], -c[0], 0.0] } else { c };
        for &v in cell {
            for k in 0..3 {
                normals[v][k] += nrm[k];
            }
        }
    }
    for nrm in &mut normals {
        let len = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
        *nrm = if len > 0.0 { nrm.map(|x| x / len) } else { [0.0; 3] };
    }
    Some(normals)
}

/// One subject's `map` on the template's vertices, from its initial
/// momenta `p0` (d per vertex) and the template shot onto it, `matched`
/// (the template's cells and maps).
pub fn subject_map(
    map: impl Into<Map>,
    template: &FShape,
    p0: &[f64],
    matched: &FShape,
) -> Result<Vec<f64>, StatsError> {
    let Map { kind, channel } = map.into();
    let (n, d) = (template.n_vertices(), template.dim());
    if matched.n_vertices() != n || matched.dim() != d || matched.cells() != template.cells() {
        return Err(StatsError::Maps {
            message: format!(
                "the matched shape ({} vertices in R^{}) is not the template's mesh ({n} vertices in R^{d})",
                matched.n_vertices(),
                matched.dim()
            ),
        });
    }
    let normals = || {
        vertex_normals(template).ok_or_else(|| StatsError::Maps {
            message: format!(
                "the `{}` map needs normals, which {}s in R^{d} do not have",
                kind.name(),
                template.kind().name()
            ),
        })
    };
    let along = |vectors: &dyn Fn(usize, usize) -> f64, normals: &[[f64; 3]]| -> Vec<f64> {
        (0..n).map(|v| (0..d).map(|k| vectors(v, k) * normals[v][k]).sum()).collect()
    };
    match kind {
        MapKind::Signal => match (template.channel(channel), matched.channel(channel)) {
            _ if template.signal().is_some()
                && matched.signal().is_some()
                && template.n_channels() != matched.n_channels() =>
            {
                Err(StatsError::Maps {
                    message: format!(
                        "the template carries {} signal map(s) and the subject's matched shape {}",
                        template.n_channels(),
                        matched.n_channels()
                    ),
                })
            }
            (Some(f), Some(f1)) => Ok(f1.iter().zip(f).map(|(a, b)| a - b).collect()),
            _ => Err(StatsError::Maps {
                message: format!(
                    "the `{}` map needs signal map {} of the template (it carries {}) and of the subject ({})",
                    Map { kind, channel }.name(),
                    channel + 1,
                    template.n_channels(),
                    matched.n_channels()
                ),
            }),
        },
        MapKind::Momentum => {
            if p0.len() != n * d {
                return Err(StatsError::Maps {
                    message: format!("{} momentum values for {n} vertices in R^{d}", p0.len()),
                });
            }
            let areas = template.vertex_volumes();
            let dot = along(&|v, k| p0[v * d + k], &normals()?);
            Ok(dot.iter().zip(&areas).map(|(x, a)| if *a > 0.0 { x / a } else { 0.0 }).collect())
        }
        MapKind::Displacement => {
            let (x0, x1) = (template.points(), matched.points());
            Ok(along(&|v, k| x1[v * d + k] - x0[v * d + k], &normals()?))
        }
        MapKind::Area => {
            let (a0, a1) = (template.vertex_volumes(), matched.vertex_volumes());
            Ok(a0.iter().zip(&a1).map(|(a, b)| if *a > 0.0 && *b > 0.0 { (b / a).ln() } else { 0.0 }).collect())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fshape_mesh::generate::{circle, icosphere};

    #[test]
    fn a_sphere_grown_by_ten_percent_moves_out_and_gains_log_area() {
        let sphere = icosphere(2, 1.0).with_signal(Some(vec![1.0; 162])).unwrap();
        let grown = sphere.clone().with_points(sphere.points().iter().map(|x| 1.1 * x).collect()).unwrap();
        let grown = grown.with_signal(Some(vec![1.5; 162])).unwrap();
        let p0 = sphere.points().to_vec();
        for v in 0..162 {
            assert!((subject_map(MapKind::Displacement, &sphere, &p0, &grown).unwrap()[v] - 0.1).abs() < 2e-3);
            assert!((subject_map(MapKind::Area, &sphere, &p0, &grown).unwrap()[v] - 2.0 * 1.1f64.ln()).abs() < 1e-12);
            assert!((subject_map(MapKind::Signal, &sphere, &p0, &grown).unwrap()[v] - 0.5).abs() < 1e-15);
        }
        // A second map: each map's change on its own, refused past the last.
        let two = |s: &FShape, a: f64, b: f64| s.clone().with_signals(Some([a, b].repeat(s.n_vertices())), 2).unwrap();
        let (before, after) = (two(&sphere, 1.0, 10.0), two(&grown, 1.5, 7.0));
        for (map, change) in [("signal", 0.5), ("signal_2", -3.0)] {
            let map = Map::from_name(map).unwrap();
            assert!(subject_map(map, &before, &p0, &after).unwrap().iter().all(|c| *c == change), "{map:?}");
        }
        let third = Map::from_name("signal_3").unwrap();
        assert_eq!(third, Map { kind: MapKind::Signal, channel: 2 });
        assert!(!third.available(&before) && Map::from_name("signal_2").unwrap().available(&before));
        let e = subject_map(third, &before, &p0, &after).unwrap_err().to_string();
        assert!(e.contains("signal map 3 of the template (it carries 2)"), "{e}");
        let e = subject_map(MapKind::Signal, &before, &p0, &grown).unwrap_err().to_string();
        assert!(e.contains("the template carries 2 signal map(s) and the subject's matched shape 1"), "{e}");
        assert!(Map::from_name("signal_1").is_none() && Map::from_name("area_2").is_none());
        let names: Vec<String> = Map::every(&before).into_iter().map(Map::name).collect();
        assert_eq!(names, ["signal", "signal_2", "momentum", "displacement", "area"]);
        // p0 = x (radial, length 1): its normal component per unit area.
        let areas = sphere.vertex_volumes();
        let m = subject_map(MapKind::Momentum, &sphere, &p0, &grown).unwrap();
        for v in 0..162 {
            assert!((m[v] * areas[v] - 1.0).abs() < 2e-3, "{}", m[v] * areas[v]);
        }
    }

    #[test]
    fn a_circle_s_normals_point_out_and_a_planar_mesh_has_none() {
        let c = circle(64, 1.0);
        let normals = vertex_normals(&c).unwrap();
        for (v, nrm) in normals.iter().enumerate() {
            let p = c.point(v);
            // Parallel to the radius (either orientation, the same for all).
            assert!((nrm[0] * p[0] + nrm[1] * p[1]).abs() > 0.999);
            assert!(
                (nrm[0] * p[0] + nrm[1] * p[1]) * (normals[0][0] * c.point(0)[0] + normals[0][1] * c.point(0)[1]) > 0.0
            );
        }
        let square = fshape_mesh::generate::square(50, 1);
        assert!(vertex_normals(&square).is_none());
        let e = subject_map(MapKind::Momentum, &square, &vec![0.0; 2 * square.n_vertices()], &square).unwrap_err();
        assert!(e.to_string().contains("needs normals"), "{e}");
    }
}
