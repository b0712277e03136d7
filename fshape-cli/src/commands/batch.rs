//! `fshape batch`: one `fshape match` per row of a table of pairs, on one
//! machine (rows in sequence or `--jobs` at once) or spread over a cluster
//! job array (`--shard I/N`, or Slurm's array variables). Every row has its
//! own output directory and checkpoint, so a batch stopped anywhere is
//! started again with the same command: finished rows are kept, stopped
//! rows resume, failed rows are tried again. A row that fails (unreadable
//! mesh, bad signal, a diverging registration) is recorded and the others
//! go on. After its rows each invocation writes the index of every row
//! (`index.csv`, `index.json`) from what the row directories hold;
//! `--index-only` writes it without running anything (for a job that runs
//! after a job array).
//!
//! Registrations give the same bits for any number of threads, so a row's
//! result does not depend on the mode it ran in.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fshape_match::ops::batch::{self, BatchPair, BatchRequest};
use fshape_match::record::{BatchIndex, BatchRow, Status};

/// `fshape batch`'s arguments (its help is on the command).
#[derive(clap::Args)]
pub struct Args {
    /// The pairs: a header naming the columns (source, target, and
    /// optionally source_signal, target_signal, source_mask, target_mask,
    /// name), then one pair per line; paths relative to the table, `#`
    /// comments. Several maps per side: their files separated by `;`
    /// (one channel each, in the same order on both sides).
    pub pairs: PathBuf,
    /// The configuration of every registration (as for `fshape match`).
    #[arg(long)]
    pub config: PathBuf,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Rows registered at once on this machine, the cores shared among
    /// them (results are the same bits in any mode).
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// This task's share of the rows, I/N with 0 <= I < N (rows I,
    /// I + N, ...): a cluster job array. Default: Slurm's
    /// SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN of SLURM_ARRAY_TASK_COUNT
    /// when set, else every row.
    #[arg(long, value_parser = crate::args::shard)]
    pub shard: Option<crate::args::Shard>,
    /// Only write the index from the rows' directories.
    #[arg(long)]
    pub index_only: bool,
    #[command(flatten)]
    pub times: crate::args::Times,
    /// Vertex property of every mesh to read as the signal.
    #[arg(long)]
    pub signal_name: Option<String>,
    /// Accept NaN in signal files as missing values: each masks its
    /// vertex.
    #[arg(long)]
    pub allow_missing: bool,
    #[command(flatten)]
    pub view: crate::args::View,
    #[command(flatten)]
    pub report: crate::args::Report,
}

pub fn run(a: Args) -> Result<()> {
    let shard = match a.shard {
        Some(s) => Some((s.index, s.count)),
        None => shard_from_env()?,
    };
    run_with(&BatchArgs {
        pairs: &a.pairs,
        config: &a.config,
        out: &a.out,
        jobs: a.jobs,
        shard,
        index_only: a.index_only,
        signal_name: a.signal_name,
        allow_missing: a.allow_missing,
        times: &a.times.times,
        view: a.view.camera.pair(),
        verbosity: a.report.verbosity(),
    })
}

/// The command's arguments.
pub struct BatchArgs<'a> {
    /// The table of pairs.
    pub pairs: &'a Path,
    pub config: &'a Path,
    pub out: &'a Path,
    /// Rows registered at once on this machine.
    pub jobs: usize,
    /// This invocation's share of the rows: (index from 0, count).
    pub shard: Option<(usize, usize)>,
    /// Only write the index.
    pub index_only: bool,
    pub signal_name: Option<String>,
    /// NaN in a signal file masks its vertex.
    pub allow_missing: bool,
    pub times: &'a [f64],
    pub view: (f64, f64),
    /// How each row reports its progress (its lines start with its name).
    pub verbosity: crate::args::Verbosity,
}

/// Writes index.csv, index.json and report.html of every row; returns
/// the index.
fn write_index(a: &BatchArgs<'_>, request: &BatchRequest<'_>, rows: &[BatchPair]) -> Result<BatchIndex> {
    let index = request.index(rows);
    fshape_report::outputs::write_batch_index(a.out, &index, a.view)?;
    Ok(index)
}

/// Registers one row into `dir` as `fshape match` would (resuming its
/// checkpoint if it has one); its error's message on failure.
fn register_row(a: &BatchArgs<'_>, row: &BatchPair, dir: &Path) -> std::result::Result<(), String> {
    let result = crate::commands::matching::run_with(&crate::commands::matching::MatchArgs {
        masking: (
            crate::inputs::Masking { mask: row.source_mask.as_deref(), allow_missing: a.allow_missing },
            crate::inputs::Masking { mask: row.target_mask.as_deref(), allow_missing: a.allow_missing },
        ),
        source: &row.source,
        target: &row.target,
        signals: (&row.source_signal, &row.target_signal),
        config: a.config,
        out: dir,
        resume: dir.join("checkpoint.bin").exists(),
        stop_after: None,
        signal_name: a.signal_name.clone(),
        times: a.times,
        view: a.view,
        stage_templates: &[],
        verbosity: a.verbosity,
        label: Some(&row.name),
    });
    result.map_err(|e| {
        let message = crate::inputs::message(&e);
        eprintln!("row {} ({}:{}) failed: {message}", row.name, a.pairs.display(), row.line);
        message
    })
}

