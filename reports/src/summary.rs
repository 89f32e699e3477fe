//! What one run measured, typed: its [`Status`], why it stopped ([`End`]),
//! which watchdog tripped ([`Trip`]), and the measured [`Outcome`] that both
//! a run's own `summary.json` ([`RunSummary`]) and a row of the comparison's
//! `results.csv` ([`crate::ResultRow`]) carry.
//!
//! The enums read and write the same kebab-case words the files hold
//! (`ok`, `time-limit`, ...); an empty cell is the `Unset` variant.

use std::collections::BTreeMap;
use std::fmt;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::ops::{Deref, DerefMut};
use std::path::Path;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::ReportError;

/// Defines a unit enum with its file words, `as_str`, `Display`, `FromStr`,
/// and comparison with those words.
macro_rules! file_words {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = $s:literal,)+ }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default, Serialize, Deserialize)]
        pub enum $name {
            $($(#[$vm])* #[serde(rename = $s)] $v,)+
        }

        impl $name {
            /// Every variant, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$v,)+];

            /// The word the files hold.
            pub fn as_str(self) -> &'static str {
                match self {
                    $($name::$v => $s,)+
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl std::str::FromStr for $name {
            type Err = String;

            fn from_str(s: &str) -> Result<Self, String> {
                Self::ALL
                    .iter()
                    .copied()
                    .find(|v| v.as_str() == s)
                    .ok_or_else(|| {
                        let words: Vec<&str> = Self::ALL.iter().map(|v| v.as_str()).collect();
                        format!("expected one of {words:?}, found {s:?}")
                    })
            }
        }

        impl PartialEq<&str> for $name {
            fn eq(&self, other: &&str) -> bool {
                self.as_str() == *other
            }
        }
    };
}

file_words! {
    /// How a run (or a haptic loop) ended up.
    Status {
        /// Nothing recorded yet (an empty cell).
        #[default]
        Unset = "",
        /// Ran to its end with every watchdog quiet.
        Ok = "ok",
        /// A watchdog tripped (the run's numbers are not trustworthy).
        Unstable = "unstable",
        /// The model cannot run the scene; the reason says why.
        Unsupported = "unsupported",
        /// The run crashed, could not start, was not reproducible, or scored
        /// errors that are not finite (the reason says which).
        Failed = "failed",
        /// Killed at the wall-clock limit.
        Timeout = "timeout",
        /// A haptic loop that a model error ended early.
        Stopped = "stopped",
    }
}

file_words! {
    /// Why a run stopped stepping.
    End {
        /// Not recorded (the run did not step).
        #[default]
        Unset = "",
        /// The scene's settling criterion held.
        Settled = "settled",
        /// A settling scene reached its duration without settling.
        TimeLimit = "time-limit",
        /// A scene without settling criterion ran its duration.
        Duration = "duration",
        /// A watchdog (or a model error) stopped it.
        Watchdog = "watchdog",
    }
}

file_words! {
    /// The kind of watchdog that tripped; the message in
    /// [`Outcome::watchdog`] carries what it saw.
    Trip {
        /// No watchdog tripped.
        #[default]
        None = "",
        /// A position or energy is NaN or infinite.
        NonFinite = "non-finite",
        /// A node left the scene's bounding sphere.
        LeftScene = "left-scene",
        /// An edge stretched beyond the limit.
        Stretch = "stretch",
        /// Energy grew beyond the hand's work.
        Energy = "energy",
        /// A body penetrated the vessel or tissue beyond the limit.
        Penetration = "penetration",
        /// The model's step returned an error.
        ModelError = "model-error",
    }
}

impl Trip {
    /// The kind of a watchdog message as the runner writes it: the kind's
    /// leading words (`"stretch 6e-2 > 0.05"` is [`Trip::Stretch`]); any other
    /// non-empty message is a model's error.
    pub fn of_message(message: &str) -> Trip {
        const LEADS: [(&str, Trip); 5] = [
            ("non-finite state", Trip::NonFinite),
            ("node left the scene", Trip::LeftScene),
            ("stretch ", Trip::Stretch),
            ("energy grew", Trip::Energy),
            ("penetration ", Trip::Penetration),
        ];
        if message.is_empty() {
            return Trip::None;
        }
        LEADS
            .iter()
            .find(|(lead, _)| message.starts_with(lead))
            .map_or(Trip::ModelError, |(_, t)| *t)
    }
}

/// What one run measured: the columns `status` through `watchdog_t` of
/// `results.csv`, and the same keys of a run's `summary.json`.
///
/// `None` is "not measured" (an empty cell, `null` in JSON). Times are in
/// the units their names say, everything else SI.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Outcome {
    /// How the run ended up.
    pub status: Status,
    /// Unsupported reason / failure message / watchdog message (`""` if ok).
    pub reason: String,
    /// Why the run stopped stepping.
    pub end: End,
    /// Steps taken (first repeat); a whole number, written without a fraction.
    #[serde(serialize_with = "whole_number")]
    pub steps: Option<f64>,
    /// Simulated time reached (s).
    pub sim_time_s: Option<f64>,
    /// Median wall time per step after warm-up (ms).
    pub ms_per_step_median: Option<f64>,
    /// 95th percentile wall time per step (ms).
    pub ms_per_step_p95: Option<f64>,
    /// Slowest step after warm-up, over every repeat (ms): what a haptic
    /// loop's deadline has to survive. Missing in reports written before it
    /// existed (`results.csv`'s optional `ms_per_step_max` column).
    #[serde(default)]
    pub ms_per_step_max: Option<f64>,
    /// Steps per wall-clock second (1/s).
    pub steps_per_s: Option<f64>,
    /// Simulated seconds per wall-clock second (dimensionless; >= 1 is real time).
    pub real_time_factor: Option<f64>,
    /// Mean solver iterations per step.
    pub solver_iters_mean: Option<f64>,
    /// Maximum solver iterations in one step.
    pub solver_iters_max: Option<f64>,
    /// Peak resident memory (MiB).
    pub peak_rss_mb: Option<f64>,
    /// Model build time (ms).
    pub build_ms: Option<f64>,
    /// Wall time of all steps of one run (s): time to solution for static
    /// scenes, where per-step times of models with different `dt` do not
    /// compare.
    pub solve_wall_s: Option<f64>,
    /// Whether every stability watchdog stayed quiet.
    pub stable: Option<bool>,
    /// Message of the first watchdog that tripped, with what it saw (`""` if none).
    pub watchdog: String,
    /// Simulated time at which the watchdog tripped (s).
    pub watchdog_t: Option<f64>,
}

impl Outcome {
    /// The kind of watchdog that tripped, read from [`Outcome::watchdog`].
    pub fn trip(&self) -> Trip {
        Trip::of_message(&self.watchdog)
    }
}

/// Writes a whole count as an integer (`12`, not `12.0`), anything else as is.
fn whole_number<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    match *v {
        Some(x) if x.fract() == 0.0 && x.abs() < 9.0e15 && x.is_sign_positive() => s.serialize_some(&(x as u64)),
        _ => v.serialize(s),
    }
}

