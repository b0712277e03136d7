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
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{Context, Result, bail};
use fshape_match::record::{self, BatchIndex, BatchRow, MatchRecord, RunRecord, Status};
use fshape_mesh::io;

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

/// One row of the table.
#[derive(Clone, Debug)]
struct Row {
    /// Its position among the table's rows (from 0) and its line (from 1).
    index: usize,
    line: usize,
    name: String,
    source: PathBuf,
    target: PathBuf,
    /// One file per signal channel (none: the mesh's own signal).
    source_signal: Vec<PathBuf>,
    target_signal: Vec<PathBuf>,
    source_mask: Option<PathBuf>,
    target_mask: Option<PathBuf>,
    /// Why the row cannot run, if it cannot (the others still do).
    invalid: Option<String>,
}

const COLUMNS: [&str; 7] = ["source", "target", "source_signal", "target_signal", "source_mask", "target_mask", "name"];

/// Reads the table: `#` comments and blank lines skipped, a header naming
/// its columns (`source` and `target` required; `source_signal`,
/// `target_signal`, `source_mask`, `target_mask` and `name` optional, in
/// any order), then one pair per
/// line, paths relative to the table. A malformed row is returned with
/// `invalid` set; a malformed header or an unreadable file is an error.
fn read_pairs(path: &Path) -> Result<Vec<Row>> {
    let records = io::table::read_table(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut lines = records.into_iter();
    let Some(io::table::Record { line: header_line, fields: columns }) = lines.next() else {
        bail!("{}: no header (expected a line naming the columns, such as `source,target,name`)", path.display());
    };
    let header = columns.join(",");
    for (k, c) in columns.iter().enumerate() {
        if !COLUMNS.contains(&c.as_str()) {
            bail!("{}:{header_line}: unknown column `{c}` (the columns are {})", path.display(), COLUMNS.join(", "));
        }
        if columns[..k].contains(c) {
            bail!("{}:{header_line}: column `{c}` twice", path.display());
        }
    }
    let col = |name: &str| columns.iter().position(|c| *c == name);
    let (Some(source), Some(target)) = (col("source"), col("target")) else {
        bail!("{}:{header_line}: the header must name a `source` and a `target` column", path.display());
    };
    let mut rows: Vec<Row> = Vec::new();
    for (index, io::table::Record { line, fields }) in lines.enumerate() {
        let field = |k: Option<usize>| k.and_then(|k| fields.get(k)).filter(|f| !f.is_empty());
        let name = field(col("name")).map_or_else(|| format!("row_{:03}", index + 1), |s| s.to_string());
        // Several maps: `a.csv;b.csv`, a channel each.
        let maps = |f: Option<&String>| -> Vec<PathBuf> {
            f.into_iter()
                .flat_map(|f| f.split(';'))
                .map(str::trim)
                .filter(|f| !f.is_empty())
                .map(|f| base.join(f))
                .collect()
        };
        let mut row = Row {
            index,
            line,
            name: name.clone(),
            source: field(Some(source)).map_or_else(PathBuf::new, |f| base.join(f)),
            target: field(Some(target)).map_or_else(PathBuf::new, |f| base.join(f)),
            source_signal: maps(field(col("source_signal"))),
            target_signal: maps(field(col("target_signal"))),
            source_mask: field(col("source_mask")).map(|s| base.join(s)),
            target_mask: field(col("target_mask")).map(|s| base.join(s)),
            invalid: None,
        };
        row.invalid = if fields.len() != columns.len() {
            Some(format!("expected {} fields ({header}), found {}", columns.len(), fields.len()))
        } else if field(Some(source)).is_none() || field(Some(target)).is_none() {
            Some("a source and a target are required".into())
        } else if name.starts_with('.') || name.contains(['/', '\\']) {
            Some(format!("name `{name}` is not a plain directory name"))
        } else {
            rows.iter().find(|r| r.name == name).map(|other| format!("name `{name}` is also line {}'s", other.line))
        };
        rows.push(row);
    }
    Ok(rows)
}

/// A row's state, from its directory.
fn entry(out: &Path, pairs: &Path, row: &Row) -> BatchRow {
    let dir = out.join(&row.name);
    let mut e = BatchRow {
        row: row.index + 1,
        line: row.line,
        name: row.name.clone(),
        source: row.source.display().to_string(),
        target: row.target.display().to_string(),
        status: Status::Pending,
        value: None,
        attachment: None,
        mean_distance: None,
        p95_distance: None,
        target_within_1pct: None,
        signal_rms: None,
        iterations: None,
        seconds: None,
        error: None,
    };
    if let Some(why) = &row.invalid {
        e.status = Status::Failed;
        e.error = Some(format!("{}:{}: {why}", pairs.display(), row.line));
        return e;
    }
    let summary = dir.join("summary.json");
    if summary.exists() {
        match MatchRecord::read(&summary) {
            Ok(s) => {
                e.status = Status::Done;
                e.value = Some(s.final_value);
                e.attachment = Some(s.final_attachment);
                if let Some(q) = &s.quality {
                    e.mean_distance = Some(q.mean_distance);
                    e.p95_distance = Some(q.p95_distance);
                    e.target_within_1pct = Some(q.target_within_1pct);
                    e.signal_rms = q.signal_rms;
                }
                e.iterations = Some(s.iterations as u64);
                e.seconds = Some(s.seconds);
            }
            // A summary this fshape cannot read (damaged, or another
            // version's): said, not taken for a row to run again.
            Err(why) => {
                e.status = Status::Failed;
                e.error = Some(why.to_string());
            }
        }
    } else if let Ok(why) = std::fs::read_to_string(dir.join("error.txt")) {
        e.status = Status::Failed;
        e.error = Some(why.trim().to_string());
    } else if dir.join("checkpoint.bin").exists() {
        e.status = Status::Incomplete;
    }
    e
}

/// Writes index.csv, index.json and report.html of every row; returns
/// the entries.
fn write_index(a: &BatchArgs<'_>, rows: &[Row]) -> Result<Vec<BatchRow>> {
    let entries: Vec<BatchRow> = rows.iter().map(|r| entry(a.out, a.pairs, r)).collect();
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:e}"));
    let header = "row,line,name,source,target,status,value,attachment,mean_distance,p95_distance,target_within_1pct,\
                  signal_rms,iterations,seconds,error";
    let mut table = vec![header.split(',').map(str::to_string).collect::<Vec<_>>()];
    for e in &entries {
        table.push(vec![
            e.row.to_string(),
            e.line.to_string(),
            e.name.clone(),
            e.source.clone(),
            e.target.clone(),
            e.status.name().to_string(),
            opt(e.value),
            opt(e.attachment),
            opt(e.mean_distance),
            opt(e.p95_distance),
            opt(e.target_within_1pct),
            opt(e.signal_rms),
            e.iterations.map_or(String::new(), |i| i.to_string()),
            e.seconds.map_or(String::new(), |s| format!("{s:.3}")),
            e.error.clone().unwrap_or_default(),
        ]);
    }
    // Through the csv crate, with cells a spreadsheet would run as formulas
    // (`=…`, `+…`, `@…`) shown as text: names and errors come from users' files.
    let csv = io::table::table_text(&table, true);
    let count = |s: Status| entries.iter().filter(|e| e.status == s).count();
    let index = BatchIndex {
        kind: record::Kind::Batch,
        format: record::FORMAT,
        pairs: a.pairs.display().to_string(),
        config: a.config.display().to_string(),
        done: count(Status::Done),
        failed: count(Status::Failed),
        incomplete: count(Status::Incomplete),
        pending: count(Status::Pending),
        rows: entries,
    };
    std::fs::create_dir_all(a.out).with_context(|| format!("creating {}", a.out.display()))?;
    io::write_atomic(&a.out.join("index.csv"), csv.as_bytes(), false)?;
    io::write_atomic(&a.out.join("index.json"), &index.to_json(), false)?;
    let page = fshape_report::batch_page_of(a.out, &index, a.view)?;
    io::write_atomic(&a.out.join("report.html"), fshape_report::html(&page).as_bytes(), false)?;
    Ok(index.rows)
}

