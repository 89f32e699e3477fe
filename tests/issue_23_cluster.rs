//! Issue 23: sharded runs through the `surgbench` binary. A shard killed
//! halfway (SIGKILL, as a node failure or a scheduler's time limit) and run
//! again finishes without redoing its finished points; shards read their
//! index from an array job's variables; a sharded run never takes over a
//! folder that is not a sharded run's; merge names missing points (exit 1
//! unless --partial) and refuses folders of other commits or comparisons
//! (exit 2 unless --allow-mixed).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Every wait here ends by then; the runs take well under a second, the
/// hanging one its comparison's 4 s limit.
const HARD_LIMIT: Duration = Duration::from_secs(120);

fn surgbench() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_surgbench"));
    c.env("SURGBENCH_FAULTY_MODELS", "1")
        .env("RUST_BACKTRACE", "0")
        .env("SURGBENCH_COMMIT", "c0ffee");
    for (var, count) in surgbench_comparisons::plan::INDEX_VARS {
        c.env_remove(var);
        if let Some(v) = count {
            c.env_remove(v);
        }
    }
    c
}

/// `args` run to completion: (exit code, stdout, stderr).
fn run(mut cmd: Command, args: &[&str]) -> (i32, String, String) {
    cmd.args(args);
    let o = common::output_within(cmd, HARD_LIMIT, &format!("surgbench {args:?}"));
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A comparison of the DER cantilever at `segments`, written to `dir/name.toml`,
/// plus `extra` TOML.
fn comparison(dir: &Path, name: &str, segments: &str, extra: &str) -> PathBuf {
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(
        &p,
        format!(
            "name = \"{name}\"\nmodels = [\"der\"]\ntimeout_s = 4\n[[scenario]]\nid = \"cantilever-gravity\"\n\
             sweep = {{ segments = [{segments}] }}\n{extra}"
        ),
    )
    .unwrap();
    p
}

/// The point files of a sharded run's folder, by name, with their bytes
/// (none before the shard made its `points/` folder).
fn points(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let p = dir.join("points");
    if p.is_dir() {
        common::snapshot(&p)
    } else {
        Default::default()
    }
}

/// A shard killed with SIGKILL while its last point (a hanging model) runs
/// leaves the points it finished; run again, it skips them (their files
/// keep their bytes) and runs only the rest; merge then has every point.
#[test]
fn killed_shard_resumes_without_redoing_finished_points() {
    let tmp = tempfile::tempdir().unwrap();
    let c = comparison(
        tmp.path(),
        "resume",
        "8, 10, 12",
        "[scenario.models.faulty-hang]\nsweep = { segments = [10] }\n",
    );
    let text = std::fs::read_to_string(&c).unwrap();
    std::fs::write(&c, text.replace("[\"der\"]", "[\"der\", \"faulty-hang\"]")).unwrap();
    let sweep = tmp.path().join("sweep");
    let mut cmd = surgbench();
    cmd.args(["run", c.to_str().unwrap(), "--shard", "0/1", "--out"])
        .arg(&sweep)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    let mut child = cmd.spawn().unwrap();
    // The three DER points come first in the plan; the hanging one after.
    let start = Instant::now();
    while points(&sweep).len() < 3 {
        assert!(
            start.elapsed() < HARD_LIMIT,
            "the shard never finished its first points"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(200));
    child.kill().unwrap();
    child.wait().unwrap();
    let before = points(&sweep);
    assert_eq!(before.len(), 3, "killed in the hanging point: {:?}", before.keys());

    let (code, out, err) = run(
        surgbench(),
        &[
            "run",
            c.to_str().unwrap(),
            "--shard",
            "0/1",
            "--out",
            sweep.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("4 points, 3 finished earlier and skipped, 1 run"), "{out}");
    let after = points(&sweep);
    assert_eq!(after.len(), 4, "{:?}", after.keys());
    for (name, bytes) in &before {
        assert!(after.get(name) == Some(bytes), "{} was written again", name.display());
    }
    let report = tmp.path().join("report");
    let (code, _, err) = run(
        surgbench(),
        &["merge", sweep.to_str().unwrap(), "--out", report.to_str().unwrap()],
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("1 points failed or timed out") && err.contains("faulty-hang"),
        "{err}"
    );
    let rows = surgbench_reports::read_results_csv(&report.join("results.csv")).unwrap();
    assert_eq!(rows.len(), 4);
    assert_eq!(rows[3].status, surgbench_reports::Status::Timeout, "{:?}", rows[3]);
    assert!(rows.iter().all(|r| !r.host.is_empty()), "every row names its host");
}

/// Two shards from the Slurm array variables, then merge: every point once,
/// in the comparison's order, with the same error columns as an unsharded
/// run. Without a count variable (an Indexed Job), --shards gives it.
#[test]
fn array_index_variables_pick_the_shard() {
    let tmp = tempfile::tempdir().unwrap();
    let c = comparison(tmp.path(), "arr", "6, 8, 10, 12, 14", "");
    let sweep = tmp.path().join("sweep");
    for k in ["0", "1"] {
        let mut cmd = surgbench();
        cmd.env("SLURM_ARRAY_TASK_ID", k).env("SLURM_ARRAY_TASK_COUNT", "2");
        let (code, out, err) = run(cmd, &["run", c.to_str().unwrap(), "--out", sweep.to_str().unwrap()]);
        assert_eq!(code, 0, "{err}");
        assert!(
            out.contains(&format!(
                "shard {k}/2 (from SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT)"
            )),
            "{out}"
        );
    }
    let mut cmd = surgbench();
    cmd.env("JOB_COMPLETION_INDEX", "0");
    let (code, _, err) = run(cmd, &["run", c.to_str().unwrap(), "--out", sweep.to_str().unwrap()]);
    assert!(code == 0, "the plan in --out gives the count: {err}");
    let mut cmd = surgbench();
    cmd.env("JOB_COMPLETION_INDEX", "0");
    let fresh = tmp.path().join("fresh");
    let (code, _, err) = run(cmd, &["run", c.to_str().unwrap(), "--out", fresh.to_str().unwrap()]);
    assert_eq!(code, 2, "no count anywhere: {err}");
    assert!(err.contains("--shards"), "{err}");

    let merged = tmp.path().join("merged");
    let (code, _, err) = run(
        surgbench(),
        &["merge", sweep.to_str().unwrap(), "--out", merged.to_str().unwrap()],
    );
    assert_eq!(code, 0, "{err}");
    let local = tmp.path().join("local");
    let (code, _, err) = run(
        surgbench(),
        &["run", c.to_str().unwrap(), "--quiet", "--out", local.to_str().unwrap()],
    );
    assert_eq!(code, 0, "{err}");
    let m = surgbench_reports::read_results_csv(&merged.join("results.csv")).unwrap();
    let l = surgbench_reports::read_results_csv(&local.join("results.csv")).unwrap();
    let key = |r: &surgbench_reports::ResultRow| (r.fidelity.clone(), r.status, r.metrics.clone(), r.steps);
    assert_eq!(
        m.iter().map(key).collect::<Vec<_>>(),
        l.iter().map(key).collect::<Vec<_>>()
    );
}

/// A sharded run refuses a folder that is a report of an unsharded run
/// (or anyone's non-empty folder) and touches nothing in it.
#[test]
fn sharded_run_never_takes_over_another_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let c = comparison(tmp.path(), "own", "8", "");
    let report = tmp.path().join("report");
    let (code, _, err) = run(
        surgbench(),
        &["run", c.to_str().unwrap(), "--quiet", "--out", report.to_str().unwrap()],
    );
    assert_eq!(code, 0, "{err}");
    let mine = tmp.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("thesis.tex"), "thesis").unwrap();
    for dir in [&report, &mine] {
        let before = common::snapshot(dir);
        let (code, _, err) = run(
            surgbench(),
            &[
                "run",
                c.to_str().unwrap(),
                "--shard",
                "0/2",
                "--out",
                dir.to_str().unwrap(),
            ],
        );
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("choose another --out"), "{err}");
        assert!(common::snapshot(dir) == before, "{} changed", dir.display());
    }
}

