//! Command-line behaviour: bad input gets one clear line and exit code 2
//! with nothing written; a failed run never damages an earlier report; a
//! model that panics, aborts or hangs is recorded, and the comparison goes
//! on; `run-one` honours parameter overrides.

use std::path::Path;
use std::process::{Command, Output};

fn surgbench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_surgbench"))
        .args(args)
        .env("SURGBENCH_FAULTY_MODELS", "1")
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("surgbench runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit code 2, one line on stderr mentioning `needle`, and `out` untouched.
fn assert_usage_error(args: &[&str], needle: &str, out: &Path) {
    let o = surgbench(args);
    let err = stderr(&o);
    assert_eq!(
        o.status.code(),
        Some(2),
        "args {args:?}: expected exit 2, stderr: {err}"
    );
    assert!(
        err.contains(needle),
        "args {args:?}: stderr should mention `{needle}`: {err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "args {args:?}: one line expected: {err}");
    assert!(!out.exists(), "args {args:?}: {} must not be written", out.display());
}

#[test]
fn bad_input_is_a_clear_usage_error_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let o = out.to_str().unwrap();
    let base = ["run-one", "--out", o];
    let case = |extra: &[&str], needle: &str| {
        let mut a: Vec<&str> = base.to_vec();
        a.extend_from_slice(extra);
        assert_usage_error(&a, needle, &out);
    };
    case(
        &["--scenario", "nope", "--model", "faulty-panic"],
        "unknown scenario `nope`",
    );
    let gravity = ["--scenario", "cantilever-gravity", "--model", "faulty-panic"];
    case(
        &["--scenario", "cantilever-gravity", "--model", "nope"],
        "unknown model `nope`",
    );
    case(
        &[&gravity[..], &["--param", "lenght=1"]].concat(),
        "no parameter `lenght`",
    );
    case(&[&gravity[..], &["--param", "length=-0.1"]].concat(), "`length`");
    case(
        &[&gravity[..], &["--param", "poisson_ratio=0.5"]].concat(),
        "`poisson_ratio`",
    );
    case(&[&gravity[..], &["--param", "length=abc"]].concat(), "not a number");
    case(
        &[&gravity[..], &["--repeat-budget", "0"]].concat(),
        "--repeat-budget must be > 0",
    );
    case(
        &[&gravity[..], &["--repeat-budget", "nan"]].concat(),
        "--repeat-budget must be > 0",
    );
    case(&[&gravity[..], &["--fidelity", "dt=0"]].concat(), "`dt`");
    case(&[&gravity[..], &["--fidelity", "dt=-1e-3"]].concat(), "`dt`");
    case(&[&gravity[..], &["--fidelity", "segments=2.5"]].concat(), "`segments`");
    case(
        &[&gravity[..], &["--fidelity", "warp=1"]].concat(),
        "unknown fidelity key `warp`",
    );
    // A choice is a name: an unknown one, or the numeric code it once had,
    // is refused listing the names.
    let fem = ["--scenario", "block-compression", "--model", "fem", "--fidelity"];
    case(
        &[&fem[..], &["solver=lu"]].concat(),
        "unknown choice `lu` (choices: direct, cg)",
    );
    case(&[&fem[..], &["solver=1"]].concat(), "takes a name, one of: direct, cg");
    case(&[&fem[..], &["factor_reuse=2"]].concat(), "switch: 0 (off) or 1 (on)");
    case(&[&fem[..], &["cg_tol=tight"]].concat(), "`cg_tol` takes a number");
    case(
        &[&fem[..], &["solver=Direct"]].concat(),
        "neither a number nor a choice name",
    );
    // A missing required argument is clap's usage error (exit 2 too).
    let o = surgbench(&["run-one", "--scenario", "cantilever-gravity"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn malformed_comparison_and_csv_are_usage_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("report");
    let o = out.to_str().unwrap();
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, "name = \"x\"\nmodels = [\"der\"\n").unwrap();
    assert_usage_error(
        &["run", bad.to_str().unwrap(), "--out", o],
        "malformed comparison TOML",
        &out,
    );
    let unknown = tmp.path().join("unknown.toml");
    std::fs::write(
        &unknown,
        "name = \"x\"\nmodels = [\"nope\"]\n[[scenario]]\nid = \"cantilever-gravity\"\n",
    )
    .unwrap();
    assert_usage_error(
        &["run", unknown.to_str().unwrap(), "--out", o],
        "unknown model `nope`",
        &out,
    );
    assert_usage_error(&["run", "no-such-comparison", "--out", o], "unknown comparison", &out);
    // `report` on a folder whose results.csv is malformed.
    let rep = tmp.path().join("rep");
    std::fs::create_dir(&rep).unwrap();
    std::fs::write(rep.join("results.csv"), "comparison,scenario\nx\n").unwrap();
    let o = surgbench(&["report", rep.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("results.csv"), "{}", stderr(&o));
}

#[test]
fn misbehaving_models_are_recorded_and_the_comparison_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let cmp = tmp.path().join("faulty.toml");
    std::fs::write(
        &cmp,
        "name = \"faulty\"\nmodels = [\"faulty-panic\", \"faulty-abort\", \"faulty-hang\", \"faulty-nonfinite\"]\n\
         timeout_s = 2\n[[scenario]]\nid = \"cantilever-gravity\"\nsweep = { segments = [10] }\n",
    )
    .unwrap();
    let out = tmp.path().join("report");
    let o = surgbench(&["run", cmp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let row = |m: &str| {
        csv.lines()
            .find(|l| l.contains(&format!(",{m},")))
            .unwrap_or_else(|| panic!("no row for {m}: {csv}"))
            .to_string()
    };
    assert!(
        row("faulty-panic").contains(",failed,") && row("faulty-panic").contains("panicked on purpose"),
        "{}",
        row("faulty-panic")
    );
    assert!(
        row("faulty-abort").contains(",failed,") && row("faulty-abort").contains("SIGABRT"),
        "{}",
        row("faulty-abort")
    );
    assert!(row("faulty-hang").contains(",timeout,"), "{}", row("faulty-hang"));
    let nf = row("faulty-nonfinite");
    assert!(
        nf.contains(",unstable,") && nf.contains("non-finite state at t=0.0030 s"),
        "{nf}"
    );
}

#[test]
fn a_failed_run_leaves_the_earlier_report_intact() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("report");
    let o = out.to_str().unwrap();
    let good = tmp.path().join("good.toml");
    std::fs::write(
        &good,
        "name = \"good\"\nmodels = [\"faulty-nonfinite\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nsweep = { segments = [10] }\n",
    )
    .unwrap();
    let r = surgbench(&["run", good.to_str().unwrap(), "--out", o, "--quiet"]);
    assert!(r.status.success(), "{}", stderr(&r));
    let before = std::fs::read(out.join("results.csv")).unwrap();
    let bad = tmp.path().join("bad.toml");
    std::fs::write(
        &bad,
        "name = \"bad\"\nmodels = [\"faulty-nonfinite\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nparams = { radius = -1 }\n",
    )
    .unwrap();
    let r = surgbench(&["run", bad.to_str().unwrap(), "--out", o, "--quiet"]);
    assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
    assert_eq!(
        std::fs::read(out.join("results.csv")).unwrap(),
        before,
        "earlier report changed"
    );
    let leftovers: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "temporary folders left behind: {leftovers:?}");
}

/// `[[haptic]]` entries run after the comparison's runs, each in its own
/// process: an ok loop, a model that panics inside the loop, and a model that
/// cannot run the scene all appear in `haptic.csv` and the report's table.
#[test]
fn haptic_loops_land_in_the_report() {
    let tmp = tempfile::tempdir().unwrap();
    let cmp = tmp.path().join("haptic.toml");
    std::fs::write(
        &cmp,
        "name = \"h\"\nmodels = [\"chainmail\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nquick_sweep = { segments = [10] }\n\
         [[haptic]]\nmodel = \"chainmail\"\nscenario = \"arch-insertion\"\nfidelity = { segments = 20 }\nquick_duration_s = 0.2\n\
         [[haptic]]\nmodel = \"faulty-panic\"\nscenario = \"cantilever-gravity\"\nquick_duration_s = 0.2\n\
         [[haptic]]\nmodel = \"meshless\"\nscenario = \"capstan\"\nquick_duration_s = 0.2\n",
    )
    .unwrap();
    let out = tmp.path().join("report");
    let o = surgbench(&[
        "run",
        cmp.to_str().unwrap(),
        "--quick",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = surgbench_reports::read_haptic_csv(&out.join("haptic.csv")).unwrap();
    assert_eq!(rows.len(), 3, "{rows:?}");
    assert_eq!(rows[0].status, "ok", "{:?}", rows[0]);
    assert_eq!(rows[0].ticks, Some(200.0), "0.2 s at 1 kHz: {:?}", rows[0]);
    assert!(
        rows[1].status == "failed" && rows[1].reason.contains("panicked on purpose"),
        "{:?}",
        rows[1]
    );
    assert_eq!(rows[2].status, "unsupported", "{:?}", rows[2]);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("## Haptic loop") && md.contains("of 200 ("), "{md}");
}

/// `list` names every comparison file and none is unreadable (the crate
/// manifest that shares the folder is not one).
#[test]
fn list_shows_the_comparisons_and_nothing_unreadable() {
    let o = surgbench(&["list"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    for name in ["standard", "tissue", "navigation"] {
        assert!(
            out.contains(&format!("  {name} ")),
            "`list` lacks comparison {name}: {out}"
        );
    }
    assert!(!out.contains("unreadable") && !out.contains("  Cargo "), "{out}");
    // each choice key shows its names, each name what it selects
    assert!(
        out.contains("fidelity solver         direct | cg: linear solver of each Newton step"),
        "{out}"
    );
    assert!(
        out.contains("= \"nested-dissection\" geometric nested dissection"),
        "{out}"
    );
    assert!(out.contains("fidelity pbd            0 | 1: "), "{out}");
}
