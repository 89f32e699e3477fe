//! The CI performance gate: instruction counts under valgrind (callgrind)
//! are deterministic run to run on a given CPU type and binary, unlike
//! wall-clock time on a shared 2-core machine. Each workload (a model on a
//! scenario at a fixed fidelity) is counted at `steps` and `2 steps`; the
//! difference divided by `steps` is the cost of one step, free of build and
//! start-up cost. A `static_solve` workload (a settling scene at a model's
//! static defaults, whose first step solves the whole load and whose later
//! steps find nothing left to do) is counted at 0 and `steps` steps
//! instead: the cost of the solve past the build. The gate fails when a workload costs more than
//! `(1 + margin)` times its committed baseline.
//!
//! With [`crate::interrupt::install`] called first, a SIGINT or SIGTERM to
//! the gate kills and reaps the running valgrind, removes its files and
//! writes no baseline ([`GateError::Interrupted`]).

use crate::child::Waited;
use crate::registry;
use crate::resolve::ResolvedRun;
use crate::scenario::UsageError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use surgbench_core::Setting;

/// One gated workload.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Workload {
    /// Model id.
    pub model: String,
    /// Scenario id.
    pub scenario: String,
    /// Parameter overrides.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    /// Fidelity knobs (numbers or choice names).
    #[serde(default)]
    pub fidelity: BTreeMap<String, Setting>,
    /// Steps counted (the gate also counts twice as many).
    pub steps: usize,
    /// Steps taken before those counted or timed (default 0): a workload
    /// measured in a steady state (an instrument already pressing the
    /// wall) rather than from its start. The gate counts at `warmup +
    /// steps` and `warmup + 2 steps`; the criterion bench steps `warmup`
    /// outside its timing.
    #[serde(default)]
    pub warmup: usize,
    /// One static solve: counted at 0 and `steps` (= 1) steps, the cost of
    /// the first step past the build (default `false`).
    #[serde(default)]
    pub static_solve: bool,
    /// Counted by the gate (default `true`); `false` keeps a workload too
    /// large for valgrind in CI to the criterion bench only.
    #[serde(default = "counted")]
    pub gate: bool,
}

fn counted() -> bool {
    true
}

impl Workload {
    /// Stable key: `model/scenario/fidelity`.
    pub fn key(&self) -> String {
        let f: Vec<String> = self.fidelity.iter().map(|(k, v)| format!("{k}={v}")).collect();
        format!("{}/{}/{}", self.model, self.scenario, f.join(";"))
    }
}

/// `benches/gate.toml`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GateConfig {
    /// Allowed relative growth of instructions per step (e.g. 0.05).
    pub margin: f64,
    /// Workloads.
    pub workload: Vec<Workload>,
}

/// `benches/gate-baseline.json`: instructions per step by workload key, one
/// set per CPU model (counts are tied to the CPU type: valgrind hides some
/// instruction sets, and code may pick a SIMD path at run time), so a
/// project whose machines change CPU type keeps a baseline for each.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
pub struct Baseline {
    /// Instructions per step by workload key, by CPU model name.
    #[serde(default)]
    pub by_cpu: BTreeMap<String, BTreeMap<String, f64>>,
    /// Single-CPU form of earlier baseline files (read, never written).
    #[serde(default, skip_serializing)]
    cpu: Option<String>,
    #[serde(default, skip_serializing)]
    instructions_per_step: Option<BTreeMap<String, f64>>,
}

impl Baseline {
    /// Parse a baseline file, accepting the earlier single-CPU form.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut b: Baseline = serde_json::from_str(text).map_err(|e| e.to_string())?;
        if let (Some(cpu), Some(counts)) = (b.cpu.take(), b.instructions_per_step.take()) {
            b.by_cpu.entry(cpu).or_insert(counts);
        }
        Ok(b)
    }
}

