//! What several commands write: a geodesic's states as files.

use std::path::{Path, PathBuf};

use anyhow::Result;
use fshape_mesh::FShape;
use fshape_mesh::io::{self, Encoding};

/// A file to write: its path and contents.
pub type Output = (PathBuf, Vec<u8>);

/// The states at `times` as VTK and PLY files, and a ParaView collection
/// (contents and names; nothing is written here).
pub fn trajectory_files(
    template: &FShape,
    traj: &fshape_shoot::Trajectory,
    times: &[f64],
    out: &Path,
) -> Result<(Vec<Output>, Vec<String>)> {
    let mut outputs: Vec<Output> = Vec::new();
    let mut files = Vec::new();
    let mut steps: Vec<(f64, String)> = Vec::new();
    for (k, &t) in times.iter().enumerate() {
        let (x, f) = traj.at(t);
        let state = template.clone().with_points(x)?.with_signals(Some(f), template.n_channels().max(1))?;
        for ext in ["vtk", "ply"] {
            let name = format!("state_{k:03}.{ext}");
            let format = if ext == "vtk" { io::Format::Vtk } else { io::Format::Ply };
            let mut bytes = Vec::new();
            io::write_to(&mut bytes, &state, format, Encoding::Binary)?;
            outputs.push((out.join(&name), bytes));
            files.push(name);
        }
        steps.push((t, format!("state_{k:03}.vtk")));
    }
    let entries: Vec<(f64, &str)> = steps.iter().map(|(t, f)| (*t, f.as_str())).collect();
    let pvd = io::vtk::collection(&entries);
    outputs.push((out.join("trajectory.pvd"), pvd.into_bytes()));
    files.push("trajectory.pvd".into());
    Ok((outputs, files))
}
