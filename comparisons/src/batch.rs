//! The batch runner: a comparison's jobs, each in its own child process
//! with a wall-clock limit, so a model that panics, aborts or hangs is
//! recorded as failed (with its message and time) and the comparison goes
//! on. Results are written to a temporary folder and renamed into place at
//! the end: a failed or interrupted run leaves earlier reports intact.
//!
//! With [`crate::interrupt::install`] called first, a SIGINT or SIGTERM to
//! the batch kills the running child, waits for it, removes the temporary
//! folder and returns [`BatchError::Interrupted`]: no process and no
//! temporary folder outlive the batch, and the earlier report is untouched.
//!
//! A SIGKILL cannot be caught. Each child gets the batch's pid
//! ([`crate::child::PARENT_PID_VAR`]) and ends itself within a fraction of
//! a second once the batch is gone ([`crate::child::start_watchdog`]); the
//! killed batch's own `.OUT.tmp-PID` folder stays until the next run into
//! the same `--out`, which removes every such folder whose process is no
//! longer alive ([`temp_sibling`]). The earlier report at `--out` is
//! untouched in both cases.

use crate::child::{Waited, spawn_with_limit};
use crate::comparison::{Comparison, HapticJob, Job};
use crate::registry;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;
use surgbench_reports::{HapticRow, ResultRow, RunInfo, RunSummary, Status};

pub use surgbench_reports::staging::{replace_dir, temp_sibling};

/// How to run a comparison.
#[derive(Debug, Clone)]
pub struct BatchOptions {
    /// Use the quick sweeps and one repeat.
    pub quick: bool,
    /// Restrict to these models.
    pub models: Option<Vec<String>>,
    /// Report folder (replaced atomically at the end; see [`crate::outdir`]).
    pub out: PathBuf,
    /// Replace `out` even when it is a non-empty folder that is not a surgbench report.
    pub force: bool,
    /// Threads per run (RAYON_NUM_THREADS of the child).
    pub threads: usize,
    /// Override the comparison's repeats.
    pub repeats: Option<usize>,
    /// Override the comparison's per-run wall-clock limit (s).
    pub timeout_s: Option<f64>,
    /// No progress bar.
    pub quiet: bool,
    /// The `surgbench` executable to spawn for each run.
    pub exe: PathBuf,
    /// Arguments before the subcommand: empty for the binary, `["-m",
    /// "surgbench"]` when `exe` is a Python interpreter (the bindings).
    pub exe_args: Vec<String>,
    /// The command line, for the record.
    pub command: String,
    /// Time budgets per step (ms) for the report's verdicts, ascending.
    pub budgets_ms: Vec<f64>,
}

/// Why a batch could not produce a report.
#[derive(Debug)]
pub enum BatchError {
    /// Bad input: nothing was run or written.
    Usage(crate::UsageError),
    /// Writing the report failed; the previous report is intact.
    Io(String),
    /// SIGINT or SIGTERM (the number) arrived: the running child was
    /// killed, the temporary folder removed, the previous report is intact.
    Interrupted(i32),
}

impl std::fmt::Display for BatchError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BatchError::Usage(u) => u.fmt(f),
            BatchError::Io(s) => f.write_str(s),
            BatchError::Interrupted(sig) => write!(
                f,
                "interrupted by signal {sig}: the running job was stopped and nothing was written (any earlier report is unchanged)"
            ),
        }
    }
}

impl From<crate::UsageError> for BatchError {
    fn from(u: crate::UsageError) -> Self {
        BatchError::Usage(u)
    }
}

fn io(ctx: &str) -> impl Fn(std::io::Error) -> BatchError + '_ {
    move |e| BatchError::Io(format!("{ctx}: {e}"))
}

/// File-name-safe form of a fidelity string.
pub fn slug(s: &str) -> String {
    if s.is_empty() {
        return "default".into();
    }
    s.chars()
        .map(|c| match c {
            '=' => '-',
            ';' => '_',
            c if c.is_ascii_alphanumeric() || c == '.' || c == '-' || c == '_' => c,
            _ => '~',
        })
        .collect()
}

fn base_row(c: &Comparison, job: &Job) -> ResultRow {
    let sc = registry::scenario(&job.scenario).ok();
    let f = registry::model(&job.model).ok();
    ResultRow {
        comparison: c.name.clone(),
        scenario: job.scenario.clone(),
        model: job.model.clone(),
        family: f.map(|f| f.family().name().to_string()).unwrap_or_default(),
        fidelity: job.fidelity.to_string(),
        params: job
            .params
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(";"),
        primary_error: sc.map(|s| s.primary_error().to_string()).unwrap_or_default(),
        ..Default::default()
    }
}

