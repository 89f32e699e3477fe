//! Running one shard of a [`Plan`] into a folder that many shards share.
//!
//! Layout of a sharded run's folder (`--out DIR`), which the shards of one
//! plan share, each possibly on another machine of a cluster's shared file
//! system:
//!
//! ```text
//! DIR/.surgbench-shards     marker: a sharded run's folder (SHARDS_MARKER)
//! DIR/plan.json             the plan (Plan), the same bytes from every shard
//! DIR/points/<id>.json      one finished point (PointRecord), written atomically
//! DIR/runs/<scenario>/<model>/<fidelity>/   its run-one files, as in a report
//! ```
//!
//! Every file a shard writes belongs to one of its own points, or is the
//! plan (identical from every shard), and is written to a temporary name
//! carrying the host and pid and renamed into place: shards never write
//! into one file, and nothing of another shard's is removed or replaced.
//! The folder is never replaced as a whole (the rule of `run --out`): a
//! sharded run joins a folder that is absent, empty or already a sharded
//! run's, and refuses anything else.
//!
//! A point is finished once its `points/<id>.json` exists; a shard run
//! again (resumed) skips its finished points, so a shard killed halfway
//! completes on the next run without redoing them.

use crate::UsageError;
use crate::batch::{self, BatchError, BatchOptions};
use crate::comparison::{Comparison, Job};
use crate::plan::{Plan, PlanPoint, describe, host_name, write_atomic};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;
use surgbench_reports::{ResultRow, Status};

/// The file that marks a folder as a sharded run's.
pub const SHARDS_MARKER: &str = ".surgbench-shards";

/// What the marker says to a person who finds it.
const SHARDS_MARKER_TEXT: &str = "This folder holds the points of a sharded surgbench run (plan.json, points/, \
runs/); shards add to it and never replace it. `surgbench merge` turns it into a report.\n";

/// The folder of point files.
pub const POINTS_DIR: &str = "points";

/// The `format` a point file carries.
pub const POINT_FORMAT: &str = "surgbench-point/1";

/// One finished point: its result row and where and how it ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointRecord {
    /// [`POINT_FORMAT`].
    pub format: String,
    /// The point's id ([`crate::plan::point_id`]).
    pub id: String,
    /// Shard index that ran it.
    pub shard: usize,
    /// Shard count.
    pub shards: usize,
    /// Comparison name.
    pub comparison: String,
    /// Comparison file hash ([`crate::plan::file_hash`]).
    pub comparison_hash: String,
    /// Commit of the code that ran it.
    pub commit: String,
    /// Host name of the machine it ran on.
    pub host: String,
    /// CPU model, OS and architecture of that machine.
    pub machine: String,
    /// Cores on that machine.
    pub cores: usize,
    /// Threads per run.
    pub threads: usize,
    /// When it finished (UTC, ISO 8601).
    pub finished: String,
    /// Wall time of the point, child process included (s).
    pub wall_s: f64,
    /// The result row as `results.csv` cells ([`surgbench_reports::row_cells`]):
    /// numbers in round-trip text, so the merged `results.csv` holds the
    /// very bits this shard measured.
    pub cells: BTreeMap<String, String>,
}

impl PointRecord {
    /// The result row, with the host it ran on.
    pub fn row(&self) -> Result<ResultRow, String> {
        let mut row = surgbench_reports::row_from_cells(&self.cells)?;
        row.host = self.host.clone();
        Ok(row)
    }

    /// Reads a point file; errors name the file.
    pub fn read(path: &Path) -> Result<PointRecord, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let rec: PointRecord =
            serde_json::from_str(&text).map_err(|e| format!("{}: not a point file: {e}", path.display()))?;
        if rec.format != POINT_FORMAT {
            return Err(format!(
                "{}: format `{}`, this surgbench reads `{POINT_FORMAT}`",
                path.display(),
                rec.format
            ));
        }
        rec.row().map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(rec)
    }
}

/// The path of point `id`'s file in a sharded run's folder.
pub fn point_path(dir: &Path, id: &str) -> PathBuf {
    dir.join(POINTS_DIR).join(format!("{id}.json"))
}

