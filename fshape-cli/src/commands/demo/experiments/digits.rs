//! The digits (paper section 5.1): a handwritten 2 onto a 3 for three ratios γ_V/γ_f.

use anyhow::{Context, Result};
use fshape_match::ops::ModelKind;
use fshape_match::{Config, NormKind};
use fshape_mesh::generate::{sample_image, square};
use fshape_mesh::io::image::read_image;
use fshape_mesh::io::{Encoding, write_mesh};

use super::{BUNNY_DECREASE, DigitsArgs, attachment, from_fshapestk, run_match, schedule, write_inputs};

/// Points asked of `generate::square` for the digits: the paper's
/// resolution (4780 and 4868 vertices, the paper has 4900) and the coarse
/// stages' template (1148 vertices).
pub const DIGITS_POINTS: (usize, usize) = (4250, 1000);

/// Digits (paper section 5.1): a handwritten 2 onto a handwritten 3 (MNIST,
/// values rescaled to [0, 0.6]) on two different Delaunay squares of about
/// 4900 vertices, L² (lumped) metamorphosis for each γ_V/γ_f, with the
/// scale-free default γ_W, p_0 in the energy metric, and four stages: k_p
/// 0.141, 0.071 and 0.035 on a coarser square carrying the same 2 (1148
/// vertices), then 0.035 on the template, each ending on the decrease test
/// [`BUNNY_DECREASE`] (limits 4, 4, 4 and 1 times `max_iterations`).
pub fn digits(a: &DigitsArgs<'_>) -> Result<()> {
    let dir = a.out.join("digits");
    let shape = |file: &str, points: usize, seed: u64| -> Result<fshape_mesh::FShape> {
        let path = a.data.join("digits").join(file);
        let image = read_image(&path, None)?;
        let mesh = square(points, seed);
        let values: Vec<f64> = sample_image(&image, &mesh).iter().map(|v| 0.6 * v / 255.0).collect();
        Ok(mesh.with_signal(Some(values))?)
    };
    let (two, three) = ("mnist5k_1000_label2.csv", "mnist5k_1500_label3.csv");
    let (source, target) = (shape(two, DIGITS_POINTS.0, 1)?, shape(three, DIGITS_POINTS.0, 2)?);
    let (sp, tp) = write_inputs(&dir, &source, &target)?;
    let coarse = dir.join("source_coarse.ply");
    write_mesh(&coarse, &shape(two, DIGITS_POINTS.1, 1)?, Encoding::Binary)?;
    eprintln!(
        "digits: source {} vertices, target {} vertices (a 2 onto a 3, signal in [0, 0.6])",
        source.n_vertices(),
        target.n_vertices()
    );
    let (v1, v2) = (from_fshapestk(0.2), from_fshapestk(0.1));
    let (p1, p2, p3, f) = (from_fshapestk(0.2), from_fshapestk(0.1), from_fshapestk(0.05), from_fshapestk(0.7));
    let n = a.max_iterations;
    for &ratio in a.ratios {
        let run = dir.join(format!("ratio_{ratio}"));
        let mut config = Config::new(vec![v1, v2]);
        config.model.kind = ModelKind::Metamorphosis;
        config.model.norm = NormKind::L2Lumped;
        config.model.gamma_f = 1.0 / ratio;
        config.model.gamma_w = a.gamma_w;
        config.deformation.tolerance = Some(1e-6);
        config.attachment = Some(attachment(p3, f, Some(1e-6))?);
        config.optimizer.momentum_metric = fshape_match::Metric::Energy;
        config.schedule = Some(schedule(&[p1, p2, p3, p3], vec![BUNNY_DECREASE.0; 4], vec![4 * n, 4 * n, 4 * n, n])?);
        let header = format!(
            "fshape demo digits: gamma_V / gamma_f = {ratio}, scale-free weights (gamma_w {}),\n\
             p_0 in the energy metric; k_p 0.141, 0.071, 0.035 on source_coarse.ply, then 0.035\n\
             on the source (--stage-templates), each stage ending when J fell by less than {}\n\
             over {} iterations. Widths are the paper's (fshapesTk's exp(-u/s^2)) divided by\n\
             sqrt(2) for fshape's exp(-u/(2 s^2)).",
            a.gamma_w, BUNNY_DECREASE.0, BUNNY_DECREASE.1
        );
        eprintln!("digits: gamma_V/gamma_f = {ratio} -> {}", run.display());
        let templates = [coarse.clone(), coarse.clone(), coarse.clone()];
        run_match(&sp, &tp, &header, &config, &run, (0.0, 90.0), &templates)
            .with_context(|| format!("digits, gamma_V/gamma_f = {ratio}"))?;
    }
    Ok(())
}
