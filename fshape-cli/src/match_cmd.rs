//! `fshape match`: minimise J over the initial momenta, stage by stage of
//! the coarse-to-fine schedule, with a checkpoint after every accepted
//! iteration so that a run killed at any point resumes (`--resume`) to the
//! result an uninterrupted run gives, bit for bit.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use fshape_mesh::FShape;
use fshape_mesh::io;
use fshape_shoot::matching::{MatchObjective, Metrics, Unknowns};
use fshape_shoot::optimize::{State, Stop};
use fshape_shoot::{Config, ModelKind, Problem};
use serde::{Deserialize, Serialize};

/// The command's arguments.
pub struct MatchArgs<'a> {
    pub source: &'a Path,
    pub target: &'a Path,
    pub config: &'a Path,
    pub out: &'a Path,
    pub resume: bool,
    pub stop_after: Option<usize>,
    pub signal_name: Option<String>,
    pub times: &'a [f64],
    /// Azimuth and elevation of the renders, degrees.
    pub view: (f64, f64),
}

/// One accepted iteration.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
struct Iteration {
    iteration: usize,
    /// J and its parts at the accepted point.
    value: f64,
    energy: f64,
    signal_energy: f64,
    attachment: f64,
    /// Accepted step length and objective evaluations so far.
    step: f64,
    evaluations: usize,
}

/// A finished stage of the schedule.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
struct Stage {
    kernel_geom: String,
    stop: Stop,
    reason: String,
    initial: Iteration,
    iterations: Vec<Iteration>,
}

/// Everything needed to continue: written atomically after every
/// accepted iteration.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Checkpoint {
    /// FNV-1a of the source, target and configuration bytes: a checkpoint
    /// of other inputs is refused.
    fingerprint: String,
    /// Finished stages.
    done: Vec<Stage>,
    /// The current stage's optimiser state and records (`None` between
    /// stages).
    current: Option<(State, Iteration, Vec<Iteration>)>,
    /// The unknowns at the end of the last finished stage (warm start).
    warm: Option<Vec<f64>>,
    /// Wall seconds spent on this match so far, by this and earlier
    /// invocations, as of this write.
    seconds: f64,
}

