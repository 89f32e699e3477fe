//! `surgbench diff OLD NEW` (two reports compared point by point, what
//! changed beyond the tolerances: [`surgbench_reports::diff`]) and
//! `surgbench accuracy-gate REPORT` (the same against the committed errors
//! of the quick comparison on this CPU type: CI's accuracy gate).

use super::Failure;
use clap::Args;
use std::path::{Path, PathBuf};
use surgbench_comparisons::gate::cpu_model;
use surgbench_reports::diff::{Change, DiffOptions, PointDiff, ReportDiff, diff_reports};
use surgbench_reports::{ResultRow, fmt_sig, read_results_csv, write_results_csv};

/// `surgbench diff`.
#[derive(Args)]
pub(crate) struct DiffArgs {
    /// The earlier report: its folder or its results.csv.
    old: PathBuf,
    /// The later report: its folder or its results.csv.
    new: PathBuf,
    /// Relative tolerance on metrics (default: round-off).
    #[arg(long, default_value_t = DiffOptions::default().rel)]
    tolerance: f64,
    /// Absolute tolerance on metrics, in each metric's unit.
    #[arg(long, default_value_t = 0.0)]
    abs_tolerance: f64,
    /// Relative tolerance on the median ms/step.
    #[arg(long, default_value_t = 0.25)]
    time_tolerance: f64,
    /// Judge errors and statuses only, not times (times differ from machine
    /// to machine and run to run).
    #[arg(long)]
    errors_only: bool,
    /// Exit 1 when anything regressed (a worse status or error, a slower
    /// step beyond the time tolerance, a point no longer measured).
    #[arg(long)]
    fail_on_regression: bool,
    /// List every point, not only those that changed.
    #[arg(long)]
    all: bool,
}

/// `surgbench accuracy-gate`.
#[derive(Args)]
pub(crate) struct AccuracyGateArgs {
    /// Report folder of `surgbench run --quick` (or its results.csv).
    report: PathBuf,
    /// Folder of the baselines, one `<cpu>.csv` per CPU type.
    #[arg(long, default_value = "benches/accuracy-baseline")]
    baseline_dir: PathBuf,
    /// Record this report's errors as this CPU type's baseline (on purpose!).
    #[arg(long)]
    update: bool,
    /// Relative tolerance on errors (default: round-off).
    #[arg(long, default_value_t = DiffOptions::default().rel)]
    tolerance: f64,
}

/// The results.csv of a report folder, or the file itself.
fn load(path: &Path) -> Result<Vec<ResultRow>, Failure> {
    let csv = if path.is_dir() {
        path.join("results.csv")
    } else {
        path.to_path_buf()
    };
    if !csv.is_file() {
        return Err(Failure::Usage(format!(
            "{} is neither a report folder with a results.csv nor a results.csv",
            path.display()
        )));
    }
    read_results_csv(&csv).map_err(|e| Failure::Usage(e.to_string()))
}

/// A tolerance that is a number >= 0 (infinity allowed: never flag).
fn check_tolerance(name: &str, v: f64) -> Result<(), Failure> {
    if v >= 0.0 {
        Ok(())
    } else {
        Err(Failure::Usage(format!("--{name} must be a number >= 0, got {v}")))
    }
}

/// `surgbench diff`: print, then judge with --fail-on-regression.
pub(crate) fn cmd_diff(a: &DiffArgs) -> Result<(), Failure> {
    check_tolerance("tolerance", a.tolerance)?;
    check_tolerance("abs-tolerance", a.abs_tolerance)?;
    check_tolerance("time-tolerance", a.time_tolerance)?;
    let (old, new) = (load(&a.old)?, load(&a.new)?);
    let opts = DiffOptions {
        rel: a.tolerance,
        abs: a.abs_tolerance,
        time: (!a.errors_only).then_some(a.time_tolerance),
    };
    let d = diff_reports(&old, &new, &opts);
    print_diff(&d, a.all);
    let bad = d.regressions();
    if a.fail_on_regression && bad > 0 {
        return Err(Failure::Runtime(format!("{bad} regression(s)")));
    }
    Ok(())
}

/// A value for the table (`-` when absent).
fn val(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| fmt_sig(v, 4))
}

/// One point: status, changed metrics (all with `all`), time.
fn print_point(p: &PointDiff, all: bool) {
    say!("{}", p.key);
    if p.status.0 != p.status.1 || all {
        say!(
            "    {:<36} {:>12} -> {:<12} {}",
            "status",
            p.status.0.as_str(),
            p.status.1.as_str(),
            p.status_change.word()
        );
    }
    for m in p.metrics.iter().filter(|m| all || m.change != Change::Same) {
        let rel = match (m.old, m.new) {
            (Some(a), Some(b)) if a != 0.0 => format!("{:+.3}%", 100.0 * (b - a) / a.abs()),
            _ => String::new(),
        };
        let mark = if m.primary { "*" } else { "" };
        say!(
            "    {:<36} {:>12} -> {:<12} {:<10} {}",
            format!("{}{mark}", m.name),
            val(m.old),
            val(m.new),
            rel,
            m.change.word()
        );
    }
    if let Some((t0, t1)) = p.ms_per_step
        && (all || p.time_change != Change::Same)
    {
        say!(
            "    {:<36} {:>12} -> {:<12} {:<10} {}",
            "ms/step (median)",
            fmt_sig(t0, 3),
            fmt_sig(t1, 3),
            format!("x{:.2}", t1 / t0),
            p.time_change.word()
        );
    }
}

