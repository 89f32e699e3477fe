//! `surgbench`: run the standard comparison, one run, or re-render a report;
//! plan, run and merge a comparison sharded over a cluster's array jobs
//! ([`cluster`]).
//!
//! Exit codes: 0 success, 1 a run or write failed at runtime, 2 bad usage
//! (unknown scenario/model/parameter, out-of-range value, malformed file,
//! more steps than [`surgbench_comparisons::runner::MAX_STEPS`]); on exit 2
//! nothing is written. `run`, `run-one` and `gate` interrupted by SIGINT or
//! SIGTERM stop their child (if any), remove their temporary files, write
//! nothing and exit 130 or 143; a `run-one` or `haptic` child whose `run`
//! was killed by SIGKILL ends itself with exit 1
//! ([`surgbench_comparisons::child`]). `merge` exits 1 when points are
//! missing (without `--partial`) and 2 for folders of another comparison
//! or commit (without `--allow-mixed`), writing nothing in both cases.

use clap::{Args, Parser, Subcommand};

/// `println!` that ignores a closed stdout (e.g. piped into `head`): output
/// for people must never turn into a panic.
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}
mod cluster;
mod diff;

use std::path::{Path, PathBuf};
use surgbench_comparisons::batch::{self, BatchOptions};
use surgbench_comparisons::comparison::Comparison;
use surgbench_comparisons::datasets::project_root;
use surgbench_comparisons::gate::{self, GateError};
use surgbench_comparisons::haptic::run_haptic_loop;
use surgbench_comparisons::resolve::ResolvedRun;
use surgbench_comparisons::runner::{RunOptions, RunSummary};
use surgbench_comparisons::scenario::parse_overrides;
use surgbench_comparisons::user_mesh::UserMesh;
use surgbench_comparisons::{UsageError, registry};
use surgbench_comparisons::{child, interrupt, outdir, plan, shard_run};

#[derive(Parser)]
#[command(
    name = "surgbench",
    version,
    about = "Validate and benchmark surgical-simulator solvers side by side on identical scenes",
    long_about = "surgbench runs interchangeable models (rods, tissue) on identical scenarios, scores them \
against analytic, FEM and phantom references, and writes comparison reports (CSV, plots, HTML).\n\n\
Start with `surgbench list`, then `surgbench run --quick` (writes reports/out/latest/)."
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// List scenarios (with parameters and defaults), models (with capabilities) and comparisons.
    List,
    /// Run a comparison (default: comparisons/standard.toml) and write a
    /// report; with --shard K/N (or an array job's index variable) run one
    /// shard of it into a folder the shards share.
    Run(RunArgs),
    /// Plan a sharded run: every point with its stable id and shard,
    /// written to DIR/plan.json; prints how many points each shard gets.
    Plan(cluster::PlanArgs),
    /// Gather the points of sharded run folders into one report; names the
    /// points missing or failed (exit 1 if any are missing, unless --partial).
    Merge(cluster::MergeArgs),
    /// Run one scenario with one model at one fidelity; writes summary.json,
    /// observables.csv and final_state.csv into --out.
    RunOne(RunOneArgs),
    /// Re-render plots and pages of a report folder from its results.csv.
    Report {
        /// Report folder holding results.csv.
        dir: PathBuf,
    },
    /// Compare two reports point by point: status, every metric and the
    /// median ms/step, with what got worse beyond the tolerances (exit 1 with
    /// --fail-on-regression when anything did).
    Diff(diff::DiffArgs),
    /// CI accuracy gate: a quick report's errors against this CPU type's
    /// baseline in benches/accuracy-baseline/ (round-off tolerance).
    AccuracyGate(diff::AccuracyGateArgs),
    /// CI performance gate: instructions per step under valgrind against
    /// benches/gate-baseline.json; fails past the margin in benches/gate.toml.
    Gate(GateArgs),
    /// Drive a model from a haptic device at a fixed rate against the wall
    /// clock (default 1 kHz) and report deadline misses, latency and jitter:
    /// can this model drive a haptic device?
    Haptic(HapticArgs),
    /// (internal) The workload the gate counts under valgrind.
    #[command(hide = true)]
    GateWorkload(GateWorkloadArgs),
}

