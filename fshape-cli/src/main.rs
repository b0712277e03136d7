//! `fshape`: inspect, convert, compare, shoot and register functional
//! shapes. Exit codes: 0 success, 1 bad input (the message names the file
//! and the place), 2 usage error.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use fshape_fem::{Norm, SignalNorm};
use fshape_mesh::io::{self, Encoding, ReadOptions};
use fshape_mesh::{FShape, Finding, Repairs, Severity};
use fshape_varifold::{Attachment, VarifoldKernel};
use serde::Serialize;

mod atlas_cmd;
mod batch_cmd;
mod checkpoint_cmd;
mod demo;
mod match_cmd;
#[cfg(feature = "mpi")]
mod processes;
mod render;

#[derive(Parser)]
#[command(name = "fshape", version, about = "Functional shapes: meshes carrying a signal, and their metamorphoses")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print counts, dimension, bounding box, total volume, signal range and
    /// the validation report of a mesh file (.ply, .obj, .vtk, .gii, optionally
    /// .gz, or a FreeSurfer surface such as lh.pial).
    Info {
        /// The mesh file.
        file: PathBuf,
        /// Vertex property to read as the signal (default: `signal` if present).
        #[arg(long)]
        signal_name: Option<String>,
        /// Per-vertex signal file replacing the mesh's signal: a CSV column with a
        /// header, GIfTI (.shape.gii, .func.gii), FreeSurfer curv (lh.thickness) or .mgh/.mgz.
        #[arg(long)]
        signal: Option<PathBuf>,
        /// Print JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Assemble the signal norm matrix D_s of a mesh (lumped or P1 mass, or
    /// H1 = mass + length² × stiffness) and print a summary; optionally
    /// export it in MatrixMarket format (symmetric, lower triangle).
    Fem {
        /// The mesh file.
        file: PathBuf,
        /// Which norm: l2-lumped, l2 or h1.
        #[arg(long, default_value = "h1")]
        norm: String,
        /// Length scale ℓ of the H1 gradient term, in the mesh's units
        /// (the paper uses 1; choose a length of the data's scale, e.g. a few
        /// mm on a cortex).
        #[arg(long, default_value_t = 1.0)]
        length: f64,
        /// Write D_s to this MatrixMarket file.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// How close a shape X is to a target Y, as `fshape match` reports a
    /// registration: the mean symmetric closest-point distance, its 95th
    /// percentile and maximum, and the share of Y within 1 % of X, as
    /// fractions of Y's bounding-box diagonal; the signal error at closest
    /// points (rms and 99th percentile, of Y's signal range; the rms also
    /// over the part of Y within 1 % of X and the part beyond) and the
    /// roughness of X's signal against Y's (the ratio of their Dirichlet
    /// seminorms: above 1 when X's signal oscillates). The signal error and
    /// roughness again from X's side: over all of X, over its part beyond
    /// 1 % of Y and over its part past Y's boundary (e.g. over Y's holes),
    /// which Y's samples cannot see.
    Quality {
        /// The shape X (e.g. a registration's state at t = 1).
        source: PathBuf,
        /// The target Y.
        target: PathBuf,
        /// Vertex property to read as the signal of both files (default `signal`).
        #[arg(long)]
        signal_name: Option<String>,
        /// Per-vertex signal file for the source (CSV, GIfTI, FreeSurfer curv or MGH).
        #[arg(long)]
        source_signal: Option<PathBuf>,
        /// Per-vertex signal file for the target (CSV, GIfTI, FreeSurfer curv or MGH).
        #[arg(long)]
        target_signal: Option<PathBuf>,
        /// Print JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// The data attachment A(X, Y) = ⟨X,X⟩ − 2⟨X,Y⟩ + ⟨Y,Y⟩ between two
    /// fshapes (functional varifold; varifold or current without a signal
    /// kernel). Prints A itself, a squared distance, then the three inner
    /// products. Widths use exp(−u/(2σ²)); fshapesTk's σ is ours × √2.
    Distance {
        /// The source mesh X.
        source: PathBuf,
        /// The target mesh Y.
        target: PathBuf,
        /// Position kernel: gaussian:σ, gaussian:σ1,σ2,... (a sum) or cauchy:σ.
        #[arg(long)]
        kernel_geom: String,
        /// Signal kernel gaussian:σ_f (omit for the purely geometric distance).
        #[arg(long)]
        kernel_signal: Option<String>,
        /// Direction kernel: linear (currents), binet, gaussian-oriented:σ_t
        /// or gaussian-unoriented:σ_t.
        #[arg(long)]
        kernel_grass: String,
        /// Truncate the position kernel at tolerance τ (changes each inner
        /// product by at most τ·k(0)·mass(X)·mass(Y)); exact by default.
        #[arg(long)]
        tolerance: Option<f64>,
        /// Vertex property to read as the signal of both files (default `signal`).
        #[arg(long)]
        signal_name: Option<String>,
        /// Per-vertex signal file for the source (CSV, GIfTI, FreeSurfer curv or MGH).
        #[arg(long)]
        source_signal: Option<PathBuf>,
        /// Per-vertex signal file for the target (CSV, GIfTI, FreeSurfer curv or MGH).
        #[arg(long)]
        target_signal: Option<PathBuf>,
        /// Print JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Shoot a metamorphosis geodesic from SOURCE with initial momenta and
    /// write the states at the chosen times (VTK + ParaView .pvd, PLY with
    /// the signal as vertex property `signal`) and summary.json.
    Shoot {
        /// The template mesh (its signal, if any, is f_0; else 0).
        source: PathBuf,
        /// Initial momenta p_0: CSV, a header line, then p_x,p_y (or p_x,p_y,p_z) per vertex.
        #[arg(long)]
        momentum: PathBuf,
        /// Signal momentum p^f (one-column CSV; default 0). For the
        /// tangential model, the signal residual ζ.
        #[arg(long)]
        signal_momentum: Option<PathBuf>,
        /// Model configuration (TOML; see fshape_match::Config).
        #[arg(long)]
        config: PathBuf,
        /// Output directory (created if needed).
        #[arg(long)]
        out: PathBuf,
        /// Times in [0, 1] at which to write the state.
        #[arg(long, value_delimiter = ',', default_value = "0,0.25,0.5,0.75,1")]
        times: Vec<f64>,
        /// Vertex property of SOURCE to read as the signal.
        #[arg(long)]
        signal_name: Option<String>,
    },
    /// Register SOURCE onto TARGET: minimise J = H + γ_W·A over the initial
    /// momenta (L-BFGS by default), stage by stage of the configuration's
    /// coarse-to-fine schedule. Writes the geodesic (VTK + .pvd, PLY), the
    /// momenta (p0.csv, pf.csv, momenta.vtk), summary.json and energy.svg/.png.
    /// A checkpoint is written after every iteration: after Ctrl-C or a
    /// kill, `--resume` continues to the same result, bit for bit.
    Match {
        /// The template mesh (its signal, if any, is f_0; else 0).
        source: PathBuf,
        /// The target mesh.
        target: PathBuf,
        /// Model, attachment, optimizer and schedule (TOML; see fshape_match::Config).
        #[arg(long)]
        config: PathBuf,
        /// Output directory (created if needed).
        #[arg(long)]
        out: PathBuf,
        /// Continue from OUT/checkpoint.bin.
        #[arg(long)]
        resume: bool,
        /// Stop after this many iterations in this run, leaving the checkpoint.
        #[arg(long)]
        stop_after: Option<usize>,
        /// Times in [0, 1] at which to write the geodesic.
        #[arg(long, value_delimiter = ',', default_value = "0,0.25,0.5,0.75,1")]
        times: Vec<f64>,
        /// Vertex property of both meshes to read as the signal.
        #[arg(long)]
        signal_name: Option<String>,
        /// Per-vertex signal file for the source (CSV, GIfTI, FreeSurfer curv or MGH).
        #[arg(long, visible_alias = "signal")]
        source_signal: Option<PathBuf>,
        /// Per-vertex signal file for the target (CSV, GIfTI, FreeSurfer curv or MGH).
        #[arg(long)]
        target_signal: Option<PathBuf>,
        /// Camera of the PNG renders of surfaces in space: azimuth,elevation in degrees.
        #[arg(long, value_delimiter = ',', num_args = 1, allow_hyphen_values = true, default_values_t = [30.0, 20.0])]
        view: Vec<f64>,
        /// Coarser versions of SOURCE (same surface, fewer vertices, with
        /// its signal), one per stage before the last: the coarse stages
        /// run on them and carry their momenta to the next.
        #[arg(long, value_delimiter = ',')]
        stage_templates: Vec<PathBuf>,
    },
    /// Register every pair of a table: one `fshape match` per row, each in
    /// OUT/NAME (its own checkpoint and outputs), then OUT/index.csv and
    /// index.json (every row's status, J, match quality, time and error).
    /// Run the same command again to resume: finished rows are kept,
    /// stopped rows resume, failed ones are tried again. A failed row does
    /// not stop the others (the exit status is 1 if any failed).
    Batch {
        /// The pairs: a header naming the columns (source, target, and
        /// optionally source_signal, target_signal, name), then one pair per
        /// line; paths relative to the table, `#` comments.
        pairs: PathBuf,
        /// The configuration of every registration (as for `fshape match`).
        #[arg(long)]
        config: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// Rows registered at once on this machine, the cores shared among
        /// them (results are the same bits in any mode).
        #[arg(long, default_value_t = 1)]
        jobs: usize,
        /// This task's share of the rows, I/N with 0 <= I < N (rows I,
        /// I + N, ...): a cluster job array. Default: Slurm's
        /// SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN of SLURM_ARRAY_TASK_COUNT
        /// when set, else every row.
        #[arg(long)]
        shard: Option<String>,
        /// Only write the index from the rows' directories.
        #[arg(long)]
        index_only: bool,
        /// Times in [0, 1] at which to write each geodesic.
        #[arg(long, value_delimiter = ',', default_value = "0,0.25,0.5,0.75,1")]
        times: Vec<f64>,
        /// Vertex property of every mesh to read as the signal.
        #[arg(long)]
        signal_name: Option<String>,
        /// Camera of the renders: azimuth,elevation in degrees.
        #[arg(long, value_delimiter = ',', num_args = 1, allow_hyphen_values = true, default_values_t = [30.0, 20.0])]
        view: Vec<f64>,
    },
    /// Estimate a template from a population (metamorphosis atlas, free
    /// template): the template's positions and signal and every subject's
    /// momenta minimise the mean of the subjects' matching objectives
    /// (the `fshape match` configuration). Writes the template, each
    /// subject's momenta and matched template, momenta.csv (one row per
    /// subject), pictures and summary.json; checkpoints every iteration.
    Atlas {
        /// The subjects' meshes (with a `signal` vertex property).
        subjects: Vec<PathBuf>,
        /// A list of subjects, one per line: `mesh[,signal file]`, paths
        /// relative to the list (read before the positional ones).
        #[arg(long = "subjects")]
        list: Option<PathBuf>,
        /// The initial template (default: the first subject). Without a
        /// signal it takes the subjects' mean (vertex by vertex when they
        /// share its vertices).
        #[arg(long)]
        template: Option<PathBuf>,
        /// The configuration (TOML, as for `fshape match`).
        #[arg(long)]
        config: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// Continue from OUT/checkpoint.bin.
        #[arg(long)]
        resume: bool,
        /// Stop after this many iterations in this run, leaving the checkpoint.
        #[arg(long)]
        stop_after: Option<usize>,
        /// Vertex property of every mesh to read as the signal.
        #[arg(long)]
        signal_name: Option<String>,
        /// Camera of the renders: azimuth,elevation in degrees.
        #[arg(long, value_delimiter = ',', num_args = 1, allow_hyphen_values = true, default_values_t = [30.0, 20.0])]
        view: Vec<f64>,
        /// Coarser versions of the initial template (same surface, fewer
        /// vertices; without a signal they take the template's), one per
        /// stage before the last: the coarse stages run on them and carry
        /// the template and momenta to the next.
        #[arg(long, value_delimiter = ',')]
        stage_templates: Vec<PathBuf>,
    },
    /// Run one of the paper's experiments on data shipped in the repository
    /// (inputs, one config per run and `fshape match` outputs under OUT).
    Demo {
        /// Which experiment: digits, bunny, cortex, atlas-digits (an atlas
        /// of 64 writers' 3s) or atlas-spheres (an atlas with a known
        /// answer); the atlases write `fshape atlas` outputs.
        #[arg(value_parser = ["digits", "bunny", "cortex", "atlas-digits", "atlas-spheres"])]
        name: String,
        /// Output directory.
        #[arg(long, default_value = "demo-output")]
        out: PathBuf,
        /// The repository's data directory.
        #[arg(long)]
        data: Option<PathBuf>,
        /// Iteration limit per schedule stage.
        #[arg(long, default_value_t = 100)]
        max_iterations: usize,
        /// Digits: the ratios γ_V/γ_f to run.
        #[arg(long, value_delimiter = ',', default_value = "1,20,100")]
        ratios: Vec<f64>,
        /// Weight γ_W of the data attachment (scale-free: the demos
        /// normalise lengths and signals).
        #[arg(long, default_value_t = 1e3)]
        gamma_w: f64,
        /// Bunny: the 642-vertex sphere as template and the first three
        /// stages on it (about a minute per norm) instead of the paper's
        /// 10242 vertices.
        #[arg(long)]
        quick: bool,
        /// atlas-digits: only the first N subjects (0: all 64).
        #[arg(long, default_value_t = 0)]
        subjects: usize,
    },
    /// PNG pictures of meshes coloured by their signal, all from one
    /// camera, framed together and with one colour range, so that they
    /// compare: e.g. two registrations' end states and their target seen
    /// from below.
    Render {
        /// The meshes.
        #[arg(required = true)]
        meshes: Vec<PathBuf>,
        /// One PNG per mesh, in the same order.
        #[arg(long, value_delimiter = ',', required = true)]
        out: Vec<PathBuf>,
        /// Camera: azimuth,elevation in degrees (the azimuth turns about z,
        /// from the −y side; elevation 90 looks down z).
        #[arg(long, value_delimiter = ',', num_args = 1, allow_hyphen_values = true, default_values_t = [30.0, 20.0])]
        view: Vec<f64>,
        /// Signal values at the ends of the colour map: lo,hi (default: the
        /// range of all the meshes' signals).
        #[arg(long, value_delimiter = ',', num_args = 1, allow_hyphen_values = true)]
        range: Vec<f64>,
        /// Vertex property to read as the signal (default `signal`).
        #[arg(long)]
        signal_name: Option<String>,
    },
    /// Convert between mesh formats (by extension: .ply, .obj, .vtk, .gii,
    /// each optionally .gz, or a FreeSurfer surface name such as lh.pial),
    /// optionally attaching a signal from a signal file.
    Convert {
        /// Input mesh.
        input: PathBuf,
        /// Output mesh; its extension chooses the format.
        output: PathBuf,
        /// Vertex property of the input to read as the signal.
        #[arg(long)]
        signal_name: Option<String>,
        /// Per-vertex signal file replacing the input's signal (CSV, GIfTI, FreeSurfer curv or MGH).
        #[arg(long)]
        signal: Option<PathBuf>,
        /// Write ASCII instead of binary (PLY, VTK).
        #[arg(long)]
        ascii: bool,
        /// Drop unused vertices, zero-volume and duplicate cells before writing.
        #[arg(long)]
        repair: bool,
    },
    /// Where a run's checkpoint (OUT/checkpoint.bin, binary) stands, as one
    /// line of JSON: finished stages, the stage under way with its
    /// iterations and evaluations, wall seconds so far.
    Checkpoint {
        /// The checkpoint file.
        file: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info { file, signal_name, signal, json } => info(&file, signal_name, signal.as_deref(), json),
        Command::Fem { file, norm, length, out, json } => fem(&file, &norm, length, out.as_deref(), json),
        Command::Distance {
            source,
            target,
            kernel_geom,
            kernel_signal,
            kernel_grass,
            tolerance,
            signal_name,
            source_signal,
            target_signal,
            json,
        } => distance(&DistanceArgs {
            source: &source,
            target: &target,
            kernel: (&kernel_geom, kernel_signal.as_deref(), &kernel_grass),
            tolerance,
            signal_name,
            signals: (source_signal.as_deref(), target_signal.as_deref()),
            json,
        }),
        Command::Quality { source, target, signal_name, source_signal, target_signal, json } => {
            quality(&source, &target, signal_name, (source_signal.as_deref(), target_signal.as_deref()), json)
        }
        Command::Render { meshes, out, view, range, signal_name } => {
            let Some(camera) = camera(&view) else { return ExitCode::from(2) };
            render_meshes(&meshes, &out, camera, &range, signal_name)
        }
        Command::Shoot { source, momentum, signal_momentum, config, out, times, signal_name } => shoot(&ShootArgs {
            source: &source,
            momentum: &momentum,
            signal_momentum: signal_momentum.as_deref(),
            config: &config,
            out: &out,
            times: &times,
            signal_name,
        }),
        Command::Match {
            source,
            target,
            config,
            out,
            resume,
            stop_after,
            times,
            signal_name,
            source_signal,
            target_signal,
            view,
            stage_templates,
        } => {
            let Some((azimuth, elevation)) = camera(&view) else { return ExitCode::from(2) };
            match_cmd::run(&match_cmd::MatchArgs {
                source: &source,
                target: &target,
                signals: (source_signal.as_deref(), target_signal.as_deref()),
                config: &config,
                out: &out,
                resume,
                stop_after,
                signal_name,
                times: &times,
                view: (azimuth, elevation),
                stage_templates: &stage_templates,
            })
        }
        Command::Batch { pairs, config, out, jobs, shard, index_only, times, signal_name, view } => {
            let Some((azimuth, elevation)) = camera(&view) else { return ExitCode::from(2) };
            let shard = match shard {
                Some(s) => batch_cmd::parse_shard(&s).map(Some),
                None => batch_cmd::shard_from_env(),
            };
            shard.and_then(|shard| {
                batch_cmd::run(&batch_cmd::BatchArgs {
                    pairs: &pairs,
                    config: &config,
                    out: &out,
                    jobs,
                    shard,
                    index_only,
                    signal_name,
                    times: &times,
                    view: (azimuth, elevation),
                })
            })
        }
        Command::Atlas {
            subjects,
            list,
            template,
            config,
            out,
            resume,
            stop_after,
            signal_name,
            view,
            stage_templates,
        } => {
            let Some((azimuth, elevation)) = camera(&view) else { return ExitCode::from(2) };
            atlas_cmd::run(&atlas_cmd::AtlasArgs {
                subjects: &subjects,
                list: list.as_deref(),
                template: template.as_deref(),
                config: &config,
                out: &out,
                resume,
                stop_after,
                signal_name,
                view: (azimuth, elevation),
                stage_templates: &stage_templates,
            })
        }
        Command::Demo { name, out, data, max_iterations, ratios, gamma_w, quick, subjects } => {
            let data = data.unwrap_or_else(demo::default_data);
            match name.as_str() {
                _ if quick && name != "bunny" => {
                    Err(anyhow::anyhow!("--quick: only the bunny demo has a quick variant"))
                }
                "bunny" => demo::bunny(&demo::RunArgs { out: &out, data: &data, max_iterations, gamma_w, quick }),
                "cortex" => demo::cortex(&demo::RunArgs { out: &out, data: &data, max_iterations, gamma_w, quick }),
                "atlas-spheres" => demo::atlas_spheres(&out, max_iterations, gamma_w),
                "atlas-digits" => demo::atlas_digits(
                    &demo::DigitsArgs { out: &out, data: &data, ratios: &ratios, max_iterations, gamma_w },
                    subjects,
                ),
                _ => {
                    demo::digits(&demo::DigitsArgs { out: &out, data: &data, ratios: &ratios, max_iterations, gamma_w })
                }
            }
        }
        Command::Convert { input, output, signal_name, signal, ascii, repair } => {
            convert(&input, &output, signal_name, signal.as_deref(), ascii, repair)
        }
        Command::Checkpoint { file } => checkpoint_cmd::run(&file),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", message(&e));
            ExitCode::from(1)
        }
    }
}

/// `--view`'s azimuth and elevation, or `None` after saying why.
fn camera(view: &[f64]) -> Option<(f64, f64)> {
    match view {
        [a, e] if a.is_finite() && e.is_finite() => Some((*a, *e)),
        _ => {
            let got: Vec<String> = view.iter().map(f64::to_string).collect();
            eprintln!("error: --view: expected azimuth,elevation (two finite degrees), got {}", got.join(","));
            None
        }
    }
}

/// `--stage-templates`: the meshes, then `None` for the last stage (none
/// given: no stage templates).
fn stage_templates(
    paths: &[PathBuf],
    signal_name: Option<String>,
    stages: usize,
) -> Result<Option<Vec<Option<FShape>>>> {
    if paths.is_empty() {
        return Ok(None);
    }
    if paths.len() + 1 != stages {
        bail!(
            "--stage-templates: {} meshes for a schedule of {stages} stages: give one per stage before the last ({})",
            paths.len(),
            stages.saturating_sub(1)
        );
    }
    let mut templates =
        paths.iter().map(|p| load(p, signal_name.clone(), None).map(Some)).collect::<Result<Vec<_>>>()?;
    templates.push(None);
    Ok(Some(templates))
}

/// The error and its causes joined by ": ", skipping a cause whose text the
/// previous message already contains (the library errors name their source
/// in their own message and also return it from `source()`).
pub(crate) fn message(e: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in e.chain() {
        let m = cause.to_string();
        if !parts.last().is_some_and(|p| p.contains(&m)) {
            parts.push(m);
        }
    }
    parts.join(": ")
}

/// Reads a mesh and, if given, replaces its signal by a signal file's (CSV
/// column, GIfTI data array, FreeSurfer curv or MGH).
fn load(path: &Path, signal_name: Option<String>, signal: Option<&Path>) -> Result<FShape> {
    let shape = io::read_mesh(path, &ReadOptions { signal_name })?;
    let Some(csv) = signal else { return Ok(shape) };
    let column = io::read_signal(csv)?;
    shape
        .with_signal(Some(column.values))
        .with_context(|| format!("attaching the signal of {} to {}", csv.display(), path.display()))
}

#[derive(Serialize)]
struct ProblemGroup {
    code: &'static str,
    count: usize,
    examples: Vec<String>,
}

#[derive(Serialize)]
struct SignalSummary {
    min: f64,
    max: f64,
    mean: f64,
}

#[derive(Serialize)]
struct Info {
    path: String,
    dim: usize,
    cell_kind: &'static str,
    n_vertices: usize,
    n_cells: usize,
    bbox_min: Vec<f64>,
    bbox_max: Vec<f64>,
    bbox_diagonal: f64,
    total_volume: f64,
    signal: Option<SignalSummary>,
    closed: bool,
    boundary_loops: usize,
    components: usize,
    euler_characteristic: i64,
    errors: Vec<ProblemGroup>,
    warnings: Vec<ProblemGroup>,
}

fn group(problems: &[&Finding]) -> Vec<ProblemGroup> {
    let mut out: Vec<ProblemGroup> = Vec::new();
    for p in problems {
        match out.iter_mut().find(|g| g.code == p.code()) {
            Some(g) => {
                g.count += 1;
                if g.examples.len() < 5 {
                    g.examples.push(p.to_string());
                }
            }
            None => out.push(ProblemGroup { code: p.code(), count: 1, examples: vec![p.to_string()] }),
        }
    }
    out
}

fn summary(path: &Path, s: &FShape) -> Info {
    let topo = s.topology();
    let bbox = s.bounding_box();
    let report = s.validate();
    let by = |sev| report.problems.iter().filter(|p| p.severity() == sev).collect::<Vec<_>>();
    Info {
        path: path.display().to_string(),
        dim: s.dim(),
        cell_kind: s.kind().name(),
        n_vertices: s.n_vertices(),
        n_cells: s.n_cells(),
        bbox_diagonal: bbox.diagonal(),
        bbox_min: bbox.min,
        bbox_max: bbox.max,
        total_volume: s.total_volume(),
        signal: s.signal().filter(|f| !f.is_empty()).map(|f| SignalSummary {
            min: f.iter().copied().fold(f64::INFINITY, f64::min),
            max: f.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            mean: f.iter().sum::<f64>() / f.len() as f64,
        }),
        closed: topo.is_closed(),
        boundary_loops: topo.n_boundary_loops,
        components: topo.n_components,
        euler_characteristic: topo.euler_characteristic(s.kind(), s.n_cells()),
        errors: group(&by(Severity::Error)),
        warnings: group(&by(Severity::Warning)),
    }
}

fn info(path: &Path, signal_name: Option<String>, signal: Option<&Path>, json: bool) -> Result<()> {
    let shape = load(path, signal_name, signal)?;
    let i = summary(path, &shape);
    if json {
        println!("{}", serde_json::to_string_pretty(&i)?);
        return Ok(());
    }
    println!("{}", i.path);
    println!("  {} mesh in R^{}: {} vertices, {} cells", i.cell_kind, i.dim, i.n_vertices, i.n_cells);
    println!("  bounding box {:?} .. {:?} (diagonal {:.6})", i.bbox_min, i.bbox_max, i.bbox_diagonal);
    println!("  total {}: {:.9}", if shape.kind().dim() == 1 { "length" } else { "area" }, i.total_volume);
    match &i.signal {
        Some(f) => println!("  signal: min {:.6}, max {:.6}, mean {:.6}", f.min, f.max, f.mean),
        None => println!("  signal: none"),
    }
    println!(
        "  {}, {} component(s), {} boundary loop(s), Euler characteristic {}",
        if i.closed { "closed" } else { "open" },
        i.components,
        i.boundary_loops,
        i.euler_characteristic
    );
    for (label, groups) in [("error", &i.errors), ("warning", &i.warnings)] {
        for g in groups {
            println!("  {label}: {} × {}: {}", g.count, g.code, g.examples.join("; "));
        }
    }
    if i.errors.is_empty() && i.warnings.is_empty() {
        println!("  no problems found");
    }
    Ok(())
}

fn convert(
    input: &Path,
    output: &Path,
    signal_name: Option<String>,
    signal: Option<&Path>,
    ascii: bool,
    repair: bool,
) -> Result<()> {
    let mut shape = load(input, signal_name, signal)?;
    if repair {
        let (fixed, log) = shape.repaired(Repairs::ALL);
        eprintln!("repair: dropped {} cell(s) and {} vertex(es)", log.dropped_cells.len(), log.dropped_vertices.len());
        shape = fixed;
    }
    let encoding = if ascii { Encoding::Ascii } else { Encoding::Binary };
    io::write_mesh(output, &shape, encoding)?;
    Ok(())
}

#[derive(Serialize)]
struct FemSummary {
    path: String,
    norm: &'static str,
    length: Option<f64>,
    n: usize,
    nnz: usize,
    nnz_lower: usize,
    trace: f64,
    total_area: f64,
}

fn fem(path: &Path, norm: &str, length: f64, out: Option<&Path>, json: bool) -> Result<()> {
    let shape = load(path, None, None)?;
    let norm = Norm::parse(norm, length)?;
    let d = SignalNorm::try_new(&shape, norm)?;
    let values = d.assemble(shape.points()).with_context(|| format!("assembling D for {}", path.display()))?;
    let (col_ptr, row_idx) = d.pattern();
    let mut trace = 0.0;
    for c in 0..d.n_vertices() {
        for e in col_ptr[c]..col_ptr[c + 1] {
            if row_idx[e] == c {
                trace += values[e];
            }
        }
    }
    let n = d.n_vertices();
    let summary = FemSummary {
        path: path.display().to_string(),
        norm: norm.name(),
        length: matches!(norm, Norm::H1 { .. }).then_some(length),
        n,
        nnz: 2 * values.len() - n,
        nnz_lower: values.len(),
        trace,
        total_area: shape.total_volume(),
    };
    if let Some(out) = out {
        let comment = format!("fshape signal norm {} of {}", norm.name(), path.display());
        io::mtx::write_symmetric_lower(out, n, col_ptr, row_idx, &values, &comment)?;
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "{}: {} norm, {} × {} matrix, {} nonzeros ({} in the lower triangle)",
            summary.path, summary.norm, n, n, summary.nnz, summary.nnz_lower
        );
        println!("  trace {:.9e}, total area {:.9e}", summary.trace, summary.total_area);
    }
    Ok(())
}

struct DistanceArgs<'a> {
    source: &'a Path,
    target: &'a Path,
    kernel: (&'a str, Option<&'a str>, &'a str),
    tolerance: Option<f64>,
    signal_name: Option<String>,
    signals: (Option<&'a Path>, Option<&'a Path>),
    json: bool,
}

#[derive(Serialize)]
struct DistanceSummary {
    source: String,
    target: String,
    kernel_geom: String,
    kernel_signal: Option<String>,
    kernel_grass: String,
    tolerance: Option<f64>,
    /// A(X, Y), a squared distance.
    value: f64,
    xx: f64,
    xy: f64,
    yy: f64,
    source_cells: usize,
    target_cells: usize,
    seconds: f64,
}

/// Prints the load-time warnings that matter to a data attachment.
fn warn_massless(path: &Path, s: &FShape) {
    let report = s.validate();
    for (code, what) in [("unused_vertex", "unused vertices"), ("zero_volume_cell", "cells of zero volume")] {
        let n = report.count(code);
        if n > 0 {
            eprintln!("warning: {}: {n} {what}; they carry no mass in the data attachment", path.display());
        }
    }
}

fn distance(a: &DistanceArgs<'_>) -> Result<()> {
    let (geom, signal, grass) = a.kernel;
    let mut kernel = VarifoldKernel::parse(geom, signal, grass)?;
    if let Some(tol) = a.tolerance {
        kernel = kernel.truncated(tol)?;
    }
    let x = load(a.source, a.signal_name.clone(), a.signals.0)?;
    let y = load(a.target, a.signal_name.clone(), a.signals.1)?;
    warn_massless(a.source, &x);
    warn_massless(a.target, &y);
    let start = std::time::Instant::now();
    let d = Attachment::new(&y, kernel)
        .and_then(|att| att.eval(&x))
        .with_context(|| format!("A({}, {})", a.source.display(), a.target.display()))?;
    let summary = DistanceSummary {
        source: a.source.display().to_string(),
        target: a.target.display().to_string(),
        kernel_geom: geom.to_string(),
        kernel_signal: signal.map(str::to_string),
        kernel_grass: grass.to_string(),
        tolerance: a.tolerance,
        value: d.value,
        xx: d.xx,
        xy: d.xy,
        yy: d.yy,
        source_cells: x.n_cells(),
        target_cells: y.n_cells(),
        seconds: start.elapsed().as_secs_f64(),
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("A = {:.12e}", d.value);
        println!("<X,X> = {:.12e}\n<X,Y> = {:.12e}\n<Y,Y> = {:.12e}", d.xx, d.xy, d.yy);
        println!("({} and {} cells, {:.3} s)", x.n_cells(), y.n_cells(), summary.seconds);
    }
    Ok(())
}

/// `fshape quality`: the match quality of one file against another.
fn quality(
    source: &Path,
    target: &Path,
    signal_name: Option<String>,
    signals: (Option<&Path>, Option<&Path>),
    json: bool,
) -> Result<()> {
    let x = load(source, signal_name.clone(), signals.0)?;
    let y = load(target, signal_name, signals.1)?;
    let q = fshape_match::quality(&x, &y)
        .with_context(|| format!("the quality of {} against {}", source.display(), target.display()))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&q)?);
    } else {
        println!("{} against {}: {}", source.display(), target.display(), q.describe());
    }
    Ok(())
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