/// This invocation's shard: `--shard`, else Slurm's array variables, else
/// all rows.
pub fn shard_from_env() -> Result<Option<(usize, usize)>> {
    let Ok(id) = std::env::var("SLURM_ARRAY_TASK_ID") else { return Ok(None) };
    let number = |name: &str, value: &str| -> Result<usize> {
        value.trim().parse().with_context(|| format!("{name}={value} is not a task number"))
    };
    let id = number("SLURM_ARRAY_TASK_ID", &id)?;
    let min = match std::env::var("SLURM_ARRAY_TASK_MIN") {
        Ok(v) => number("SLURM_ARRAY_TASK_MIN", &v)?,
        Err(_) => 0,
    };
    let count = std::env::var("SLURM_ARRAY_TASK_COUNT")
        .context("SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not")?;
    let count = number("SLURM_ARRAY_TASK_COUNT", &count)?;
    match id.checked_sub(min) {
        Some(i) if i < count => Ok(Some((i, count))),
        _ => bail!(
            "SLURM_ARRAY_TASK_ID={id} is not within {count} tasks from SLURM_ARRAY_TASK_MIN={min} \
             (submit the array as --array=0-{}, contiguous, or pass --shard I/N)",
            count.saturating_sub(1)
        ),
    }
}

/// Runs this invocation's rows, then writes the index.
pub fn run_with(a: &BatchArgs<'_>) -> Result<()> {
    let request = |shard: Option<(usize, usize)>| BatchRequest {
        pairs: a.pairs,
        config: a.config,
        out: a.out,
        jobs: a.jobs,
        shard: shard.unwrap_or((0, 1)),
    };
    #[cfg(feature = "mpi")]
    {
        if let Some((world, universe)) = crate::processes::init()? {
            // Under mpirun the rows are dealt to the processes (a given
            // --shard is refused: one way at a time); process 0 writes the
            // index once every process has finished its rows.
            use fshape_match::Cluster;
            let (rank, size) = (world.rank(), world.size());
            // (`shard` also holds a job array's, from Slurm's variables.)
            if a.shard.is_some() {
                bail!(
                    "batch under mpirun deals the rows to its {size} processes: do not also give --shard or run it as a job array"
                );
            }
            let rows = batch::read_pairs(a.pairs)?;
            let failed = if a.index_only { Ok(()) } else { run_rows(a, &request(Some((rank, size))), &rows) };
            crate::processes::barrier(&universe);
            if rank == 0 {
                let index = write_index(a, &request(None), &rows)?;
                report(a, &index.rows, None::<fn(&BatchRow) -> bool>);
            }
            return failed;
        }
    }
    let rows = batch::read_pairs(a.pairs)?;
    let all = request(None);
    if a.index_only {
        let index = write_index(a, &all, &rows)?;
        report(a, &index.rows, None::<fn(&BatchRow) -> bool>);
        return Ok(());
    }
    let mine = request(a.shard);
    let failed = run_rows(a, &mine, &rows);
    let index = write_index(a, &all, &rows)?;
    let (shard, shards) = mine.shard;
    report(a, &index.rows, Some(shard_filter(shard, shards)));
    failed
}

/// Registers this shard's rows that have not finished; an error when any
/// of its rows failed.
fn run_rows(a: &BatchArgs<'_>, request: &BatchRequest<'_>, rows: &[BatchPair]) -> Result<()> {
    // (Under mpirun or a job array, said by the first shard.)
    crate::inputs::read_config(a.config, request.shard.0 == 0)?;
    let (shard, shards) = request.shard;
    let mine = rows.iter().filter(|r| request.in_shard(r)).count();
    let todo = request.todo(rows);
    eprintln!(
        "batch: {} rows in {}, {mine} in this shard ({shard}/{shards}), {} to run, {} at a time",
        rows.len(),
        a.pairs.display(),
        todo.len(),
        a.jobs.max(1)
    );
    let run = batch::run_rows(request, rows, &todo, &|row, dir| register_row(a, row, dir));
    for (name, e) in &run.unwritable {
        eprintln!("row {name}: {e}");
    }
    let failed = run.failed + run.unwritable.len();
    if failed > 0 {
        bail!("{failed} of this shard's {mine} rows failed; see {}", a.out.join("index.csv").display());
    }
    Ok(())
}

fn shard_filter(shard: usize, shards: usize) -> impl Fn(&BatchRow) -> bool {
    move |e| (e.row - 1) % shards == shard
}

/// Prints the counts (of the rows `in_shard` selects, all without one).
fn report(a: &BatchArgs<'_>, entries: &[BatchRow], in_shard: Option<impl Fn(&BatchRow) -> bool>) {
    let selected: Vec<&BatchRow> = entries.iter().filter(|e| in_shard.as_ref().is_none_or(|f| f(e))).collect();
    let count = |s: Status| selected.iter().filter(|e| e.status == s).count();
    println!(
        "batch: {} done, {} failed, {} incomplete, {} pending of {} rows; index in {} and report.html",
        count(Status::Done),
        count(Status::Failed),
        count(Status::Incomplete),
        count(Status::Pending),
        selected.len(),
        a.out.join("index.csv").display()
    );
}
