//! Issue 16, item 5: orphaned children. `kill -TERM` (or `-INT` to the
//! parent only) of `surgbench run` killed the parent at once: its `run-one`
//! child went on under PID 1 (forever, for a hanging model: the wall-clock
//! limit lives in the parent), and the `.OUT.tmp-PID` folder stayed beside
//! `--out`.
//!
//! Now the parent catches SIGINT/SIGTERM, kills and reaps the running
//! child, removes its temporary folder and exits 130 / 143; an earlier
//! report at `--out` is left byte for byte as it was.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::snapshot;

/// Every wait in this file ends by then: the runs here take well under a
/// second each, so a minute only ever runs out when something hangs.
const HARD_LIMIT: Duration = Duration::from_secs(60);

fn surgbench() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_surgbench"));
    c.env("SURGBENCH_FAULTY_MODELS", "1").env("RUST_BACKTRACE", "0");
    c
}

/// One-run comparison of `model` on the cantilever, at 10 segments.
fn comparison(dir: &Path, name: &str, model: &str) -> PathBuf {
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(
        &p,
        format!(
            "name = \"{name}\"\nmodels = [\"{model}\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nsweep = {{ segments = [10] }}\n"
        ),
    )
    .unwrap();
    p
}

/// Live processes whose command line mentions `needle`: pid, parent pid
/// and command line (zombies, already dead and waiting to be reaped, are
/// left out).
fn processes_mentioning(needle: &str) -> Vec<(u32, u32, String)> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmd) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
        if !cmd.contains(needle) {
            continue;
        }
        // /proc/PID/stat: "pid (comm) state ppid ..."; comm may hold spaces.
        let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
            continue;
        };
        let rest: Vec<&str> = stat[stat.rfind(')').unwrap() + 1..].split_whitespace().collect();
        if rest[0] != "Z" {
            found.push((pid, rest[1].parse().unwrap(), cmd));
        }
    }
    found
}

/// Kills whatever a failed test left running (by pid, those that mention
/// this test's own temporary folder).
struct Reaper(String);

impl Drop for Reaper {
    fn drop(&mut self) {
        for (pid, ..) in processes_mentioning(&self.0) {
            let _ = Command::new("kill").args(["-KILL", &pid.to_string()]).status();
        }
    }
}

fn wait_with_limit(child: &mut Child) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(
            start.elapsed() < HARD_LIMIT,
            "surgbench run did not exit after the signal"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// An earlier report at `--out`, then `surgbench run` of a hanging model
/// into the same `--out`, sent `signal` once its child runs: the parent
/// exits `code`, no process is left, no temporary folder, and the earlier
/// report is byte-identical.
fn interrupted_run_cleans_up(signal: &str, code: i32) {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().to_str().unwrap().to_string();
    let _reaper = Reaper(root.clone());
    let out = tmp.path().join("report");

    let good = comparison(tmp.path(), "good", "faulty-nonfinite");
    let r = surgbench()
        .arg("run")
        .arg(&good)
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let before = snapshot(&out);
    assert!(before.contains_key(Path::new("results.csv")), "{before:?}");

    let hang = comparison(tmp.path(), "hang", "faulty-hang");
    let mut parent = surgbench()
        .arg("run")
        .arg(&hang)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--timeout", "600"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the parent has started its `run-one` child (past exec:
    // its command line is run-one's).
    let start = Instant::now();
    loop {
        let kids = processes_mentioning(&root)
            .into_iter()
            .filter(|(_, ppid, cmd)| *ppid == parent.id() && cmd.contains(" run-one "))
            .count();
        if kids > 0 {
            break;
        }
        assert!(
            parent.try_wait().unwrap().is_none(),
            "surgbench run ended before it started its child"
        );
        assert!(start.elapsed() < HARD_LIMIT, "no run-one child appeared");
        std::thread::sleep(Duration::from_millis(10));
    }

    let sent = Command::new("kill")
        .args([&format!("-{signal}"), &parent.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success(), "kill -{signal} failed");
    let status = wait_with_limit(&mut parent);
    let mut err = String::new();
    std::io::Read::read_to_string(parent.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(code), "SIG{signal}: {status:?}, stderr: {err}");
    assert!(err.contains("interrupted by signal"), "stderr: {err}");

    let left = processes_mentioning(&root);
    assert!(left.is_empty(), "processes left after SIG{signal}: {left:?}");
    let temps: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.contains(".tmp-"))
        .collect();
    assert!(temps.is_empty(), "temporary folders left after SIG{signal}: {temps:?}");
    assert!(snapshot(&out) == before, "the earlier report changed after SIG{signal}");
}

#[test]
fn sigterm_stops_the_child_and_removes_the_temporary_folder() {
    interrupted_run_cleans_up("TERM", 143);
}

#[test]
fn sigint_to_the_parent_only_stops_the_child_too() {
    interrupted_run_cleans_up("INT", 130);
}