/// Registers one row (resuming its checkpoint if it has one); a failure is
/// written to its error.txt.
fn run_row(a: &BatchArgs<'_>, row: &Row) -> Result<()> {
    let dir = a.out.join(&row.name);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let error_file = dir.join("error.txt");
    if error_file.exists() {
        std::fs::remove_file(&error_file).with_context(|| format!("removing {}", error_file.display()))?;
    }
    let resume = dir.join("checkpoint.bin").exists();
    let result = crate::commands::matching::run_with(&crate::commands::matching::MatchArgs {
        masking: (
            crate::inputs::Masking { mask: row.source_mask.as_deref(), allow_missing: a.allow_missing },
            crate::inputs::Masking { mask: row.target_mask.as_deref(), allow_missing: a.allow_missing },
        ),
        source: &row.source,
        target: &row.target,
        signals: (&row.source_signal, &row.target_signal),
        config: a.config,
        out: &dir,
        resume,
        stop_after: None,
        signal_name: a.signal_name.clone(),
        times: a.times,
        view: a.view,
        stage_templates: &[],
        verbosity: a.verbosity,
        label: Some(&row.name),
    });
    if let Err(e) = &result {
        let message = crate::inputs::message(e);
        eprintln!("row {} ({}:{}) failed: {message}", row.name, a.pairs.display(), row.line);
        io::write_atomic(&error_file, format!("{message}\n").as_bytes(), false)?;
    }
    result
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

/// Parses `I/N` (I from 0 to N − 1).
pub fn run_with(a: &BatchArgs<'_>) -> Result<()> {
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
            let mine = BatchArgs { shard: Some((rank, size)), signal_name: a.signal_name.clone(), ..*a };
            let rows = read_pairs(a.pairs)?;
            let failed = if a.index_only { Ok(()) } else { run_rows(&mine, &rows) };
            crate::processes::barrier(&universe);
            if rank == 0 {
                let entries = write_index(a, &rows)?;
                report(a, &entries, None::<fn(&BatchRow) -> bool>);
            }
            return failed;
        }
    }
    let rows = read_pairs(a.pairs)?;
    if a.index_only {
        let entries = write_index(a, &rows)?;
        report(a, &entries, None::<fn(&BatchRow) -> bool>);
        return Ok(());
    }
    let failed = run_rows(a, &rows);
    let (shard, shards) = a.shard.unwrap_or((0, 1));
    let entries = write_index(a, &rows)?;
    report(a, &entries, Some(shard_filter(shard, shards)));
    failed
}

