//! Fidelity knobs: the settings that trade speed for accuracy. The harness
//! sweeps them; each model resolves the ones it leaves unset to its defaults.
//!
//! ```
//! use surgbench_core::Fidelity;
//! let f = Fidelity::parse_pairs(&["segments=20", "dt=1e-3", "damping=2"]).unwrap();
//! assert_eq!(f.segments, Some(20));
//! assert_eq!(f.extras["damping"], 2.0);
//! assert!(Fidelity::parse_pairs(&["dt=-1"]).is_err());
//! ```

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// A model-specific fidelity knob accepted in [`Fidelity::extras`].
#[derive(Debug, Clone, Copy)]
pub struct FidelityKey {
    /// Name used on the command line and in comparison TOML.
    pub name: &'static str,
    /// One line: what it does, its unit, its default.
    pub doc: &'static str,
}

/// Discretization, time step, solver effort, and model-specific extras.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Fidelity {
    /// Number of rod segments (edges) over the free length.
    pub segments: Option<usize>,
    /// Tissue mesh refinement level (0 = coarsest).
    pub mesh_level: Option<usize>,
    /// Time step (s).
    pub dt: Option<f64>,
    /// Solver iterations (Newton, PBD, relaxation...: the model says which).
    pub iterations: Option<usize>,
    /// Named model-specific knobs (see [`crate::ModelFactory::fidelity_keys`]).
    pub extras: BTreeMap<String, f64>,
}

/// A fidelity string could not be parsed or a value is out of range.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FidelityError(pub String);

impl fmt::Display for FidelityError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for FidelityError {}

impl Fidelity {
    /// Set one knob by name, validating its range.
    pub fn set(&mut self, key: &str, value: f64) -> Result<(), FidelityError> {
        if !value.is_finite() {
            return Err(FidelityError(format!("fidelity `{key}` must be finite")));
        }
        let as_count = |min: f64| -> Result<usize, FidelityError> {
            if value < min || value.fract() != 0.0 || value > 1e9 {
                Err(FidelityError(format!(
                    "fidelity `{key}` must be an integer >= {min}, got {value}"
                )))
            } else {
                Ok(value as usize)
            }
        };
        match key {
            "segments" => self.segments = Some(as_count(1.0)?),
            "mesh_level" => self.mesh_level = Some(as_count(0.0)?),
            "iterations" => self.iterations = Some(as_count(1.0)?),
            "dt" => {
                if value <= 0.0 {
                    return Err(FidelityError(format!("fidelity `dt` must be > 0 s, got {value}")));
                }
                self.dt = Some(value)
            }
            other => {
                if other.is_empty() || !other.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                    return Err(FidelityError(format!("bad fidelity key `{other}`")));
                }
                self.extras.insert(other.to_string(), value);
            }
        }
        Ok(())
    }

    /// Parse `key=value` pairs (command line form); a key given twice is an
    /// error naming it.
    pub fn parse_pairs<S: AsRef<str>>(pairs: &[S]) -> Result<Self, FidelityError> {
        let mut f = Self::default();
        for p in pairs {
            let p = p.as_ref();
            let (k, v) = p
                .split_once('=')
                .ok_or_else(|| FidelityError(format!("fidelity `{p}` is not of the form key=value")))?;
            let v: f64 = v
                .trim()
                .parse()
                .map_err(|_| FidelityError(format!("fidelity `{k}`: `{v}` is not a number")))?;
            let k = k.trim();
            if let Some((_, first)) = f.pairs().into_iter().find(|(name, _)| name == k) {
                return Err(FidelityError(format!(
                    "fidelity `{k}` is given twice ({k}={first} and {k}={v}); give it once"
                )));
            }
            f.set(k, v)?;
        }
        Ok(f)
    }

    /// Overlay `other`'s set knobs on top of `self`.
    pub fn merged(&self, other: &Fidelity) -> Fidelity {
        let mut f = self.clone();
        if other.segments.is_some() {
            f.segments = other.segments;
        }
        if other.mesh_level.is_some() {
            f.mesh_level = other.mesh_level;
        }
        if other.dt.is_some() {
            f.dt = other.dt;
        }
        if other.iterations.is_some() {
            f.iterations = other.iterations;
        }
        for (k, v) in &other.extras {
            f.extras.insert(k.clone(), *v);
        }
        f
    }

    /// All set knobs as `(name, value)` pairs, in a fixed order.
    pub fn pairs(&self) -> Vec<(String, f64)> {
        let mut v = Vec::new();
        if let Some(s) = self.segments {
            v.push(("segments".to_string(), s as f64));
        }
        if let Some(s) = self.mesh_level {
            v.push(("mesh_level".to_string(), s as f64));
        }
        if let Some(s) = self.dt {
            v.push(("dt".to_string(), s));
        }
        if let Some(s) = self.iterations {
            v.push(("iterations".to_string(), s as f64));
        }
        for (k, x) in &self.extras {
            v.push((k.clone(), *x));
        }
        v
    }

    /// Reject extras the model does not declare (typos must not pass silently).
    pub fn check_extras(&self, known: &[FidelityKey]) -> Result<(), FidelityError> {
        for k in self.extras.keys() {
            if !known.iter().any(|kk| kk.name == k) {
                let names: Vec<_> = known.iter().map(|k| k.name).collect();
                return Err(FidelityError(format!(
                    "unknown fidelity key `{k}` (this model knows segments, mesh_level, dt, iterations{}{})",
                    if names.is_empty() { "" } else { ", " },
                    names.join(", ")
                )));
            }
        }
        Ok(())
    }

    /// An extra knob or its default.
    pub fn extra(&self, name: &str, default: f64) -> f64 {
        self.extras.get(name).copied().unwrap_or(default)
    }
}

impl fmt::Display for Fidelity {
    /// `segments=20;dt=0.001` form, stable across runs (used in file names and CSV).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts: Vec<String> = self.pairs().into_iter().map(|(k, v)| format!("{k}={v}")).collect();
        f.write_str(&parts.join(";"))
    }
}