/// What a comparison run covers: shared by `run` and `plan`.
#[derive(Args)]
struct SweepArgs {
    /// Comparison name (comparisons/NAME.toml in the project root: the nearest
    /// folder up from here holding comparisons/, or $SURGBENCH_ROOT) or path to a .toml file.
    #[arg(default_value = "standard")]
    comparison: String,
    /// Only these models (comma-separated ids).
    #[arg(long, value_delimiter = ',')]
    models: Option<Vec<String>>,
    /// Smaller sweeps, one repeat: a report in a minute or two.
    #[arg(long)]
    quick: bool,
    /// Repeats per run (overrides the comparison; timings pooled).
    #[arg(long)]
    repeats: Option<usize>,
    /// Wall-clock limit per run in seconds (overrides the comparison).
    #[arg(long)]
    timeout: Option<f64>,
    /// Accuracy target of a scenario's primary error, SCENARIO=VALUE in the
    /// metric's unit (repeatable; overrides the comparison and the
    /// scenario's own): the report's verdicts judge against it.
    #[arg(long = "target", visible_alias = "tolerance", value_name = "SCENARIO=VALUE")]
    targets: Vec<String>,
    /// Time budgets per step in ms the report's verdicts name (default
    /// 1,16,33: a 1 kHz haptic loop, 60 and 30 Hz frames).
    #[arg(long, value_delimiter = ',', value_name = "MS,...")]
    budget_ms: Option<Vec<f64>>,
}

impl SweepArgs {
    /// The comparison, with the `--target`s applied to its scenarios.
    fn comparison(&self) -> Result<(Comparison, PathBuf), Failure> {
        let path = find_comparison(&self.comparison)?;
        let mut c = Comparison::load(&path)?;
        for t in &self.targets {
            let bad = || Failure::Usage(format!("--target {t}: expected SCENARIO=VALUE, VALUE a number >= 0"));
            let (id, v) = t.split_once('=').ok_or_else(bad)?;
            let v: f64 = v.trim().parse().map_err(|_| bad())?;
            if !(v >= 0.0 && v.is_finite()) {
                return Err(bad());
            }
            let mut found = false;
            for e in c.scenario.iter_mut().filter(|e| e.id == id.trim()) {
                e.target = Some(v);
                e.target_from_cli = true;
                found = true;
            }
            if !found {
                return Err(Failure::Usage(format!(
                    "--target {t}: the comparison `{}` runs no scenario `{}`",
                    c.name,
                    id.trim()
                )));
            }
        }
        Ok((c, path))
    }

    /// The `--budget-ms` values ascending, or the defaults; a usage error
    /// unless each is a number > 0.
    fn budgets_ms(&self) -> Result<Vec<f64>, Failure> {
        match &self.budget_ms {
            Some(b) => {
                if b.is_empty() || !b.iter().all(|v| *v > 0.0 && v.is_finite()) {
                    return Err(Failure::Usage(format!(
                        "--budget-ms must be numbers > 0 (ms), got {b:?}"
                    )));
                }
                let mut b = b.clone();
                b.sort_by(f64::total_cmp);
                Ok(b)
            }
            None => Ok(surgbench_reports::DEFAULT_BUDGETS_MS.to_vec()),
        }
    }

    /// `--repeats`, `--timeout` and `--budget-ms` in range.
    fn check(&self) -> Result<(), Failure> {
        self.budgets_ms()?;
        if self.repeats == Some(0) {
            return Err(Failure::Usage("--repeats must be >= 1".into()));
        }
        if let Some(t) = self.timeout
            && !(t > 0.0)
        {
            return Err(Failure::Usage(format!("--timeout must be > 0 s, got {t}")));
        }
        Ok(())
    }
}

