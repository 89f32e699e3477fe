//! What a model declares about its fidelity extras, and the fidelity its
//! build receives once resolved against that declaration.
//!
//! A [`FidelityKey`] is a number (its unit in the doc, the values it takes
//! declared as a [`Span`] and checked here, not by each model), an on/off
//! [`KeyKind::Switch`] (the number 0 or 1), or a [`KeyKind::Choice`] among
//! names. [`Settings`] is a fidelity resolved once: the model's defaults for
//! the scene overlaid with the request, every extra a declared key, every
//! choice one of its names. [`crate::model::resolve`] makes it; a model's
//! [`crate::ModelFactory::build_resolved`] reads it.
//!
//! ```
//! use surgbench_core::settings::{Choice, FidelityKey};
//! use surgbench_core::Fidelity;
//! const KEYS: &[FidelityKey] = &[FidelityKey::choice(
//!     "solver",
//!     "linear solver",
//!     &[Choice::new("direct", "sparse Cholesky"), Choice::new("cg", "PCG")],
//! )];
//! assert_eq!(KEYS[0].values(), "direct | cg");
//! assert!(Fidelity::parse_pairs(&["solver=cg"]).unwrap().validate_extras(KEYS).is_ok());
//! let e = Fidelity::parse_pairs(&["solver=lu"]).unwrap().validate_extras(KEYS).unwrap_err();
//! assert!(e.0.contains("direct, cg"), "{e}");
//! assert!(Fidelity::parse_pairs(&["solver=1"]).unwrap().validate_extras(KEYS).is_err());
//! ```

use crate::error::BuildError;
use crate::fidelity::{Fidelity, FidelityError, Setting};

/// One named option of a choice key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Choice {
    /// The name written in TOML and on the command line (`cg`).
    pub name: &'static str,
    /// One line: what it selects.
    pub doc: &'static str,
}

impl Choice {
    /// A choice `name` documented by `doc`.
    pub const fn new(name: &'static str, doc: &'static str) -> Self {
        Self { name, doc }
    }
}

/// The numbers a numeric key takes: an interval, its ends open or closed,
/// whole numbers only if `whole`. Always finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// Lower end (may be `-inf`).
    pub min: f64,
    /// Upper end (may be `inf`).
    pub max: f64,
    /// Whether `min` itself is excluded.
    pub open_min: bool,
    /// Whether `max` itself is excluded.
    pub open_max: bool,
    /// Whole numbers only (counts, thread numbers).
    pub whole: bool,
}

impl Span {
    /// Any finite number.
    pub const ANY: Span = Span {
        min: f64::NEG_INFINITY,
        max: f64::INFINITY,
        open_min: false,
        open_max: false,
        whole: false,
    };

    /// Whether `v` is in the span.
    pub fn contains(&self, v: f64) -> bool {
        let above = if self.open_min { v > self.min } else { v >= self.min };
        let below = if self.open_max { v < self.max } else { v <= self.max };
        v.is_finite() && above && below && (!self.whole || v.fract() == 0.0)
    }

    /// For listings and messages: `number`, `number >= 0`, `number in (0, 1)`,
    /// `integer in 1..=64`.
    pub fn describe(&self) -> String {
        let what = if self.whole { "integer" } else { "number" };
        match (self.min.is_finite(), self.max.is_finite()) {
            (false, false) => what.into(),
            (true, false) => format!("{what} {} {}", if self.open_min { ">" } else { ">=" }, self.min),
            (false, true) => format!("{what} {} {}", if self.open_max { "<" } else { "<=" }, self.max),
            (true, true) if self.whole => format!("{what} in {}..={}", self.min, self.max),
            (true, true) => format!(
                "{what} in {}{}, {}{}",
                if self.open_min { "(" } else { "[" },
                self.min,
                self.max,
                if self.open_max { ")" } else { "]" }
            ),
        }
    }
}

/// The values a fidelity key takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum KeyKind {
    /// A number in a [`Span`]; its unit is in the key's doc.
    Number(Span),
    /// On/off: the number 0 (off) or 1 (on).
    Switch,
    /// One of these names.
    Choice(&'static [Choice]),
}

/// A model-specific fidelity knob accepted in [`Fidelity::extras`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FidelityKey {
    /// Name used on the command line and in comparison TOML.
    pub name: &'static str,
    /// One line: what it does, its unit, its default.
    pub doc: &'static str,
    /// The values it takes.
    pub kind: KeyKind,
}