/// Load the gate configuration.
pub fn load_config(path: &Path) -> Result<GateConfig, UsageError> {
    let text = std::fs::read_to_string(path).map_err(|e| UsageError(format!("cannot read {}: {e}", path.display())))?;
    let c: GateConfig =
        toml::from_str(&text).map_err(|e| UsageError(format!("{}: {}", path.display(), e.message())))?;
    if !(c.margin >= 0.0) {
        return Err(UsageError(format!("{}: margin must be >= 0", path.display())));
    }
    for w in &c.workload {
        registry::model(&w.model)?;
        registry::scenario(&w.scenario)?;
        if w.steps == 0 {
            return Err(UsageError(format!(
                "{}: workload {} has steps = 0",
                path.display(),
                w.key()
            )));
        }
        if w.static_solve && w.steps != 1 {
            return Err(UsageError(format!(
                "{}: static_solve workload {} must have steps = 1 (its first step is the whole solve)",
                path.display(),
                w.key()
            )));
        }
        if w.static_solve && w.warmup != 0 {
            return Err(UsageError(format!(
                "{}: static_solve workload {} cannot have a warmup (its first step is the whole solve)",
                path.display(),
                w.key()
            )));
        }
    }
    Ok(c)
}

/// CPU model name (from /proc/cpuinfo).
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

impl Workload {
    /// The workload resolved and validated (scenario, model, parameters, fidelity).
    pub fn resolve(&self) -> Result<ResolvedRun, UsageError> {
        let overrides: Vec<(String, f64)> = self.params.iter().map(|(k, v)| (k.clone(), *v)).collect();
        ResolvedRun::from_knobs(&self.scenario, &self.model, &overrides, &self.fidelity)
    }
}

/// Build the workload's model and take `steps` steps (what valgrind counts).
pub fn run_workload(w: &Workload, steps: usize) -> Result<(), UsageError> {
    step_workload(&w.resolve()?, steps, &w.key())
}

/// Build `run`'s model and take `steps` steps along its control timeline;
/// errors are prefixed with `key`.
pub fn step_workload(run: &ResolvedRun, steps: usize, key: &str) -> Result<(), UsageError> {
    let mut m = run.build().map_err(|e| UsageError(format!("{key}: {}", e.0)))?;
    let dt = m.dt();
    for k in 0..steps {
        let cmd = run.scene().control.command_at((k + 1) as f64 * dt);
        m.step(dt, &cmd).map_err(|e| UsageError(format!("{key}: {e}")))?;
    }
    Ok(())
}

/// Why the gate could not judge.
#[derive(Debug)]
pub enum GateError {
    /// Valgrind or the workload failed, or the baseline could not be written.
    Failed(String),
    /// SIGINT or SIGTERM (the number) arrived: the running valgrind was
    /// killed and reaped, its files removed, and no baseline was written.
    Interrupted(i32),
}

impl std::fmt::Display for GateError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GateError::Failed(s) => f.write_str(s),
            GateError::Interrupted(sig) => write!(
                f,
                "interrupted by signal {sig}: valgrind was stopped and no baseline was written (the baseline file is unchanged)"
            ),
        }
    }
}

impl From<String> for GateError {
    fn from(s: String) -> Self {
        GateError::Failed(s)
    }
}

/// Count instructions of `exe gate-workload ... --steps n` under callgrind.
/// Valgrind's output and stderr go to files in the temporary folder, and
/// its own temporaries (`valgrind_proc_<pid>_auxv`, ...) to a folder of
/// the gate's there, all removed however the count ends; a signal to the
/// gate kills valgrind ([`crate::child::spawn_with_limit`]). (Valgrind
/// removes its temporaries itself shortly after it starts: one killed
/// before that left its `auxv` file behind.)
fn count(exe: &Path, w: &Workload, n: usize) -> Result<f64, GateError> {
    let stem = format!("surgbench-callgrind-{}-{n}", std::process::id());
    let out_file = std::env::temp_dir().join(format!("{stem}.out"));
    let err_file = std::env::temp_dir().join(format!("{stem}.stderr"));
    let scratch = std::env::temp_dir().join(format!("{stem}.tmp"));
    std::fs::create_dir_all(&scratch)
        .map_err(|e| format!("cannot make valgrind's temporary folder {}: {e}", scratch.display()))?;
    let mut cmd = Command::new("valgrind");
    cmd.env("TMPDIR", &scratch);
    // No gdbserver: its FIFOs in the temporary folder would outlive a
    // killed valgrind. It does not change the instructions counted.
    cmd.arg("--tool=callgrind")
        .arg("--vgdb=no")
        .arg(format!("--callgrind-out-file={}", out_file.display()))
        .arg(exe)
        .arg("gate-workload")
        .arg("--model")
        .arg(&w.model)
        .arg("--scenario")
        .arg(&w.scenario)
        .arg("--steps")
        .arg(n.to_string());
    for (k, v) in &w.params {
        cmd.arg("--param").arg(format!("{k}={v}"));
    }
    for (k, v) in &w.fidelity {
        cmd.arg("--fidelity").arg(format!("{k}={v}"));
    }
    cmd.env("RAYON_NUM_THREADS", "1");
    let waited = crate::child::spawn_with_limit(cmd, &err_file, f64::INFINITY);
    let counted = read_count(waited, &out_file, &err_file, w);
    let _ = std::fs::remove_file(&out_file);
    let _ = std::fs::remove_file(&err_file);
    let _ = std::fs::remove_dir_all(&scratch);
    counted
}