/// FNV-1a, 64 bits, as hex: only to recognise a checkpoint of the same
/// inputs (written by hand: a dozen lines, no cryptographic need).
fn fingerprint(parts: &[&[u8]]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for p in parts {
        for &b in p.iter().chain(&[0xff]) {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    format!("{h:016x}")
}

#[derive(Serialize)]
struct Summary<'a> {
    source: String,
    target: String,
    config: String,
    model: String,
    norm: &'static str,
    gamma_v: f64,
    gamma_f: f64,
    gamma_w: f64,
    steps: usize,
    metrics: Metrics,
    stages: &'a [Stage],
    /// J's parts at the result.
    final_value: f64,
    final_energy: f64,
    final_attachment: f64,
    /// √H_0: the geodesic distance (metamorphosis; the path energy's root
    /// otherwise).
    geodesic_distance: f64,
    hamiltonian: Vec<f64>,
    iterations: usize,
    evaluations: usize,
    seconds: f64,
    files: Vec<String>,
}

fn parts(it: usize, s: &State, o: &fshape_shoot::Objective) -> Iteration {
    Iteration {
        iteration: it,
        value: o.value,
        energy: o.energy,
        signal_energy: o.signal_energy,
        attachment: o.attachment,
        step: s.step,
        evaluations: s.evaluations,
    }
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    io::write_atomic(path, &serde_json::to_vec_pretty(value)?, false)?;
    Ok(())
}

pub fn run(a: &MatchArgs<'_>) -> Result<()> {
    let start = Instant::now();
    let bytes = |p: &Path| std::fs::read(p).with_context(|| format!("reading {}", p.display()));
    let print = fingerprint(&[&bytes(a.source)?, &bytes(a.target)?, &bytes(a.config)?]);
    let config = Config::read(a.config)?;
    let model = config.model()?;
    let schedule = config.schedule()?;
    let (settings, metric) = config.optimizer()?;
    if let Some(t) = a.times.iter().find(|t| !(0.0..=1.0).contains(*t)) {
        bail!("--times: {t} is outside [0, 1]");
    }
    let source = crate::load(a.source, a.signal_name.clone(), None)?;
    let target = crate::load(a.target, a.signal_name.clone(), None)?;
    if source.dim() != target.dim() || source.kind() != target.kind() {
        bail!(
            "{} and {} are not the same kind of shape (dimension or cell type)",
            a.source.display(),
            a.target.display()
        );
    }
    let checkpoint_path = a.out.join("checkpoint.json");
    let mut ck = if a.resume {
        let text = std::fs::read_to_string(&checkpoint_path)
            .with_context(|| format!("--resume: reading {}", checkpoint_path.display()))?;
        let ck: Checkpoint = serde_json::from_str(&text).with_context(|| format!("{}", checkpoint_path.display()))?;
        if ck.fingerprint != print {
            bail!(
                "{}: written for other inputs (source, target or configuration changed); remove it or drop --resume",
                checkpoint_path.display()
            );
        }
        ck
    } else {
        Checkpoint { fingerprint: print, done: Vec::new(), current: None, warm: None, seconds: 0.0 }
    };
    std::fs::create_dir_all(a.out).with_context(|| format!("creating {}", a.out.display()))?;
    // Wall time of the earlier runs of this match (every checkpoint records
    // the total so far, so a killed run loses at most one iteration's).
    let earlier = ck.seconds;
    let (kind, norm, steps) = (model.kind, model.norm.name(), model.steps);
    let (gamma_v, gamma_f, gamma_w) = (model.gamma_v, model.gamma_f, model.gamma_w);
    let mut problem = Problem::new(&source, model).with_context(|| format!("setting up {}", a.source.display()))?;
    let unknowns = Unknowns::new(&problem, metric)?;
    let mut budget = a.stop_after;
    let mut has_target = false;
    for (k, (geom, kernel)) in schedule.iter().enumerate().skip(ck.done.len()) {
        problem.set_target(&target, kernel.clone()).with_context(|| format!("target {}", a.target.display()))?;
        has_target = true;
        let mut objective = MatchObjective::new(&problem, unknowns.clone());
        let (mut state, initial, mut records) = match ck.current.take() {
            Some(c) => c,
            None => {
                let x0 = ck.warm.clone().unwrap_or_else(|| vec![0.0; unknowns.len()]);
                let state = State::start(x0, &mut objective)?;
                let first = parts(0, &state, objective.last.as_ref().context("the objective was evaluated")?);
                (state, first, Vec::new())
            }
        };
        let bar = progress(&settings, k, schedule.len(), geom, records.len());
        let stop = loop {
            if budget == Some(0) {
                ck.current = Some((state, initial, records));
                ck.seconds = earlier + start.elapsed().as_secs_f64();
                write_json(&checkpoint_path, &ck)?;
                bar.abandon_with_message("stopped by --stop-after; continue with --resume");
                eprintln!("stopped after the requested iterations; checkpoint in {}", checkpoint_path.display());
                return Ok(());
            }
            if let Some(stop) = state.iterate(&settings, &mut objective)? {
                break stop;
            }
            let it = parts(state.iteration, &state, objective.last.as_ref().context("the objective was evaluated")?);
            bar.set_position(state.iteration as u64);
            bar.set_message(format!(
                "J {:.4e} = H {:.3e} + γ_W·A {:.3e}, step {:.2e}",
                it.value,
                it.energy,
                gamma_w * it.attachment,
                it.step
            ));
            records.push(it);
            budget = budget.map(|b| b - 1);
            ck.current = Some((state.clone(), initial.clone(), records.clone()));
            ck.seconds = earlier + start.elapsed().as_secs_f64();
            write_json(&checkpoint_path, &ck)?;
            ck.current = None;
        };
        bar.finish_with_message(format!("{} after {} iterations", stop.describe(), records.len()));
        ck.warm = Some(state.x.clone());
        ck.done.push(Stage {
            kernel_geom: geom.clone(),
            stop,
            reason: stop.describe().into(),
            initial,
            iterations: records,
        });
        ck.seconds = earlier + start.elapsed().as_secs_f64();
        write_json(&checkpoint_path, &ck)?;
    }
    // The result: shoot the final momenta, write everything. (Resuming a
    // finished run skips every stage: the data term is then set here.)
    if let Some((_, kernel)) = schedule.last().filter(|_| !has_target) {
        problem.set_target(&target, kernel.clone()).with_context(|| format!("target {}", a.target.display()))?;
    }
    let x = ck.warm.clone().context("at least one stage ran")?;
    let (p0, pf) = unknowns.unpack(&x);
    let (objective, traj) = problem.objective(&p0, &pf)?;
    let template = problem.template().clone();
    let (mut outputs, mut files) = crate::trajectory_files(&template, &traj, a.times, a.out)?;
    let csv = |header: &str, v: &[f64], w: usize| -> Vec<u8> {
        let mut s = format!("{header}\n");
        for row in v.chunks_exact(w) {
            let cells: Vec<String> = row.iter().map(|c| format!("{c}")).collect();
            s.push_str(&cells.join(","));
            s.push('\n');
        }
        s.into_bytes()
    };
    let dim = template.dim();
    let header = if dim == 3 { "p_x,p_y,p_z" } else { "p_x,p_y" };
    outputs.push((a.out.join("p0.csv"), csv(header, &p0, dim)));
    files.push("p0.csv".into());
    if kind != ModelKind::Lddmm {
        outputs.push((a.out.join("pf.csv"), csv(if kind == ModelKind::Tangential { "zeta" } else { "pf" }, &pf, 1)));
        files.push("pf.csv".into());
    }
    outputs.push((a.out.join("momenta.vtk"), momenta_vtk(&template, &p0, &pf).into_bytes()));
    files.push("momenta.vtk".into());
    // Renders of the geodesic at the chosen times and of the target, all
    // with one camera, framing and colour range.
    let frames: Vec<FShape> = a
        .times
        .iter()
        .map(|&t| {
            let (x, f) = traj.at(t);
            template.clone().with_points(x)?.with_signal(Some(f))
        })
        .collect::<Result<_, _>>()?;
    let mut all: Vec<&FShape> = frames.iter().collect();
    all.push(&target);
    let view = crate::render::View::fit(&all, a.view.0, a.view.1).with_range_of(&[&frames[0], &target]);
    for (k, frame) in frames.iter().enumerate() {
        let name = format!("render_{k:03}.png");
        outputs.push((a.out.join(&name), crate::render::png(&crate::render::rasterise(frame, &view))?));
        files.push(name);
    }
    outputs.push((a.out.join("target.png"), crate::render::png(&crate::render::rasterise(&target, &view))?));
    files.push("target.png".into());
    let (svg, png) = energy_plot(&ck.done, gamma_w)?;
    outputs.push((a.out.join("energy.svg"), svg.into_bytes()));
    outputs.push((a.out.join("energy.png"), png));
    files.extend(["energy.svg".into(), "energy.png".into()]);
    let iterations = ck.done.iter().map(|s| s.iterations.len()).sum();
    let evaluations = ck.done.iter().map(|s| s.iterations.last().unwrap_or(&s.initial).evaluations).sum();
    let summary = Summary {
        source: a.source.display().to_string(),
        target: a.target.display().to_string(),
        config: a.config.display().to_string(),
        model: format!("{kind:?}").to_lowercase(),
        norm,
        gamma_v,
        gamma_f,
        gamma_w,
        steps,
        metrics: metric,
        stages: &ck.done,
        final_value: objective.value,
        final_energy: objective.energy,
        final_attachment: objective.attachment,
        geodesic_distance: objective.energy.max(0.0).sqrt(),
        hamiltonian: traj.hamiltonian.clone(),
        iterations,
        evaluations,
        seconds: earlier + start.elapsed().as_secs_f64(),
        files: files.clone(),
    };
    outputs.push((a.out.join("summary.json"), serde_json::to_vec_pretty(&summary)?));
    for (path, bytes) in &outputs {
        io::write_atomic(path, bytes, false)?;
    }
    println!(
        "{} -> {}: J {:.6e} (energy {:.4e}, attachment {:.4e}) after {iterations} iterations in {} stage(s); wrote {} files to {}",
        a.source.display(),
        a.target.display(),
        objective.value,
        objective.energy,
        objective.attachment,
        ck.done.len(),
        outputs.len(),
        a.out.display()
    );
    Ok(())
}

/// A progress bar on stderr (drawn only on a terminal).
fn progress(
    settings: &fshape_shoot::optimize::Settings,
    stage: usize,
    stages: usize,
    geom: &str,
    done: usize,
) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(settings.max_iterations as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} it, ETA {eta} | {msg}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    bar.set_prefix(format!("stage {}/{stages} ({geom})", stage + 1));
    bar.set_position(done as u64);
    bar
}