/// Last meaningful lines of a child's stderr (the panic message).
fn stderr_tail(path: &Path) -> String {
    let s = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = s
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with("note:"))
        .collect();
    // A Rust panic prints "thread '...' panicked at FILE:LINE:COL:" then the message.
    let tail = match lines.iter().position(|l| l.contains("panicked at")) {
        Some(i) => lines[i..(i + 2).min(lines.len())].join(" "),
        None => lines
            .iter()
            .rev()
            .take(2)
            .rev()
            .copied()
            .collect::<Vec<_>>()
            .join(" | "),
    };
    if tail.is_empty() {
        "no message".into()
    } else {
        tail.chars().take(400).collect()
    }
}

/// What became of a child process: it succeeded (its output is read by the
/// caller) or it did not, as a status and reason for the row.
enum ChildEnd {
    /// Exited with status 0.
    Success,
    /// Could not start, crashed, or was killed at the limit.
    Failed(Status, String),
    /// Killed because the batch got this signal; the caller stops.
    Interrupted(i32),
}

/// Spawn `cmd` with stderr to `err_path`, wait up to `timeout` s, and say
/// how it ended: the one place a child job is started and classified.
fn run_child(cmd: Command, err_path: &Path, timeout: f64, opts: &BatchOptions) -> ChildEnd {
    match spawn_with_limit(cmd, err_path, timeout) {
        Err(e) => ChildEnd::Failed(Status::Failed, format!("could not start {}: {e}", opts.exe.display())),
        Ok((Waited::TimedOut, elapsed)) => {
            ChildEnd::Failed(Status::Timeout, format!("killed after {elapsed:.1} s wall-clock limit"))
        }
        Ok((Waited::Interrupted(sig), _)) => ChildEnd::Interrupted(sig),
        Ok((Waited::Exited(s), _)) if s.success() => ChildEnd::Success,
        Ok((Waited::Exited(s), elapsed)) => ChildEnd::Failed(
            Status::Failed,
            format!(
                "{} after {elapsed:.2} s: {}",
                exit_description(&s),
                stderr_tail(err_path)
            ),
        ),
    }
}

/// Longest folder or file name (bytes) [`folder_name`] gives; file systems
/// refuse names over 255 bytes.
const MAX_NAME: usize = 100;

/// `v` for a folder name: as the CSV writes it (`0.001`, `20`) when that is
/// short, else the shortest round-trip scientific form (`1e300`, not three
/// hundred digits). Distinct values keep distinct names.
fn folder_number(v: f64) -> String {
    let plain = format!("{v}");
    if plain.len() <= 16 { plain } else { format!("{v:e}") }
}

/// A fidelity setting for a folder name: a number as [`folder_number`], a
/// choice by its name.
fn folder_setting(v: &surgbench_core::fidelity::Setting) -> String {
    match v {
        surgbench_core::fidelity::Setting::Number(x) => folder_number(*x),
        surgbench_core::fidelity::Setting::Choice(c) => c.clone(),
    }
}

/// `k=v;k=v` of `pairs` (values already formatted for a folder name).
fn folder_pairs<'a>(pairs: impl IntoIterator<Item = (&'a str, String)>) -> String {
    let p: Vec<String> = pairs.into_iter().map(|(k, v)| format!("{k}={v}")).collect();
    p.join(";")
}

/// A file-name-safe name for `s` ([`slug`]) of at most [`MAX_NAME`] bytes:
/// a longer slug keeps its first 80 bytes and ends in `~` and a hash
/// (FNV-1a, 64 bits) of the whole, so names stay short, unique and the same
/// from run to run.
pub fn folder_name(s: &str) -> String {
    let slug = slug(s);
    if slug.len() <= MAX_NAME {
        return slug;
    }
    let hash = surgbench_reports::fnv1a(s.as_bytes());
    // The slug is ASCII, so any byte index is a character boundary.
    format!("{}~{hash:016x}", &slug[..80])
}