/// The points that changed (every point with `all`), then the counts.
fn print_diff(d: &ReportDiff, all: bool) {
    for p in d.points.iter().filter(|p| all || p.worst() != Change::Same) {
        print_point(p, all);
    }
    for k in &d.missing {
        say!("{k}\n    missing in NEW: WORSE");
    }
    for k in &d.added {
        say!("{k}\n    only in NEW");
    }
    let count = |c: Change| d.points.iter().filter(|p| p.worst() == c).count();
    say!(
        "{} points in both: {} same, {} better, {} changed (not judged), {} worse; {} missing in NEW, {} only in NEW ({} regression(s); * = primary metric)",
        d.points.len(),
        count(Change::Same),
        count(Change::Better),
        count(Change::Changed),
        count(Change::Worse),
        d.missing.len(),
        d.added.len(),
        d.regressions()
    );
}

/// File name of a CPU type's baseline: its model name in lower case, runs
/// of other characters as one `-` ("Intel(R) Xeon(R) Processor" ->
/// "intel-r-xeon-r-processor").
fn cpu_slug(cpu: &str) -> String {
    let mut s = String::new();
    for c in cpu.chars() {
        if c.is_ascii_alphanumeric() {
            s.push(c.to_ascii_lowercase());
        } else if !s.ends_with('-') && !s.is_empty() {
            s.push('-');
        }
    }
    s.trim_end_matches('-').to_string()
}

/// The rows a baseline keeps: everything but wall-clock figures and where
/// they ran (those change from run to run; the errors do not).
fn without_timings(rows: &[ResultRow]) -> Vec<ResultRow> {
    rows.iter()
        .map(|r| {
            let mut r = r.clone();
            r.ms_per_step_median = None;
            r.ms_per_step_p95 = None;
            r.ms_per_step_max = None;
            r.steps_per_s = None;
            r.real_time_factor = None;
            r.peak_rss_mb = None;
            r.build_ms = None;
            r.solve_wall_s = None;
            r.host.clear();
            r.run_dir.clear();
            r
        })
        .collect()
}

/// `surgbench accuracy-gate`: diff the report's errors against this CPU
/// type's baseline (times not judged); with `--update`, write the baseline
/// (a temporary file renamed into place: a failed write leaves the old one).
pub(crate) fn cmd_accuracy_gate(a: &AccuracyGateArgs) -> Result<(), Failure> {
    check_tolerance("tolerance", a.tolerance)?;
    let rows = load(&a.report)?;
    let cpu = cpu_model();
    let path = a.baseline_dir.join(format!("{}.csv", cpu_slug(&cpu)));
    if a.update {
        let io = |e: std::io::Error| Failure::Runtime(format!("cannot write {}: {e}", path.display()));
        std::fs::create_dir_all(&a.baseline_dir).map_err(io)?;
        let tmp = path.with_extension("csv.tmp");
        if let Err(e) = write_results_csv(&tmp, &without_timings(&rows)) {
            let _ = std::fs::remove_file(&tmp);
            return Err(Failure::Runtime(e.to_string()));
        }
        std::fs::rename(&tmp, &path).map_err(io)?;
        say!(
            "accuracy baseline for `{cpu}` written to {} ({} points)",
            path.display(),
            rows.len()
        );
        return Ok(());
    }
    if !path.is_file() {
        return Err(Failure::Runtime(format!(
            "no accuracy baseline for this CPU `{cpu}` ({} does not exist): errors are reproducible bit for bit only on one CPU type; record one with `surgbench accuracy-gate REPORT --update`",
            path.display()
        )));
    }
    let base = read_results_csv(&path).map_err(|e| Failure::Runtime(e.to_string()))?;
    let opts = DiffOptions {
        rel: a.tolerance,
        abs: 0.0,
        time: None,
    };
    let d = diff_reports(&base, &rows, &opts);
    print_diff(&d, false);
    let bad = d.regressions();
    if bad > 0 {
        return Err(Failure::Runtime(format!(
            "accuracy gate: {bad} regression(s) against {}; if the change is intended, refresh with `surgbench accuracy-gate REPORT --update` (README, \"Gates\")",
            path.display()
        )));
    }
    say!(
        "accuracy gate passed ({} points against {}, relative tolerance {:e})",
        d.points.len(),
        path.display(),
        a.tolerance
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::cpu_slug;

    #[test]
    fn cpu_slugs_are_file_names() {
        assert_eq!(cpu_slug("Intel(R) Xeon(R) Processor"), "intel-r-xeon-r-processor");
        assert_eq!(
            cpu_slug("AMD EPYC 7B13 64-Core Processor"),
            "amd-epyc-7b13-64-core-processor"
        );
        assert_eq!(cpu_slug("  x  "), "x");
    }
}
