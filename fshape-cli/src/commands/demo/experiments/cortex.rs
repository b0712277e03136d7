//! The cortex (paper section 5.2): a left hemisphere's thickness onto the right one's.

use anyhow::{Context, Result};
use fshape_match::ops::ModelKind;
use fshape_match::{Config, NormKind};
use fshape_mesh::io::{self, Encoding, write_mesh};

use super::{BUNNY_DECREASE, RunArgs, attachment, run_match, schedule, write_inputs};

/// The H¹ length scale of the cortex runs, in millimetres: thickness
/// variations over less than ~2πℓ ≈ 30 mm (a few gyri) cost more through
/// their gradient than through their size.
pub const CORTEX_LENGTH_MM: f64 = 5.0;

/// Cortex (the paper's thickness maps, section 5.2, on fsaverage5): the left
/// pial surface with its thickness onto the right one mirrored (x → −x,
/// faces reoriented) with its thickness, in millimetres; H¹ tangential
/// model against H¹ metamorphosis, scale-free default weights (γ_W =
/// `gamma_w`), p_0 in the energy metric, and four stages: k_p 20 mm on
/// fsaverage3 (the source's first 642 vertices), 10 and 5 mm on fsaverage4
/// (2562), 5 mm on the source, each ending on [`BUNNY_DECREASE`] (limits
/// 4, 4, 2 and 2 times `max_iterations`: the last stage starts from a J
/// ten times the coarse stages' end, the prolongation's cost on a folded
/// surface, and needs about 50 iterations to recover).
pub fn cortex(a: &RunArgs<'_>) -> Result<()> {
    let dir = a.out.join("cortex");
    let fs5 = a.data.join("fsaverage5");
    let source = io::read_mesh(&fs5.join("lh.pial.thick.ply.gz"), &io::ReadOptions::default())?;
    let right = io::read_mesh(&fs5.join("rh.pial.ply.gz"), &io::ReadOptions::default())?;
    let thick = io::csv::read_signal(&fs5.join("rh.thick.csv.gz"), false)?;
    anyhow::ensure!(
        thick.values.len() == right.n_vertices(),
        "{}: {} values for {} vertices",
        fs5.join("rh.thick.csv.gz").display(),
        thick.values.len(),
        right.n_vertices()
    );
    let target = fshape_match::demo::mirror_x(&right.with_signal(Some(thick.values))?)?;
    let (sp, tp) = write_inputs(&dir, &source, &target)?;
    eprintln!(
        "cortex: left pial ({} vertices) onto the mirrored right pial ({} vertices), thickness in mm",
        source.n_vertices(),
        target.n_vertices()
    );
    // fsaverage5 is an icosahedral subdivision: its first 2562 and 642
    // vertices are fsaverage4's and fsaverage3's, the coarse stages'
    // templates.
    let level4 = source.coarsened().context("fsaverage5's fsaverage4")?;
    let level3 = level4.coarsened().context("fsaverage5's fsaverage3")?;
    let mut coarse = Vec::new();
    for (name, shape) in [("source_coarse2.ply", &level3), ("source_coarse1.ply", &level4)] {
        let path = dir.join(name);
        write_mesh(&path, shape, Encoding::Binary)?;
        coarse.push(path);
    }
    let templates = [coarse[0].clone(), coarse[1].clone(), coarse[1].clone()];
    let n = a.max_iterations;
    for kind in [ModelKind::Tangential, ModelKind::Metamorphosis] {
        let run = dir.join(kind.name());
        let mut config = Config::new(vec![20.0, 10.0]);
        config.model.kind = kind;
        config.model.norm = NormKind::H1;
        config.model.length = CORTEX_LENGTH_MM;
        config.model.gamma_w = a.gamma_w;
        config.deformation.tolerance = Some(1e-6);
        config.attachment = Some(attachment(5.0, 1.0, Some(1e-6))?);
        config.optimizer.momentum_metric = fshape_match::Metric::Energy;
        let limits = vec![4 * n, 4 * n, 2 * n, 2 * n];
        config.schedule = Some(schedule(&[20.0, 10.0, 5.0, 5.0], vec![BUNNY_DECREASE.0; 4], limits)?);
        let header = format!(
            "fshape demo cortex: {}, H1 with length {CORTEX_LENGTH_MM} mm, scale-free weights\n\
             (gamma_w {}, gamma_f 0.1), p_0 in the energy metric. Everything is in mm\n\
             (fsaverage5, FreeSurfer surface RAS); widths use exp(-u/(2 s^2)). Stages: k_p 20 mm\n\
             on fsaverage3 (source_coarse2.ply), 10 and 5 mm on fsaverage4 (source_coarse1.ply),\n\
             5 mm on the source (--stage-templates), each ending when J fell by less than {}\n\
             over {} iterations.",
            kind.name(),
            a.gamma_w,
            BUNNY_DECREASE.0,
            BUNNY_DECREASE.1
        );
        eprintln!("cortex: {} -> {}", kind.name(), run.display());
        // Seen from −x: the lateral side of a left hemisphere, anterior to the left.
        run_match(&sp, &tp, &header, &config, &run, (-90.0, 0.0), &templates)
            .with_context(|| format!("cortex, {}", kind.name()))?;
    }
    Ok(())
}