/// `surgbench run`.
#[derive(Args)]
struct RunArgs {
    #[command(flatten)]
    sweep: SweepArgs,
    /// Report folder (default: reports/out/latest in the project root: the
    /// nearest folder up from here holding comparisons/, or $SURGBENCH_ROOT),
    /// replaced as a whole: an
    /// earlier surgbench report or an empty folder (any other folder only
    /// with --force; a file never).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace --out even when it is a non-empty folder that is not a surgbench report.
    #[arg(long)]
    force: bool,
    /// Threads per run (RAYON_NUM_THREADS); runs themselves go one at a time.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Run shard K of N (K from 0) into the shared folder --out. Without it,
    /// an array job's index is read from SLURM_ARRAY_TASK_ID,
    /// JOB_COMPLETION_INDEX, AWS_BATCH_JOB_ARRAY_INDEX or BATCH_TASK_INDEX.
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Shard count, where the index comes without one (JOB_COMPLETION_INDEX)
    /// and --out holds no plan yet.
    #[arg(long, value_name = "N")]
    shards: Option<usize>,
    /// Run a sharded run's finished points again instead of skipping them.
    #[arg(long)]
    no_resume: bool,
}

impl RunArgs {
    /// The batch runner's options for this command, writing into `out`.
    fn batch_options(&self, out: PathBuf) -> Result<BatchOptions, Failure> {
        Ok(BatchOptions {
            quick: self.sweep.quick,
            models: self.sweep.models.clone(),
            out,
            force: self.force,
            threads: self.threads,
            repeats: self.sweep.repeats,
            timeout_s: self.sweep.timeout,
            quiet: self.quiet,
            exe: launcher()?.exe.clone(),
            exe_args: launcher()?.args.clone(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
            budgets_ms: self.sweep.budgets_ms()?,
        })
    }
}

/// The scenario x model x parameters x fidelity a single-run command takes.
#[derive(Args)]
struct RunSpec {
    /// Scenario id (see `surgbench list`).
    #[arg(long)]
    scenario: String,
    /// Model id (see `surgbench list`).
    #[arg(long)]
    model: String,
    /// Scenario parameter override, NAME=VALUE in SI units (repeatable).
    #[arg(long = "param", value_name = "NAME=VALUE")]
    params: Vec<String>,
    /// Fidelity knob, KEY=VALUE: segments, mesh_level, dt, iterations or a model extra (repeatable).
    #[arg(long = "fidelity", value_name = "KEY=VALUE")]
    fidelity: Vec<String>,
    /// Build the scene on this file instead of the scenario's own geometry:
    /// a tetrahedral tissue mesh (.msh Gmsh 4.x, .mesh Medit) or a closed
    /// vessel surface (.stl, .obj), for the scenarios `surgbench list` marks.
    #[arg(long, value_name = "FILE")]
    mesh: Option<PathBuf>,
    /// Factor from the --mesh file's units to metres (1e-3 for millimetres).
    #[arg(long, value_name = "FACTOR", default_value_t = 1.0, requires = "mesh")]
    mesh_scale: f64,
}

impl RunSpec {
    /// Resolve and validate the run once.
    fn resolve(&self) -> Result<ResolvedRun, UsageError> {
        let mesh = match &self.mesh {
            Some(path) => Some(UserMesh::load(path, self.mesh_scale)?),
            None => None,
        };
        ResolvedRun::from_pairs(
            &self.scenario,
            &self.model,
            &parse_overrides(&self.params)?,
            &self.fidelity,
            mesh,
        )
    }
}

/// `surgbench run-one`.
#[derive(Args)]
struct RunOneArgs {
    #[command(flatten)]
    spec: RunSpec,
    /// Output folder, replaced as a whole: an earlier surgbench run folder or
    /// an empty folder (any other folder only with --force; a file never).
    #[arg(long)]
    out: PathBuf,
    /// Replace --out even when it is a non-empty folder that is not a surgbench run.
    #[arg(long)]
    force: bool,
    /// Repeats (timings pooled; results must be bit-identical).
    #[arg(long, default_value_t = 1)]
    repeats: usize,
    /// After the first repeat, start another only while the repeats so far
    /// took less than this many seconds of wall time, builds included
    /// (default: always --repeats).
    #[arg(long, value_name = "S")]
    repeat_budget: Option<f64>,
    /// Print nothing on success.
    #[arg(long)]
    quiet: bool,
}

/// `surgbench gate`.
#[derive(Args)]
struct GateArgs {
    /// Record the current counts as the new baseline (on purpose!).
    #[arg(long)]
    update: bool,
    /// Gate configuration.
    #[arg(long, default_value = "benches/gate.toml")]
    config: PathBuf,
    /// Baseline file.
    #[arg(long, default_value = "benches/gate-baseline.json")]
    baseline: PathBuf,
}

/// `surgbench haptic`.
#[derive(Args)]
struct HapticArgs {
    #[command(flatten)]
    spec: RunSpec,
    /// Loop rate (Hz).
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Wall-clock duration of the loop (s).
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Replay a recorded session (CSV: t,insertion,rotation) instead of the scenario's timeline.
    #[arg(long)]
    replay: Option<PathBuf>,
    /// Write what the device rendered (force, torque) to this CSV (with --replay).
    #[arg(long)]
    record: Option<PathBuf>,
    /// Also write the measured numbers as a one-row `haptic.csv` to this file.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// `surgbench gate-workload`.
#[derive(Args)]
struct GateWorkloadArgs {
    #[command(flatten)]
    spec: RunSpec,
    /// Steps to take after the build.
    #[arg(long)]
    steps: usize,
}

/// Failure kinds mapped to exit codes.
enum Failure {
    /// Exit 2.
    Usage(String),
    /// Exit 1.
    Runtime(String),
    /// Stopped by this signal: exit 128 + signal.
    Interrupted(String, i32),
}

impl From<UsageError> for Failure {
    fn from(u: UsageError) -> Self {
        Failure::Usage(u.0)
    }
}

fn find_comparison(name: &str) -> Result<PathBuf, UsageError> {
    let p = Path::new(name);
    if p.extension().is_some_and(|e| e == "toml") || p.components().count() > 1 {
        return if p.is_file() {
            Ok(p.to_path_buf())
        } else {
            Err(UsageError(format!("comparison file {} not found", p.display())))
        };
    }
    let f = project_root().join("comparisons").join(format!("{name}.toml"));
    if f.is_file() {
        Ok(f)
    } else {
        Err(UsageError(format!(
            "unknown comparison `{name}` (no {}): run from a surgbench checkout, set SURGBENCH_ROOT \
             to one, or give the path of a .toml file",
            f.display()
        )))
    }
}

/// Compact number for listings: scientific outside [1e-3, 1e4).
fn short(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e4 || v.abs() < 1e-3) {
        format!("{v:e}")
    } else {
        format!("{}", (v * 1e6).round() / 1e6)
    }
}

/// One fidelity key of `list`: its name, what it takes and its doc; a
/// choice key then lists each name with what it selects.
fn list_key(k: &surgbench_core::FidelityKey) {
    use surgbench_core::KeyKind;
    say!("  {:<14}fidelity {:<14} {}: {}", "", k.name, k.values(), k.doc);
    if let KeyKind::Choice(choices) = k.kind {
        for c in choices {
            say!("  {:<29}{:<18} {}", "", format!("= \"{}\"", c.name), c.doc);
        }
    }
}

fn list() {
    say!("SCENARIOS");
    for s in registry::scenarios() {
        say!("  {:<22} [{}] {}", s.id(), s.family().name(), s.description());
        say!("  {:<22} reference: {}", "", s.reference());
        let t = s.target();
        say!(
            "  {:<22} target: {} <= {} ({})",
            "",
            s.primary_error(),
            short(t.value),
            t.why
        );
        if let Some(k) = s.info().mesh {
            say!("  {:<22} --mesh FILE: {}", "", k.describe());
        }
        for p in s.params() {
            say!(
                "  {:<24}{:<16} = {:<10} {:<7} {}",
                "",
                p.name,
                short(p.default),
                p.unit,
                p.doc
            );
        }
    }
    say!("\nMODELS");
    for r in registry::models() {
        let f = r.factory;
        let caps: Vec<_> = f.capabilities().iter().map(|c| c.name()).collect();
        say!("  {:<12} [{}] {}", f.id(), f.family().name(), f.description());
        say!("  {:<12} capabilities: {}", "", caps.join(", "));
        for k in f.fidelity_keys() {
            list_key(k);
        }
    }
    say!("\nCOMPARISONS");
    if let Ok(rd) = std::fs::read_dir(project_root().join("comparisons")) {
        let mut names: Vec<_> = rd
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            // The folder is also the harness crate: its manifest is not a comparison.
            .filter(|p| p.extension().is_some_and(|e| e == "toml") && !p.ends_with("Cargo.toml"))
            .collect();
        names.sort();
        for p in names {
            let desc = Comparison::load(&p)
                .map(|c| c.description)
                .unwrap_or_else(|e| format!("(unreadable: {e})"));
            say!("  {:<22} {}", p.file_stem().unwrap_or_default().to_string_lossy(), desc);
        }
    }
}

/// How this process starts the children of a batch: the `surgbench`
/// binary itself, or a Python interpreter running `-m surgbench` (the
/// bindings). Set once, by [`main`].
pub struct Launcher {
    /// The executable.
    pub exe: PathBuf,
    /// Arguments that come before the subcommand (`["-m", "surgbench"]`).
    pub args: Vec<String>,
}

static LAUNCHER: std::sync::OnceLock<Launcher> = std::sync::OnceLock::new();

/// The command line `args` (the program name first) as the `surgbench`
/// binary runs it, with the batch's children started by `launcher`; the
/// exit code as documented above. Help, `--version` and malformed
/// arguments print and exit the process (exit 2 for the latter), as any
/// command-line program does.
pub fn main<I, T>(args: I, launcher: Launcher) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let _ = LAUNCHER.set(launcher);
    let res = match Cli::parse_from(args).cmd {
        Cmd::List => {
            list();
            Ok(())
        }
        Cmd::Run(a) => cmd_run(a),
        Cmd::Plan(a) => cluster::cmd_plan(a),
        Cmd::Merge(a) => cluster::cmd_merge(a),
        Cmd::RunOne(a) => cmd_run_one(&a),
        Cmd::Report { dir } => cmd_report(&dir),
        Cmd::Gate(a) => cmd_gate(&a),
        Cmd::Diff(a) => diff::cmd_diff(&a),
        Cmd::AccuracyGate(a) => diff::cmd_accuracy_gate(&a),
        Cmd::Haptic(a) => cmd_haptic(&a),
        Cmd::GateWorkload(a) => cmd_gate_workload(&a),
    };
    match res {
        Ok(()) => 0,
        Err(Failure::Usage(m)) => {
            eprintln!("error: {m}");
            2
        }
        Err(Failure::Runtime(m)) => {
            eprintln!("error: {m}");
            1
        }
        Err(Failure::Interrupted(m, sig)) => {
            eprintln!("error: {m}");
            interrupt::exit_code(sig)
        }
    }
}