/// A job's folder under the report: `runs/<scenario>[@<params>]/<model>/<fidelity>`,
/// the parameters and the fidelity each a [`folder_name`].
pub fn run_dir_of(job: &Job) -> PathBuf {
    // Parameter overrides are part of the folder name: one scenario may
    // appear several times in a comparison with different parameters.
    let scen_dir = if job.params.is_empty() {
        job.scenario.clone()
    } else {
        let p = folder_pairs(job.params.iter().map(|(k, v)| (k.as_str(), folder_number(*v))));
        format!("{}@{}", job.scenario, folder_name(&p))
    };
    let pairs = job.fidelity.pairs();
    let fid = folder_pairs(pairs.iter().map(|(k, v)| (k.as_str(), folder_setting(v))));
    PathBuf::from("runs")
        .join(scen_dir)
        .join(&job.model)
        .join(folder_name(&fid))
}

/// Run one job in a child process (its files in `runs/..` beside `runs`,
/// see [`run_dir_of`]); returns its row, or the signal that interrupted it.
pub(crate) fn run_job(
    c: &Comparison,
    job: &Job,
    runs: &Path,
    opts: &BatchOptions,
    repeats: usize,
    timeout: f64,
) -> Result<ResultRow, BatchError> {
    let mut row = base_row(c, job);
    if let Some(reason) = &job.unsupported {
        row.status = Status::Unsupported;
        row.reason = reason.clone();
        return Ok(row);
    }
    let rel = run_dir_of(job);
    let dir = runs.parent().expect("runs has a parent").join(&rel);
    if let Some(p) = dir.parent() {
        let _ = std::fs::create_dir_all(p);
    }
    let err_path = dir.with_extension("stderr.txt");
    let mut cmd = child_command(opts, "run-one", &job.model, &job.scenario, &job.params, &job.fidelity);
    cmd.arg("--out")
        .arg(&dir)
        .arg("--repeats")
        .arg(repeats.to_string())
        .arg("--quiet");
    if let Some(b) = c.repeat_budget_s.filter(|_| repeats > 1) {
        cmd.arg("--repeat-budget").arg(b.to_string());
    }
    match run_child(cmd, &err_path, timeout, opts) {
        ChildEnd::Interrupted(sig) => return Err(BatchError::Interrupted(sig)),
        ChildEnd::Failed(status, reason) => {
            (row.status, row.reason) = (status, reason);
            // A child killed while writing leaves its temporary folder.
            remove_temp_siblings(&dir);
        }
        ChildEnd::Success => match RunSummary::read(&dir.join("summary.json")) {
            Ok(s) => row = row.with_summary(s, rel.to_string_lossy().into_owned()),
            Err(_) => {
                row.status = Status::Failed;
                row.reason = "run finished but wrote no readable summary.json".into();
            }
        },
    }
    if matches!(row.status, Status::Ok | Status::Unstable | Status::Unsupported) {
        let _ = std::fs::remove_file(&err_path);
    }
    Ok(row)
}

/// `surgbench <sub> --model M --scenario S --param .. --fidelity ..` with the
/// batch's thread count: what every child process of a batch starts from.
fn child_command(
    opts: &BatchOptions,
    sub: &str,
    model: &str,
    scenario: &str,
    params: &[(String, f64)],
    fidelity: &surgbench_core::Fidelity,
) -> Command {
    let mut cmd = Command::new(&opts.exe);
    cmd.args(&opts.exe_args)
        .arg(sub)
        .arg("--model")
        .arg(model)
        .arg("--scenario")
        .arg(scenario);
    for (k, v) in params {
        cmd.arg("--param").arg(format!("{k}={v}"));
    }
    for (k, v) in fidelity.pairs() {
        cmd.arg("--fidelity").arg(format!("{k}={v}"));
    }
    cmd.env("RAYON_NUM_THREADS", opts.threads.to_string())
        .env("RUST_BACKTRACE", "0")
        // The child ends itself if this process dies without killing it.
        .env(crate::child::PARENT_PID_VAR, std::process::id().to_string());
    cmd
}

/// How a child that did not succeed ended, for the reason column.
fn exit_description(s: &std::process::ExitStatus) -> String {
    match (s.code(), std::os::unix::process::ExitStatusExt::signal(s)) {
        (Some(c), _) => format!("exit code {c}"),
        (None, Some(6)) => "aborted (SIGABRT)".into(),
        (None, Some(sig)) => format!("killed by signal {sig}"),
        (None, None) => "killed".into(),
    }
}

