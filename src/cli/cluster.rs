//! The cluster commands: `plan`, `run --shard` and `merge`
//! ([`surgbench_comparisons::plan`], [`surgbench_comparisons::shard_run`],
//! [`surgbench_comparisons::merge`]).

use super::{Failure, RunArgs, SweepArgs, install_interrupt};
use clap::Args;
use std::path::PathBuf;
use surgbench_comparisons::batch::{self, BatchError};
use surgbench_comparisons::comparison::{Comparison, Job};
use surgbench_comparisons::merge::{self, MergeOptions};
use surgbench_comparisons::plan::{self, Plan, PlanSettings, ShardIndex};
use surgbench_comparisons::shard_run;

/// `surgbench plan`.
#[derive(Args)]
pub(crate) struct PlanArgs {
    #[command(flatten)]
    sweep: SweepArgs,
    /// How many shards (array tasks) to split the points over.
    #[arg(long)]
    shards: usize,
    /// The sharded run's folder (shared by every shard): absent, empty or
    /// an earlier sharded run's with the same plan.
    #[arg(long)]
    out: PathBuf,
    /// Also list every point with its id and shard.
    #[arg(long)]
    verbose: bool,
}

/// `surgbench merge`.
#[derive(Args)]
pub(crate) struct MergeArgs {
    /// Sharded run folders (`run --shard ... --out DIR`) to gather.
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Report folder, replaced as a whole like `run --out`: an earlier
    /// surgbench report or an empty folder (any other folder only with --force).
    #[arg(long)]
    out: PathBuf,
    /// Replace --out even when it is a non-empty folder that is not a surgbench report.
    #[arg(long)]
    force: bool,
    /// Write the report even when points are missing (they are listed).
    #[arg(long)]
    partial: bool,
    /// Merge folders whose comparison, comparison file or commit differ.
    #[arg(long)]
    allow_mixed: bool,
}

/// The comparison `sweep` names, its validated jobs and their plan over `shards`.
fn make_plan(sweep: &SweepArgs, shards: usize) -> Result<(Comparison, Plan, Vec<Job>), Failure> {
    sweep.check()?;
    let (quick, models, repeats, timeout) = (sweep.quick, sweep.models.clone(), sweep.repeats, sweep.timeout);
    let (c, path) = sweep.comparison()?;
    let jobs = batch::checked_jobs(&c, quick, models.as_deref())?;
    let settings = PlanSettings {
        comparison_hash: plan::file_hash(&path)?,
        commit: batch::git_commit(),
        quick,
        models,
        repeats: batch::repeats_of(&c, quick, repeats),
        timeout_s: batch::timeout_of(&c, timeout),
        shards,
        budgets_ms: sweep.budgets_ms()?,
    };
    let p = Plan::new(&c, &jobs, settings)?;
    Ok((c, p, jobs))
}

/// `surgbench plan`: write the plan into the sharded run's folder and say
/// how many points each shard gets.
pub(crate) fn cmd_plan(a: PlanArgs) -> Result<(), Failure> {
    let (c, p, _) = make_plan(&a.sweep, a.shards)?;
    shard_run::ensure_plan(&a.out, &p)?;
    say!(
        "{}: {} points over {} shards, commit {}, plan in {}",
        p.comparison,
        p.points.len(),
        p.shards,
        p.commit,
        a.out.join(plan::PLAN_FILE).display()
    );
    for (k, n) in p.counts().iter().enumerate() {
        say!("  shard {k}: {n} points");
    }
    if a.verbose {
        for pt in &p.points {
            say!("  {} shard {}: {}", pt.id, pt.shard, plan::describe(pt));
        }
    }
    if !c.haptic.is_empty() {
        say!(
            "note: a sharded run leaves out the comparison's [[haptic]] loops (they time the wall clock of one machine)"
        );
    }
    Ok(())
}