impl FidelityKey {
    /// A numeric key taking any finite number (narrow it with
    /// [`Self::at_least`], [`Self::above`], [`Self::within`],
    /// [`Self::between`] or [`Self::whole`]).
    pub const fn number(name: &'static str, doc: &'static str) -> Self {
        Self {
            name,
            doc,
            kind: KeyKind::Number(Span::ANY),
        }
    }

    /// This numeric key with its span.
    const fn span(self, min: f64, max: f64, open_min: bool, open_max: bool, whole: bool) -> Self {
        Self {
            kind: KeyKind::Number(Span {
                min,
                max,
                open_min,
                open_max,
                whole,
            }),
            ..self
        }
    }

    /// Numbers `>= min`.
    pub const fn at_least(self, min: f64) -> Self {
        self.span(min, f64::INFINITY, false, false, false)
    }

    /// Numbers `> min`.
    pub const fn above(self, min: f64) -> Self {
        self.span(min, f64::INFINITY, true, false, false)
    }

    /// Numbers in `[min, max]`.
    pub const fn within(self, min: f64, max: f64) -> Self {
        self.span(min, max, false, false, false)
    }

    /// Numbers in `(min, max)`.
    pub const fn between(self, min: f64, max: f64) -> Self {
        self.span(min, max, true, true, false)
    }

    /// Whole numbers in `min..=max`.
    pub const fn whole(self, min: f64, max: f64) -> Self {
        self.span(min, max, false, false, true)
    }

    /// An on/off key (0 or 1).
    pub const fn switch(name: &'static str, doc: &'static str) -> Self {
        Self {
            name,
            doc,
            kind: KeyKind::Switch,
        }
    }

    /// A key that takes one of `choices` by name.
    pub const fn choice(name: &'static str, doc: &'static str, choices: &'static [Choice]) -> Self {
        Self {
            name,
            doc,
            kind: KeyKind::Choice(choices),
        }
    }

    /// The values it takes, for listings: `number`, `0 | 1`, `direct | cg`.
    pub fn values(&self) -> String {
        match self.kind {
            KeyKind::Number(span) => span.describe(),
            KeyKind::Switch => "0 | 1".into(),
            KeyKind::Choice(c) => names(c).join(" | "),
        }
    }

    /// `Ok` if `value` is one this key takes; the error names the key and,
    /// for a choice, lists the names.
    pub fn check(&self, value: &Setting) -> Result<(), FidelityError> {
        let key = self.name;
        match (self.kind, value) {
            (KeyKind::Number(span), Setting::Number(v)) if span.contains(*v) => Ok(()),
            (KeyKind::Number(span), Setting::Number(v)) => Err(FidelityError(format!(
                "fidelity `{key}` must be {} {}, got {v}",
                if span.whole { "an" } else { "a" },
                span.describe()
            ))),
            (KeyKind::Switch, Setting::Number(v)) if *v == 0.0 || *v == 1.0 => Ok(()),
            (KeyKind::Choice(c), Setting::Choice(n)) if c.iter().any(|c| c.name == n) => Ok(()),
            (KeyKind::Number(_), Setting::Choice(n)) => {
                Err(FidelityError(format!("fidelity `{key}` takes a number, got `{n}`")))
            }
            (KeyKind::Switch, v) => Err(FidelityError(format!(
                "fidelity `{key}` is a switch: 0 (off) or 1 (on), got `{v}`"
            ))),
            (KeyKind::Choice(c), Setting::Number(v)) => Err(FidelityError(format!(
                "fidelity `{key}` takes a name, one of: {}; got the number {v}",
                names(c).join(", ")
            ))),
            (KeyKind::Choice(c), Setting::Choice(n)) => Err(FidelityError(format!(
                "fidelity `{key}`: unknown choice `{n}` (choices: {})",
                names(c).join(", ")
            ))),
        }
    }
}

fn names(c: &[Choice]) -> Vec<&'static str> {
    c.iter().map(|c| c.name).collect()
}

impl Fidelity {
    /// Reject extras the model does not declare and values its keys do not
    /// take (typos and numeric codes for choices must not pass silently).
    pub fn validate_extras(&self, known: &[FidelityKey]) -> Result<(), FidelityError> {
        self.check_extras_against(known).map_err(|(_, e)| e)
    }

