//! The bunny (paper section 5.1): H¹ against lumped L² on the Stanford bunny's texture.

use std::path::Path;

use anyhow::{Context, Result};
use fshape_match::{Config, NormKind};
use fshape_mesh::io::{self, Encoding, write_mesh};

use super::{BUNNY_DECREASE, RunArgs, run_match, schedule, write_inputs};

/// The tolerance of the bunny's coarse stages at the paper's resolution
/// (same window): with 1 % the H¹ run ended short of the quality bar
/// (89.2 % of the target within 1 % of the diagonal, signal error 5.55 %),
/// with 0.5 % it met it (91.7 %, 4.40 %) in a minute more
/// (docs/guide/src/experiments.md).
pub const BUNNY_COARSE_DECREASE: f64 = 5e-3;

/// The test of the bunny's deep stage, the last one on the 642-vertex
/// sphere (k_p 0.05): J fell by less than this fraction over this many
/// iterations. The decrease tests above end a stage while J still falls
/// by a few tenths of a percent per iteration, far from the optimum (run
/// on to 1000 iterations, the quick H¹ run's J fell from 1.86 to 1.38 and
/// its signal error from 5.8 % to 3.0 %). Iterations on 642 vertices cost
/// a tenth of a second, so this stage goes on much longer and the stages
/// on finer templates start near their optimum (docs/guide/src/experiments.md,
/// “a deep stage on the coarse sphere”).
pub const BUNNY_DEEP_DECREASE: (f64, usize) = (2e-3, 10);

/// γ_f of the bunny runs, below the default 0.1 (issue 16 lets a demo
/// leave the defaults if it says why). The paper's comparison of the
/// norms is about a signal that is matched closely: it says the lumped-L²
/// oscillations shrink as γ_f grows, at the price of the signal's
/// accuracy. Measured at the paper's resolution with this demo's stages
/// (docs/guide/src/experiments.md, “γ_f, the weight the paper's comparison of the norms turns on”), H¹ matches the bunny better
/// on every measure as γ_f falls from 0.1 (3.17 % signal error, fitted
/// with 94 % of the target's amplitude) to 0.01 (1.86 %, 98 %), in 285 s
/// instead of 207, while lumped L²'s oscillations grow (its error
/// 4.22 % → 5.47 %, all of the increase oscillation).
pub const BUNNY_GAMMA_F: f64 = 0.01;

/// L-BFGS's memory in the bunny runs (the default is 10): on the quick
/// setting's long last stage, 30 pairs reach after 400 iterations the J
/// that 10 pairs reach after 550 to 600, at the same cost per iteration
/// (docs/guide/src/experiments.md, “a deep stage on the coarse sphere”).
pub const BUNNY_LBFGS_MEMORY: usize = 30;

