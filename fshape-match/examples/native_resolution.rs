//! Time to quality at native resolution: a real cortex with its real
//! signal registered onto a copy of itself moved by a known smooth
//! displacement with a known signal change ([`fshape_match::demo::displaced`]).
//!
//! ```text
//! cargo run --release -p fshape-match --example native_resolution -- CASE [--out DIR] [--config FILE] [--profile]
//! ```
//!
//! CASE is `s1` (data/pycortex_S1/lh.pia, 152 893 vertices, with its
//! pial-to-white distance) or `conte69` (data/conte69_32k/lh.midthickness,
//! 32 492 vertices, with its thickness; the medial wall, `nan` in the
//! file as HCP ships it, masked: it moves with the surface and counts in
//! the geometric attachment, its thickness counts nowhere), or
//! `conte69-maps`: the same with two maps, thickness and HCP's T1w/T2w
//! myelin map (data/conte69_32k/lh.t1wt2w), NaN on the same wall, each
//! with its own signal width (1 mm and 0.5, about three of its
//! deviations). S1's pial-to-white distance has no missing values (its
//! wall is not marked).
//! The target is the source moved by six 20 mm wide bumps of
//! displacement, at most 10 mm, with four 20 mm wide bumps of ±½ standard
//! deviation added to its signal (seed 35). The configuration
//! is [`config`]'s for the surface's size unless `--config` gives one.
//! It prints a line per iteration, then the time, evaluations, peak
//! memory (the process's VmHWM) and `fshape quality`'s figures before
//! and after, and writes source, target and matched shape (PLY) and
//! summary.json into DIR
//! (default target/native_resolution/CASE). `--profile` instead times two
//! evaluations of J and its gradient at full resolution with the last
//! stage's kernels, from zero momenta, split into kernel sums, FEM and
//! data attachment (the first two run at the same time in parallel).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use fshape_match::{Config, Control, Iteration, Observer, Session, StageSpec};
use fshape_mesh::io::{self, Encoding, ReadOptions};

/// The registration the benchmark runs on a surface of `n` vertices: the
/// cortex demo's model (H¹ metamorphosis, ℓ = 5 mm; deformation widths 20
/// and 10 mm with τ = 1e-6; attachment gaussian:σ / `kernel_signal` (gaussian:1
/// mm for one map) / Binet with τ = 1e-6), γ_f = 0.01, RK4 with 5 steps, p_0 in the energy
/// metric, and four stages: k_p 20, 10 and 5 mm on copies simplified to
/// 2000, 8000 and a fifth of the vertices (at least 8000; the targets
/// simplified alike), then k_p 2.5 mm on the surface itself, with at most
/// 100, 100, 60 and 10 iterations. A real pair (`prealign`: two surfaces
/// in their own frames) is rigidly pre-aligned first.
fn config(n: usize, kernel_signal: &str, prealign: bool) -> Result<Config> {
    let third = (n / 5 / 1000 * 1000).max(8000);
    let prealign = if prealign { "[prealign]\nkind = \"rigid\"\n" } else { "" };
    let text = format!(
        r#"
[model]
kind = "metamorphosis"
norm = "h1"
length = 5.0
gamma_f = 0.01

[deformation]
widths = [20.0, 10.0]
tolerance = 1e-6

[integrator]
steps = 5

[attachment]
kernel_geom = "gaussian:5"
kernel_signal = "{kernel_signal}"
kernel_grass = "binet"
tolerance = 1e-6

[optimizer]
momentum_metric = "energy"

[[stage]]
kernel_geom = "gaussian:20"
max_iterations = 100
decrease_tolerance = 1e-2
decrease_window = 5
vertices = 2000

[[stage]]
kernel_geom = "gaussian:10"
max_iterations = 100
decrease_tolerance = 1e-2
decrease_window = 5
vertices = 8000

[[stage]]
kernel_geom = "gaussian:5"
max_iterations = 60
decrease_tolerance = 1e-3
decrease_window = 5
vertices = {third}

[[stage]]
kernel_geom = "gaussian:2.5"
max_iterations = 10
decrease_tolerance = 1e-3
decrease_window = 3

{prealign}"#
    );
    Ok(Config::parse(&text)?)
}

/// A line per stage and per iteration, with the elapsed time.
struct Lines(Instant);

