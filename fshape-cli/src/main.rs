//! `fshape`: inspect, convert, compare, shoot and register functional
//! shapes. Exit codes: 0 success, 1 bad input (the message names the file
//! and the place), 2 usage error. Each command is a module of `commands`
//! (its arguments and its `run`); this file only dispatches.

// The program parses, calls the library's operations and prints: a long
// function is doing an operation's work (the threshold, 80 lines, is in
// clippy.toml).
#![warn(clippy::too_many_lines)]

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod args;
mod commands;
mod inputs;
#[cfg(feature = "mpi")]
mod processes;
mod progress;

#[derive(Parser)]
#[command(name = "fshape", version, about = "Functional shapes: meshes carrying a signal, and their metamorphoses")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Counts, bounding box, signal range and validation of a mesh file.
    ///
    /// Print counts, dimension, bounding box, total volume, signal range and
    /// the validation report of a mesh file (.ply, .obj, .vtk, .gii, optionally
    /// .gz, or a FreeSurfer surface such as lh.pial).
    Info(commands::info::Args),
    /// Assemble a mesh's signal norm matrix and summarise or export it.
    ///
    /// Assemble the signal norm matrix D_s of a mesh (lumped or P1 mass, or
    /// H1 = mass + length² × stiffness) and print a summary; optionally
    /// export it in MatrixMarket format (symmetric, lower triangle).
    Fem(commands::fem::Args),
    /// How close a shape is to a target, as `fshape match` reports it.
    ///
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
    Quality(commands::quality::Args),
    /// The data attachment between two fshapes, a squared distance.
    ///
    /// The data attachment A(X, Y) = ⟨X,X⟩ − 2⟨X,Y⟩ + ⟨Y,Y⟩ between two
    /// fshapes (functional varifold; varifold or current without a signal
    /// kernel). Prints A itself, a squared distance, then the three inner
    /// products. Widths use exp(−u/(2σ²)); fshapesTk's σ is ours × √2.
    Distance(commands::distance::Args),
    /// Shoot a metamorphosis geodesic from initial momenta.
    ///
    /// Writes the states from SOURCE at the chosen times (VTK + ParaView
    /// .pvd, PLY with the signal as vertex property `signal`) and
    /// summary.json.
    Shoot(commands::shoot::Args),
    /// Register a source onto a target (coarse to fine, resumable).
    ///
    /// Register SOURCE onto TARGET: minimise J = H + γ_W·A over the initial
    /// momenta (L-BFGS by default), stage by stage of the configuration's
    /// coarse-to-fine schedule. Writes the geodesic (VTK + .pvd, PLY), the
    /// momenta (p0.csv, pf.csv, momenta.vtk), summary.json and energy.svg/.png.
    /// A checkpoint is written after every iteration: after Ctrl-C or a
    /// kill, `--resume` continues to the same result, bit for bit. With a
    /// `[prealign]` section (kind = "rigid" | "similarity" | "affine") the
    /// source is first aligned to the target on the data attachment, from
    /// 24 starts; summary.json's `prealign` holds the 4 × 4 matrix.
    Match(commands::matching::Args),
    /// Register every pair of a table, each in its own folder.
    ///
    /// Register every pair of a table: one `fshape match` per row, each in
    /// OUT/NAME (its own checkpoint and outputs), then OUT/index.csv and
    /// index.json (every row's status, J, match quality, time and error).
    /// Run the same command again to resume: finished rows are kept,
    /// stopped rows resume, failed ones are tried again. A failed row does
    /// not stop the others (the exit status is 1 if any failed).
    Batch(commands::batch::Args),
    /// Estimate a template and each subject's momenta from a population.
    ///
    /// Estimate a template from a population (metamorphosis atlas, free
    /// template): the template's positions and signal and every subject's
    /// momenta minimise the mean of the subjects' matching objectives
    /// (the `fshape match` configuration). Writes the template, each
    /// subject's momenta and matched template, momenta.csv (one row per
    /// subject), pictures and summary.json; checkpoints every iteration.
    Atlas(commands::atlas::Args),
    /// Fit one geodesic to each subject's visits over time.
    ///
    /// Geodesic regression: for each subject of the visits table, the
    /// metamorphosis from its earliest visit (the baseline) whose states
    /// at the visits' ages match the visits (J = H + γ_W Σ w·A, the
    /// `fshape match` configuration). Writes each visit's fitted state,
    /// pictures of the fits beside the visits, the momenta, the rates per
    /// unit age (normal velocity and each map's rate) and summary.json,
    /// in OUT (one subject) or OUT/SUBJECT; checkpoints every iteration.
    Regress(commands::regress::Args),
    /// Group statistics on an atlas: GLM maps and permutation tests.
    ///
    /// Group statistics on an atlas: where do the subjects' shapes and
    /// signals differ with a covariate (a group, an age)? From an `fshape
    /// atlas` folder and a covariates table, per-vertex maps on the
    /// template (signal change, normal momentum, normal displacement, log
    /// area change) are tested with a general linear model and
    /// permutations (Freedman–Lane; family-wise error by the maximum
    /// statistic, TFCE as an option), and the momenta's principal scores
    /// with Hotelling's T². Writes t/F, effect and p maps (GIfTI, PLY),
    /// pictures, multivariate.csv and summary.json. The same seed gives
    /// the same bits.
    Stats(commands::stats::Args),
    /// Carry a map, parcellation or label through a registration.
    ///
    /// Carry a map, a parcellation or a label through a registration: from
    /// the source's vertices onto the target's (or back, `--onto source`),
    /// each receiving vertex reading the values at its closest point on the
    /// other surface as matched (barycentric for maps, leaving out corners
    /// without a value; the heaviest region for labels). Vertices farther
    /// than `--max-distance` (2 % of the target's diagonal) get none. RUN
    /// is an `fshape match` output or an atlas subject's folder.
    Transfer(commands::transfer::Args),
    /// Run one of the paper's experiments on data shipped here.
    ///
    /// Writes the inputs, one config per run and the `fshape match`
    /// outputs under OUT.
    Demo(commands::demo::Args),
    /// PNG pictures of meshes from one camera in one colour range.
    ///
    /// PNG pictures of meshes coloured by their signal, all from one
    /// camera, framed together and with one colour range, so that they
    /// compare: e.g. two registrations' end states and their target seen
    /// from below.
    Render(commands::render::Args),
    /// Convert between mesh formats, optionally attaching a signal.
    ///
    /// Convert between mesh formats (by extension: .ply, .obj, .vtk, .gii,
    /// each optionally .gz, or a FreeSurfer surface name such as lh.pial),
    /// optionally attaching a signal from a signal file.
    Convert(commands::convert::Args),
    /// Write a match, atlas or batch folder's report.html again.
    ///
    /// Write DIR/report.html again for an `fshape match`, `atlas` or
    /// `batch` output folder (they write it themselves): one page, viewable
    /// offline, with the geodesic as a 3-D view (rotate, zoom, a time
    /// slider), the match quality, the stages, the energy plot and the
    /// configuration; for an atlas the template, each subject and the
    /// modes; for a batch the index with thumbnails.
    Report(commands::report::Args),
    /// Where a run's checkpoint stands, as one line of JSON.
    ///
    /// Where a run's checkpoint (OUT/checkpoint.bin, binary) stands, as one
    /// line of JSON: finished stages, the stage under way with its
    /// iterations and evaluations, wall seconds so far.
    Checkpoint(commands::checkpoint::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // FSHAPE_SIMD caps the kernel sums' instruction set; a value the
    // library would ignore is refused here, before any work.
    if let Err(e) = fshape_match::ops::check_environment() {
        eprintln!("error: {e}");
        return ExitCode::from(1);
    }
    let result = match cli.command {
        Command::Info(a) => commands::info::run(a),
        Command::Fem(a) => commands::fem::run(a),
        Command::Quality(a) => commands::quality::run(a),
        Command::Distance(a) => commands::distance::run(a),
        Command::Shoot(a) => commands::shoot::run(a),
        Command::Match(a) => commands::matching::run(a),
        Command::Batch(a) => commands::batch::run(a),
        Command::Atlas(a) => commands::atlas::run(a),
        Command::Stats(a) => commands::stats::run(a),
        Command::Regress(a) => commands::regress::run(a),
        Command::Transfer(a) => commands::transfer::run(a),
        Command::Demo(a) => commands::demo::run(a),
        Command::Render(a) => commands::render::run(a),
        Command::Convert(a) => commands::convert::run(a),
        Command::Checkpoint(a) => commands::checkpoint::run(a),
        Command::Report(a) => commands::report::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", inputs::message(&e));
            ExitCode::from(1)
        }
    }
}
