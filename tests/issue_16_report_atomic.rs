//! Issue 16, item 3: `surgbench report DIR` was not atomic. With a
//! malformed `haptic.csv` it exited 2 after redrawing the plots, leaving
//! pages and plots disagreeing; on a full disk it deleted every plot first
//! and left an `index.html` pointing at missing files.
//!
//! Now the report is rendered into a temporary sibling of DIR and moved
//! into place when complete: a failure leaves every file of DIR byte for
//! byte as it was and no temporary folder beside it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::snapshot;

fn surgbench() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_surgbench"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// A real report (one DER run on the cantilever) in `parent/report`.
fn report_dir(parent: &Path) -> PathBuf {
    let cmp = parent.join("one.toml");
    std::fs::write(
        &cmp,
        "name = \"one\"\nmodels = [\"der\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nsweep = { segments = [10] }\n",
    )
    .unwrap();
    let out = parent.join("report");
    let o = surgbench()
        .arg("run")
        .arg(&cmp)
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

/// Marks the report's plots as an earlier render's (other bytes, one plot
/// the current rows would not draw), so a failed `report` that redrew or
/// removed them shows in a snapshot.
fn mark_earlier_plots(dir: &Path) {
    let plots = dir.join("plots");
    for e in std::fs::read_dir(&plots).unwrap().flatten() {
        let mut bytes = std::fs::read(e.path()).unwrap();
        bytes.extend_from_slice(b"\n<!-- earlier render -->\n");
        std::fs::write(e.path(), bytes).unwrap();
    }
    std::fs::write(plots.join("earlier-pareto.svg"), "<svg/>").unwrap();
}

fn report(dir: &Path) -> Output {
    surgbench().arg("report").arg(dir).output().unwrap()
}

/// Names in `parent` other than `keep`: temporary or old folders left behind.
fn leftovers(parent: &Path, keep: &[&str]) -> Vec<String> {
    std::fs::read_dir(parent)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect()
}

/// `surgbench report` of the report in `tmp/report` after `spoil` changed
/// it and its plots were marked as an earlier render's: it exits `code`
/// with a message naming `needle`, and the folder is byte for byte as it
/// was, with nothing left beside it.
fn failed_report_changes_nothing(spoil: impl FnOnce(&Path), code: i32, needle: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = report_dir(tmp.path());
    spoil(&dir);
    mark_earlier_plots(&dir);
    let before = snapshot(&dir);
    assert!(
        before.keys().any(|p| p.starts_with("plots")) && before.contains_key(Path::new("index.html")),
        "the report has plots and pages to lose: {:?}",
        before.keys()
    );
    let o = report(&dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(code), "stderr: {err}");
    assert!(err.contains(needle), "the error names `{needle}`: {err}");
    assert!(snapshot(&dir) == before, "a failed `report` changed the folder");
    assert_eq!(leftovers(tmp.path(), &["one.toml", "report"]), Vec::<String>::new());
}

#[test]
fn a_malformed_haptic_csv_leaves_the_report_byte_identical() {
    let spoil = |dir: &Path| std::fs::write(dir.join("haptic.csv"), "model,scenario\nder,arch-insertion\n").unwrap();
    failed_report_changes_nothing(spoil, 2, "haptic.csv");
}

/// A failure while rendering, after the plots are drawn (here `report.md`
/// is a folder of the user's, which the page cannot replace), is a runtime
/// error that also leaves everything as it was.
#[test]
fn a_failure_while_rendering_leaves_the_report_byte_identical() {
    let spoil = |dir: &Path| {
        std::fs::remove_file(dir.join("report.md")).unwrap();
        std::fs::create_dir(dir.join("report.md")).unwrap();
        std::fs::write(dir.join("report.md/draft.txt"), "draft\n").unwrap();
    };
    failed_report_changes_nothing(spoil, 1, "report.md");
}

/// A successful re-render replaces pages and plots (a stale plot goes),
/// and keeps everything else in the folder: the data, the runs, the
/// marker, a file of the user's.
#[test]
fn a_rerender_keeps_every_other_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = report_dir(tmp.path());
    std::fs::write(dir.join("plots/stale-pareto.svg"), "<svg/>").unwrap();
    std::fs::write(dir.join("notes.txt"), "my notes\n").unwrap();
    std::fs::write(dir.join("index.html"), "old page").unwrap();
    let before = snapshot(&dir);
    let o = report(&dir);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let after = snapshot(&dir);
    for (path, bytes) in &before {
        let rendered = path.starts_with("plots") || path == Path::new("index.html") || path == Path::new("report.md");
        if !rendered {
            assert_eq!(after.get(path), Some(bytes), "{} changed or went", path.display());
        }
    }
    assert!(
        !after.contains_key(Path::new("plots/stale-pareto.svg")),
        "stale plot kept"
    );
    assert_ne!(after[Path::new("index.html")], b"old page", "the page was not rendered");
    assert!(after.keys().any(|p| p.extension().is_some_and(|e| e == "png")));
    assert_eq!(leftovers(tmp.path(), &["one.toml", "report"]), Vec::<String>::new());
}
