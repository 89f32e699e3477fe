//! What the quasi-static tissue models share: the default that solves a
//! settling scene as one static problem, and the adaptive load stepping
//! that solves it.

use crate::{Fidelity, Scene, Setting};

/// Time step (s) that solves a settling scene in one step to the end of
/// its loads: [`Scene::inputs_held_from`], at most half the duration (the
/// runner's next step then finds the state unchanged and ends the run as
/// settled). `None` on a scene that does not settle or whose loads never
/// stop changing, or are held from the start.
pub fn static_dt(scene: &Scene) -> Option<f64> {
    scene.settle?;
    let held = scene.inputs_held_from().filter(|&t| t > 0.0)?;
    Some(held.min(0.5 * scene.duration))
}

/// The integrator a quasi-static model names `quasi-static`; a settling
/// scene that the caller runs with any other (dynamic) integrator and no
/// `dt` gets `dynamic_dt`, not the static one step to the whole load of
/// [`static_dt`]. For [`crate::ModelFactory::complete_defaults`].
pub fn keep_dynamic_dt(requested: &Fidelity, merged: &mut Fidelity, dynamic_dt: f64) {
    let dynamic = matches!(merged.extras.get("integrator"), Some(Setting::Choice(c)) if c != "quasi-static");
    if requested.dt.is_none() && dynamic {
        merged.dt = Some(dynamic_dt);
    }
}

/// Adaptive load stepping of one quasi-static step from the load factor
/// `from` to `to`. It starts with the whole change; a Newton solve that
/// fails is retried from the last equilibrium with half the increment,
/// down to [`LoadStepper::MAX_HALVINGS`] halvings of the whole change and
/// at most [`LoadStepper::MAX_FAILURES`] failures in all; a solve in at most
/// [`LoadStepper::FAST_NEWTON`] iterations that did not follow a failure
/// doubles the next increment (the increment control of Crisfield,
/// Non-linear Finite Element Analysis of Solids and Structures, vol. 1,
/// Sec. 9.5: scale the increment by the ratio of desired to used
/// iterations).
///
/// The caller solves at [`LoadStepper::target`] from its last equilibrium
/// and reports the outcome:
///
/// ```
/// use surgbench_core::statics::LoadStepper;
/// // A solver that fails any increment larger than 0.3 and otherwise
/// // converges in 3 iterations.
/// let mut steps = LoadStepper::new(0.0, 1.0);
/// let mut last = 0.0;
/// loop {
///     let to = steps.target();
///     if to - last > 0.3 {
///         assert!(steps.failed(), "0.25 is reached before the halvings run out");
///     } else if steps.converged(3) {
///         break;
///     } else {
///         last = to;
///     }
/// }
/// // 1 and 0.5 fail; 0.25 converges; 0.5 converges fast and doubles the
/// // increment; 1 fails; 0.75 and 1 converge.
/// assert_eq!((steps.increments, steps.failures), (4, 3));
/// ```
#[derive(Debug, Clone)]
pub struct LoadStepper {
    to: f64,
    /// Load factor of the last equilibrium.
    lo: f64,
    /// Current increment (signed).
    h: f64,
    /// Smallest increment tried.
    h_min: f64,
    /// Failed solves since the last converged one.
    since_converged: usize,
    /// Converged solves that moved the load factor.
    pub increments: usize,
    /// Failed solves retried with half the increment.
    pub failures: usize,
}

impl LoadStepper {
    /// Smallest increment, as halvings of the step's whole change: ten
    /// reach 1/1024 of it.
    pub const MAX_HALVINGS: i32 = 10;
    /// Most failed solves in one step (a load past a limit point otherwise
    /// creeps towards it forever).
    pub const MAX_FAILURES: usize = 3 * Self::MAX_HALVINGS as usize;
    /// A solve this fast started in Newton's quadratic range, so the next
    /// increment doubles.
    pub const FAST_NEWTON: usize = 4;

    /// Stepping from the equilibrium at load factor `from` to `to`.
    pub fn new(from: f64, to: f64) -> Self {
        let h = to - from;
        LoadStepper {
            to,
            lo: from,
            h,
            h_min: h.abs() * 0.5f64.powi(Self::MAX_HALVINGS),
            since_converged: 0,
            increments: 0,
            failures: 0,
        }
    }

    /// Load factor of the next solve: the last equilibrium plus the
    /// increment, or the end if that is within one increment.
    pub fn target(&self) -> f64 {
        if (self.to - self.lo).abs() <= self.h.abs() {
            self.to
        } else {
            self.lo + self.h
        }
    }

