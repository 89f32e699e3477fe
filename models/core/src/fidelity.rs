//! Fidelity knobs: the settings that trade speed for accuracy. The harness
//! sweeps them; each model resolves the ones it leaves unset to its defaults.
//! A model-specific extra is a number or a choice by name ([`Setting`]).
//!
//! ```
//! use surgbench_core::{Fidelity, Setting};
//! let f = Fidelity::parse_pairs(&["segments=20", "dt=1e-3", "damping=2", "solver=cg"]).unwrap();
//! assert_eq!(f.segments, Some(20));
//! assert_eq!(f.extras["damping"], Setting::Number(2.0));
//! assert_eq!(f.extras["solver"], Setting::Choice("cg".into()));
//! assert_eq!(f.to_string(), "segments=20;dt=0.001;damping=2;solver=cg");
//! assert!(Fidelity::parse_pairs(&["dt=-1"]).is_err());
//! assert!(Fidelity::parse_pairs(&["dt=fast"]).is_err());
//! ```

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// The value of a model-specific fidelity extra: a number (a count, a
/// tolerance, a unit quantity, an on/off switch 0/1) or a choice by name
/// (`solver = "cg"`). Numbers read and print as `f64` does; a choice is
/// lowercase letters, digits and `-`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Setting {
    /// A number.
    Number(f64),
    /// A choice by name.
    Choice(String),
}

impl Setting {
    /// Read a command-line value: a number if it parses as one, else a
    /// choice name.
    pub fn parse(text: &str) -> Result<Self, FidelityError> {
        let t = text.trim();
        match t.parse::<f64>() {
            Ok(v) => Ok(Self::Number(v)),
            Err(_) if is_choice_name(t) => Ok(Self::Choice(t.to_string())),
            Err(_) => Err(FidelityError(format!(
                "`{t}` is neither a number nor a choice name (lowercase letters, digits, `-`)"
            ))),
        }
    }
}

/// A choice name: lowercase ASCII letters, digits and `-`, starting with a letter.
fn is_choice_name(s: &str) -> bool {
    s.starts_with(|c: char| c.is_ascii_lowercase())
        && s.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
}

impl From<f64> for Setting {
    fn from(v: f64) -> Self {
        Self::Number(v)
    }
}

impl From<&str> for Setting {
    fn from(v: &str) -> Self {
        Self::Choice(v.to_string())
    }
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Number(v) => write!(f, "{v}"),
            Self::Choice(n) => f.write_str(n),
        }
    }
}

impl<'de> Deserialize<'de> for Setting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Setting;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or a choice name")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Setting, E> {
                Ok(Setting::Number(v))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Setting, E> {
                Ok(Setting::Number(v as f64))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Setting, E> {
                Ok(Setting::Number(v as f64))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Setting, E> {
                if is_choice_name(v) {
                    Ok(Setting::Choice(v.to_string()))
                } else {
                    Err(E::custom(format!(
                        "`{v}` is not a choice name (lowercase letters, digits, `-`)"
                    )))
                }
            }
        }
        d.deserialize_any(V)
    }
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
    pub extras: BTreeMap<String, Setting>,
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
    /// Set one knob by name to a number, validating its range.
    pub fn set(&mut self, key: &str, value: f64) -> Result<(), FidelityError> {
        self.set_setting(key, Setting::Number(value))
    }

    /// Set one knob by name to a number or a choice; the discretization,
    /// `dt` and `iterations` take numbers in range, an extra any finite
    /// number or choice name (its model's keys say which it takes).
    pub fn set_setting(&mut self, key: &str, value: Setting) -> Result<(), FidelityError> {
        let value = match value {
            Setting::Choice(name) => {
                if !is_choice_name(&name) {
                    return Err(FidelityError(format!(
                        "fidelity `{key}`: `{name}` is not a choice name (lowercase letters, digits, `-`)"
                    )));
                }
                if matches!(key, "segments" | "mesh_level" | "iterations" | "dt") {
                    return Err(FidelityError(format!("fidelity `{key}` takes a number, got `{name}`")));
                }
                return self.set_extra(key, Setting::Choice(name));
            }
            Setting::Number(v) => v,
        };
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
            other => self.set_extra(other, Setting::Number(value))?,
        }
        Ok(())
    }

    /// Insert a model-specific extra under a well-formed key.
    fn set_extra(&mut self, key: &str, value: Setting) -> Result<(), FidelityError> {
        // Words of letters, digits and `_`, joined by single dots (a pair's
        // `rod.solver` names its half).
        let word = |w: &str| !w.is_empty() && w.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !key.split('.').all(word) {
            return Err(FidelityError(format!("bad fidelity key `{key}`")));
        }
        self.extras.insert(key.to_string(), value);
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
            let k = k.trim();
            let v = Setting::parse(v).map_err(|e| FidelityError(format!("fidelity `{k}`: {e}")))?;
            if let Some((_, first)) = f.pairs().into_iter().find(|(name, _)| name == k) {
                return Err(FidelityError(format!(
                    "fidelity `{k}` is given twice ({k}={first} and {k}={v}); give it once"
                )));
            }
            f.set_setting(k, v)?;
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
            f.extras.insert(k.clone(), v.clone());
        }
        f
    }

    /// All set knobs as `(name, value)` pairs, in a fixed order.
    pub fn pairs(&self) -> Vec<(String, Setting)> {
        let mut v = Vec::new();
        if let Some(s) = self.segments {
            v.push(("segments".to_string(), Setting::Number(s as f64)));
        }
        if let Some(s) = self.mesh_level {
            v.push(("mesh_level".to_string(), Setting::Number(s as f64)));
        }
        if let Some(s) = self.dt {
            v.push(("dt".to_string(), Setting::Number(s)));
        }
        if let Some(s) = self.iterations {
            v.push(("iterations".to_string(), Setting::Number(s as f64)));
        }
        for (k, x) in &self.extras {
            v.push((k.clone(), x.clone()));
        }
        v
    }
}

impl fmt::Display for Fidelity {
    /// `segments=20;dt=0.001` form, stable across runs (used in file names and CSV).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts: Vec<String> = self.pairs().into_iter().map(|(k, v)| format!("{k}={v}")).collect();
        f.write_str(&parts.join(";"))
    }
}