/// Reads a map of numbers, dropping the `null`s JSON writes for NaN and infinity.
fn finite_map<'de, D: Deserializer<'de>>(d: D) -> Result<BTreeMap<String, f64>, D::Error> {
    let m: BTreeMap<String, Option<f64>> = BTreeMap::deserialize(d)?;
    Ok(m.into_iter().filter_map(|(k, v)| v.map(|v| (k, v))).collect())
}

/// One sample of a run's time series (a row of `observables.csv`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Sample {
    /// Time (s).
    pub t: f64,
    /// Tip position (m).
    pub tip: [f64; 3],
    /// Hand force (N).
    pub hand_force: [f64; 3],
    /// Hand torque (N m).
    pub hand_torque: [f64; 3],
    /// Total mechanical energy (J).
    pub energy: f64,
    /// Primary error at this time (NaN when not scored).
    pub error: f64,
    /// The reference's tip position at this time (m; NaN where the
    /// scenario's reference is not a trajectory).
    pub reference_tip: [f64; 3],
    /// The force the scene scores and the reference's value of it (N; NaN
    /// where the scene is not scored along a force history).
    pub force: [f64; 2],
    /// The indentation depth that force is plotted against (m; NaN where
    /// the scene is not scored along a load curve).
    pub depth: f64,
}

/// One node of a run's final state (a row of `final_state.csv`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NodeState {
    /// Body index (rods first, then tissues).
    pub body: usize,
    /// Node index within the body.
    pub node: usize,
    /// Rest position (m).
    pub rest: [f64; 3],
    /// Final position (m).
    pub x: [f64; 3],
}

/// A material point the scenario's reference measures (a Truth Cube bead):
/// where it starts, where the model's final state puts it and where the
/// reference has it (m). A row of a run's `markers.csv`, which the report
/// maps the per-point errors from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Marker {
    /// Rest position (m).
    pub rest: [f64; 3],
    /// Final position in the model (m).
    pub model: [f64; 3],
    /// Final position in the reference (m).
    pub reference: [f64; 3],
}

/// One point of a tip path in its bend plane (a row of a run's
/// `tip_path.csv`): `x` along the insertion, `s` the lateral offset along
/// the bend, and where the scene fits an arc there, that arc's `s` at the
/// same `x` (m; NaN elsewhere).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlanePoint {
    /// Along the insertion (m).
    pub x: f64,
    /// Lateral offset in the bend plane (m).
    pub s: f64,
    /// The best-fit arc's offset at `x` (m), NaN outside its window.
    pub fit: f64,
}