/// Run one haptic loop in a child process (`surgbench haptic ... --csv`):
/// a panicking or hanging model, or one still running after `limit` s (the
/// batch's wall-clock limit per run), becomes a `failed` / `timeout` row; a
/// signal to the batch is returned as [`BatchError::Interrupted`].
fn run_haptic_job(job: &HapticJob, dir: &Path, opts: &BatchOptions, limit: f64) -> Result<HapticRow, BatchError> {
    let mut row = HapticRow {
        model: job.model.clone(),
        scenario: job.scenario.clone(),
        fidelity: job.fidelity.to_string(),
        rate_hz: job.rate_hz,
        duration_s: job.duration_s,
        ..Default::default()
    };
    if let Some(reason) = &job.unsupported {
        row.status = Status::Unsupported;
        row.reason = reason.clone();
        return Ok(row);
    }
    let pairs = job.fidelity.pairs();
    let fid = folder_pairs(pairs.iter().map(|(k, v)| (k.as_str(), folder_setting(v))));
    let stem = folder_name(&format!("{}-{}-{fid}", job.model, job.scenario));
    let csv = dir.join(format!("{stem}.csv"));
    let err_path = dir.join(format!("{stem}.stderr.txt"));
    let mut cmd = child_command(opts, "haptic", &job.model, &job.scenario, &job.params, &job.fidelity);
    cmd.arg("--rate")
        .arg(job.rate_hz.to_string())
        .arg("--duration")
        .arg(job.duration_s.to_string())
        .arg("--csv")
        .arg(&csv);
    // Model build and the loop's own duration, with room for a slow
    // machine, and never past the batch's limit per run (`limit`, s).
    let timeout = (2.0 * job.duration_s + 120.0).min(limit);
    match run_child(cmd, &err_path, timeout, opts) {
        ChildEnd::Interrupted(sig) => return Err(BatchError::Interrupted(sig)),
        ChildEnd::Failed(status, reason) => (row.status, row.reason) = (status, reason),
        ChildEnd::Success => match surgbench_reports::read_haptic_csv(&csv) {
            Ok(mut r) if r.len() == 1 => row = r.remove(0),
            Ok(r) => {
                row.status = Status::Failed;
                row.reason = format!("haptic loop wrote {} rows, expected 1", r.len());
            }
            Err(e) => {
                row.status = Status::Failed;
                row.reason = format!("haptic loop finished but its CSV is unreadable: {e}");
            }
        },
    }
    let _ = std::fs::remove_file(&err_path);
    let _ = std::fs::remove_file(&csv);
    Ok(row)
}

/// Today's date and time (UTC) from the system clock, ISO 8601.
pub fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // Civil from days (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

fn command_output(cmd: &str, args: &[&str]) -> Option<String> {
    let o = Command::new(cmd).args(args).stderr(Stdio::null()).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

/// Versions of the crates that matter, read from the workspace's Cargo.lock
/// as it was when the harness was built.
pub fn crate_versions() -> BTreeMap<String, String> {
    const LOCK: &str = include_str!("../../Cargo.lock");
    const WANT: &[&str] = &[
        "nalgebra",
        "faer",
        "rapier3d",
        "parry3d",
        "plotters",
        "csv",
        "criterion",
        "rayon",
    ];
    let mut out = BTreeMap::new();
    let mut name = "";
    for line in LOCK.lines() {
        if let Some(n) = line.strip_prefix("name = ") {
            name = n.trim_matches('"');
        } else if let Some(v) = line.strip_prefix("version = ")
            && WANT.contains(&name)
        {
            out.insert(name.to_string(), v.trim_matches('"').to_string());
        }
    }
    out.insert("surgbench".into(), env!("CARGO_PKG_VERSION").into());
    out
}

/// This machine's CPU model, OS and architecture, for the record.
pub fn machine_description() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    format!("{cpu} ({} {})", std::env::consts::OS, std::env::consts::ARCH)
}

/// Environment variable naming the commit when there is no git checkout to
/// ask (a container image built from a source archive).
pub const COMMIT_VAR: &str = "SURGBENCH_COMMIT";

/// The commit of the code that runs: [`COMMIT_VAR`] when set, else
/// `git rev-parse --short=12 HEAD` in the current folder, else `unknown`.
pub fn git_commit() -> String {
    std::env::var(COMMIT_VAR)
        .ok()
        .map(|c| c.trim().to_string())
        .filter(|c| !c.is_empty())
        .or_else(|| command_output("git", &["rev-parse", "--short=12", "HEAD"]))
        .unwrap_or_else(|| "unknown".into())
}