/// The instruction count of a finished valgrind run: its summary line in
/// `out_file`, or why there is none.
fn read_count(
    waited: std::io::Result<(Waited, f64)>,
    out_file: &Path,
    err_file: &Path,
    w: &Workload,
) -> Result<f64, GateError> {
    let status = match waited {
        Err(e) => return Err(format!("cannot run valgrind (is it installed?): {e}").into()),
        Ok((Waited::Interrupted(sig), _)) => return Err(GateError::Interrupted(sig)),
        Ok((Waited::TimedOut, _)) => return Err(format!("lost track of the valgrind run of {}", w.key()).into()),
        Ok((Waited::Exited(s), _)) => s,
    };
    if !status.success() {
        let err = std::fs::read_to_string(err_file).unwrap_or_default();
        return Err(format!(
            "valgrind run of {} failed: {}",
            w.key(),
            err.lines().last().unwrap_or("")
        )
        .into());
    }
    let text = std::fs::read_to_string(out_file).map_err(|e| format!("no callgrind output: {e}"))?;
    text.lines()
        .find_map(|l| l.strip_prefix("summary:").or_else(|| l.strip_prefix("totals:")))
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse::<f64>().ok())
        .ok_or_else(|| "callgrind output has no summary line".to_string().into())
}

/// One workload's verdict.
#[derive(Debug, Clone)]
pub struct Verdict {
    /// Workload key.
    pub key: String,
    /// Measured instructions per step.
    pub measured: f64,
    /// Baseline, if recorded.
    pub baseline: Option<f64>,
    /// Within the margin (or no baseline yet).
    pub pass: bool,
}

/// Reads the baseline file at `path`. An absent file is an empty baseline
/// (the first `--update` records one); anything else that cannot be read
/// as a baseline (a folder, an unreadable file, bytes that are not UTF-8,
/// malformed JSON) is a [`UsageError`] naming the file: it is never taken
/// for an empty baseline, which `--update` would write back without the
/// other CPUs' counts.
pub fn load_baseline(path: &Path) -> Result<Baseline, UsageError> {
    let bad = |what: String| {
        UsageError(format!(
            "baseline {}: {what}; nothing was measured or written (fix the file or restore it from version control)",
            path.display()
        ))
    };
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Baseline::default()),
        Err(e) => return Err(bad(format!("cannot read it: {e}"))),
    };
    let text = String::from_utf8(bytes).map_err(|e| {
        bad(format!(
            "not UTF-8 text (invalid byte at offset {})",
            e.utf8_error().valid_up_to()
        ))
    })?;
    Baseline::parse(&text).map_err(|e| bad(format!("not a gate baseline: {e}")))
}

/// Writes `baseline` to `path` through a temporary file in the same folder
/// renamed over it: a failed write (full disk, a killed process) leaves
/// the earlier baseline as it was.
pub fn save_baseline(path: &Path, baseline: &Baseline) -> Result<(), String> {
    let json = serde_json::to_string_pretty(baseline).map_err(|e| e.to_string())? + "\n";
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("baseline");
    let tmp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let written = std::fs::write(&tmp, json).and_then(|()| std::fs::rename(&tmp, path));
    written.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("cannot write {}: {e}", path.display())
    })
}