/// J, the energy and γ_W·A against the iteration number (log scale), all
/// stages one after the other, as (SVG text, PNG bytes).
fn energy_plot(stages: &[Stage], gamma_w: f64) -> Result<(String, Vec<u8>)> {
    use plotters::prelude::*;
    let mut series: [Vec<(f64, f64)>; 3] = Default::default();
    let mut n = 0usize;
    for s in stages {
        for it in std::iter::once(&s.initial).chain(&s.iterations) {
            for (k, v) in [it.value, it.energy, gamma_w * it.attachment].into_iter().enumerate() {
                if v > 0.0 && v.is_finite() {
                    series[k].push((n as f64, v));
                }
            }
            n += 1;
        }
    }
    register_plot_font()?;
    let mut svg = String::new();
    draw_energy(SVGBackend::with_string(&mut svg, PLOT_SIZE).into_drawing_area(), &series, n)?;
    let mut rgb = vec![0u8; (PLOT_SIZE.0 * PLOT_SIZE.1 * 3) as usize];
    draw_energy(BitMapBackend::with_buffer(&mut rgb, PLOT_SIZE).into_drawing_area(), &series, n)?;
    let png = crate::render::png_sized(&rgb, PLOT_SIZE.0, PLOT_SIZE.1)?;
    Ok((svg, png))
}