/// Cores on this machine.
pub fn cores() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}

/// Facts about this machine and build, for `summary.json`.
pub fn run_info(comparison: &str, opts: &BatchOptions) -> RunInfo {
    RunInfo {
        comparison: comparison.into(),
        date: utc_now(),
        commit: git_commit(),
        machine: machine_description(),
        cores: cores(),
        threads: opts.threads,
        rustc: command_output("rustc", &["--version"]).unwrap_or_else(|| "unknown".into()),
        crate_versions: crate_versions(),
        command: opts.command.clone(),
        quick: opts.quick,
        wall_s: 0.0,
        python_models: BTreeMap::new(),
        fitted: BTreeMap::new(),
        targets: BTreeMap::new(),
        budgets_ms: opts.budgets_ms.clone(),
    }
}

/// The registered models written in Python among the models of `rows`, by
/// id, with their description.
pub fn python_models<'a>(rows: impl IntoIterator<Item = &'a ResultRow>) -> BTreeMap<String, String> {
    let ran: std::collections::BTreeSet<&str> = rows.into_iter().map(|r| r.model.as_str()).collect();
    crate::registry::models()
        .into_iter()
        .filter(|r| r.krate == crate::registry::PYTHON && ran.contains(r.factory.id()))
        .map(|r| (r.factory.id().to_string(), r.factory.description().to_string()))
        .collect()
}

/// The models of `rows` whose settings rest on a fitted constant, by id,
/// with what was fitted on which case (`ModelFactory::fitted`).
pub fn fitted_models<'a>(rows: impl IntoIterator<Item = &'a ResultRow>) -> BTreeMap<String, String> {
    let ran: std::collections::BTreeSet<&str> = rows.into_iter().map(|r| r.model.as_str()).collect();
    crate::registry::models()
        .into_iter()
        .filter(|r| ran.contains(r.factory.id()))
        .filter_map(|r| Some((r.factory.id().to_string(), r.factory.fitted()?.to_string())))
        .collect()
}

