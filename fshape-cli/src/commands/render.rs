//! `fshape render`: PNG pictures of meshes from one camera, in one colour range.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use fshape_mesh::FShape;
use fshape_mesh::io;
use fshape_report::render;

use crate::inputs::load;

/// `fshape render`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The meshes.
    #[arg(required = true)]
    pub meshes: Vec<PathBuf>,
    /// One PNG per mesh, in the same order.
    #[arg(long, value_delimiter = ',', required = true)]
    pub out: Vec<PathBuf>,
    #[command(flatten)]
    pub view: crate::args::View,
    /// Signal values at the ends of the colour map: lo,hi (default: the
    /// range of all the meshes' signals).
    #[arg(long, value_delimiter = ',', num_args = 1, allow_hyphen_values = true)]
    pub range: Vec<f64>,
    /// Vertex property to read as the signal (default `signal`).
    #[arg(long)]
    pub signal_name: Option<String>,
}

pub fn run(a: Args) -> Result<()> {
    render_meshes(&a.meshes, &a.out, a.view.camera.pair(), &a.range, a.signal_name)
}

/// `fshape render`: every mesh read before any picture is written, then
/// one PNG per mesh (each written whole or not at all).
fn render_meshes(
    meshes: &[PathBuf],
    out: &[PathBuf],
    (azimuth, elevation): (f64, f64),
    range: &[f64],
    signal_name: Option<String>,
) -> Result<()> {
    if out.len() != meshes.len() {
        bail!("--out: {} picture(s) for {} mesh(es); give one PNG path per mesh", out.len(), meshes.len());
    }
    if let Some(p) = out.iter().find(|p| !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"))) {
        bail!("--out: {} is not a .png path", p.display());
    }
    let range = match range {
        [] => None,
        [lo, hi] if lo.is_finite() && hi.is_finite() && lo < hi => Some((*lo, *hi)),
        _ => bail!("--range: expected lo,hi (two finite values, lo < hi), got {range:?}"),
    };
    let shapes = meshes.iter().map(|p| load(p, signal_name.clone(), None)).collect::<Result<Vec<_>>>()?;
    if let Some(i) = shapes.iter().position(|s| s.dim() != shapes[0].dim()) {
        bail!(
            "{} is {}-D and {} is {}-D: one picture frames meshes of one dimension",
            meshes[i].display(),
            shapes[i].dim(),
            meshes[0].display(),
            shapes[0].dim()
        );
    }
    let all: Vec<&FShape> = shapes.iter().collect();
    let mut view = render::View::fit(&all, azimuth, elevation);
    if let Some((lo, hi)) = range {
        view = view.with_range(lo, hi);
    }
    for (shape, path) in shapes.iter().zip(out) {
        let png = render::picture(shape, &view)?;
        io::write_atomic(path, &png, false).with_context(|| format!("writing {}", path.display()))?;
        println!("{}", path.display());
    }
    Ok(())
}