/// Merge with a shard not run: exit 1 naming the missing points, nothing
/// written; --partial writes the report of the points there are. Folders
/// of two commits or two comparisons: exit 2 unless --allow-mixed.
#[test]
fn merge_names_missing_points_and_refuses_mixed_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let c = comparison(tmp.path(), "mix", "6, 8, 10, 12", "");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (a, b, report) = (tmp.path().join("a"), tmp.path().join("b"), tmp.path().join("report"));
    let (code, _, err) = run(surgbench(), &["run", &s(&c), "--shard", "0/2", "--out", &s(&a)]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(surgbench(), &["merge", &s(&a), "--out", &s(&report)]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("points are missing") && err.contains("shard 1: cantilever-gravity / der"),
        "{err}"
    );
    assert!(!report.exists(), "a refused merge writes nothing");
    let (code, _, err) = run(surgbench(), &["merge", &s(&a), "--partial", "--out", &s(&report)]);
    assert_eq!(code, 0, "{err}");

    // Shard 1 of the same plan, built at another commit, in another folder.
    let mut other = surgbench();
    other.env("SURGBENCH_COMMIT", "decaf");
    let (code, _, err) = run(other, &["run", &s(&c), "--shard", "1/2", "--out", &s(&b)]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(surgbench(), &["merge", &s(&a), &s(&b), "--out", &s(&report)]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("commit: c0ffee here, decaf there") && err.contains("--allow-mixed"),
        "{err}"
    );
    let (code, _, err) = run(
        surgbench(),
        &[
            "merge",
            &s(&a),
            &s(&b),
            "--allow-mixed",
            "--force",
            "--out",
            &s(&report),
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        surgbench_reports::read_results_csv(&report.join("results.csv"))
            .unwrap()
            .len(),
        4
    );

    // Another comparison's shard.
    let other_c = comparison(tmp.path(), "other", "6, 8, 10, 12", "");
    let d = tmp.path().join("d");
    let (code, _, err) = run(surgbench(), &["run", &s(&other_c), "--shard", "1/2", "--out", &s(&d)]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(surgbench(), &["merge", &s(&a), &s(&d), "--out", &s(&report)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("comparison: mix here, other there"), "{err}");
}

/// `--budget-ms` is part of a sharded run's plan: the merged report's
/// verdicts name the budgets the shards ran with, and a shard asking for
/// others is refused as another run.
#[test]
fn the_plan_carries_the_time_budgets_to_the_merged_report() {
    let tmp = tempfile::tempdir().unwrap();
    let c = comparison(tmp.path(), "bud", "6, 8", "");
    let (c, sweep) = (c.to_str().unwrap(), tmp.path().join("sweep"));
    let sw = sweep.to_str().unwrap();
    let (code, _, err) = run(
        surgbench(),
        &["plan", c, "--shards", "2", "--budget-ms", "50,2", "--out", sw],
    );
    assert_eq!(code, 0, "{err}");
    for k in ["0/2", "1/2"] {
        let (code, _, err) = run(
            surgbench(),
            &["run", c, "--shard", k, "--budget-ms", "2,50", "--quiet", "--out", sw],
        );
        assert_eq!(code, 0, "{err}");
    }
    let (code, _, err) = run(surgbench(), &["run", c, "--shard", "0/2", "--quiet", "--out", sw]);
    assert_eq!(code, 2, "default budgets are another run: {err}");
    assert!(err.contains("budgets_ms"), "{err}");
    let merged = tmp.path().join("merged");
    let (code, _, err) = run(surgbench(), &["merge", sw, "--out", merged.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let info = surgbench_reports::read_run_info(&merged.join("summary.json")).unwrap();
    assert_eq!(info.budgets_ms, vec![2.0, 50.0]);
}
