//! `surgbench merge`: the points of one or more sharded run folders
//! ([`crate::shard_run`]) gathered into one report.
//!
//! The rows come in the plan's order (the comparison's, as `surgbench run`
//! writes them), each with the host it ran on; the report groups speed
//! figures by machine when more than one machine ran (see
//! `surgbench_reports::render`). Points that no shard has finished are
//! named; so are the ones that failed or timed out. Folders whose plans or
//! points belong to different comparisons, comparison files or commits are
//! refused unless the caller allows it.

use crate::UsageError;
use crate::batch::{self, BatchError};
use crate::plan::{Plan, PlanPoint, describe};
use crate::shard_run::{POINTS_DIR, PointRecord};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use surgbench_reports::{ResultRow, RunInfo, Status};

/// The points of the sharded run folders, gathered.
#[derive(Debug, Default)]
pub struct Gathered {
    /// The first folder's plan (the others' agree with it unless mixing was allowed).
    pub plan: Option<Plan>,
    /// Rows of the finished points, in plan order, with the folder each came from.
    pub rows: Vec<(ResultRow, PathBuf)>,
    /// The records of those points, in the same order.
    pub records: Vec<PointRecord>,
    /// Points of the plans that no folder has finished.
    pub missing: Vec<PlanPoint>,
    /// Finished points whose status is `failed` or `timeout`, described.
    pub failed: Vec<String>,
    /// What differs between the folders' plans and points (empty: one run).
    pub mixed: Vec<String>,
}

/// Reads every `points/*.json` of `dir` (temporary files, which start with
/// `.`, are not points), by id.
fn read_points(dir: &Path) -> Result<BTreeMap<String, PointRecord>, UsageError> {
    let pdir = dir.join(POINTS_DIR);
    let mut out = BTreeMap::new();
    let entries = match std::fs::read_dir(&pdir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(UsageError(format!("cannot read {}: {e}", pdir.display()))),
    };
    let mut paths: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or(".");
            !name.starts_with('.') && name.ends_with(".json")
        })
        .collect();
    paths.sort();
    for p in paths {
        let rec = PointRecord::read(&p).map_err(UsageError)?;
        out.insert(rec.id.clone(), rec);
    }
    Ok(out)
}

/// What differs between `plan` and a point `rec` it holds, as a line, if anything.
fn record_mismatch(plan: &Plan, rec: &PointRecord, dir: &Path) -> Option<String> {
    let mut d = Vec::new();
    for (what, a, b) in [
        ("comparison", &plan.comparison, &rec.comparison),
        ("comparison file hash", &plan.comparison_hash, &rec.comparison_hash),
        ("commit", &plan.commit, &rec.commit),
    ] {
        if a != b {
            d.push(format!("{what} {b} (plan: {a})"));
        }
    }
    (!d.is_empty()).then(|| format!("{}: point {} has {}", dir.display(), rec.id, d.join(", ")))
}

/// Gathers the points of the sharded run folders `dirs`. A folder without
/// a plan, or a plan or point file that cannot be read, is a usage error.
/// Differences between the folders' plans (comparison, comparison file,
/// commit, sweeps, ...) or between a plan and its points (comparison, file,
/// commit) are listed in [`Gathered::mixed`]; the caller refuses them
/// unless told otherwise. A point finished in several folders counts once
/// (the first folder's).
pub fn gather(dirs: &[PathBuf]) -> Result<Gathered, UsageError> {
    let mut g = Gathered::default();
    let mut expected: Vec<PlanPoint> = Vec::new();
    let mut seen = BTreeSet::new();
    let mut found: BTreeMap<String, (PointRecord, PathBuf)> = BTreeMap::new();
    for dir in dirs {
        let plan = Plan::load(dir)?.ok_or_else(|| {
            UsageError(format!(
                "{} has no {}: not a sharded run's folder (surgbench run --shard K/N --out DIR writes one)",
                dir.display(),
                crate::plan::PLAN_FILE
            ))
        })?;
        match &g.plan {
            None => g.plan = Some(plan.clone()),
            Some(first) => {
                // The shard count may differ: the same points, sharded otherwise.
                let d: Vec<String> = first
                    .differences(&plan)
                    .into_iter()
                    .filter(|l| !l.starts_with("shards:") && !l.starts_with("points:"))
                    .collect();
                if !d.is_empty() {
                    g.mixed
                        .push(format!("{} and {}: {}", dirs[0].display(), dir.display(), d.join("; ")));
                }
            }
        }
        for p in &plan.points {
            if seen.insert(p.id.clone()) {
                expected.push(p.clone());
            }
        }
        for (id, rec) in read_points(dir)? {
            if let Some(m) = record_mismatch(&plan, &rec, dir) {
                g.mixed.push(m);
            }
            if !plan.points.iter().any(|p| p.id == id) {
                g.mixed
                    .push(format!("{}: point {id} is in no plan of that folder", dir.display()));
            }
            found.entry(id).or_insert((rec, dir.clone()));
        }
    }
    for p in expected {
        match found.remove(&p.id) {
            Some((rec, dir)) => {
                let row = rec.row().map_err(UsageError)?;
                if matches!(row.status, Status::Failed | Status::Timeout) {
                    g.failed
                        .push(format!("{} {}: {}: {}", p.id, describe(&p), row.status, row.reason));
                }
                g.rows.push((row, dir));
                g.records.push(rec);
            }
            None => g.missing.push(p),
        }
    }
    Ok(g)
}

