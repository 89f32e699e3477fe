//! Issue 16, item 4: `gate --update` lost baselines. A baseline file with
//! one non-UTF-8 byte (or an unreadable one, or a folder) was read as
//! empty and rewritten in place with this CPU's counts alone, dropping the
//! other CPUs'.
//!
//! Now such a baseline is a usage error (exit 2) naming the file, raised
//! before anything is measured, and nothing is written; a new baseline is
//! written to a temporary file in the same folder and renamed over the old.
//! The CLI cases fail before valgrind runs; the write path is tested on the
//! library functions `gate` itself calls.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use surgbench_comparisons::gate::{Baseline, load_baseline, save_baseline};

mod common;
use common::snapshot;

/// Two CPUs' counts, as a project with two kinds of CI machine keeps them.
const TWO_CPUS: &str = r#"{
  "by_cpu": {
    "AMD EPYC 7B13": { "der/cantilever-tip-load/segments=100": 1234.0 },
    "Intel Xeon": { "der/cantilever-tip-load/segments=100": 1300.0 }
  }
}
"#;

/// `surgbench gate --update --baseline <baseline>` with the project's gate
/// configuration. A gate that measured would run valgrind for minutes: the
/// limit makes that a failure of this test, not a hang.
fn gate_update(baseline: &Path) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_surgbench"));
    cmd.args(["gate", "--update", "--config"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/gate.toml"))
        .arg("--baseline")
        .arg(baseline);
    common::output_within(cmd, Duration::from_secs(30), "surgbench gate --update")
}

/// Exit 2 before measuring, naming the file and `what`.
fn assert_refused(o: &Output, baseline: &Path, what: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    assert!(
        err.contains(&baseline.display().to_string()) && err.contains(what),
        "the error names the file and `{what}`: {err}"
    );
    assert!(
        o.stdout.is_empty(),
        "nothing measured: {}",
        String::from_utf8_lossy(&o.stdout)
    );
}

#[test]
fn a_non_utf8_baseline_is_refused_and_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("gate-baseline.json");
    let mut bytes = TWO_CPUS.as_bytes().to_vec();
    let at = TWO_CPUS.find("Xeon").unwrap();
    bytes[at] = 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let before = snapshot(tmp.path());
    assert_refused(&gate_update(&path), &path, "not UTF-8");
    assert!(snapshot(tmp.path()) == before, "the baseline or its folder changed");
}

#[test]
fn a_folder_as_baseline_is_refused_and_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("gate-baseline.json");
    std::fs::create_dir(&path).unwrap();
    std::fs::write(path.join("keep.txt"), "mine\n").unwrap();
    let before = snapshot(tmp.path());
    assert_refused(&gate_update(&path), &path, "cannot read it");
    assert!(path.is_dir(), "the folder is still a folder");
    assert!(snapshot(tmp.path()) == before, "the folder changed");
}

/// A baseline that cannot be opened (here its parent is a file) is refused
/// too, not read as empty.
#[test]
fn an_unreadable_baseline_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("file"), "x").unwrap();
    let path = tmp.path().join("file/gate-baseline.json");
    assert_refused(&gate_update(&path), &path, "cannot read it");
    assert_eq!(std::fs::read_to_string(tmp.path().join("file")).unwrap(), "x");
}

/// What `gate --update` does once it has measured: load, add this CPU's
/// counts, save. The other CPUs' counts survive, the file is replaced
/// through a temporary file that does not stay behind, and an absent
/// baseline loads as empty.
#[test]
fn update_keeps_the_other_cpus_and_leaves_no_temporary_file() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("gate-baseline.json");
    assert!(load_baseline(&path).unwrap().by_cpu.is_empty(), "absent is empty");
    std::fs::write(&path, TWO_CPUS).unwrap();
    let mut b: Baseline = load_baseline(&path).unwrap();
    b.by_cpu
        .entry("Intel Xeon".into())
        .or_default()
        .insert("der/cantilever-tip-load/segments=100".into(), 1310.0);
    save_baseline(&path, &b).unwrap();
    let back = load_baseline(&path).unwrap();
    assert_eq!(
        back.by_cpu["AMD EPYC 7B13"]["der/cantilever-tip-load/segments=100"],
        1234.0
    );
    assert_eq!(
        back.by_cpu["Intel Xeon"]["der/cantilever-tip-load/segments=100"],
        1310.0
    );
    let names: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["gate-baseline.json"], "no temporary file left");
}
