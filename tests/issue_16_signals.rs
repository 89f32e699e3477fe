//! Issue 16, item 5: orphaned children. `kill -TERM` (or `-INT` to the
//! parent only) of `surgbench run` killed the parent at once: its `run-one`
//! child went on under PID 1 (forever, for a hanging model: the wall-clock
//! limit lives in the parent), and the `.OUT.tmp-PID` folder stayed beside
//! `--out`. `kill -KILL` of the parent orphaned the child the same way;
//! `surgbench gate` interrupted left valgrind running and its callgrind
//! files behind; `run-one` interrupted died at once.
//!
//! Now the parent catches SIGINT/SIGTERM, kills and reaps the running
//! child, removes its temporary folder and exits 130 / 143; an earlier
//! report at `--out` is left byte for byte as it was. A child whose parent
//! was killed by SIGKILL ends itself; the next run into the same `--out`
//! removes the killed parent's temporary folder. `gate` and `run-one`
//! interrupted stop what they run, leave no temporary file and write
//! nothing, exiting 130 / 143.

use std::collections::BTreeMap;
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
            "the surgbench process did not exit after the signal"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Wait until `parent` has started a child whose command line (mentioning
/// `root`) contains `what`, past its exec; returns the child's pid.
fn wait_for_child(parent: &mut Child, root: &str, what: &str) -> u32 {
    let start = Instant::now();
    loop {
        let kid = processes_mentioning(root)
            .into_iter()
            .find(|(_, ppid, cmd)| *ppid == parent.id() && cmd.contains(what));
        if let Some((pid, ..)) = kid {
            return pid;
        }
        assert!(
            parent.try_wait().unwrap().is_none(),
            "the parent ended before it started its child `{what}`"
        );
        assert!(start.elapsed() < HARD_LIMIT, "no child `{what}` appeared");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Names of the temporary entries (`.NAME.tmp-PID`) in `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.contains(".tmp-"))
        .collect();
    names.sort();
    names
}

/// Whether process `pid` catches signal number `signal` (its bit in the
/// `SigCgt` mask of /proc/PID/status): from then on the signal reaches
/// surgbench's handler instead of killing the process outright.
fn catches(pid: u32, signal: u32) -> bool {
    let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) else {
        return false;
    };
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .and_then(|m| u64::from_str_radix(m.trim(), 16).ok())
        .is_some_and(|mask| mask & (1 << (signal - 1)) != 0)
}

/// Send `kill -SIGNAL` to `pid`.
fn send(signal: &str, pid: u32) {
    let sent = Command::new("kill")
        .args([&format!("-{signal}"), &pid.to_string()])
        .status()
        .unwrap();
    assert!(sent.success(), "kill -{signal} {pid} failed");
}

/// Run `surgbench run COMPARISON --out OUT --quiet` to completion.
fn run_to_completion(comparison: &Path, out: &Path) {
    let mut cmd = surgbench();
    cmd.arg("run").arg(comparison).arg("--out").arg(out).arg("--quiet");
    let r = common::output_within(cmd, HARD_LIMIT, "surgbench run");
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

/// Send `signal` to `child` and check what every interrupted command
/// leaves: exit `code` with "interrupted by signal" on stderr, no process
/// mentioning `root`, no temporary folder in `tmp`, and `out` as `before`.
fn signal_and_check(
    child: &mut Child,
    signal: &str,
    code: i32,
    root: &str,
    tmp: &Path,
    out: &Path,
    before: &BTreeMap<PathBuf, Vec<u8>>,
) {
    send(signal, child.id());
    let status = wait_with_limit(child);
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(code), "SIG{signal}: {status:?}, stderr: {err}");
    assert!(err.contains("interrupted by signal"), "stderr: {err}");
    let left = processes_mentioning(root);
    assert!(left.is_empty(), "processes left after SIG{signal}: {left:?}");
    let temps = temporaries(tmp);
    assert!(temps.is_empty(), "temporary folders left after SIG{signal}: {temps:?}");
    assert!(snapshot(out) == *before, "--out changed after SIG{signal}");
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
    run_to_completion(&good, &out);
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
    wait_for_child(&mut parent, &root, " run-one ");

    signal_and_check(&mut parent, signal, code, &root, tmp.path(), &out, &before);
}

#[test]
fn sigterm_stops_the_child_and_removes_the_temporary_folder() {
    interrupted_run_cleans_up("TERM", 143);
}

#[test]
fn sigint_to_the_parent_only_stops_the_child_too() {
    interrupted_run_cleans_up("INT", 130);
}

/// `kill -KILL` of `surgbench run` while its child runs a hanging model:
/// the child sees its parent gone and ends itself, so no process is left
/// (the wait below is only a hard limit: it ends as soon as none is).
/// SIGKILL cannot be caught, so the killed parent's own `.report.tmp-PID`
/// folder necessarily stays (and only it: the child had nothing of its own
/// on disk); the next `run` into the same `--out` removes it, as the
/// process that made it is gone. The earlier report is untouched.
#[test]
fn sigkill_of_the_parent_ends_its_child_and_the_next_run_cleans_up() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().to_str().unwrap().to_string();
    let _reaper = Reaper(root.clone());
    let out = tmp.path().join("report");
    let good = comparison(tmp.path(), "good", "faulty-nonfinite");
    run_to_completion(&good, &out);
    let before = snapshot(&out);

    let hang = comparison(tmp.path(), "hang", "faulty-hang");
    let mut parent = surgbench()
        .arg("run")
        .arg(&hang)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--timeout", "600"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let parent_pid = parent.id();
    let child = wait_for_child(&mut parent, &root, " run-one ");
    send("KILL", parent_pid);
    let status = wait_with_limit(&mut parent);
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(9),
        "{status:?}"
    );

    let start = Instant::now();
    loop {
        let left = processes_mentioning(&root);
        if left.is_empty() {
            break;
        }
        assert!(
            start.elapsed() < HARD_LIMIT,
            "the orphaned run-one (pid {child}) did not end itself: {left:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let own = format!(".report.tmp-{parent_pid}");
    assert_eq!(temporaries(tmp.path()), vec![own.clone()], "beside --out after SIGKILL");
    let nested: Vec<_> = snapshot(&tmp.path().join(&own))
        .into_keys()
        .filter(|p| p.to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(nested.is_empty(), "the child left temporary files: {nested:?}");
    assert!(snapshot(&out) == before, "the earlier report changed after SIGKILL");

    run_to_completion(&good, &out);
    let temps = temporaries(tmp.path());
    assert!(temps.is_empty(), "the next run left the stale folder: {temps:?}");
    assert!(out.join("results.csv").is_file());
}

/// `surgbench gate --update` sent SIGTERM while valgrind counts a hanging
/// workload: the gate kills and reaps valgrind, removes the callgrind files
/// from the temporary folder (`TMPDIR`, a folder of this test's), leaves
/// the baseline byte for byte as it was with no temporary file beside it,
/// and exits 143. Skipped, saying so, where valgrind is not installed (CI
/// installs it).
#[test]
fn sigterm_to_gate_stops_valgrind_and_writes_nothing() {
    if Command::new("valgrind").arg("--version").output().is_err() {
        eprintln!("skipped: valgrind is not installed (the CI installs it with apt)");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().to_str().unwrap().to_string();
    let _reaper = Reaper(root.clone());
    let tmpdir = tmp.path().join("tmpdir");
    std::fs::create_dir(&tmpdir).unwrap();
    let config = tmp.path().join("gate.toml");
    std::fs::write(
        &config,
        "margin = 0.05\n[[workload]]\nmodel = \"faulty-hang\"\nscenario = \"cantilever-gravity\"\nsteps = 10\n",
    )
    .unwrap();
    let baseline = tmp.path().join("baseline.json");
    let before =
        "{\n  \"by_cpu\": {\n    \"Another CPU\": {\n      \"der/cantilever-gravity/\": 1000.0\n    }\n  }\n}\n";
    std::fs::write(&baseline, before).unwrap();

    let mut gate = surgbench()
        .arg("gate")
        .arg("--update")
        .arg("--config")
        .arg(&config)
        .arg("--baseline")
        .arg(&baseline)
        .env("TMPDIR", &tmpdir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // valgrind's command line names its output file in TMPDIR.
    wait_for_child(&mut gate, &root, "callgrind");
    send("TERM", gate.id());
    let status = wait_with_limit(&mut gate);
    let mut err = String::new();
    std::io::Read::read_to_string(gate.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(143), "{status:?}, stderr: {err}");
    assert!(err.contains("interrupted by signal 15"), "stderr: {err}");

    let left = processes_mentioning(&root);
    assert!(left.is_empty(), "processes left after SIGTERM to gate: {left:?}");
    let files: Vec<_> = snapshot(&tmpdir).into_keys().collect();
    assert!(files.is_empty(), "files left in TMPDIR: {files:?}");
    let temps = temporaries(tmp.path());
    assert!(temps.is_empty(), "temporary files left beside the baseline: {temps:?}");
    assert_eq!(
        std::fs::read_to_string(&baseline).unwrap(),
        before,
        "the baseline changed"
    );
}

/// An earlier run at `--out`, then `surgbench run-one` of a hanging model
/// into the same `--out`, sent `signal` once it catches it: it exits
/// `code` although its step never returns, `--out` is byte for byte as it
/// was and no temporary sibling is left.
fn interrupted_run_one_cleans_up(signal: &str, number: u32, code: i32) {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().to_str().unwrap().to_string();
    let _reaper = Reaper(root.clone());
    let out = tmp.path().join("run");
    let run_one = |model: &str| {
        let mut c = surgbench();
        c.args(["run-one", "--scenario", "cantilever-gravity", "--model", model])
            .args(["--fidelity", "segments=10", "--quiet", "--out"])
            .arg(&out);
        c
    };
    let r = common::output_within(run_one("faulty-nonfinite"), HARD_LIMIT, "run-one");
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let before = snapshot(&out);
    assert!(before.contains_key(Path::new("summary.json")), "{before:?}");

    let mut proc = run_one("faulty-hang")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !catches(proc.id(), number) {
        assert!(proc.try_wait().unwrap().is_none(), "run-one ended before the signal");
        assert!(start.elapsed() < HARD_LIMIT, "run-one never caught SIG{signal}");
        std::thread::sleep(Duration::from_millis(10));
    }
    signal_and_check(&mut proc, signal, code, &root, tmp.path(), &out, &before);
}

#[test]
fn sigterm_stops_a_hanging_run_one_and_leaves_out_as_it_was() {
    interrupted_run_one_cleans_up("TERM", 15, 143);
}

#[test]
fn sigint_stops_a_hanging_run_one_and_leaves_out_as_it_was() {
    interrupted_run_one_cleans_up("INT", 2, 130);
}
