//! Issue 16, item 1: `--out` deleted whatever it pointed at.
//! `mkdir -p mine && echo thesis > mine/thesis.tex && surgbench run-one
//! --scenario cantilever-gravity --model der --out mine` exited 0 and
//! thesis.tex was gone; an existing file became a directory.
//!
//! Now `run --out` and `run-one --out` replace only an absent or empty
//! folder or one of surgbench's own (marked by `.surgbench-output`); any
//! other folder only with `--force`; a plain file never. A refusal is exit
//! code 2 and touches nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `surgbench run-one` of the reproduction into `out`, plus `extra`.
fn run_one(out: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_surgbench"))
        .args(["run-one", "--scenario", "cantilever-gravity", "--model", "der"])
        .args(["--fidelity", "segments=10", "--quiet", "--out"])
        .arg(out)
        .args(extra)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("surgbench runs")
}

/// `surgbench run --quick` of a one-run comparison into `out`, plus `extra`.
fn run_batch(out: &Path, extra: &[&str]) -> Output {
    let dir = tempfile::tempdir().unwrap();
    let cmp = dir.path().join("one.toml");
    std::fs::write(
        &cmp,
        "name = \"one\"\nmodels = [\"der\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nquick_sweep = { segments = [10] }\n",
    )
    .unwrap();
    Command::new(env!("CARGO_BIN_EXE_surgbench"))
        .arg("run")
        .arg(&cmp)
        .args(["--quick", "--quiet", "--out"])
        .arg(out)
        .args(extra)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("surgbench runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit 2 with a message naming `needle`.
fn assert_refused(o: &Output, needle: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "expected exit 2, stderr: {err}");
    assert!(err.contains(needle), "stderr should mention `{needle}`: {err}");
}

/// The user folder `<dir>/mine` holding `thesis.tex` ("thesis\n").
fn user_folder(dir: &Path) -> PathBuf {
    let mine = dir.join("mine");
    std::fs::create_dir_all(&mine).unwrap();
    std::fs::write(mine.join("thesis.tex"), "thesis\n").unwrap();
    mine
}

#[test]
fn run_one_refuses_a_user_folder_and_keeps_the_thesis() {
    let tmp = tempfile::tempdir().unwrap();
    let mine = user_folder(tmp.path());
    assert_refused(&run_one(&mine, &[]), "--force");
    assert_eq!(std::fs::read_to_string(mine.join("thesis.tex")).unwrap(), "thesis\n");
    let names: Vec<_> = std::fs::read_dir(&mine)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["thesis.tex"], "nothing added to the user's folder");
    let siblings = std::fs::read_dir(tmp.path()).unwrap().count();
    assert_eq!(siblings, 1, "no temporary folder left beside it");
}

#[test]
fn run_refuses_a_user_folder_and_keeps_the_thesis() {
    let tmp = tempfile::tempdir().unwrap();
    let mine = user_folder(tmp.path());
    assert_refused(&run_batch(&mine, &[]), "--force");
    assert_eq!(std::fs::read_to_string(mine.join("thesis.tex")).unwrap(), "thesis\n");
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
}

#[test]
fn a_plain_file_is_never_replaced_even_with_force() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("notes.txt");
    std::fs::write(&file, "notes\n").unwrap();
    for extra in [&[][..], &["--force"][..]] {
        assert_refused(&run_one(&file, extra), "not a folder");
        assert_refused(&run_batch(&file, extra), "not a folder");
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "notes\n", "{extra:?}");
    }
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
}

#[test]
fn an_earlier_surgbench_run_folder_is_replaced() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let o = run_one(&out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join(".surgbench-output").is_file(), "the run folder is marked");
    std::fs::write(out.join("stale.txt"), "from before").unwrap();
    let o = run_one(&out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("summary.json").is_file());
    assert!(
        !out.join("stale.txt").exists(),
        "the earlier run is replaced as a whole"
    );
}

#[test]
fn an_earlier_surgbench_report_folder_is_replaced() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("report");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join(".surgbench-output"), "marker").unwrap();
    std::fs::write(out.join("stale.txt"), "from before").unwrap();
    let o = run_batch(&out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("results.csv").is_file() && out.join(".surgbench-output").is_file());
    assert!(
        !out.join("stale.txt").exists(),
        "the earlier report is replaced as a whole"
    );
}

#[test]
fn force_replaces_a_user_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let mine = user_folder(tmp.path());
    let o = run_one(&mine, &["--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(mine.join("summary.json").is_file());
    assert!(
        !mine.join("thesis.tex").exists(),
        "--force replaces the folder as a whole"
    );
}