/// How to write a merged report.
#[derive(Debug, Clone)]
pub struct MergeOptions {
    /// Report folder (the rules of `run --out`: [`crate::outdir`]).
    pub out: PathBuf,
    /// Replace `out` even when it is a non-empty folder that is not a surgbench report.
    pub force: bool,
    /// The command line, for the record.
    pub command: String,
}

/// The report header of a merged run: the plan's comparison and commit,
/// the machines that ran it, and the summed wall time of its points.
fn merged_info(g: &Gathered, opts: &MergeOptions) -> RunInfo {
    let plan = g.plan.as_ref();
    let mut machines: BTreeMap<&str, &str> = BTreeMap::new();
    for r in &g.records {
        machines.insert(&r.host, &r.machine);
    }
    let machine = match machines.len() {
        1 => machines.iter().map(|(h, m)| format!("{m} on {h}")).collect(),
        n => format!(
            "{n} machines: {}",
            machines
                .iter()
                .map(|(h, m)| format!("{h} ({m})"))
                .collect::<Vec<_>>()
                .join("; ")
        ),
    };
    let first = g.records.first();
    RunInfo {
        comparison: plan.map(|p| p.comparison.clone()).unwrap_or_default(),
        date: batch::utc_now(),
        commit: plan.map(|p| p.commit.clone()).unwrap_or_default(),
        machine,
        cores: first.map_or(0, |r| r.cores),
        threads: first.map_or(0, |r| r.threads),
        // Not known: the shards' binaries may have been built anywhere
        // (the commit above is what they share); the page says "(unknown)".
        rustc: String::new(),
        crate_versions: batch::crate_versions(),
        command: opts.command.clone(),
        quick: plan.is_some_and(|p| p.quick),
        wall_s: g.records.iter().map(|r| r.wall_s).sum(),
        python_models: batch::python_models(g.rows.iter().map(|(r, _)| r)),
        fitted: batch::fitted_models(g.rows.iter().map(|(r, _)| r)),
        targets: plan.map(|p| p.targets.clone()).unwrap_or_default(),
        budgets_ms: plan.map_or_else(
            || surgbench_reports::DEFAULT_BUDGETS_MS.to_vec(),
            |p| p.budgets_ms.clone(),
        ),
    }
}

/// Links each row's run folder (`run_dir`, relative to the sharded run's
/// folder it came from) into the report folder `to` at the same path.
fn link_run_dirs(g: &Gathered, to: &Path) -> std::io::Result<()> {
    for (row, from) in &g.rows {
        if row.run_dir.is_empty() || !from.join(&row.run_dir).is_dir() {
            continue;
        }
        let dst = to.join(&row.run_dir);
        if dst.exists() {
            continue;
        }
        std::fs::create_dir_all(&dst)?;
        surgbench_reports::staging::link_tree(&from.join(&row.run_dir), &dst, &|_| false)?;
    }
    Ok(())
}

/// Writes the merged report of `g` into `opts.out` the way `surgbench run`
/// writes its report: `results.csv` (with the `host` column), `summary.json`,
/// the run folders (hard links) and the rendered pages, built in a temporary
/// sibling and moved into place; on any error `opts.out` is left as it was.
pub fn write_report(g: &Gathered, opts: &MergeOptions) -> Result<(), BatchError> {
    crate::outdir::check_replaceable(&opts.out, opts.force)?;
    let io = |what: &'static str| move |e: std::io::Error| BatchError::Io(format!("{what}: {e}"));
    let tmp = batch::temp_sibling(&opts.out).map_err(io("cannot create the temporary report folder"))?;
    let rows: Vec<ResultRow> = g.rows.iter().map(|(r, _)| r.clone()).collect();
    let result = (|| -> Result<(), BatchError> {
        crate::outdir::write_marker(&tmp).map_err(io("cannot write the report marker"))?;
        link_run_dirs(g, &tmp).map_err(io("cannot link the run folders"))?;
        let info = merged_info(g, opts);
        let report = |e: surgbench_reports::ReportError| BatchError::Io(e.to_string());
        surgbench_reports::write_results_csv(&tmp.join("results.csv"), &rows).map_err(report)?;
        surgbench_reports::write_run_info(&tmp.join("summary.json"), &info).map_err(report)?;
        surgbench_reports::render(&tmp, &rows, &info).map_err(report)?;
        batch::replace_dir(&tmp, &opts.out).map_err(io("cannot move the report into place"))
    })();
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}
