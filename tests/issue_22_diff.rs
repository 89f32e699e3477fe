//! Issue 22, item 6: comparing reports. `surgbench diff OLD NEW` lists per
//! point what changed, flags regressions beyond the tolerances and, with
//! `--fail-on-regression`, exits 1 when there are any; bad input is exit 2.
//! `surgbench accuracy-gate` diffs a report's errors against a committed
//! per-CPU baseline and never touches the baseline unless told to.

use std::path::Path;
mod common;

use common::{quick_run, surgbench, text};
use surgbench_reports::{ResultRow, Status, read_results_csv, write_results_csv};

/// Two points of a synthetic report; `tip` is the first one's primary error.
fn report(dir: &Path, tip: f64, ms: f64) -> String {
    let row = |fid: &str, err: f64| {
        let mut r = ResultRow {
            comparison: "t".into(),
            scenario: "cantilever-gravity".into(),
            model: "der".into(),
            family: "rod".into(),
            fidelity: fid.into(),
            primary_error: "tip_error_rel".into(),
            ..Default::default()
        };
        r.status = Status::Ok;
        r.ms_per_step_median = Some(ms);
        r.metrics.insert("tip_error_rel".into(), err);
        r.metrics.insert("hand_force_n".into(), 1.0);
        r
    };
    std::fs::create_dir_all(dir).unwrap();
    write_results_csv(
        &dir.join("results.csv"),
        &[row("segments=10", tip), row("segments=20", 2.5e-3)],
    )
    .unwrap();
    dir.to_str().unwrap().to_string()
}

/// A worse primary error is listed and, with the flag, fails; times are
/// judged unless --errors-only; bad input is a usage error.
#[test]
fn diff_flags_regressions_and_exits_by_them() {
    let t = tempfile::tempdir().unwrap();
    let a = report(&t.path().join("a"), 1e-2, 1.0);
    let b = report(&t.path().join("b"), 1.1e-2, 1.0);
    let same = surgbench(&["diff", &a, &a, "--fail-on-regression"]);
    assert_eq!(same.status.code(), Some(0), "{}", text(&same));
    assert!(text(&same).contains("2 points in both: 2 same"), "{}", text(&same));

    let listed = surgbench(&["diff", &a, &b]);
    assert_eq!(
        listed.status.code(),
        Some(0),
        "without the flag a regression is listed only"
    );
    let out = text(&listed);
    assert!(
        out.contains("tip_error_rel*") && out.contains("+10.000%") && out.contains("WORSE"),
        "{out}"
    );
    let failed = surgbench(&["diff", &a, &b, "--fail-on-regression"]);
    assert_eq!(failed.status.code(), Some(1), "{}", text(&failed));
    // 10 % is within a 20 % tolerance.
    let tol = surgbench(&["diff", &a, &b, "--fail-on-regression", "--tolerance", "0.2"]);
    assert_eq!(tol.status.code(), Some(0), "{}", text(&tol));
    // The reverse direction is an improvement, not a regression.
    let better = surgbench(&["diff", &b, &a, "--fail-on-regression"]);
    assert_eq!(better.status.code(), Some(0), "{}", text(&better));
    assert!(text(&better).contains("better"));

    let slow = report(&t.path().join("slow"), 1e-2, 2.0);
    let timed = surgbench(&["diff", &a, &slow, "--fail-on-regression"]);
    assert_eq!(
        timed.status.code(),
        Some(1),
        "2x the time is past 25 %: {}",
        text(&timed)
    );
    let errors_only = surgbench(&["diff", &a, &slow, "--fail-on-regression", "--errors-only"]);
    assert_eq!(errors_only.status.code(), Some(0), "{}", text(&errors_only));

    let missing = surgbench(&["diff", &a, "/nonexistent/report"]);
    assert_eq!(missing.status.code(), Some(2), "{}", text(&missing));
    let neg = surgbench(&["diff", &a, &b, "--tolerance=-1"]);
    assert_eq!(neg.status.code(), Some(2), "{}", text(&neg));
    assert!(
        text(&neg).contains("--tolerance must be a number >= 0"),
        "{}",
        text(&neg)
    );
    let garbage = t.path().join("garbage.csv");
    std::fs::write(&garbage, "not,a,report\n1,2,3\n").unwrap();
    let bad = surgbench(&["diff", &a, garbage.to_str().unwrap()]);
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad));
}

/// The gate refuses without a baseline, records one on --update (timings
/// blanked), passes an equal report, fails a worse one and leaves the
/// baseline as it was.
#[test]
fn accuracy_gate_records_judges_and_keeps_its_baseline() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("baselines");
    let dir_s = dir.to_str().unwrap();
    let a = report(&t.path().join("a"), 1e-2, 1.0);
    let none = surgbench(&["accuracy-gate", &a, "--baseline-dir", dir_s]);
    assert_eq!(none.status.code(), Some(1), "{}", text(&none));
    assert!(
        text(&none).contains("no accuracy baseline for this CPU"),
        "{}",
        text(&none)
    );

    let up = surgbench(&["accuracy-gate", &a, "--baseline-dir", dir_s, "--update"]);
    assert_eq!(up.status.code(), Some(0), "{}", text(&up));
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    assert_eq!(files.len(), 1, "one baseline file, no temporary left: {files:?}");
    let recorded = read_results_csv(&files[0]).unwrap();
    assert_eq!(recorded.len(), 2);
    assert!(
        recorded.iter().all(|r| r.ms_per_step_median.is_none()),
        "timings are not kept"
    );
    let before = std::fs::read(&files[0]).unwrap();

    // Slower but equally accurate: the accuracy gate does not judge time.
    let slow = report(&t.path().join("slow"), 1e-2, 3.0);
    let pass = surgbench(&["accuracy-gate", &slow, "--baseline-dir", dir_s]);
    assert_eq!(pass.status.code(), Some(0), "{}", text(&pass));
    assert!(
        text(&pass).contains("accuracy gate passed (2 points"),
        "{}",
        text(&pass)
    );

    let worse = report(&t.path().join("worse"), 1e-2 * (1.0 + 1e-6), 1.0);
    let fail = surgbench(&["accuracy-gate", &worse, "--baseline-dir", dir_s]);
    assert_eq!(
        fail.status.code(),
        Some(1),
        "1e-6 relative is past round-off: {}",
        text(&fail)
    );
    assert!(text(&fail).contains("--update"), "{}", text(&fail));
    assert_eq!(
        std::fs::read(&files[0]).unwrap(),
        before,
        "a failed gate leaves the baseline"
    );
}

/// Two runs of the same comparison by the same binary: every error equal
/// (the premise of the accuracy gate).
#[test]
fn reruns_diff_as_identical() {
    let t = tempfile::tempdir().unwrap();
    let cmp = t.path().join("one.toml");
    std::fs::write(
        &cmp,
        "name = \"one\"\nmodels = [\"der\", \"pbd-rod\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nquick_sweep = { segments = [10] }\n",
    )
    .unwrap();
    let dirs: Vec<String> = ["r1", "r2"]
        .iter()
        .map(|d| {
            let out = t.path().join(d);
            let o = quick_run(&cmp, &out, &[]);
            assert_eq!(o.status.code(), Some(0), "{}", text(&o));
            out.to_str().unwrap().to_string()
        })
        .collect();
    let d = surgbench(&["diff", &dirs[0], &dirs[1], "--errors-only", "--fail-on-regression"]);
    assert_eq!(d.status.code(), Some(0), "{}", text(&d));
    assert!(text(&d).contains("2 points in both: 2 same"), "{}", text(&d));
}