/// Catch SIGINT/SIGTERM from now on ([`interrupt`]).
fn install_interrupt() -> Result<(), Failure> {
    interrupt::install().map_err(|e| Failure::Runtime(format!("cannot install signal handlers: {e}")))
}

/// What starts the child processes of a batch ([`Launcher`]).
fn launcher() -> Result<&'static Launcher, Failure> {
    LAUNCHER
        .get()
        .ok_or_else(|| Failure::Runtime("no launcher for child processes was set".into()))
}

/// `surgbench run`: a comparison's batch, then a one-line count.
fn cmd_run(a: RunArgs) -> Result<(), Failure> {
    if a.threads == 0 {
        return Err(Failure::Usage("--threads must be >= 1".into()));
    }
    a.sweep.check()?;
    let shard = match &a.shard {
        Some(text) => Some(plan::parse_shard(text)?),
        None => plan::shard_from_env(&|k| std::env::var(k).ok())?,
    };
    match shard {
        Some(s) => return cluster::cmd_run_sharded(a, s),
        None if a.shards.is_some() => {
            return Err(Failure::Usage(
                "--shards goes with --shard K/N or an array job's index variable".into(),
            ));
        }
        None => {}
    }
    let (c, _) = a.sweep.comparison()?;
    // From here on a SIGINT/SIGTERM stops the running child and removes the
    // temporary report folder instead of orphaning both.
    install_interrupt()?;
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| project_root().join("reports/out/latest"));
    let opts = a.batch_options(out.clone())?;
    let rows = batch::run_comparison(&c, &opts).map_err(cluster::batch_failure)?;
    if !a.quiet {
        say!("{} runs: {}", rows.len(), shard_run::status_line(&rows));
        say!("report: {}", out.join("index.html").display());
    }
    Ok(())
}