/// The columns of `markers.csv`, in order.
pub const MARKER_COLUMNS: [&str; 9] = ["x0", "y0", "z0", "x", "y", "z", "ref_x", "ref_y", "ref_z"];

/// One fidelity knob of a run as `summary.json` records it: a number, or a
/// model's choice by name (`"solver": "cg"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum FidelityValue {
    /// A number (segments, `dt`, a tolerance, a 0/1 switch...).
    Number(f64),
    /// A choice by name.
    Name(String),
}

impl FidelityValue {
    /// The number, if it is one.
    pub fn number(&self) -> Option<f64> {
        match self {
            Self::Number(v) => Some(*v),
            Self::Name(_) => None,
        }
    }
}

/// Everything one run measured: `run-one`'s `summary.json`, read back by the
/// batch runner into a `results.csv` row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct RunSummary {
    /// Scenario id.
    pub scenario: String,
    /// Model id.
    pub model: String,
    /// All resolved parameter values.
    pub params: BTreeMap<String, f64>,
    /// Overrides as given (`k=v;k=v`).
    pub overrides: String,
    /// Resolved fidelity (model defaults overlaid with the request).
    pub fidelity: BTreeMap<String, FidelityValue>,
    /// Resolved fidelity as a string.
    pub fidelity_string: String,
    /// What the run measured.
    #[serde(flatten)]
    pub outcome: Outcome,
    /// Headline error metric name.
    pub primary_error: String,
    /// Error metrics against the reference (non-finite values are dropped on reading).
    #[serde(deserialize_with = "finite_map")]
    pub errors: BTreeMap<String, f64>,
    /// Final tip position (m).
    pub tip: Option<[f64; 3]>,
    /// Reference tip position (m).
    pub reference_tip: Option<[f64; 3]>,
    /// Repeats run.
    pub repeats: usize,
    /// The user's mesh file the scene was built on (`run-one --mesh`), as
    /// given; absent when the scenario built its own geometry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<String>,
    /// Time series (not in `summary.json`; written to `observables.csv`).
    #[serde(skip)]
    pub series: Vec<Sample>,
    /// Final node positions (not in `summary.json`; written to `final_state.csv`).
    #[serde(skip)]
    pub final_state: Vec<NodeState>,
    /// The reference centreline of the rod at the end of the run (m, base to
    /// tip; not in `summary.json`: written to `reference_centreline.csv`
    /// when the scenario has one, e.g. a cantilever's elastica).
    #[serde(skip)]
    pub reference_centreline: Vec<[f64; 3]>,
    /// The scenario's measured points at the end of the run (not in
    /// `summary.json`: written to `markers.csv` when the scenario scores
    /// points, e.g. the Truth Cube's beads).
    #[serde(skip)]
    pub markers: Vec<Marker>,
    /// The tip path in its bend plane at the end of the run (not in
    /// `summary.json`: written to `tip_path.csv` when the scene scores a
    /// path's shape, e.g. the steered needles).
    #[serde(skip)]
    pub plane_path: Vec<PlanePoint>,
}

impl Deref for RunSummary {
    type Target = Outcome;

    fn deref(&self) -> &Outcome {
        &self.outcome
    }
}

impl DerefMut for RunSummary {
    fn deref_mut(&mut self) -> &mut Outcome {
        &mut self.outcome
    }
}

impl RunSummary {
    /// Writes `summary.json`, `observables.csv`, `final_state.csv` and, when
    /// the scenario has them, `reference_centreline.csv`, `markers.csv` and
    /// `tip_path.csv` into `dir` (which must exist).
    pub fn write_files(&self, dir: &Path) -> std::io::Result<()> {
        let json = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(dir.join("summary.json"), json + "\n")?;
        self.write_series(&dir.join("observables.csv"))?;
        if !self.reference_centreline.is_empty() {
            self.write_centreline(&dir.join("reference_centreline.csv"))?;
        }
        if !self.markers.is_empty() {
            self.write_markers(&dir.join("markers.csv"))?;
        }
        if !self.plane_path.is_empty() {
            self.write_plane_path(&dir.join("tip_path.csv"))?;
        }
        self.write_final_state(&dir.join("final_state.csv"))
    }

    fn write_plane_path(&self, path: &Path) -> std::io::Result<()> {
        let mut f = BufWriter::new(File::create(path)?);
        writeln!(f, "x,s,arc_s")?;
        for p in &self.plane_path {
            let fit = if p.fit.is_finite() {
                format!("{:e}", p.fit)
            } else {
                String::new()
            };
            writeln!(f, "{:e},{:e},{fit}", p.x, p.s)?;
        }
        f.flush()
    }