/// The bunny (paper section 5.1): the level-5 sphere with signal 0 onto the
/// textured 2581-vertex Stanford bunny, H¹ against lumped L², the shipped
/// `data/configs/bunny.toml` with scale-free weights (γ_W = `gamma_w`,
/// γ_f = [`BUNNY_GAMMA_F`]), p_0 in the energy metric, L-BFGS with
/// [`BUNNY_LBFGS_MEMORY`] pairs, and five stages: k_p 0.2, 0.1 and 0.05
/// on the level-3 sphere (642 vertices), 0.05 on the level-4 sphere
/// (2562), then 0.05 on the template, each ending on its decrease test
/// ([`BUNNY_COARSE_DECREASE`] for the first two and the fourth,
/// [`BUNNY_DEEP_DECREASE`] for the third, [`BUNNY_DECREASE`] for the
/// last), with limits of 4, 4, 6, 1.5 and 0.4 times `max_iterations`
/// iterations as a safety net (docs/guide/src/experiments.md). `quick`: the
/// level-3 sphere as the template and the first three stages on it.
pub fn bunny(a: &RunArgs<'_>) -> Result<()> {
    let dir = a.out.join(if a.quick { "bunny-quick" } else { "bunny" });
    let bunny = io::read_mesh(&a.data.join("stanford_bunny/bunny_qslim_2581v.ply.gz"), &io::ReadOptions::default())?;
    let level = if a.quick { 3 } else { 5 };
    let (template, target) = fshape_match::demo::bunny_setting_at_level(&bunny, level)?;
    let (sp, tp) = write_inputs(&dir, &template, &target)?;
    let mut stage_templates = Vec::new();
    if !a.quick {
        let mut coarse = Vec::new();
        for level in [3, 4] {
            let path = dir.join(format!("sphere_level{level}.ply"));
            write_mesh(&path, &fshape_match::demo::bunny_setting_at_level(&bunny, level)?.0, Encoding::Binary)?;
            coarse.push(path);
        }
        stage_templates = vec![coarse[0].clone(), coarse[0].clone(), coarse[0].clone(), coarse[1].clone()];
    }
    let shipped = Config::read(&a.data.join("configs/bunny.toml"))?;
    let n = a.max_iterations as f64;
    let budget = |f: f64| ((f * n).round() as usize).max(1);
    // Each stage ends on its decrease test (tolerance, window); the limits
    // are a safety net. The quick run is the first three stages.
    let coarse_test = (BUNNY_COARSE_DECREASE, BUNNY_DECREASE.1);
    let stages = [
        (0.2, coarse_test, 4.0),
        (0.1, coarse_test, 4.0),
        (0.05, BUNNY_DEEP_DECREASE, 6.0),
        (0.05, coarse_test, 1.5),
        (0.05, BUNNY_DECREASE, 0.4),
    ];
    let stages = if a.quick { &stages[..3] } else { &stages[..] };
    let widths: Vec<f64> = stages.iter().map(|s| s.0).collect();
    let mut plan =
        schedule(&widths, stages.iter().map(|s| s.1.0).collect(), stages.iter().map(|s| budget(s.2)).collect())?;
    plan.decrease_window = Some(stages.iter().map(|s| s.1.1).collect());
    for norm in [NormKind::H1, NormKind::L2Lumped] {
        let name = if norm == NormKind::H1 { "h1" } else { "l2-lumped" };
        let run = dir.join(name);
        let mut config = shipped.clone();
        config.model.norm = norm;
        config.model.normalize = true;
        config.model.gamma_f = BUNNY_GAMMA_F;
        config.model.gamma_w = a.gamma_w;
        config.optimizer.momentum_metric = fshape_match::Metric::Energy;
        config.optimizer.memory = BUNNY_LBFGS_MEMORY;
        config.schedule = Some(plan.clone());
        let stages_text = if a.quick {
            "three stages on the level-3 sphere: k_p 0.2, 0.1, 0.05"
        } else {
            "five stages: k_p 0.2, 0.1, 0.05 on the level-3 sphere,\n\
             0.05 on the level-4 sphere, 0.05 on the template (--stage-templates)"
        };
        let header = format!(
            "fshape demo bunny: data/configs/bunny.toml with norm {name}, scale-free weights\n\
             (gamma_w {}, gamma_f {}), p_0 in the energy metric, L-BFGS memory {}, and\n\
             {stages_text},\neach ending when J fell by less than {} over {} iterations\n\
             (the k_p 0.05 stage on the level-3 sphere: {} over {}{}).",
            a.gamma_w,
            BUNNY_GAMMA_F,
            BUNNY_LBFGS_MEMORY,
            coarse_test.0,
            coarse_test.1,
            BUNNY_DEEP_DECREASE.0,
            BUNNY_DEEP_DECREASE.1,
            if a.quick {
                String::new()
            } else {
                format!("; the last stage: {} over {}", BUNNY_DECREASE.0, BUNNY_DECREASE.1)
            }
        );
        eprintln!("bunny: {name} -> {}", run.display());
        run_match(&sp, &tp, &header, &config, &run, (0.0, 90.0), &stage_templates)
            .with_context(|| format!("bunny, {name}"))?;
    }
    render_from_below(&dir, &template, &target)
}

/// The paper's comparison of the norms (its figure of the bunny from
/// below): both runs' end states and the target seen from −y, where the
/// target has its holes, in one frame and the colour range of template
/// and target: DIR/below_h1.png, below_l2-lumped.png, below_target.png.
fn render_from_below(dir: &Path, template: &fshape_mesh::FShape, target: &fshape_mesh::FShape) -> Result<()> {
    let end = |name: &str| io::read_mesh(&dir.join(name).join("state_005.ply"), &io::ReadOptions::default());
    let (h1, l2) = (end("h1")?, end("l2-lumped")?);
    let view = fshape_report::render::View::fit(&[&h1, &l2, target], 0.0, 0.0).with_range_of(&[template, target]);
    for (shape, name) in [(&h1, "h1"), (&l2, "l2-lumped"), (target, "target")] {
        let path = dir.join(format!("below_{name}.png"));
        io::write_atomic(&path, &fshape_report::render::picture(shape, &view)?, false)?;
    }
    eprintln!("bunny: both norms and the target seen from below -> {}", dir.join("below_*.png").display());
    Ok(())
}