/// Count every workload and compare with `baseline` (from
/// [`load_baseline`]); with `update`, record this CPU's counts in it
/// (the other CPUs' are kept) and write it to `baseline_path`. With
/// [`crate::interrupt::install`] called first, a SIGINT/SIGTERM stops the
/// running valgrind and returns [`GateError::Interrupted`] before anything
/// is written.
pub fn run_gate(
    exe: &Path,
    cfg: &GateConfig,
    mut all: Baseline,
    baseline_path: &Path,
    update: bool,
) -> Result<Vec<Verdict>, GateError> {
    let cpu = cpu_model();
    let base = match all.by_cpu.get(&cpu) {
        Some(b) => b.clone(),
        None if update => BTreeMap::new(),
        None => {
            let known: Vec<&str> = all.by_cpu.keys().map(String::as_str).collect();
            return Err(format!(
                "no baseline for this CPU `{cpu}` (recorded: {known:?}): instruction counts are not comparable across CPU types; record one with `surgbench gate --update`"
            )
            .into());
        }
    };
    let mut verdicts = Vec::new();
    let mut new = BTreeMap::new();
    for w in cfg.workload.iter().filter(|w| w.gate) {
        let (lo, hi) = if w.static_solve {
            (0, w.steps)
        } else {
            (w.warmup + w.steps, w.warmup + 2 * w.steps)
        };
        let a = count(exe, w, lo)?;
        let b = count(exe, w, hi)?;
        let per_step = (b - a) / (hi - lo) as f64;
        let key = w.key();
        let old = base.get(&key).copied();
        let pass = update || old.is_some_and(|o| per_step <= o * (1.0 + cfg.margin));
        new.insert(key.clone(), per_step);
        verdicts.push(Verdict {
            key,
            measured: per_step,
            baseline: old,
            pass,
        });
    }
    if let Some(sig) = crate::interrupt::pending() {
        return Err(GateError::Interrupted(sig));
    }
    if update {
        all.by_cpu.insert(cpu, new);
        save_baseline(baseline_path, &all)?;
    }
    Ok(verdicts)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Earlier single-CPU files still load (as one CPU's counts), and the
    /// per-CPU form round-trips keeping every CPU.
    #[test]
    fn baselines_load_old_and_per_cpu_forms() {
        let old = r#"{"cpu": "Intel X", "instructions_per_step": {"der/a/": 10.0}}"#;
        let b = Baseline::parse(old).unwrap();
        assert_eq!(b.by_cpu["Intel X"]["der/a/"], 10.0);
        let mut b2 = b.clone();
        b2.by_cpu
            .insert("AMD Y".into(), BTreeMap::from([("der/a/".to_string(), 12.0)]));
        let text = serde_json::to_string(&b2).unwrap();
        assert!(!text.contains("instructions_per_step"), "{text}");
        let back = Baseline::parse(&text).unwrap();
        assert_eq!(back.by_cpu.len(), 2);
        assert_eq!(back.by_cpu["AMD Y"]["der/a/"], 12.0);
        assert!(Baseline::parse("{not json").is_err());
    }

    /// Every committed baseline count belongs to a workload of
    /// benches/gate.toml: a renamed fidelity knob or choice changes the
    /// workload's key, and must rename the baseline's key with it rather
    /// than leave the count orphaned (and the workload ungated).
    #[test]
    fn committed_baseline_keys_are_workload_keys() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let cfg = load_config(&root.join("benches/gate.toml")).unwrap();
        let keys: Vec<String> = cfg.workload.iter().map(Workload::key).collect();
        assert!(
            keys.contains(&"pbd-rod/cantilever-tip-load/segments=100;solver=direct;substeps=4".to_string()),
            "{keys:?}"
        );
        let text = std::fs::read_to_string(root.join("benches/gate-baseline.json")).unwrap();
        let base = Baseline::parse(&text).unwrap();
        for (cpu, counts) in &base.by_cpu {
            for k in counts.keys() {
                assert!(
                    keys.contains(k),
                    "baseline of `{cpu}` has `{k}`, no workload of gate.toml: {keys:?}"
                );
            }
        }
    }
}