/// `surgbench run-one`: one run, its files written to a temporary sibling
/// of `--out` and moved into place. A SIGINT/SIGTERM, or the end of the
/// batch that started it, ends it (the watchdog, [`child`]) without leaving
/// the temporary sibling: `--out` is then as it was, or the complete new
/// run if the signal came after the move.
fn cmd_run_one(a: &RunOneArgs) -> Result<(), Failure> {
    outdir::check_replaceable(&a.out, a.force)?;
    let resolved = a.spec.resolve()?;
    if a.repeats == 0 {
        return Err(Failure::Usage("--repeats must be >= 1".into()));
    }
    if let Some(b) = a.repeat_budget
        && !(b > 0.0)
    {
        return Err(Failure::Usage(format!("--repeat-budget must be > 0 s, got {b}")));
    }
    install_interrupt()?;
    child::start_watchdog();
    let opts = RunOptions {
        repeats: a.repeats,
        repeat_budget_s: a.repeat_budget.unwrap_or(f64::INFINITY),
        ..Default::default()
    };
    let summary = resolved.run(&opts)?;
    write_run(&summary, &a.out)?;
    if !a.quiet {
        print_run(&summary, &a.out);
    }
    Ok(())
}

/// `Err(Interrupted)` once a SIGINT/SIGTERM has arrived.
fn interrupted() -> Result<(), Failure> {
    match interrupt::pending() {
        Some(sig) => Err(Failure::Interrupted(
            format!("interrupted by signal {sig}: nothing was written (any earlier folder at --out is unchanged)"),
            sig,
        )),
        None => Ok(()),
    }
}