/// Remove every temporary sibling of `out` ([`temp_sibling`], any pid).
fn remove_temp_siblings(out: &Path) {
    let (Some(parent), Some(name)) = (out.parent(), out.file_name().and_then(|n| n.to_str())) else {
        return;
    };
    let prefix = format!(".{name}.tmp-");
    for e in std::fs::read_dir(parent).into_iter().flatten().flatten() {
        if e.file_name().to_str().is_some_and(|n| n.starts_with(&prefix)) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Every job that runs writes its own folder: two jobs with one folder
/// (the same scenario, parameters, model and fidelity listed twice, e.g.
/// by two entries of one scenario) are a usage error naming it.
fn check_distinct_folders(jobs: &[Job]) -> Result<(), crate::UsageError> {
    let mut seen = std::collections::BTreeSet::new();
    for job in jobs.iter().filter(|j| j.unsupported.is_none()) {
        let dir = run_dir_of(job);
        if !seen.insert(dir.clone()) {
            return Err(crate::UsageError(format!(
                "the comparison lists one run twice ({} with {} at [{}]): {} would be written twice; list it once",
                job.scenario,
                job.model,
                job.fidelity,
                dir.display()
            )));
        }
    }
    Ok(())
}

/// `Err(Interrupted)` once a SIGINT/SIGTERM has reached the batch.
fn interrupted() -> Result<(), BatchError> {
    crate::interrupt::pending().map_or(Ok(()), |sig| Err(BatchError::Interrupted(sig)))
}

/// The runs of comparison `c` (quick sweeps or full, `models` only),
/// validated before anything runs: under `quick` the full sweeps and haptic
/// loops are validated too, so that a mistake in them shows now, not in the
/// long run; no runs at all, or one run listed twice, is a usage error.
pub fn checked_jobs(c: &Comparison, quick: bool, models: Option<&[String]>) -> Result<Vec<Job>, crate::UsageError> {
    if quick {
        c.jobs(false, models)?;
        c.haptic_jobs(false, models)?;
    }
    let jobs = c.jobs(quick, models)?;
    if jobs.is_empty() {
        return Err(crate::UsageError(
            "the comparison selects no runs (no models match?)".into(),
        ));
    }
    check_distinct_folders(&jobs)?;
    Ok(jobs)
}

/// Repeats per run: 1 under `--quick`, else `--repeats` (`repeats`), the
/// comparison's, or 1.
pub fn repeats_of(c: &Comparison, quick: bool, repeats: Option<usize>) -> usize {
    if quick { 1 } else { repeats.or(c.repeats).unwrap_or(1) }
}

/// Wall-clock limit per run (s): `--timeout` (`timeout_s`), the comparison's, or 300.
pub fn timeout_of(c: &Comparison, timeout_s: Option<f64>) -> f64 {
    timeout_s.or(c.timeout_s).unwrap_or(300.0)
}

/// Run a comparison and write its report to `opts.out`. Returns the rows.
/// On any error, an interruption included, the temporary folder is removed
/// and `opts.out` is left as it was.
pub fn run_comparison(c: &Comparison, opts: &BatchOptions) -> Result<Vec<ResultRow>, BatchError> {
    let started = Instant::now();
    crate::outdir::check_replaceable(&opts.out, opts.force)?;
    let jobs = checked_jobs(c, opts.quick, opts.models.as_deref())?;
    let haptic_jobs = c.haptic_jobs(opts.quick, opts.models.as_deref())?;
    let targets = c.targets()?;
    let repeats = repeats_of(c, opts.quick, opts.repeats);
    let timeout = timeout_of(c, opts.timeout_s);
    let tmp = temp_sibling(&opts.out).map_err(io("cannot create the temporary report folder"))?;
    let result = (|| -> Result<Vec<ResultRow>, BatchError> {
        crate::outdir::write_marker(&tmp).map_err(io("cannot write the report marker"))?;
        let runs = tmp.join("runs");
        std::fs::create_dir_all(&runs).map_err(io("cannot create runs/"))?;
        // Each run's cost in the report this batch replaces weights the ETA.
        let previous = crate::progress::previous_costs(&opts.out);
        let prior: Vec<Option<f64>> = jobs
            .iter()
            .map(|j| {
                if j.unsupported.is_some() {
                    Some(0.0)
                } else {
                    previous.get(run_dir_of(j).to_string_lossy().as_ref()).copied()
                }
            })
            .chain(haptic_jobs.iter().map(|_| None))
            .collect();
        let mut progress = crate::progress::Progress::new(prior, opts.quiet);
        let mut rows = Vec::with_capacity(jobs.len());
        for (i, job) in jobs.iter().enumerate() {
            let fid = job.fidelity.to_string();
            let what = format!(
                "{} / {} / {}",
                job.scenario,
                job.model,
                if fid.is_empty() { "(default)" } else { fid.as_str() }
            );
            progress.start(&what);
            let t0 = Instant::now();
            let row = run_job(c, job, &runs, opts, repeats, timeout)?;
            progress.finish(i, &what, row.status.as_str(), t0.elapsed().as_secs_f64());
            rows.push(row);
            interrupted()?;
        }
        // Haptic loops run alone, after every other run, so they do not
        // compete with the batch for the cores.
        let mut haptic = Vec::with_capacity(haptic_jobs.len());
        for (i, job) in haptic_jobs.iter().enumerate() {
            let what = format!("haptic {} / {} at {} Hz", job.scenario, job.model, job.rate_hz);
            progress.start(&what);
            let t0 = Instant::now();
            let row = run_haptic_job(job, &runs, opts, timeout)?;
            progress.finish(jobs.len() + i, &what, row.status.as_str(), t0.elapsed().as_secs_f64());
            haptic.push(row);
            interrupted()?;
        }
        if !haptic.is_empty() {
            surgbench_reports::write_haptic_csv(&tmp.join("haptic.csv"), &haptic)
                .map_err(|e| BatchError::Io(e.to_string()))?;
        }
        progress.clear();
        let mut info = run_info(&c.name, opts);
        info.wall_s = started.elapsed().as_secs_f64();
        info.python_models = python_models(&rows);
        info.fitted = fitted_models(&rows);
        info.targets = targets;
        surgbench_reports::write_results_csv(&tmp.join("results.csv"), &rows)
            .map_err(|e| BatchError::Io(e.to_string()))?;
        let json = serde_json::to_string_pretty(&info).map_err(|e| BatchError::Io(e.to_string()))?;
        std::fs::write(tmp.join("summary.json"), json + "\n").map_err(io("cannot write summary.json"))?;
        surgbench_reports::render(&tmp, &rows, &info).map_err(|e| BatchError::Io(e.to_string()))?;
        interrupted()?;
        replace_dir(&tmp, &opts.out).map_err(io("cannot move the report into place"))?;
        Ok(rows)
    })();
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}