    /// [`Fidelity::validate_extras`] as a [`BuildError`] naming the key
    /// whose value is wrong (`fidelity` for an undeclared key).
    pub(crate) fn build_check_extras(&self, known: &[FidelityKey]) -> Result<(), BuildError> {
        self.check_extras_against(known)
            .map_err(|(key, e)| BuildError::bad(key.unwrap_or("fidelity"), e.0))
    }

    /// The first bad extra: its declared key (if any) and what is wrong.
    fn check_extras_against(&self, known: &[FidelityKey]) -> Result<(), (Option<&'static str>, FidelityError)> {
        for (k, v) in &self.extras {
            match known.iter().find(|kk| kk.name == k) {
                Some(key) => key.check(v).map_err(|e| (Some(key.name), e))?,
                None => {
                    let names: Vec<_> = known.iter().map(|k| k.name).collect();
                    return Err((
                        None,
                        FidelityError(format!(
                            "unknown fidelity key `{k}` (this model knows segments, mesh_level, dt, iterations{}{})",
                            if names.is_empty() { "" } else { ", " },
                            names.join(", ")
                        )),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// A model's fidelity resolved once: its defaults for the scene overlaid
/// with the request, every extra a declared key holding a value that key
/// takes. The only way to make one is [`crate::model::resolve`].
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    fidelity: Fidelity,
}

impl Settings {
    /// `full` checked against `keys`.
    pub(crate) fn new(full: Fidelity, keys: &[FidelityKey]) -> Result<Self, BuildError> {
        full.build_check_extras(keys)?;
        Ok(Self { fidelity: full })
    }

    /// The full fidelity (discretization, `dt`, iterations and extras).
    pub fn fidelity(&self) -> &Fidelity {
        &self.fidelity
    }

    /// The numeric extra `name`, if set.
    pub fn number(&self, name: &str) -> Option<f64> {
        match self.fidelity.extras.get(name) {
            Some(Setting::Number(v)) => Some(*v),
            _ => None,
        }
    }

    /// The numeric extra `name`, or `default` when unset.
    pub fn number_or(&self, name: &str, default: f64) -> f64 {
        self.number(name).unwrap_or(default)
    }

    /// The switch `name` (0 off, 1 on), or `default` when unset.
    pub fn switch(&self, name: &str, default: bool) -> bool {
        self.number(name).map_or(default, |v| v == 1.0)
    }

    /// The choice `name` as the model's own value: the entry of `table`
    /// whose name was chosen, or `default` when unset. A chosen name the
    /// table lacks (a declaration the model does not map) is a
    /// [`BuildError`] naming the key.
    pub fn pick<T: Copy>(&self, name: &str, table: &[(&str, T)], default: T) -> Result<T, BuildError> {
        match self.fidelity.extras.get(name) {
            None => Ok(default),
            Some(Setting::Choice(n)) => table
                .iter()
                .find(|(t, _)| t == n)
                .map(|(_, v)| *v)
                .ok_or_else(|| BuildError::bad(name, format!("the model declares `{n}` but does not map it"))),
            Some(Setting::Number(v)) => Err(BuildError::bad(name, format!("takes a name, got the number {v}"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn declared_ranges_are_checked_and_described() {
        const KEYS: &[FidelityKey] = &[
            FidelityKey::number("tol", "a tolerance").between(0.0, 1.0),
            FidelityKey::number("threads", "threads").whole(1.0, 64.0),
            FidelityKey::number("damping", "damping (1/s)").at_least(0.0),
            FidelityKey::number("offset", "any offset (m)"),
        ];
        assert_eq!(KEYS[0].values(), "number in (0, 1)");
        assert_eq!(KEYS[1].values(), "integer in 1..=64");
        assert_eq!(KEYS[2].values(), "number >= 0");
        assert_eq!(KEYS[3].values(), "number");
        let check = |pair: &str| Fidelity::parse_pairs(&[pair]).unwrap().validate_extras(KEYS);
        for ok in ["tol=0.5", "threads=2", "damping=0", "offset=-3"] {
            assert!(check(ok).is_ok(), "{ok}");
        }
        for (bad, says) in [
            ("tol=0", "must be a number in (0, 1), got 0"),
            ("tol=1", "got 1"),
            ("threads=1.5", "must be an integer in 1..=64, got 1.5"),
            ("threads=65", "got 65"),
            ("damping=-1", "must be a number >= 0, got -1"),
        ] {
            let e = check(bad).unwrap_err();
            assert!(e.0.contains(says), "{bad}: {e}");
        }
    }
}