/// Whether the row in `dir` finished: its summary reads (a damaged one is
/// run again, and written whole).
fn done(dir: &Path) -> bool {
    MatchRecord::read(&dir.join("summary.json")).is_ok()
}

/// Registers this shard's rows that have not finished; an error when any
/// of its rows failed.
fn run_rows(a: &BatchArgs<'_>, rows: &[Row]) -> Result<()> {
    fshape_match::Config::read(a.config)?;
    let (shard, shards) = a.shard.unwrap_or((0, 1));
    let mine: Vec<&Row> = rows.iter().filter(|r| r.index % shards == shard).collect();
    let todo: Vec<&Row> = mine.iter().copied().filter(|r| r.invalid.is_none() && !done(&a.out.join(&r.name))).collect();
    eprintln!(
        "batch: {} rows in {}, {} in this shard ({}/{shards}), {} to run, {} at a time",
        rows.len(),
        a.pairs.display(),
        mine.len(),
        shard,
        todo.len(),
        a.jobs.max(1)
    );
    std::fs::create_dir_all(a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let jobs = a.jobs.max(1).min(todo.len().max(1));
    if jobs == 1 {
        for row in &todo {
            let _ = run_row(a, row);
        }
    } else {
        // Each worker a pool of its share of the cores; rows taken in order.
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = (cores / jobs).max(1);
        let next = AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..jobs {
                s.spawn(|| {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed);
                        let Some(row) = todo.get(k) else { break };
                        let _ = match &pool {
                            Ok(pool) => pool.install(|| run_row(a, row)),
                            Err(_) => run_row(a, row),
                        };
                    }
                });
            }
        });
    }
    let failed = mine.iter().filter(|r| entry(a.out, a.pairs, r).status == Status::Failed).count();
    if failed > 0 {
        bail!("{failed} of this shard's {} rows failed; see {}", mine.len(), a.out.join("index.csv").display());
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