impl Observer for Lines {
    fn stage_started(&mut self, stage: usize, stages: usize, spec: &StageSpec, done: usize) -> Control {
        let t = self.0.elapsed().as_secs_f64();
        println!("[{t:7.1} s] stage {}/{stages}: {} ({done} iterations done)", stage + 1, spec.label);
        Control::Continue
    }
    fn iteration(&mut self, stage: usize, r: &Iteration) -> Control {
        let t = self.0.elapsed().as_secs_f64();
        println!(
            "[{t:7.1} s] stage {} iteration {:3}: J {:.6e} (energy {:.3e}, signal {:.3e}, attachment {:.3e}), {} evaluations",
            stage + 1,
            r.iteration,
            r.value,
            r.energy,
            r.signal_energy,
            r.attachment,
            r.evaluations
        );
        Control::Continue
    }
}

/// Two evaluations of J and its gradient on the full-resolution pair with
/// the last stage's data term, split by component.
fn profile(source: &fshape_mesh::FShape, target: &fshape_mesh::FShape, config: &Config) -> Result<()> {
    let plan = config.plan(source, target)?;
    let last = plan.stages.last().context("a stage")?;
    let t = Instant::now();
    let problem = fshape_shoot::Problem::new(source, plan.model.clone())?.with_target(target, last.kernel.clone())?;
    println!(
        "set up in {:.2} s; deformation: {}; attachment: {}",
        t.elapsed().as_secs_f64(),
        problem.model().kernel().path(),
        last.kernel.position().path()
    );
    let (p0, pf) = (vec![0.0; source.points().len()], vec![0.0; source.n_vertices()]);
    for _ in 0..2 {
        let t = Instant::now();
        let g = problem.objective_grad(&p0, &pf)?;
        println!(
            "J and gradient {:.2} s: forward {:.2} s, backward {:.2} s; kernel sums {:.2} s, FEM {:.2} s, attachment {:.2} s",
            t.elapsed().as_secs_f64(),
            g.forward,
            g.backward,
            g.timings.kernels,
            g.timings.fem,
            g.timings.attachment
        );
    }
    Ok(())
}