struct ShootArgs<'a> {
    source: &'a Path,
    momentum: &'a Path,
    signal_momentum: Option<&'a Path>,
    config: &'a Path,
    out: &'a Path,
    times: &'a [f64],
    signal_name: Option<String>,
}

#[derive(Serialize)]
struct ShootSummary {
    source: String,
    config: String,
    model: String,
    norm: &'static str,
    integrator: String,
    steps: usize,
    /// H(z_k) at every step k = 0..N.
    hamiltonian: Vec<f64>,
    /// Relative drift max_k |H_k − H_0| / |H_0| (0 when H_0 = 0).
    hamiltonian_drift: f64,
    times: Vec<f64>,
    files: Vec<String>,
    final_state: FinalState,
    seconds: Timing,
}

#[derive(Serialize)]
struct FinalState {
    /// Largest vertex displacement |x_1 − x_0|.
    max_displacement: f64,
    /// Root-mean-square displacement.
    rms_displacement: f64,
    /// ‖f_1 − f_0‖∞.
    max_signal_change: f64,
    /// Largest momentum norm |p_1|.
    max_momentum: f64,
}

#[derive(Serialize)]
struct Timing {
    total: f64,
    kernels: f64,
    fem: f64,
}

/// A file to write: its path and contents.
type Output = (PathBuf, Vec<u8>);

