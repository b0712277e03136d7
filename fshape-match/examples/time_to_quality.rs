//! Time to quality: the paper's bunny registered with a budget of
//! iterations per stage, for several budgets, printing for each the wall
//! time and how close the result came (match quality). The table lets the
//! next change to the optimiser, the weights or the evaluations be
//! compared with this one in one run on one machine.
//!
//! ```sh
//! cargo run --release -p fshape-match --example time_to_quality -- [LEVEL] [NORM] [GAMMA_W] [GAMMA_F] [BUDGETS] [COARSE] [METRIC] [SIGNAL_METRIC]
//! # defaults: 3 h1 1e3 0.1 25,50,100 - euclidean  (LEVEL: the template icosphere, 5 = the paper's 10242 vertices,
//! # or one level per stage, e.g. 3,4,5: the coarse stages on coarser spheres;
//! # COARSE, e.g. midpoint:5: the integrator of the first two stages, - for the model's;
//! # METRIC, SIGNAL_METRIC: of p_0 and p^f, euclidean, l2 or energy; defaults euclidean, l2)
//! ```

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use fshape_match::{Config, NormKind, Session, demo};
use fshape_mesh::io::{ReadOptions, read_mesh};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or_else(|| default.to_string());
    let levels: Vec<u32> = arg(0, "3").split(',').map(str::parse).collect::<Result<_, _>>().context("LEVEL")?;
    let level = *levels.last().context("LEVEL")?;
    let norm = match arg(1, "h1").as_str() {
        "h1" => NormKind::H1,
        "l2-lumped" => NormKind::L2Lumped,
        "l2" => NormKind::L2,
        other => anyhow::bail!("NORM: {other} (h1, l2-lumped or l2)"),
    };
    let gamma_w: f64 = arg(2, "1e3").parse().context("GAMMA_W")?;
    let gamma_f: f64 = arg(3, "0.1").parse().context("GAMMA_F")?;
    let budgets: Vec<usize> =
        arg(4, "25,50,100").split(',').map(str::parse).collect::<Result<_, _>>().context("BUDGETS")?;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let bunny = read_mesh(&root.join("data/stanford_bunny/bunny_qslim_2581v.ply.gz"), &ReadOptions::default())?;
    let (template, target) = demo::bunny_setting_at_level(&bunny, level)?;
    // The shipped bunny configuration with scale-free weights and the
    // demo's coarse-to-fine schedule.
    let mut config = Config::read(&root.join("data/configs/bunny.toml"))?;
    config.model.norm = norm;
    config.model.normalize = true;
    (config.model.gamma_f, config.model.gamma_w) = (gamma_f, gamma_w);
    let mut schedule = fshape_match::ScheduleSection::new(
        ["gaussian:0.2", "gaussian:0.1", "gaussian:0.05"]
            .iter()
            .map(|k| fshape_match::PositionKernel::parse(k))
            .collect::<Result<_, _>>()?,
    );
    // COARSE: the integrator of the first two stages, `scheme:steps`
    // (e.g. midpoint:5); the last keeps the model's (RK4, 10 steps).
    if let Some(coarse) = args.get(5).filter(|c| *c != "-") {
        let (scheme, steps) = coarse.split_once(':').context("COARSE: scheme:steps")?;
        let scheme: fshape_shoot::Integrator =
            serde_json::from_value(serde_json::json!(scheme)).context("COARSE scheme")?;
        let steps: usize = steps.parse().context("COARSE steps")?;
        let last = (config.integrator.scheme, config.integrator.steps);
        schedule.scheme = Some(vec![scheme, scheme, last.0]);
        schedule.steps = Some(vec![steps, steps, last.1]);
    }
    config.schedule = Some(schedule);
    config.optimizer.momentum_metric =
        serde_json::from_value(serde_json::json!(arg(6, "euclidean"))).context("METRIC: euclidean, l2 or energy")?;
    config.optimizer.signal_metric =
        serde_json::from_value(serde_json::json!(arg(7, "l2"))).context("SIGNAL_METRIC: euclidean, l2 or energy")?;
    println!(
        "bunny, template level {level} ({} vertices), stage levels {levels:?}, {:?}, gamma_W {gamma_w:e}, gamma_f {gamma_f}, {} threads",
        template.n_vertices(),
        norm,
        rayon::current_num_threads()
    );
    println!();
    println!(
        "| iterations per stage | stops | evaluations | seconds | J | mean distance | 95th pct. | max | target within 1% | signal error |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for budget in budgets {
        config.optimizer.max_iterations = budget;
        let start = Instant::now();
        let mut session = Session::new(&template, &target, &config)?;
        if levels.len() > 1 {
            anyhow::ensure!(levels.len() == 3, "LEVEL: one level, or one per stage (3)");
            let coarse = |l: u32| -> Result<Option<fshape_mesh::FShape>> {
                Ok(if l == level { None } else { Some(demo::bunny_setting_at_level(&bunny, l)?.0) })
            };
            session = session.with_stage_templates(vec![coarse(levels[0])?, coarse(levels[1])?, None])?;
        }
        session.run(&mut ())?;
        let r = session.result()?;
        let seconds = start.elapsed().as_secs_f64();
        let stops: Vec<String> = r.stages.iter().map(|s| format!("{:?}", s.stop)).collect();
        let q = r.quality;
        println!(
            "| {budget} | {} | {} | {seconds:.1} | {:.4e} | {:.3}% | {:.3}% | {:.3}% | {:.1}% | {:.2}% |",
            stops.join(", "),
            r.evaluations,
            r.energies.value,
            100.0 * q.mean_distance,
            100.0 * q.p95_distance,
            100.0 * q.max_distance,
            100.0 * q.target_within_1pct,
            100.0 * q.signal_rms.unwrap_or(f64::NAN)
        );
    }
    Ok(())
}