const PLOT_SIZE: (u32, u32) = (720, 420);

/// The bitmap backend draws text with ab_glyph from a font registered at run
/// time; the font is embedded (assets/, DejaVu licence) so that a headless
/// machine without system fonts still labels its plots.
fn register_plot_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = DONE.get_or_init(|| {
        plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            include_bytes!("../assets/DejaVuSansMono.ttf"),
        )
        .is_ok()
    });
    anyhow::ensure!(*ok, "plot: the embedded font assets/DejaVuSansMono.ttf did not load");
    Ok(())
}

fn draw_energy<DB: plotters::prelude::DrawingBackend>(
    root: plotters::drawing::DrawingArea<DB, plotters::coord::Shift>,
    series: &[Vec<(f64, f64)>; 3],
    n: usize,
) -> Result<()> {
    use plotters::prelude::*;
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("plot: {e}");
    let all = series.iter().flatten().map(|p| p.1);
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    let (lo, hi) = if lo.is_finite() { (lo / 2.0, hi * 2.0) } else { (1e-3, 1.0) };
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .caption("matching: objective by iteration", ("sans-serif", 18))
        .build_cartesian_2d(0f64..(n.max(2) - 1) as f64, (lo..hi).log_scale())
        .map_err(err)?;
    chart.configure_mesh().x_desc("iteration").draw().map_err(err)?;
    for (k, (name, color)) in [("J", BLACK), ("energy H", BLUE), ("γ_W·A", RED)].into_iter().enumerate() {
        chart
            .draw_series(LineSeries::new(series[k].clone(), color))
            .map_err(err)?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color));
    }
    chart.configure_series_labels().background_style(WHITE).border_style(BLACK).draw().map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// The template with p_0 as a vector field `p0` and p^f as a scalar field
/// `pf`, in legacy ASCII VTK (ParaView's glyph filter draws the arrows).
/// Written by hand: the mesh writer carries one scalar signal only, and the
/// legacy format's three sections are a few lines each.
fn momenta_vtk(template: &FShape, p0: &[f64], pf: &[f64]) -> String {
    let (n, dim) = (template.n_vertices(), template.dim());
    let k = template.kind().n_corners();
    let pad = |row: &[f64]| -> String {
        let mut v: Vec<String> = row.iter().map(|c| format!("{c}")).collect();
        v.resize(3, "0".into());
        v.join(" ")
    };
    let mut s = format!(
        "# vtk DataFile Version 3.0\nfshape match: initial momenta\nASCII\nDATASET POLYDATA\nPOINTS {n} double\n"
    );
    for p in template.points().chunks_exact(dim) {
        s.push_str(&pad(p));
        s.push('\n');
    }
    let cells = template.n_cells();
    let section = if k == 2 { "LINES" } else { "POLYGONS" };
    s.push_str(&format!("{section} {cells} {}\n", cells * (k + 1)));
    for c in template.cells().chunks_exact(k) {
        let ids: Vec<String> = c.iter().map(|i| i.to_string()).collect();
        s.push_str(&format!("{k} {}\n", ids.join(" ")));
    }
    s.push_str(&format!("POINT_DATA {n}\nVECTORS p0 double\n"));
    for p in p0.chunks_exact(dim) {
        s.push_str(&pad(p));
        s.push('\n');
    }
    s.push_str("SCALARS pf double 1\nLOOKUP_TABLE default\n");
    for v in pf {
        s.push_str(&format!("{v}\n"));
    }
    s
}