/// Makes `dir` a sharded run's folder, or checks that it is one: an absent
/// or empty folder gets the [`SHARDS_MARKER`] (shards starting at once may
/// all write it; it is the first thing any of them writes, so a folder that
/// holds anything else holds the marker too); a folder with the marker is
/// joined as it is. A file, a surgbench report folder or any other
/// non-empty folder is a usage error, and nothing in it is touched.
pub fn prepare_dir(dir: &Path) -> Result<(), UsageError> {
    let named = |what: String| UsageError(format!("--out {}: {what}", dir.display()));
    match std::fs::symlink_metadata(dir) {
        Ok(m) if !m.is_dir() => return Err(named("exists and is not a folder; choose another path".into())),
        Ok(_) if dir.join(SHARDS_MARKER).exists() => return Ok(()),
        Ok(_) => {
            let mut entries = std::fs::read_dir(dir).map_err(|e| named(format!("cannot read it: {e}")))?;
            if entries.next().is_some() && !dir.join(SHARDS_MARKER).exists() {
                let what = if dir.join(crate::outdir::MARKER).exists() {
                    "is the report of an unsharded run"
                } else {
                    "is a non-empty folder that is not a sharded run's"
                };
                return Err(named(format!(
                    "{what}; a sharded run adds its points to a shared folder and never replaces one: choose another --out"
                )));
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            std::fs::create_dir_all(dir).map_err(|e| named(format!("cannot create it: {e}")))?;
        }
        Err(e) => return Err(named(format!("cannot inspect it: {e}"))),
    }
    std::fs::write(dir.join(SHARDS_MARKER), SHARDS_MARKER_TEXT).map_err(|e| named(format!("cannot write it: {e}")))
}

/// Puts `plan` into the sharded run's folder `dir` ([`prepare_dir`] first):
/// writes it when the folder has none, and otherwise checks that the
/// folder's plan is the same run (else a usage error listing what differs).
pub fn ensure_plan(dir: &Path, plan: &Plan) -> Result<(), UsageError> {
    prepare_dir(dir)?;
    match Plan::load(dir)? {
        Some(there) => {
            let d = plan.differences(&there);
            if d.is_empty() {
                Ok(())
            } else {
                Err(UsageError(format!(
                    "{} holds the plan of another run ({}); use another --out for this one",
                    dir.join(crate::plan::PLAN_FILE).display(),
                    d.join("; ")
                )))
            }
        }
        None => plan
            .write(dir)
            .map_err(|e| UsageError(format!("cannot write the plan into {}: {e}", dir.display()))),
    }
}

/// The machine a shard runs on, as its point records name it.
struct Machine {
    host: String,
    machine: String,
    cores: usize,
}

impl Machine {
    fn this() -> Self {
        Machine {
            host: host_name(),
            machine: batch::machine_description(),
            cores: batch::cores(),
        }
    }

    /// The record of `point` of `plan`, run by shard `index` on this
    /// machine with `threads` threads in `wall_s` seconds, its result `row`.
    fn record(
        &self,
        plan: &Plan,
        point: &PlanPoint,
        index: usize,
        threads: usize,
        wall_s: f64,
        row: &ResultRow,
    ) -> PointRecord {
        PointRecord {
            format: POINT_FORMAT.into(),
            id: point.id.clone(),
            shard: index,
            shards: plan.shards,
            comparison: plan.comparison.clone(),
            comparison_hash: plan.comparison_hash.clone(),
            commit: plan.commit.clone(),
            host: self.host.clone(),
            machine: self.machine.clone(),
            cores: self.cores,
            threads,
            finished: batch::utc_now(),
            wall_s,
            cells: surgbench_reports::row_cells(row),
        }
    }
}

/// What one shard run did.
#[derive(Debug, Clone, Default)]
pub struct ShardOutcome {
    /// The shard's points.
    pub points: usize,
    /// Finished before this run and skipped.
    pub skipped: usize,
    /// Rows of the points this run ran, in plan order.
    pub rows: Vec<ResultRow>,
}

/// Runs shard `index` of `plan` (whose points are `jobs`, one each, in
/// order) into the sharded run's folder `opts.out`: each point in its own
/// child process as `surgbench run` does ([`batch`]), its row written to
/// `points/<id>.json` as soon as it is done. With `resume`, points whose
/// file exists are skipped. A SIGINT/SIGTERM stops the running point (its
/// file is not written) and returns [`BatchError::Interrupted`]; finished
/// points stay.
pub fn run_shard(
    c: &Comparison,
    plan: &Plan,
    jobs: &[Job],
    index: usize,
    opts: &BatchOptions,
    resume: bool,
) -> Result<ShardOutcome, BatchError> {
    let dir = &opts.out;
    ensure_plan(dir, plan)?;
    let points_dir = dir.join(POINTS_DIR);
    let runs = dir.join("runs");
    for d in [&points_dir, &runs] {
        std::fs::create_dir_all(d).map_err(|e| BatchError::Io(format!("cannot create {}: {e}", d.display())))?;
    }
    let here = Machine::this();
    if jobs.len() != plan.points.len() {
        return Err(BatchError::Io(format!(
            "the plan has {} points but {} jobs were given",
            plan.points.len(),
            jobs.len()
        )));
    }
    let mine: Vec<(&PlanPoint, &Job)> = plan.shard_points(index).map(|(i, p)| (p, &jobs[i])).collect();
    let mut out = ShardOutcome {
        points: mine.len(),
        ..Default::default()
    };
    for (i, (point, job)) in mine.into_iter().enumerate() {
        let path = point_path(dir, &point.id);
        if resume && PointRecord::read(&path).is_ok() {
            out.skipped += 1;
            continue;
        }
        let started = Instant::now();
        let mut row = batch::run_job(c, job, &runs, opts, plan.repeats, plan.timeout_s)?;
        row.host = here.host.clone();
        let rec = here.record(plan, point, index, opts.threads, started.elapsed().as_secs_f64(), &row);
        let text = serde_json::to_string_pretty(&rec).map_err(|e| BatchError::Io(e.to_string()))? + "\n";
        write_atomic(&path, text.as_bytes())
            .map_err(|e| BatchError::Io(format!("cannot write {}: {e}", path.display())))?;
        if !opts.quiet {
            use std::io::Write as _;
            // A closed stdout (a pipe into `head`) is no reason to stop.
            let _ = writeln!(
                std::io::stdout(),
                "[shard {index}/{}] {}/{} {}: {} ({:.1} s)",
                plan.shards,
                i + 1,
                out.points,
                describe(point),
                row.status,
                rec.wall_s
            );
        }
        out.rows.push(row);
        if let Some(sig) = crate::interrupt::pending() {
            return Err(BatchError::Interrupted(sig));
        }
    }
    Ok(out)
}

/// Counts of `rows` by status, for the one line a shard prints.
pub fn status_line(rows: &[ResultRow]) -> String {
    let count = |s: Status| rows.iter().filter(|r| r.status == s).count();
    format!(
        "{} ok, {} unstable, {} unsupported, {} failed, {} timeout",
        count(Status::Ok),
        count(Status::Unstable),
        count(Status::Unsupported),
        count(Status::Failed),
        count(Status::Timeout)
    )
}
