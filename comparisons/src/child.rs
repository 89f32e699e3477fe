//! Child processes that never outlive the process that waits for them.
//!
//! On the parent's side, [`spawn_with_limit`] starts a child and polls it
//! until it exits, its wall-clock limit passes, or a SIGINT/SIGTERM reaches
//! the parent ([`crate::interrupt`]); a child still running then is killed
//! and reaped. The batch runner (`run-one` and `haptic` jobs) and the gate
//! (valgrind) wait for their children this way.
//!
//! A parent killed by SIGKILL cannot do that. So the batch passes its pid
//! to each child in [`PARENT_PID_VAR`], and the child, once it calls
//! [`start_watchdog`], polls its parent pid every [`POLL`]: when that pid
//! changes (the parent died and the child was re-parented), it exits with
//! [`ORPHANED_EXIT_CODE`]. The same watchdog ends a process that installed
//! [`crate::interrupt`] with `128 + signal` once a signal arrives, even
//! while its main thread is stuck in a model's step. It never ends the
//! process while a [`staging`] guard lives, so a temporary folder being
//! written and moved into place is either moved or removed, never left.
//!
//! ```no_run
//! use surgbench_comparisons::child;
//! // In a child process of a batch (SURGBENCH_PARENT_PID set):
//! child::start_watchdog();
//! // ... simulate (the watchdog ends the process if the batch dies) ...
//! let _guard = child::staging();
//! // ... create a temporary folder, write it, move it into place ...
//! ```

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

/// Environment variable holding the pid of the batch that spawned a child;
/// set by the batch for every child, absent for a command run by hand.
pub const PARENT_PID_VAR: &str = "SURGBENCH_PARENT_PID";

/// Exit code of a child that ended itself because its parent died (a
/// runtime failure, like any other `1`; no one is left to read it, but
/// stderr says why).
pub const ORPHANED_EXIT_CODE: i32 = 1;

/// How often the watchdog looks at its parent pid and the signal flag.
pub const POLL: Duration = Duration::from_millis(100);

/// How the wait for a child ended.
#[derive(Debug)]
pub enum Waited {
    /// It exited (or was killed by someone else) with this status.
    Exited(std::process::ExitStatus),
    /// It was killed at the wall-clock limit (or could not be waited on).
    TimedOut,
    /// It was killed (or it ended) after this signal reached the parent.
    Interrupted(i32),
}

/// Spawn `cmd` with stdin and stdout closed and stderr to `err_path`, and
/// wait up to `timeout` s (`f64::INFINITY`: no limit), or until a
/// SIGINT/SIGTERM reaches this process ([`crate::interrupt`]); a child that
/// is not done by then is killed and waited for, so none outlives the
/// wait. A child that ends on its own while a signal is pending (a Ctrl-C
/// reaches the whole process group) counts as interrupted too. Returns how
/// it ended and the wall time (s).
pub fn spawn_with_limit(mut cmd: Command, err_path: &Path, timeout: f64) -> std::io::Result<(Waited, f64)> {
    cmd.stdin(Stdio::null()).stdout(Stdio::null());
    match std::fs::File::create(err_path) {
        Ok(f) => cmd.stderr(f),
        Err(_) => cmd.stderr(Stdio::null()),
    };
    let start = Instant::now();
    let mut child = cmd.spawn()?;
    // Kill and reap: no child outlives the wait.
    fn stop(child: &mut std::process::Child, why: Waited) -> Waited {
        let _ = child.kill();
        let _ = child.wait();
        why
    }
    let status = loop {
        match child.try_wait() {
            Ok(Some(s)) => match crate::interrupt::pending() {
                Some(sig) => break Waited::Interrupted(sig),
                None => break Waited::Exited(s),
            },
            Ok(None) => {
                if let Some(sig) = crate::interrupt::pending() {
                    break stop(&mut child, Waited::Interrupted(sig));
                }
                if start.elapsed().as_secs_f64() > timeout {
                    break stop(&mut child, Waited::TimedOut);
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(_) => break stop(&mut child, Waited::TimedOut),
        }
    };
    Ok((status, start.elapsed().as_secs_f64()))
}

/// Held while a temporary folder or file exists that the process must
/// either move into place or remove: the watchdog waits for it.
static STAGING: Mutex<()> = Mutex::new(());

/// While the returned guard lives, the watchdog does not end the process.
/// Take it before creating a temporary folder and drop it once the folder
/// is moved into place or removed: an exit then never leaves the folder
/// behind, nor stops a move halfway. Check [`crate::interrupt::pending`]
/// under the guard before moving into place, to honour a signal that
/// arrived meanwhile.
pub fn staging() -> MutexGuard<'static, ()> {
    STAGING.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The parent pid given in [`PARENT_PID_VAR`], if set and a number.
fn expected_parent() -> Option<u32> {
    std::env::var(PARENT_PID_VAR).ok()?.trim().parse().ok()
}

/// Start the watchdog thread (once per process), if there is something to
/// watch: the parent given in [`PARENT_PID_VAR`] and, once
/// [`crate::interrupt::install`] was called, the signal flag. It sleeps
/// between looks ([`POLL`]), so it takes no time from the main thread's
/// timed work. When the parent is gone it exits with
/// [`ORPHANED_EXIT_CODE`]; on a signal, with `128 + signal`; in both cases
/// after taking the [`staging`] guard and with a line on stderr.
pub fn start_watchdog() {
    static STARTED: std::sync::Once = std::sync::Once::new();
    let parent = expected_parent();
    if parent.is_none() && !crate::interrupt::installed() {
        return;
    }
    STARTED.call_once(|| {
        std::thread::spawn(move || watch(parent));
    });
}

/// The watchdog's loop; never returns.
fn watch(parent: Option<u32>) {
    loop {
        std::thread::sleep(POLL);
        if let Some(sig) = crate::interrupt::pending() {
            end(
                crate::interrupt::exit_code(sig) as i32,
                &format!("interrupted by signal {sig}: stopped, no temporary output left"),
            );
        }
        if let Some(p) = parent {
            let now = std::os::unix::process::parent_id();
            if now != p {
                end(
                    ORPHANED_EXIT_CODE,
                    &format!("the surgbench process that started this one (pid {p}) is gone; stopping"),
                );
            }
        }
    }
}

/// Exit with `code` once no temporary output is being written.
fn end(code: i32, why: &str) -> ! {
    // Held through the exit: the main thread cannot start staging anew.
    let _guard = staging();
    eprintln!("error: {why}");
    std::process::exit(code)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A child that ends on its own is `Exited` with its status; one past
    /// its limit is killed and reaped (`TimedOut`).
    #[test]
    fn waits_for_or_kills_a_child() {
        let tmp = tempfile::tempdir().unwrap();
        let err = tmp.path().join("err.txt");
        let (w, _) = spawn_with_limit(Command::new("true"), &err, 60.0).unwrap();
        assert!(matches!(w, Waited::Exited(s) if s.success()), "{w:?}");
        let mut sleep = Command::new("sleep");
        sleep.arg("60");
        let (w, elapsed) = spawn_with_limit(sleep, &err, 0.2).unwrap();
        assert!(matches!(w, Waited::TimedOut), "{w:?} after {elapsed} s");
    }
}