/// The process's peak resident memory in MB (VmHWM), where Linux tells.
fn peak_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// A mesh of `data` with its maps (one column each, NaN where a map has
/// no value: those vertices are masked, as conte69's medial wall is),
/// mirrored when asked, and how many vertices are masked.
fn read_side(data: &Path, (mesh, maps, mirrored): (&str, &[&str], bool)) -> Result<(fshape_mesh::FShape, usize)> {
    let shape = io::read_mesh(&data.join(mesh), &ReadOptions::default())?;
    let columns =
        maps.iter().map(|s| Ok(io::csv::read_signal(&data.join(s), true)?.values)).collect::<Result<Vec<_>>>()?;
    let n = shape.n_vertices();
    if let Some((s, c)) = maps.iter().zip(&columns).find(|(_, c)| c.len() != n) {
        anyhow::bail!("{s}: {} values for a mesh of {n} vertices", c.len());
    }
    // A vertex missing in any map is masked (conte69's maps share their wall).
    let missing = (0..n).filter(|&v| columns.iter().any(|c| c[v].is_nan())).count();
    let mask =
        (missing > 0).then(|| (0..n).map(|v| f64::from(u8::from(columns.iter().all(|c| !c[v].is_nan())))).collect());
    let values: Vec<f64> = (0..n).flat_map(|v| columns.iter().map(move |c| c[v])).collect();
    let shape = shape.with_signals_and_mask(Some(values), columns.len(), mask)?;
    Ok((if mirrored { fshape_match::demo::mirror_x(&shape)? } else { shape }, missing))
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let case = args.first().map(String::as_str).unwrap_or("s1");
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).map(PathBuf::from);
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data");
    let (lh, lh_thickness) = ("conte69_32k/lh.midthickness.ply.gz", "conte69_32k/lh.thickness.csv.gz");
    let (rh, rh_thickness) = ("conte69_32k/rh.midthickness.ply.gz", "conte69_32k/rh.thickness.csv.gz");
    // (mesh, its maps, whether it is a right hemisphere to mirror (x → −x,
    // faces reoriented) so that both sides are left ones; the other side
    // of a real pair; the signal kernel).
    type Side<'a> = (&'a str, &'a [&'a str], bool);
    let (side, other, kernel_signal): (Side<'_>, Option<Side<'_>>, &str) = match case {
        "s1" => (("pycortex_S1/lh.pia.ply.gz", &["pycortex_S1/lh.pia_wm_distance.csv.gz"], false), None, "gaussian:1"),
        "conte69" => ((lh, &[lh_thickness], false), None, "gaussian:1"),
        "conte69-maps" => ((lh, &[lh_thickness, "conte69_32k/lh.t1wt2w.csv.gz"], false), None, "gaussian:1,0.5"),
        "conte69-pair" => ((lh, &[lh_thickness], false), Some((rh, &[rh_thickness], true)), "gaussian:1"),
        "conte69-pair-rh" => ((rh, &[rh_thickness], true), Some((lh, &[lh_thickness], false)), "gaussian:1"),
        other => anyhow::bail!("unknown case {other}: s1, conte69, conte69-maps, conte69-pair or conte69-pair-rh"),
    };
    let signal = side.1.join(" and ");
    let out = flag("--out").unwrap_or_else(|| Path::new("target/native_resolution").join(case));
    std::fs::create_dir_all(&out)?;
    let clock = Instant::now();
    let (source, missing) = read_side(&data, side)?;
    let (target, target_missing) = match other {
        Some(other) => read_side(&data, other)?,
        None => (fshape_match::demo::displaced(&source, 10.0, 20.0, 35)?.target, missing),
    };
    println!(
        "{case}: {} vertices, {} triangles onto {} vertices; signal {signal} ({missing} and {target_missing} missing values masked); read and paired in {:.1} s",
        source.n_vertices(),
        source.n_cells(),
        target.n_vertices(),
        clock.elapsed().as_secs_f64()
    );
    let config = match flag("--config") {
        Some(path) => Config::read(&path)?,
        None => config(source.n_vertices(), kernel_signal, other.is_some())?,
    };
    if args.iter().any(|a| a == "--profile") {
        return profile(&source, &target, &config);
    }
    std::fs::write(out.join("config.toml"), config.clone().with_stage_tables().to_toml())?;
    let start = Instant::now();
    let mut session = Session::new(&source, &target, &config).context("setting up")?;
    println!("set up in {:.1} s", start.elapsed().as_secs_f64());
    session.run(&mut Lines(start))?;
    let result = session.result()?;
    let seconds = start.elapsed().as_secs_f64();
    let last = result.trajectory.steps();
    let matched = source
        .clone()
        .with_points(result.trajectory.points(last).to_vec())?
        .with_signals(Some(result.trajectory.signal(last).to_vec()), source.n_channels())?;
    for (name, s) in [("source.ply", &source), ("target.ply", &target), ("matched.ply", &matched)] {
        io::write_mesh(&out.join(name), s, Encoding::Binary)?;
    }
    let (q0, q) = (result.initial_quality, result.quality);
    let pct = |v: f64| 100.0 * v;
    println!(
        "wall {seconds:.0} s ({:.1} min), {} evaluations, {} iterations, peak memory {:.0} MB",
        seconds / 60.0,
        result.evaluations,
        result.iterations,
        peak_mb().unwrap_or(f64::NAN)
    );
    println!(
        "mean distance {:.3} % -> {:.3} % of the diagonal ({:.1} mm); within 1 %: {:.1} % -> {:.1} %; signal error {:.2} % -> {:.2} % of its range",
        pct(q0.mean_distance),
        pct(q.mean_distance),
        q.diagonal,
        pct(q0.target_within_1pct),
        pct(q.target_within_1pct),
        pct(q0.signal_rms.unwrap_or(f64::NAN)),
        pct(q.signal_rms.unwrap_or(f64::NAN))
    );
    for (c, (a, b)) in q0.channels.iter().zip(&q.channels).enumerate().skip(1) {
        println!(
            "map {}: signal error {:.2} % -> {:.2} % of its range",
            c + 1,
            pct(a.signal_rms.unwrap_or(f64::NAN)),
            pct(b.signal_rms.unwrap_or(f64::NAN))
        );
    }
    let summary = serde_json::json!({
        "case": case,
        "vertices": source.n_vertices(),
        "seconds": seconds,
        "evaluations": result.evaluations,
        "iterations": result.iterations,
        "peak_mb": peak_mb(),
        "initial_quality": q0,
        "quality": q,
        "stages": result.stages,
    });
    std::fs::write(out.join("summary.json"), serde_json::to_string_pretty(&summary)?)?;
    Ok(())
}
