//! A batch of registrations (`fshape batch`): the table of pairs, each
//! row's state read from its folder, this shard's unfinished rows run (in
//! sequence or several at once, the cores shared among them) and the index
//! of every row. The caller says how one row is registered into its folder
//! (reading its files, [`register`](super::register), writing the
//! outputs) and writes the index; the rows' folders are where a batch
//! keeps its state, so a batch stopped anywhere is started again with the
//! same request: finished rows are kept, stopped rows resume, failed rows
//! are tried again.
//!
//! Registrations give the same bits for any number of threads, so a row's
//! result does not depend on the mode it ran in.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use fshape_mesh::io::table::{self, Record};

use crate::MatchError;
use crate::record::{self, BatchIndex, BatchRow, MatchRecord, RunRecord, Status};

/// The columns a table of pairs may name.
pub const COLUMNS: [&str; 7] =
    ["source", "target", "source_signal", "target_signal", "source_mask", "target_mask", "name"];

/// One row of the table of pairs, its paths relative to the table's folder
/// made whole.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchPair {
    /// Its position among the table's rows, from 0.
    pub index: usize,
    /// Its line in the table, from 1.
    pub line: usize,
    /// Its folder's name (`row_001` unless the table names it).
    pub name: String,
    /// The source mesh.
    pub source: PathBuf,
    /// The target mesh.
    pub target: PathBuf,
    /// One file per signal channel (none: the mesh's own signal).
    pub source_signal: Vec<PathBuf>,
    /// See `source_signal`.
    pub target_signal: Vec<PathBuf>,
    /// The source's mask file.
    pub source_mask: Option<PathBuf>,
    /// The target's mask file.
    pub target_mask: Option<PathBuf>,
    /// Why the row cannot run, if it cannot (the others still do).
    pub invalid: Option<String>,
}

/// Reads a table of pairs: `#` comments and blank lines skipped, a header
/// naming its columns ([`COLUMNS`]: `source` and `target` required, the
/// others optional, in any order), then one pair per line, paths relative
/// to the table; several maps per side as files separated by `;`. A
/// malformed row comes back with `invalid` set; a malformed header or an
/// unreadable file is an error.
pub fn read_pairs(path: &Path) -> Result<Vec<BatchPair>, MatchError> {
    let records = table::read_table(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let at = |line: usize, message: String| MatchError::Table { path: path.to_path_buf(), line: Some(line), message };
    let mut lines = records.into_iter();
    let Some(Record { line: header_line, fields: columns }) = lines.next() else {
        return Err(MatchError::Table {
            path: path.to_path_buf(),
            line: None,
            message: "no header (expected a line naming the columns, such as `source,target,name`)".into(),
        });
    };
    let header = columns.join(",");
    for (k, c) in columns.iter().enumerate() {
        if !COLUMNS.contains(&c.as_str()) {
            return Err(at(header_line, format!("unknown column `{c}` (the columns are {})", COLUMNS.join(", "))));
        }
        if columns[..k].contains(c) {
            return Err(at(header_line, format!("column `{c}` twice")));
        }
    }
    let col = |name: &str| columns.iter().position(|c| *c == name);
    let (Some(source), Some(target)) = (col("source"), col("target")) else {
        return Err(at(header_line, "the header must name a `source` and a `target` column".into()));
    };
    let mut rows: Vec<BatchPair> = Vec::new();
    for (index, Record { line, fields }) in lines.enumerate() {
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
        let mut row = BatchPair {
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

/// The file in a row's folder that says why it failed.
pub const ERROR_FILE: &str = "error.txt";

/// A batch: its table, where its rows' folders are, how many rows run at
/// once and this invocation's share of the rows.
#[derive(Clone, Copy, Debug)]
pub struct BatchRequest<'a> {
    /// The table of pairs.
    pub pairs: &'a Path,
    /// The configuration file, as given (for the index).
    pub config: &'a Path,
    /// The folder of the rows' folders.
    pub out: &'a Path,
    /// Rows registered at once on this machine.
    pub jobs: usize,
    /// This invocation's share of the rows: (index from 0, count); rows
    /// I, I + N, … (a cluster job array, or a process under mpirun).
    pub shard: (usize, usize),
}

impl BatchRequest<'_> {
    /// Whether the row is in this shard.
    pub fn in_shard(&self, row: &BatchPair) -> bool {
        row.index % self.shard.1.max(1) == self.shard.0
    }

    /// A row's folder.
    pub fn folder(&self, row: &BatchPair) -> PathBuf {
        self.out.join(&row.name)
    }

    /// A row's state from its folder: done (its summary reads: the
    /// figures), failed (an invalid row, an unreadable summary, or its
    /// error file), incomplete (a checkpoint) or pending.
    pub fn row_state(&self, row: &BatchPair) -> BatchRow {
        let dir = self.folder(row);
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
            e.error = Some(format!("{}:{}: {why}", self.pairs.display(), row.line));
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
        } else if let Ok(why) = std::fs::read_to_string(dir.join(ERROR_FILE)) {
            e.status = Status::Failed;
            e.error = Some(why.trim().to_string());
        } else if dir.join("checkpoint.bin").exists() {
            e.status = Status::Incomplete;
        }
        e
    }

    /// The index of every row, from their folders.
    pub fn index(&self, rows: &[BatchPair]) -> BatchIndex {
        let entries: Vec<BatchRow> = rows.iter().map(|r| self.row_state(r)).collect();
        let count = |s: Status| entries.iter().filter(|e| e.status == s).count();
        BatchIndex {
            kind: record::Kind::Batch,
            format: record::FORMAT,
            pairs: self.pairs.display().to_string(),
            config: self.config.display().to_string(),
            done: count(Status::Done),
            failed: count(Status::Failed),
            incomplete: count(Status::Incomplete),
            pending: count(Status::Pending),
            rows: entries,
        }
    }

    /// This shard's valid rows whose summary does not read yet (a damaged
    /// one is run again, and written whole).
    pub fn todo<'r>(&self, rows: &'r [BatchPair]) -> Vec<&'r BatchPair> {
        rows.iter()
            .filter(|r| self.in_shard(r) && r.invalid.is_none())
            .filter(|r| MatchRecord::read(&self.folder(r).join("summary.json")).is_err())
            .collect()
    }
}