/// `surgbench run` as one shard of a sharded run.
pub(crate) fn cmd_run_sharded(a: RunArgs, shard: ShardIndex) -> Result<(), Failure> {
    let Some(out) = a.out.clone() else {
        return Err(Failure::Usage(
            "a sharded run needs --out DIR: the folder every shard shares".into(),
        ));
    };
    if a.force {
        return Err(Failure::Usage(
            "--force does not apply to a sharded run: it never replaces its --out folder".into(),
        ));
    }
    // The plan already in the folder (from `surgbench plan` or an earlier
    // shard) says how many shards there are.
    let existing = Plan::load(&out)?;
    let (count, note) = plan::resolve_count(&shard, a.shards, existing.as_ref())?;
    let (c, p, jobs) = make_plan(&a.sweep, count)?;
    if let Some(n) = note {
        eprintln!("note: {n}");
    }
    install_interrupt()?;
    let opts = a.batch_options(out.clone())?;
    let done = shard_run::run_shard(&c, &p, &jobs, shard.index, &opts, !a.no_resume).map_err(batch_failure)?;
    if !a.quiet {
        say!(
            "shard {}/{} (from {}): {} points, {} finished earlier and skipped, {} run: {}",
            shard.index,
            count,
            shard.source,
            done.points,
            done.skipped,
            done.rows.len(),
            shard_run::status_line(&done.rows)
        );
        say!(
            "points in {}; gather them with `surgbench merge {} --out REPORT`",
            out.join(shard_run::POINTS_DIR).display(),
            out.display()
        );
    }
    Ok(())
}

/// A batch error as the exit code it means.
pub(crate) fn batch_failure(e: BatchError) -> Failure {
    match e {
        BatchError::Usage(u) => Failure::Usage(u.0),
        BatchError::Io(s) => Failure::Runtime(s),
        e @ BatchError::Interrupted(sig) => Failure::Interrupted(e.to_string(), sig),
    }
}

/// `surgbench merge`: gather, refuse mixed runs and (without `--partial`)
/// missing points, then write the report.
pub(crate) fn cmd_merge(a: MergeArgs) -> Result<(), Failure> {
    let g = merge::gather(&a.dirs)?;
    if !g.mixed.is_empty() && !a.allow_mixed {
        return Err(Failure::Usage(format!(
            "the folders are not one run (pass --allow-mixed to merge them anyway):\n  {}",
            g.mixed.join("\n  ")
        )));
    }
    for m in &g.mixed {
        eprintln!("warning: mixed: {m}");
    }
    let planned = g.rows.len() + g.missing.len();
    if !g.failed.is_empty() {
        eprintln!("{} points failed or timed out:", g.failed.len());
        for f in &g.failed {
            eprintln!("  {f}");
        }
    }
    if !g.missing.is_empty() {
        eprintln!(
            "{} of {planned} points are missing (no shard finished them):",
            g.missing.len()
        );
        for p in &g.missing {
            eprintln!("  {} shard {}: {}", p.id, p.shard, plan::describe(p));
        }
        if !a.partial {
            return Err(Failure::Runtime(format!(
                "{} points missing: rerun their shards (finished points are skipped), or pass --partial for a report without them",
                g.missing.len()
            )));
        }
    }
    install_interrupt()?;
    let opts = MergeOptions {
        out: a.out.clone(),
        force: a.force,
        command: std::env::args().collect::<Vec<_>>().join(" "),
    };
    merge::write_report(&g, &opts).map_err(batch_failure)?;
    let rows: Vec<_> = g.rows.iter().map(|(r, _)| r.clone()).collect();
    let hosts: std::collections::BTreeSet<&str> = rows.iter().map(|r| r.host.as_str()).collect();
    say!(
        "merged {} of {planned} points from {} folders, {} machines: {}",
        rows.len(),
        a.dirs.len(),
        hosts.len(),
        shard_run::status_line(&rows)
    );
    say!("report: {}", a.out.join("index.html").display());
    Ok(())
}