/// The states at `times` as VTK and PLY files, and a ParaView collection
/// (contents and names; nothing is written here).
fn trajectory_files(
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
        let state = template.clone().with_points(x)?.with_signal(Some(f))?;
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

fn shoot(a: &ShootArgs<'_>) -> Result<()> {
    use fshape_match::Config;
    use fshape_shoot::Problem;
    let start = std::time::Instant::now();
    let config = Config::read(a.config)?;
    let model = config.model()?;
    if config.model.normalize {
        anyhow::bail!(
            "{}: [model] normalize = true makes the weights relative to a registration's target, and shooting \
             has none: set normalize = false (the weights are then taken as written), or shoot a registration's \
             momenta with the shoot.toml that fshape match wrote next to them",
            a.config.display()
        );
    }
    if let Some(t) = a.times.iter().find(|t| !(0.0..=1.0).contains(*t)) {
        anyhow::bail!("--times: {t} is outside [0, 1]");
    }
    let shape = load(a.source, a.signal_name.clone(), None)?;
    let (n, dim) = (shape.n_vertices(), shape.dim());
    let p0 = io::csv::read_vectors(a.momentum, dim)?;
    if p0.len() != n * dim {
        anyhow::bail!("{}: {} rows, but {} has {n} vertices", a.momentum.display(), p0.len() / dim, a.source.display());
    }
    let pf = match a.signal_momentum {
        Some(p) => {
            let v = io::read_signal(p)?.values;
            if v.len() != n {
                anyhow::bail!("{}: {} values, but {} has {n} vertices", p.display(), v.len(), a.source.display());
            }
            v
        }
        None => vec![0.0; n],
    };
    let kind = model.kind().name().to_string();
    let (norm, integrator, steps) = (model.norm().name(), model.integrator().name().to_string(), model.steps());
    let problem = Problem::new(&shape, model).with_context(|| format!("setting up {}", a.source.display()))?;
    let traj = problem.shoot(&p0, &pf).with_context(|| format!("shooting from {}", a.source.display()))?;
    // Everything is computed before anything is written.
    let template = problem.template().clone();
    let (mut outputs, files) = trajectory_files(&template, &traj, a.times, a.out)?;
    let h = traj.hamiltonian.clone();
    let drift = traj.drift().0;
    let (x0, x1) = (template.points(), traj.points(steps));
    let disp: Vec<f64> = x0
        .chunks_exact(dim)
        .zip(x1.chunks_exact(dim))
        .map(|(p, q)| p.iter().zip(q).map(|(u, v)| (u - v).powi(2)).sum::<f64>().sqrt())
        .collect();
    let norm_rows =
        |v: &[f64]| v.chunks_exact(dim).map(|r| r.iter().map(|u| u * u).sum::<f64>().sqrt()).fold(0.0, f64::max);
    let summary = ShootSummary {
        source: a.source.display().to_string(),
        config: a.config.display().to_string(),
        model: kind,
        norm,
        integrator,
        steps,
        hamiltonian_drift: drift,
        hamiltonian: h,
        times: a.times.to_vec(),
        files,
        final_state: FinalState {
            max_displacement: disp.iter().copied().fold(0.0, f64::max),
            rms_displacement: (disp.iter().map(|d| d * d).sum::<f64>() / n.max(1) as f64).sqrt(),
            max_signal_change: traj
                .signal(steps)
                .iter()
                .zip(template.signal().unwrap_or(&[]))
                .map(|(u, v)| (u - v).abs())
                .fold(0.0, f64::max),
            max_momentum: norm_rows(traj.momenta(steps)),
        },
        seconds: Timing { total: start.elapsed().as_secs_f64(), kernels: traj.timings.kernels, fem: traj.timings.fem },
    };
    outputs.push((a.out.join("summary.json"), serde_json::to_string_pretty(&summary)?.into_bytes()));
    std::fs::create_dir_all(a.out).with_context(|| format!("creating {}", a.out.display()))?;
    for (path, bytes) in &outputs {
        io::write_atomic(path, bytes, false)?;
    }
    println!(
        "{}: {} steps, H from {:.6e} to {:.6e}, max displacement {:.4e}; wrote {} files to {}",
        a.source.display(),
        steps,
        summary.hamiltonian[0],
        summary.hamiltonian[steps],
        summary.final_state.max_displacement,
        outputs.len(),
        a.out.display()
    );
    Ok(())
}