    /// The solve at [`Self::target`] converged in `iterations`: true when
    /// that was the end of the step, otherwise it is the new equilibrium
    /// (the caller keeps it to restart from).
    pub fn converged(&mut self, iterations: usize) -> bool {
        let hi = self.target();
        if hi != self.lo {
            self.increments += 1;
        }
        if hi == self.to {
            return true;
        }
        self.lo = hi;
        if iterations <= Self::FAST_NEWTON && self.since_converged == 0 {
            self.h *= 2.0;
        }
        self.since_converged = 0;
        false
    }

    /// The solve at [`Self::target`] failed: true when the caller should
    /// restore the last equilibrium and solve again at the halved
    /// increment, false when the step gives up (no change to halve, the
    /// smallest increment, or [`Self::MAX_FAILURES`] reached).
    pub fn failed(&mut self) -> bool {
        let halved = 0.5 * self.h.abs();
        if self.h == 0.0 || halved < self.h_min || self.failures >= Self::MAX_FAILURES {
            return false;
        }
        self.since_converged += 1;
        self.failures += 1;
        self.h *= 0.5;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs the stepper against a solver that converges in `its(from, to)`
    /// iterations or fails (`None`); returns the targets tried and whether
    /// the step ended converged.
    fn drive(from: f64, to: f64, its: impl Fn(f64, f64) -> Option<usize>) -> (Vec<f64>, bool, LoadStepper) {
        let mut s = LoadStepper::new(from, to);
        let (mut last, mut tried) = (from, Vec::new());
        loop {
            let t = s.target();
            tried.push(t);
            match its(last, t) {
                Some(n) if s.converged(n) => return (tried, true, s),
                Some(_) => last = t,
                None if s.failed() => {}
                None => return (tried, false, s),
            }
        }
    }

    #[test]
    fn a_solvable_whole_change_is_one_increment() {
        let (tried, ok, s) = drive(0.25, 1.0, |_, _| Some(8));
        assert_eq!(tried, vec![1.0]);
        assert!(ok);
        assert_eq!((s.increments, s.failures), (1, 0));
    }

    #[test]
    fn halves_on_failure_and_doubles_after_a_fast_solve() {
        // Increments above 0.2 fail; accepted ones take 2 iterations.
        let (tried, ok, s) = drive(0.0, 1.0, |a, b| (b - a <= 0.2).then_some(2));
        // 1 -> 0.5 -> 0.25 fail, 0.125 converges (after a failure: no
        // doubling), 0.25 (0.125 more) converges fast and doubles to 0.25,
        // 0.5 fails, 0.375 (0.125) converges ...
        assert_eq!(&tried[..6], &[1.0, 0.5, 0.25, 0.125, 0.25, 0.5]);
        assert!(ok);
        assert_eq!(*tried.last().unwrap(), 1.0);
        assert_eq!(s.increments, tried.len() - s.failures);
    }

    #[test]
    fn gives_up_after_ten_halvings() {
        let (tried, ok, s) = drive(0.0, 1.0, |_, _| None);
        assert!(!ok);
        // The whole change, then ten halvings down to 1/1024.
        assert_eq!(tried.len(), 11);
        assert_eq!(*tried.last().unwrap(), 1.0 / 1024.0);
        assert_eq!(s.failures, 10);
    }

    #[test]
    fn gives_up_after_max_failures_in_all() {
        // Increments above 1/256 of the change fail: after eight halvings
        // each cycle is a failure, a converged solve (no doubling after a
        // failure) and a fast one that doubles the increment again. The
        // halvings never run out; the end (128 cycles away) is not reached
        // before the failures in all do.
        let (tried, ok, s) = drive(0.0, 1.0, |a, b| (b - a <= 1.0 / 256.0).then_some(1));
        assert!(!ok);
        assert_eq!(s.failures, LoadStepper::MAX_FAILURES);
        assert!(tried.iter().all(|&t| t >= 1.0 / 1024.0));
    }

    #[test]
    fn no_change_converges_or_gives_up_at_once() {
        let (tried, ok, s) = drive(0.5, 0.5, |_, _| Some(3));
        assert_eq!((tried.len(), ok, s.increments), (1, true, 0));
        let (tried, ok, _) = drive(0.5, 0.5, |_, _| None);
        assert_eq!((tried.len(), ok), (1, false));
    }

    #[test]
    fn unloading_steps_downwards() {
        let (tried, ok, _) = drive(1.0, 0.0, |a, b| ((a - b).abs() <= 0.5).then_some(6));
        assert_eq!(tried, vec![0.0, 0.5, 0.0]);
        assert!(ok);
    }
}
