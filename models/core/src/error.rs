//! Error values of the contract. "Cannot do this scene" is a value
//! ([`Unsupported`]), never a panic; the report prints its reason where the
//! number would be.

use std::fmt;

/// A model cannot run a scene; `reason` is printed in the report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unsupported {
    /// Human-readable reason, one line.
    pub reason: String,
}

impl Unsupported {
    /// Build from any displayable reason.
    pub fn new(reason: impl Into<String>) -> Self {
        Self { reason: reason.into() }
    }
}

impl fmt::Display for Unsupported {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unsupported: {}", self.reason)
    }
}

impl std::error::Error for Unsupported {}

/// Why [`crate::ModelFactory::build`] failed.
#[derive(Debug, Clone, PartialEq)]
pub enum BuildError {
    /// The model cannot represent the scene.
    Unsupported(Unsupported),
    /// A fidelity knob or scene value is out of range or unknown.
    BadParameter {
        /// Name of the parameter or knob.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl BuildError {
    /// Shorthand for [`BuildError::BadParameter`].
    pub fn bad(name: &str, reason: impl Into<String>) -> Self {
        Self::BadParameter {
            name: name.to_string(),
            reason: reason.into(),
        }
    }
}

impl From<Unsupported> for BuildError {
    fn from(u: Unsupported) -> Self {
        Self::Unsupported(u)
    }
}

impl fmt::Display for BuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Unsupported(u) => u.fmt(f),
            Self::BadParameter { name, reason } => write!(f, "bad parameter `{name}`: {reason}"),
        }
    }
}

impl std::error::Error for BuildError {}

/// A step failed: the simulation diverged or a solver gave up. The harness
/// records this as an unstable result with its time, not as a crash.
#[derive(Debug, Clone, PartialEq)]
pub enum SimError {
    /// The state became non-finite or left any sane bound.
    Diverged {
        /// Simulated time of the failed step (s).
        t: f64,
        /// What was seen.
        reason: String,
    },
    /// A linear or nonlinear solve failed to produce a usable answer.
    SolverFailed {
        /// Simulated time of the failed step (s).
        t: f64,
        /// What was seen.
        reason: String,
    },
}

impl SimError {
    /// A step of `dt` (s) at simulated time `t` (s): `dt` must be finite and
    /// positive, else the step fails with a [`SimError::SolverFailed`]
    /// naming it.
    pub fn check_dt(t: f64, dt: f64) -> Result<(), SimError> {
        if dt > 0.0 && dt.is_finite() {
            Ok(())
        } else {
            Err(SimError::SolverFailed {
                t,
                reason: format!("time step must be > 0 s, got {dt}"),
            })
        }
    }
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Diverged { t, reason } => write!(f, "diverged at t={t:.6} s: {reason}"),
            Self::SolverFailed { t, reason } => write!(f, "solver failed at t={t:.6} s: {reason}"),
        }
    }
}

impl std::error::Error for SimError {}
