//! SIGINT and SIGTERM for a process that owns child processes or
//! temporary output: after [`install`], the first such signal only sets a
//! flag, and the process ends itself cleanly with `128 + signal` (130 for
//! SIGINT, 143 for SIGTERM). A second signal ends the process at once,
//! with the same exit code.
//!
//! Who reads the flag:
//! - `surgbench run` and `surgbench gate` poll it while they wait for a
//!   child ([`crate::child::spawn_with_limit`]): the running child
//!   (`run-one`, `haptic`, valgrind) is killed and reaped, the temporary
//!   report folder or callgrind files removed, nothing is written (no
//!   report, no baseline), and earlier output is left as it was.
//! - `surgbench run-one` polls it in its watchdog thread
//!   ([`crate::child::start_watchdog`]), which ends it even while a model
//!   hangs in a step; its temporary sibling of `--out` is either moved into
//!   place whole or removed ([`crate::child::staging`]), never left.
//!
//! SIGKILL cannot be caught: a killed `run` leaves its `.OUT.tmp-PID`
//! folder (the next run into the same `--out` removes it) and its child
//! notices the lost parent and exits ([`crate::child`]).

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Set by the first SIGINT/SIGTERM; read by [`pending`].
struct Flags {
    /// Any signal arrived.
    hit: Arc<AtomicBool>,
    /// Which one (its number).
    which: Arc<AtomicUsize>,
}

static FLAGS: OnceLock<Flags> = OnceLock::new();

/// Catch SIGINT and SIGTERM from now on (idempotent). Without this the
/// signals keep their default action (the process dies at once).
pub fn install() -> std::io::Result<()> {
    if FLAGS.get().is_some() {
        return Ok(());
    }
    let flags = Flags {
        hit: Arc::new(AtomicBool::new(false)),
        which: Arc::new(AtomicUsize::new(0)),
    };
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // Registered first, so it sees the flag as it was before this
        // signal: the first signal passes, a second one exits at once.
        signal_hook::flag::register_conditional_shutdown(sig, 128 + sig, Arc::clone(&flags.hit))?;
        signal_hook::flag::register_usize(sig, Arc::clone(&flags.which), sig as usize)?;
        signal_hook::flag::register(sig, Arc::clone(&flags.hit))?;
    }
    let _ = FLAGS.set(flags);
    Ok(())
}

/// Whether [`install`] was called in this process.
pub fn installed() -> bool {
    FLAGS.get().is_some()
}

/// The signal that arrived since [`install`], if one did.
pub fn pending() -> Option<i32> {
    let f = FLAGS.get()?;
    f.hit
        .load(Ordering::SeqCst)
        .then(|| f.which.load(Ordering::SeqCst) as i32)
}

/// The exit code for a process ended by `signal`: `128 + signal`, as a
/// shell reports it.
pub fn exit_code(signal: i32) -> u8 {
    (128 + signal).clamp(0, 255) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shell's convention: 130 for SIGINT (2), 143 for SIGTERM (15).
    #[test]
    fn exit_codes_follow_the_shell() {
        assert_eq!(exit_code(signal_hook::consts::SIGINT), 130);
        assert_eq!(exit_code(signal_hook::consts::SIGTERM), 143);
    }

    /// Nothing is pending before a signal; no signal is sent in this test
    /// (it would reach the whole test process).
    #[test]
    fn nothing_pending_without_a_signal() {
        install().expect("handlers install");
        install().expect("a second install is a no-op");
        assert_eq!(pending(), None);
    }
}