/// Write a run's files into a temporary sibling of `out` and move it into
/// place, under the [`child::staging`] guard: on an error or a signal the
/// sibling is removed and `out` is left as it was.
fn write_run(summary: &RunSummary, out: &Path) -> Result<(), Failure> {
    let _staging = child::staging();
    interrupted()?;
    let tmp =
        batch::temp_sibling(out).map_err(|e| Failure::Runtime(format!("cannot create {}: {e}", out.display())))?;
    let written = summary
        .write_files(&tmp)
        .and_then(|()| outdir::write_marker(&tmp))
        .map_err(|e| Failure::Runtime(format!("cannot write run files: {e}")))
        .and_then(|()| interrupted())
        .and_then(|()| {
            batch::replace_dir(&tmp, out)
                .map_err(|e| Failure::Runtime(format!("cannot move run into {}: {e}", out.display())))
        });
    if written.is_err() {
        // Nothing half-written stays beside --out.
        let _ = std::fs::remove_dir_all(&tmp);
    }
    written
}

/// What `run-one` tells a person about a run.
fn print_run(summary: &RunSummary, out: &Path) {
    say!(
        "{} / {} [{}]: {}{}",
        summary.scenario,
        summary.model,
        summary.fidelity_string,
        summary.status,
        if summary.reason.is_empty() {
            String::new()
        } else {
            format!(" ({})", summary.reason)
        }
    );
    if let Some(ms) = summary.ms_per_step_median {
        say!(
            "  {} steps, {:.4} s simulated, {ms:.4} ms/step median, end: {}",
            summary.steps.unwrap_or(0.0),
            summary.sim_time_s.unwrap_or(0.0),
            summary.end
        );
    }
    for (k, v) in &summary.errors {
        say!("  {k:<34} {v:.6e}");
    }
    say!("  written to {}", out.display());
}