/// What [`run_rows`] did: how many of this shard's rows failed (this
/// run's and earlier ones), and the rows whose folder or error file could
/// not be written (not run, or their error not recorded), each with why.
#[derive(Debug, Default)]
pub struct RowsRun {
    /// This shard's failed rows, from their folders.
    pub failed: usize,
    /// Rows the file system refused, by name.
    pub unwritable: Vec<(String, MatchError)>,
}

/// Registers `todo` with `register_row`, `request.jobs` rows at once (each
/// with a thread pool of its share of the cores, rows taken in order); a
/// row's error goes to its folder's [`ERROR_FILE`] (removed when it runs
/// again) and the others go on, as they do when a row's folder or error
/// file cannot be written (said in [`RowsRun::unwritable`]).
/// `register_row` registers one row into its folder (made before the
/// call) and returns its error's message.
pub fn run_rows(
    request: &BatchRequest<'_>,
    rows: &[BatchPair],
    todo: &[&BatchPair],
    register_row: &(dyn Fn(&BatchPair, &Path) -> Result<(), String> + Sync),
) -> RowsRun {
    let file_error =
        |path: &Path, e: std::io::Error| MatchError::File { path: path.to_path_buf(), message: e.to_string() };
    let one = |row: &BatchPair| -> Result<(), MatchError> {
        let dir = request.folder(row);
        std::fs::create_dir_all(&dir).map_err(|e| file_error(&dir, e))?;
        let error_file = dir.join(ERROR_FILE);
        if error_file.exists() {
            std::fs::remove_file(&error_file).map_err(|e| file_error(&error_file, e))?;
        }
        if let Err(message) = register_row(row, &dir) {
            fshape_mesh::io::write_atomic(&error_file, format!("{message}\n").as_bytes(), false)
                .map_err(|e| MatchError::File { path: error_file.clone(), message: e.to_string() })?;
        }
        Ok(())
    };
    let unwritable = std::sync::Mutex::new(Vec::new());
    let tried = |row: &BatchPair, done: Result<(), MatchError>| {
        if let Err(e) = done {
            unwritable.lock().unwrap_or_else(std::sync::PoisonError::into_inner).push((row.index, row.name.clone(), e));
        }
    };
    let jobs = request.jobs.max(1).min(todo.len().max(1));
    if jobs == 1 {
        for row in todo {
            tried(row, one(row));
        }
    } else {
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
                        let done = match &pool {
                            Ok(pool) => pool.install(|| one(row)),
                            Err(_) => one(row),
                        };
                        tried(row, done);
                    }
                });
            }
        });
    }
    // In the table's order, whichever thread met them.
    let mut unwritable = unwritable.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner);
    unwritable.sort_by_key(|(index, _, _)| *index);
    let failed = rows.iter().filter(|r| request.in_shard(r) && request.row_state(r).status == Status::Failed).count();
    RowsRun { failed, unwritable: unwritable.into_iter().map(|(_, name, e)| (name, e)).collect() }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;

    /// A table of four rows (the third invalid), in a fresh folder.
    fn table(tag: &str) -> (PathBuf, Vec<BatchPair>) {
        let dir = std::env::temp_dir().join(format!("fshape-batch-op-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let pairs = dir.join("pairs.csv");
        std::fs::write(
            &pairs,
            "# pairs\nsource,target,name\na.ply,b.ply,first\nc.ply,d.ply,\ne.ply,,x\nf.ply,g.ply,last\n",
        )
        .unwrap();
        let rows = read_pairs(&pairs).unwrap();
        (dir, rows)
    }

    #[test]
    fn rows_run_once_in_their_shard_and_their_state_is_read_from_their_folders() {
        for jobs in [1, 3] {
            let (dir, rows) = table(&format!("jobs{jobs}"));
            let names: Vec<&str> = rows.iter().map(|r| r.name.as_str()).collect();
            assert_eq!(names, ["first", "row_002", "x", "last"]);
            assert_eq!(rows[0].source, dir.join("a.ply"));
            assert_eq!(rows[2].invalid.as_deref(), Some("a source and a target are required"));
            let out = dir.join("out");
            let (pairs, config) = (dir.join("pairs.csv"), dir.join("c.toml"));
            let request = BatchRequest { pairs: &pairs, config: &config, out: &out, jobs, shard: (0, 1) };
            let seen = Mutex::new(Vec::new());
            // The first row fails, the second stops with a checkpoint, the
            // last is left alone by its shard... here every row is ours.
            let register = |row: &BatchPair, folder: &Path| -> Result<(), String> {
                seen.lock().unwrap().push(row.name.clone());
                assert!(folder.is_dir() && folder.ends_with(&row.name));
                match row.index {
                    0 => Err(format!("{} cannot be read", row.source.display())),
                    1 => {
                        std::fs::write(folder.join("checkpoint.bin"), b"state").unwrap();
                        Ok(())
                    }
                    _ => Ok(()),
                }
            };
            let todo = request.todo(&rows);
            assert_eq!(todo.len(), 3, "the invalid row is not run");
            // The last row's folder cannot be made (a file is in the way):
            // said, and the other rows still run.
            std::fs::create_dir_all(&out).unwrap();
            std::fs::write(out.join("last"), b"in the way").unwrap();
            let run = run_rows(&request, &rows, &todo, &register);
            assert_eq!(run.unwritable.len(), 1);
            assert_eq!(run.unwritable[0].0, "last");
            assert!(run.unwritable[0].1.to_string().contains("last"), "{}", run.unwritable[0].1);
            std::fs::remove_file(out.join("last")).unwrap();
            let failed = run.failed;
            let mut seen = seen.into_inner().unwrap();
            seen.sort();
            assert_eq!(seen, ["first", "row_002"], "each valid row with a folder once");
            assert_eq!(failed, 2, "the failed row and the invalid one");
            let index = request.index(&rows);
            let status: Vec<Status> = index.rows.iter().map(|r| r.status).collect();
            assert_eq!(status, [Status::Failed, Status::Incomplete, Status::Failed, Status::Pending]);
            assert!(index.rows[0].error.as_deref().unwrap().ends_with("a.ply cannot be read"));
            assert!(index.rows[2].error.as_deref().unwrap().contains("pairs.csv:5: a source and a target"));
            assert_eq!((index.done, index.failed, index.incomplete, index.pending), (0, 2, 1, 1));
            // Run again with a register that succeeds: the error file goes.
            let ok = |_: &BatchPair, _: &Path| -> Result<(), String> { Ok(()) };
            run_rows(&request, &rows, &request.todo(&rows), &ok);
            assert_eq!(request.index(&rows).rows[0].status, Status::Pending);
            // Shard 1 of 2 holds the second and fourth rows.
            let half = BatchRequest { shard: (1, 2), ..request };
            let mine: Vec<&str> = half.todo(&rows).iter().map(|r| r.name.as_str()).collect();
            assert_eq!(mine, ["row_002", "last"]);
            std::fs::remove_dir_all(&dir).unwrap();
        }
    }

    #[test]
    fn a_bad_header_is_named_with_its_line() {
        let dir = std::env::temp_dir().join(format!("fshape-batch-header-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let pairs = dir.join("pairs.csv");
        for (text, message) in [
            ("\n# nothing\n", "pairs.csv: no header"),
            ("source,weight\n", "pairs.csv:1: unknown column `weight`"),
            ("# a comment\nsource,source\n", "pairs.csv:2: column `source` twice"),
            ("source,name\n", "pairs.csv:1: the header must name a `source` and a `target`"),
        ] {
            std::fs::write(&pairs, text).unwrap();
            let e = read_pairs(&pairs).unwrap_err().to_string();
            assert!(e.contains(message), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
