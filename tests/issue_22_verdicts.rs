//! Issue 22, item 1: every scenario states an accuracy target for its
//! primary error; a comparison (`target = ...`) or the command line
//! (`--target SCENARIO=VALUE`) may state another, and `--budget-ms` the
//! time budgets. The report's first table gives, per scene and model, the
//! cheapest tested settings that meet the target, or what the best run
//! reached.

mod common;

use common::{quick_run, text};
use surgbench_comparisons::comparison::Comparison;
use surgbench_comparisons::registry;

/// Every scenario's target is a finite number >= 0 with a reason.
#[test]
fn every_scenario_states_a_target() {
    for s in registry::scenarios() {
        let t = s.target();
        assert!(t.value >= 0.0 && t.value.is_finite(), "{}: target {}", s.id(), t.value);
        assert!(t.why.len() > 10, "{}: the target says why", s.id());
    }
}

/// A comparison's target replaces the scenario's; a bad one or two that
/// disagree are usage errors.
#[test]
fn comparison_targets_override_and_are_checked() {
    let toml =
        |extra: &str| format!("name = \"t\"\nmodels = [\"der\"]\n[[scenario]]\nid = \"cantilever-gravity\"\n{extra}");
    let c = Comparison::parse(&toml("")).unwrap();
    let t = &c.targets().unwrap()["cantilever-gravity"];
    assert_eq!((t.metric.as_str(), t.value), ("tip_error_rel", 0.02));
    let c = Comparison::parse(&toml("target = 1e-3\n")).unwrap();
    let t = &c.targets().unwrap()["cantilever-gravity"];
    assert_eq!(t.value, 1e-3);
    assert!(t.why.contains("comparison `t`"), "{}", t.why);
    let e = Comparison::parse(&toml("target = -1\n")).unwrap_err();
    assert!(e.0.contains("target must be a finite number >= 0"), "{}", e.0);
    let two =
        toml("target = 1e-3\n[[scenario]]\nid = \"cantilever-gravity\"\nparams = { length = 0.2 }\ntarget = 2e-3\n");
    let e = Comparison::parse(&two).unwrap().targets().unwrap_err();
    assert!(e.0.contains("two targets"), "{}", e.0);
}

/// End to end: a run whose finer setting meets the target is reported at
/// it; a target nothing meets says so with the best run; bad flags are
/// exit 2 and write nothing.
#[test]
fn the_report_opens_with_verdicts() {
    let t = tempfile::tempdir().unwrap();
    let cmp = t.path().join("v.toml");
    std::fs::write(
        &cmp,
        "name = \"v\"\nmodels = [\"der\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nquick_sweep = { segments = [5, 20] }\n",
    )
    .unwrap();
    let run = |out: &str, extra: &[&str]| {
        let dir = t.path().join(out);
        (quick_run(&cmp, &dir, extra), dir)
    };
    // DER's tip error (measured): 4.0e-2 at 5 segments, 2.5e-3 at 20 (second
    // order: 16x apart). A 5e-3 target is met at 20 segments only.
    let (o, dir) = run("a", &["--target", "cantilever-gravity=5e-3", "--budget-ms", "16,1"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("Verdicts: accurate enough"), "{md}");
    assert!(md.contains("tip\\_error\\_rel ≤ 0.005"), "{md}");
    assert!(
        md.contains("meets it: ") && md.contains("s to the solution (segments=20;"),
        "{md}"
    );
    assert!(md.contains("set on the command line (--target)"), "{md}");
    // Nothing meets 1e-9: the best run is named.
    let (o, dir) = run("b", &["--tolerance", "cantilever-gravity=1e-9"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("misses it at every tested setting (best: "), "{md}");
    assert!(md.contains("segments=20;"), "{md}");
    for bad in [
        &["--target", "arch-insertion=1e-3"][..],
        &["--target", "cantilever-gravity"][..],
        &["--target", "cantilever-gravity=-1"][..],
        &["--budget-ms", "0"][..],
    ] {
        let (o, dir) = run("c", bad);
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {}", text(&o));
        assert!(!dir.exists(), "{bad:?} wrote {}", dir.display());
    }
}

/// Item 7, progress: with stderr not a terminal (a log file, CI), a batch
/// prints one line per finished run with the time elapsed and left; a
/// second run into the same folder weights the time left by the first
/// report's run costs, so it has an estimate before any run finished.
#[test]
fn a_logged_batch_prints_a_line_per_run() {
    let t = tempfile::tempdir().unwrap();
    let cmp = t.path().join("p.toml");
    std::fs::write(
        &cmp,
        "name = \"p\"\nmodels = [\"der\", \"needle\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nquick_sweep = { segments = [5, 10] }\n",
    )
    .unwrap();
    let out = t.path().join("r");
    let (c, o) = (cmp.to_str().unwrap(), out.to_str().unwrap());
    for pass in 0..2 {
        let run = common::surgbench(&["run", c, "--quick", "--out", o]);
        assert_eq!(run.status.code(), Some(0), "{}", text(&run));
        let err = String::from_utf8_lossy(&run.stderr);
        let lines: Vec<&str> = err.lines().filter(|l| l.starts_with('[')).collect();
        // DER at 5 and 10 segments, and the needle's one unsupported line.
        assert_eq!(lines.len(), 3, "{err}");
        assert!(lines[0].starts_with("[1/3] cantilever-gravity / "), "{err}");
        assert!(lines.iter().all(|l| l.contains(" elapsed, ETA ")), "{err}");
        assert!(
            lines
                .iter()
                .any(|l| l.contains("/ needle / ") && l.contains(": unsupported in ")),
            "{err}"
        );
        if pass == 1 {
            // Every run has a prior now: no line is without an estimate.
            assert!(!err.contains("ETA unknown"), "{err}");
        }
    }
}
