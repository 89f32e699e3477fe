//! Issue 16, item 2: values that pass validation panicked or aborted.
//! `run-one --param youngs_modulus=1e308` died of "capacity overflow"
//! (exit 101: the runner reserved `duration / dt` slots up front), as did
//! `density=1e-300`, `duration=1e300` and `--fidelity dt=1e-300`;
//! `youngs_modulus=1e25` and `duration=1e9` aborted allocating 88 GB
//! (SIGABRT); `haptic --duration 1e300` panicked inside the loop and blamed
//! the model.
//!
//! Now a run is bounded at `runner::MAX_STEPS` (1e8) steps, checked when
//! the run is resolved (single runs, comparison jobs, haptic loops), and
//! its buffers grow as it goes: each reproduction is a usage error (exit
//! 2, one line on stderr naming the bound) and writes nothing.

mod common;

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

/// A refusal comes before any model steps: milliseconds. Half a minute
/// leaves room for a loaded machine and still fails a run that goes on.
const LIMIT: Duration = Duration::from_secs(30);

/// `surgbench ARGS`, killed (and the test failed) past [`LIMIT`].
fn surgbench(args: &[&str]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_surgbench"));
    cmd.args(args);
    common::output_within(cmd, LIMIT, &format!("surgbench {args:?}"))
}

/// Exit 2, one line on stderr that names the step bound, `out` not created.
fn assert_bounded(o: &Output, what: &str, out: &Path) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: stderr: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: one line on stderr: {err}");
    assert!(err.contains("1e8 steps"), "{what}: the message names the bound: {err}");
    assert!(!out.exists(), "{what}: {} was written", out.display());
}

/// Every `run-one` reproduction of the issue on the cantilever with DER.
#[test]
fn run_one_refuses_runs_past_the_step_bound() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    for extra in [
        ["--param", "youngs_modulus=1e308"],
        ["--param", "density=1e-300"],
        ["--param", "duration=1e300"],
        ["--fidelity", "dt=1e-300"],
        ["--param", "youngs_modulus=1e25"],
        ["--param", "duration=1e9"],
    ] {
        let mut args = vec!["run-one", "--scenario", "cantilever-gravity", "--model", "der"];
        args.extend(extra);
        args.extend(["--quiet", "--out", o]);
        let r = surgbench(&args);
        assert_bounded(&r, &extra.join(" "), &out);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(err.contains("duration") && err.contains("dt"), "{extra:?}: {err}");
    }
}

/// The same bound in the batch path: the comparison is refused before any
/// run starts, and no report folder appears.
#[test]
fn a_comparison_past_the_step_bound_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let cmp = tmp.path().join("long.toml");
    std::fs::write(
        &cmp,
        "name = \"long\"\nmodels = [\"der\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nparams = { duration = 1e9 }\nsweep = { segments = [10] }\n",
    )
    .unwrap();
    let out = tmp.path().join("report");
    let r = surgbench(&["run", cmp.to_str().unwrap(), "--quiet", "--out", out.to_str().unwrap()]);
    assert_bounded(&r, "run duration=1e9", &out);
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(left.len(), 1, "only the comparison file is there: {left:?}");
}

/// `haptic --duration 1e300` (and a dt that makes each tick 1e297 substeps)
/// is a usage error, not a panic blamed on the model.
#[test]
fn haptic_refuses_loops_past_the_step_bound() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = tmp.path().join("h.csv");
    let cases: [&[&str]; 2] = [
        &["--duration", "1e300"],
        &["--duration", "0.01", "--fidelity", "dt=1e-300"],
    ];
    for extra in cases {
        let mut args = vec!["haptic", "--model", "der", "--scenario", "arch-insertion"];
        args.extend(extra);
        args.extend(["--csv", csv.to_str().unwrap()]);
        let r = surgbench(&args);
        assert_bounded(&r, &extra.join(" "), &csv);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(!err.contains("panicked"), "{extra:?}: {err}");
    }
}