/// `surgbench report`: re-render a report folder from its results.csv.
fn cmd_report(dir: &Path) -> Result<(), Failure> {
    let csv = dir.join("results.csv");
    if !csv.is_file() {
        return Err(Failure::Usage(format!("{} has no results.csv", dir.display())));
    }
    let files = surgbench_reports::render_dir(dir).map_err(|e| match e {
        surgbench_reports::ReportError::Io { .. } | surgbench_reports::ReportError::Plot { .. } => {
            Failure::Runtime(e.to_string())
        }
        _ => Failure::Usage(e.to_string()),
    })?;
    say!("rendered {} files into {}", files.len(), dir.display());
    Ok(())
}

/// `surgbench gate`: count every workload, print the table, judge.
fn cmd_gate(a: &GateArgs) -> Result<(), Failure> {
    let cfg = gate::load_config(&a.config)?;
    // Before anything is measured: a baseline that cannot be read is an
    // error, never an empty baseline that `--update` would write back.
    let baseline = gate::load_baseline(&a.baseline)?;
    // From here on a SIGINT/SIGTERM stops the running valgrind, removes its
    // files and writes no baseline.
    install_interrupt()?;
    let l = launcher()?;
    if !l.args.is_empty() {
        return Err(Failure::Usage(
            "the gate counts the instructions of the `surgbench` binary: run `surgbench gate` from a build, not through Python".into(),
        ));
    }
    let verdicts = gate::run_gate(&l.exe, &cfg, baseline, &a.baseline, a.update).map_err(|e| match e {
        GateError::Failed(s) => Failure::Runtime(s),
        e @ GateError::Interrupted(sig) => Failure::Interrupted(e.to_string(), sig),
    })?;
    say!(
        "{:<60} {:>16} {:>16} {:>8}",
        "workload",
        "instr/step",
        "baseline",
        "change"
    );
    for v in &verdicts {
        let (b, ch) = match v.baseline {
            Some(b) => (format!("{b:.0}"), format!("{:+.2}%", 100.0 * (v.measured / b - 1.0))),
            None => ("none".into(), "new".into()),
        };
        say!(
            "{:<60} {:>16.0} {:>16} {:>8} {}",
            v.key,
            v.measured,
            b,
            ch,
            if v.pass { "ok" } else { "FAIL" }
        );
    }
    let failed = verdicts.iter().filter(|v| !v.pass).count();
    if a.update {
        say!("baseline written to {}", a.baseline.display());
        Ok(())
    } else if failed > 0 {
        Err(Failure::Runtime(format!(
            "{failed} workload(s) beyond the {:.0}% margin or without a baseline; if the change is intended, refresh with `surgbench gate --update`",
            cfg.margin * 100.0
        )))
    } else {
        say!(
            "gate passed ({} workloads, margin {:.0}%)",
            verdicts.len(),
            cfg.margin * 100.0
        );
        Ok(())
    }
}