    fn write_markers(&self, path: &Path) -> std::io::Result<()> {
        let mut f = BufWriter::new(File::create(path)?);
        writeln!(f, "{}", MARKER_COLUMNS.join(","))?;
        for m in &self.markers {
            let cells: Vec<String> = [m.rest, m.model, m.reference]
                .iter()
                .flatten()
                .map(|v| format!("{v:e}"))
                .collect();
            writeln!(f, "{}", cells.join(","))?;
        }
        f.flush()
    }

    fn write_centreline(&self, path: &Path) -> std::io::Result<()> {
        let mut f = BufWriter::new(File::create(path)?);
        writeln!(f, "x,y,z")?;
        for [x, y, z] in &self.reference_centreline {
            writeln!(f, "{x:e},{y:e},{z:e}")?;
        }
        f.flush()
    }

    /// Reads a run's `summary.json` (the series and final state stay empty).
    pub fn read(path: &Path) -> Result<Self, ReportError> {
        let text = std::fs::read_to_string(path).map_err(|e| ReportError::io(path, e))?;
        serde_json::from_str(&text).map_err(|e| ReportError::Json {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    fn write_series(&self, path: &Path) -> std::io::Result<()> {
        let mut f = BufWriter::new(File::create(path)?);
        writeln!(f, "{}", crate::SERIES_COLUMNS.join(","))?;
        for x in &self.series {
            let err = if x.error.is_finite() {
                format!("{:e}", x.error)
            } else {
                String::new()
            };
            let [tx, ty, tz] = x.tip;
            let [fx, fy, fz] = x.hand_force;
            let [mx, my, mz] = x.hand_torque;
            let [rx, ry, rz] = x
                .reference_tip
                .map(|v| if v.is_finite() { format!("{v:e}") } else { String::new() });
            let [sf, rf, depth] =
                [x.force[0], x.force[1], x.depth].map(|v| if v.is_finite() { format!("{v:e}") } else { String::new() });
            writeln!(
                f,
                "{:e},{tx:e},{ty:e},{tz:e},{fx:e},{fy:e},{fz:e},{mx:e},{my:e},{mz:e},{:e},{err},{rx},{ry},{rz},{sf},{rf},{depth}",
                x.t, x.energy
            )?;
        }
        f.flush()
    }

    fn write_final_state(&self, path: &Path) -> std::io::Result<()> {
        let mut f = BufWriter::new(File::create(path)?);
        writeln!(f, "body,node,x0,y0,z0,x,y,z")?;
        for n in &self.final_state {
            let ([a, b, c], [x, y, z]) = (n.rest, n.x);
            writeln!(f, "{},{},{a:e},{b:e},{c:e},{x:e},{y:e},{z:e}", n.body, n.node)?;
        }
        f.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The words are the files' words, both ways; an unknown word is an error.
    #[test]
    fn words_round_trip() {
        for s in Status::ALL {
            assert_eq!(s.as_str().parse::<Status>().unwrap(), *s);
        }
        for e in End::ALL {
            assert_eq!(e.to_string().parse::<End>().unwrap(), *e);
        }
        assert_eq!(End::TimeLimit.to_string(), "time-limit");
        assert_eq!(serde_json::to_string(&Status::Unset).unwrap(), "\"\"");
        assert!("Ok".parse::<Status>().is_err());
    }

    /// The runner's watchdog messages read back as their kinds.
    #[test]
    fn trips_are_read_from_the_messages() {
        for (m, t) in [
            ("", Trip::None),
            ("non-finite state", Trip::NonFinite),
            ("node left the scene: |x| = 3e0 m > 1e0 m", Trip::LeftScene),
            ("stretch 6.000e-2 > 0.05", Trip::Stretch),
            (
                "energy grew by 1e0 J beyond the hand's work (0e0 J) > 1e-3 J",
                Trip::Energy,
            ),
            ("penetration 1e-3 m > 5e-4 m", Trip::Penetration),
            ("Newton did not converge", Trip::ModelError),
        ] {
            assert_eq!(Trip::of_message(m), t, "{m:?}");
        }
    }

    /// A whole step count is written as an integer, as `run-one` always has.
    #[test]
    fn steps_are_whole_numbers_in_json() {
        let o = Outcome {
            steps: Some(12.0),
            sim_time_s: Some(0.0),
            ..Outcome::default()
        };
        let text = serde_json::to_string(&o).unwrap();
        assert!(
            text.contains("\"steps\":12,") && text.contains("\"sim_time_s\":0.0"),
            "{text}"
        );
        let back: Outcome = serde_json::from_str(&text).unwrap();
        assert_eq!(back, o);
    }
}
