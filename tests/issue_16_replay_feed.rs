//! Issue 16, item 6: `haptic --replay` skipped the feed-length check that
//! `run-one` makes (a vessel scenario refuses a push that takes the clamp
//! past the end of its straight). Replaying a session that feeds 1e6 m,
//! `surgbench haptic --model chainmail --scenario arch-insertion --duration
//! 0.03 --replay s.csv`, ran past 60 s.
//!
//! Now a replayed session is checked against the scenario's own limit
//! before the model is built: a usage error (exit 2, one line), nothing
//! written, in well under a second.

mod common;

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

/// The refusal takes milliseconds and the short valid replay a few seconds
/// on a loaded 2-core machine; the reproduction used to run past 60 s.
const LIMIT: Duration = Duration::from_secs(30);

/// `surgbench haptic` of the reproduction replaying `session`,
/// killed (and the test failed) past [`LIMIT`].
fn replay(dir: &Path, session: &str, extra: &[&str]) -> Output {
    let csv = dir.join("s.csv");
    std::fs::write(&csv, session).unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_surgbench"));
    cmd.args(["haptic", "--model", "chainmail", "--scenario", "arch-insertion"])
        .args(["--duration", "0.03", "--replay"])
        .arg(&csv)
        .args(extra);
    common::output_within(cmd, LIMIT, &format!("surgbench haptic --replay of {session:?}"))
}

#[test]
fn a_replay_feeding_past_the_vessel_is_a_usage_error() {
    let tmp = tempfile::tempdir().unwrap();
    let record = tmp.path().join("rec.csv");
    let o = replay(
        tmp.path(),
        "t,insertion,rotation\n0,1e6,0\n1,1e6,0\n",
        &["--record", record.to_str().unwrap()],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    assert_eq!(err.lines().count(), 1, "one line on stderr: {err}");
    assert!(
        err.contains("s.csv") && err.contains("at t=0 s") && err.contains("descending aorta"),
        "the message names the file, the key and the limit: {err}"
    );
    assert!(!record.exists(), "nothing is written on a usage error");
}

#[test]
fn a_replay_pulling_back_out_of_the_vessel_is_a_usage_error() {
    let tmp = tempfile::tempdir().unwrap();
    let o = replay(tmp.path(), "t,insertion,rotation\n0,0,0\n1,-1,0\n", &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    assert!(err.contains("at t=1 s") && err.contains("pulled back"), "{err}");
}

#[test]
fn a_replay_within_the_vessel_still_runs() {
    let tmp = tempfile::tempdir().unwrap();
    // 1 mm in 30 ms: well inside the descending aorta.
    let o = replay(tmp.path(), "t,insertion,rotation\n0,0,0\n0.03,0.001,0\n", &[]);
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("ticks"), "the loop's report is printed: {out}");
}