/// `surgbench haptic`: one fixed-rate loop, printed and optionally written.
fn cmd_haptic(a: &HapticArgs) -> Result<(), Failure> {
    let (rate, duration) = (a.rate, a.duration);
    if !(rate > 0.0 && rate.is_finite() && duration > 0.0 && duration.is_finite()) {
        return Err(Failure::Usage(format!(
            "--rate and --duration must be > 0, got {rate} Hz, {duration} s"
        )));
    }
    if a.record.is_some() && a.replay.is_none() {
        return Err(Failure::Usage("--record needs --replay".into()));
    }
    let resolved = a.spec.resolve()?;
    // As a batch's child: end if the batch dies.
    child::start_watchdog();
    // A replayed session drives the scene instead of its own timeline: it
    // must keep within the same limits (how far the wire may be fed) that
    // the scenario checks its own timeline against, before anything runs.
    let session = match &a.replay {
        Some(path) => {
            let session = surgbench_core::haptic::Session::load(path).map_err(|e| Failure::Usage(e.to_string()))?;
            resolved
                .run
                .check_control(&session.timeline)
                .map_err(|e| Failure::Usage(format!("replay {}: {e}", path.display())))?;
            Some(session)
        }
        None => None,
    };
    let m = resolved.build()?;
    let report = match session {
        Some(session) => {
            let mut dev = surgbench_core::haptic::ReplayDevice::new(session);
            let r = run_haptic_loop(m, &mut dev, rate, duration)?;
            if let Some(out) = &a.record {
                dev.write_csv(out)
                    .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", out.display())))?;
            }
            r
        }
        None => {
            let mut dev = surgbench_core::haptic::ScriptedDevice::new(resolved.scene().control.clone());
            run_haptic_loop(m, &mut dev, rate, duration)?
        }
    };
    let (model, scenario, full) = (&a.spec.model, &a.spec.scenario, &resolved.fidelity);
    say!("{model} on {scenario} [{full}] at {rate} Hz for {duration} s");
    say!("{report}");
    if let Some(path) = &a.csv {
        let row = report.row(model, scenario, &full.to_string());
        write_haptic_row(path, row).map_err(|e| Failure::Runtime(e.to_string()))?;
    }
    Ok(())
}

/// Write a one-row `haptic.csv` to `path` through a temporary file, under
/// the [`child::staging`] guard (the watchdog never ends the process with
/// the temporary file on disk).
fn write_haptic_row(path: &Path, row: surgbench_reports::HapticRow) -> Result<(), surgbench_reports::ReportError> {
    let _staging = child::staging();
    let tmp = path.with_extension("csv.tmp");
    let written = surgbench_reports::write_haptic_csv(&tmp, &[row]).and_then(|()| {
        std::fs::rename(&tmp, path).map_err(|e| surgbench_reports::ReportError::Io {
            path: path.to_path_buf(),
            source: e,
        })
    });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// `surgbench gate-workload`: build and step, nothing else (what valgrind counts).
fn cmd_gate_workload(a: &GateWorkloadArgs) -> Result<(), Failure> {
    let s = &a.spec;
    let fidelity = surgbench_core::Fidelity::parse_pairs(&s.fidelity).map_err(|e| Failure::Usage(e.0))?;
    let w = gate::Workload {
        model: s.model.clone(),
        scenario: s.scenario.clone(),
        params: parse_overrides(&s.params)?.into_iter().collect(),
        fidelity: fidelity.pairs().into_iter().collect(),
        steps: a.steps,
        warmup: 0,
        static_solve: false,
        gate: true,
    };
    gate::run_workload(&w, a.steps)?;
    Ok(())
}
