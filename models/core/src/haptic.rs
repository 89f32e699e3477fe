//! Haptic devices: where the operator's commands come from and where the
//! hand force goes. SI units (s, m, rad, N, N m).
//!
//! A [`HapticDevice`] is polled once per haptic tick for a [`DeviceCommand`]
//! and then given the [`Feedback`] (force and torque at the operator's hand)
//! the model computed. Implementations here:
//! - [`ScriptedDevice`]: plays a [`ControlTimeline`];
//! - [`ReplayDevice`]: plays a recorded [`Session`] (CSV
//!   `t,insertion,rotation`) and records what it rendered, so the session can
//!   be written out again with the forces.
//! - `()`: the no-op device (zero command, ignores feedback).
//!
//! ```
//! use surgbench_core::haptic::{Feedback, HapticDevice, ReplayDevice, Session};
//! let s = Session::parse("<memory>", "t,insertion,rotation\n0,0,0\n1,0.02,0.5\n").unwrap();
//! let mut dev = ReplayDevice::new(s);
//! let c = dev.command(0.5);
//! assert!((c.insertion - 0.01).abs() < 1e-15 && (c.rotation - 0.25).abs() < 1e-15);
//! dev.render(&Feedback { t: 0.5, ..Default::default() });
//! assert_eq!(dev.rendered().len(), 1);
//! ```

use crate::Vec3;
use crate::io::table;
use crate::scene::{ControlKey, ControlTimeline, DeviceCommand};
use std::fmt;
use std::path::Path;

/// What the device renders to the operator's hand at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Feedback {
    /// Time of the tick (s).
    pub t: f64,
    /// Force on the hand (N), the model's `Observation::hand_force`.
    pub force: Vec3,
    /// Torque on the hand (N m), the model's `Observation::hand_torque`.
    pub torque: Vec3,
}

/// A haptic device (real or simulated). The loop calls `command(t)` at the
/// start of each tick and `render` with the result at its end.
pub trait HapticDevice: Send {
    /// The operator's command at time `t` (s).
    fn command(&mut self, t: f64) -> DeviceCommand;
    /// Render force and torque at the hand.
    fn render(&mut self, feedback: &Feedback);
}

/// The no-op device: zero command, feedback ignored.
impl HapticDevice for () {
    fn command(&mut self, _t: f64) -> DeviceCommand {
        DeviceCommand::default()
    }
    fn render(&mut self, _feedback: &Feedback) {}
}

/// Plays a control timeline; keeps the last feedback rendered.
#[derive(Debug, Clone, Default)]
pub struct ScriptedDevice {
    /// The script.
    pub timeline: ControlTimeline,
    /// Last feedback rendered, if any.
    pub last: Option<Feedback>,
}

impl ScriptedDevice {
    /// A device playing `timeline`.
    pub fn new(timeline: ControlTimeline) -> Self {
        Self { timeline, last: None }
    }
}

impl HapticDevice for ScriptedDevice {
    fn command(&mut self, t: f64) -> DeviceCommand {
        self.timeline.command_at(t)
    }
    fn render(&mut self, feedback: &Feedback) {
        self.last = Some(*feedback);
    }
}

/// A recorded session could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionError {
    /// File (or `<memory>`).
    pub file: String,
    /// 1-based line, 0 when the error is not tied to a line.
    pub line: usize,
    /// Column name (or empty).
    pub column: String,
    /// What is wrong.
    pub what: String,
}

impl fmt::Display for SessionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if self.line > 0 {
            write!(f, ": line {}", self.line)?;
        }
        if !self.column.is_empty() {
            write!(f, ", column `{}`", self.column)?;
        }
        write!(f, ": {}", self.what)
    }
}

impl std::error::Error for SessionError {}

/// A recorded operator session: samples of insertion (m, cumulative) and
/// rotation (rad, cumulative) in increasing time (s), played back by linear
/// interpolation (the nearest sample holds outside the recorded span).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Session {
    /// Samples as control keys.
    pub timeline: ControlTimeline,
}

impl Session {
    /// Read a session CSV (see [`Session::parse`]).
    pub fn load(path: &Path) -> Result<Self, SessionError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| SessionError {
            file: file.clone(),
            line: 0,
            column: String::new(),
            what: e.to_string(),
        })?;
        Self::parse(&file, &text)
    }

    /// Parse CSV text whose header names the columns `t`, `insertion` and
    /// `rotation` (any order; further columns, e.g. recorded forces, are
    /// ignored; `#` lines and blank lines are skipped). Times must increase
    /// strictly. Errors name the line and column.
    pub fn parse(file: &str, text: &str) -> Result<Self, SessionError> {
        let err = |line: usize, column: &str, what: String| SessionError {
            file: file.to_string(),
            line,
            column: column.to_string(),
            what,
        };
        let rows = table::rows(text, true).map_err(|(line, what)| err(line, "", what))?;
        let (header, samples) = rows
            .split_first()
            .ok_or_else(|| err(0, "", "empty session: no header line".into()))?;
        let hl = header.line;
        let col = |name: &str| {
            table::column(&header.cells, name).ok_or_else(|| {
                let line = text.lines().nth(hl - 1).unwrap_or("").trim();
                err(hl, name, format!("header `{line}` has no `{name}` column"))
            })
        };
        let (ct, ci, cr) = (col("t")?, col("insertion")?, col("rotation")?);
        let names = &header.cells;
        let mut keys: Vec<ControlKey> = Vec::new();
        for row in samples {
            let (ln, cells) = (row.line, &row.cells);
            if cells.len() != names.len() {
                return Err(err(
                    ln,
                    "",
                    format!("{} fields, header has {}", cells.len(), names.len()),
                ));
            }
            let num = |c: usize| {
                cells[c]
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| err(ln, &names[c], format!("`{}` is not a finite number", &cells[c])))
            };
            let key = ControlKey::feed(num(ct)?, num(ci)?, num(cr)?);
            if let Some(prev) = keys.last().filter(|prev| !(key.t > prev.t)) {
                return Err(err(
                    ln,
                    "t",
                    format!("time {} does not increase (previous {})", key.t, prev.t),
                ));
            }
            keys.push(key);
        }
        if keys.is_empty() {
            return Err(err(hl, "", "session has a header but no samples".into()));
        }
        Ok(Self {
            timeline: ControlTimeline { keys },
        })
    }

    /// Number of distinct rotation commands: maximal runs of consecutive
    /// samples over which the rotation changes.
    pub fn rotation_commands(&self) -> usize {
        let k = &self.timeline.keys;
        let mut count = 0;
        let mut moving = false;
        for w in k.windows(2) {
            let m = w[1].rotation != w[0].rotation;
            if m && !moving {
                count += 1;
            }
            moving = m;
        }
        count
    }

    /// Time of the last sample (s).
    pub fn duration(&self) -> f64 {
        self.timeline.keys.last().map_or(0.0, |k| k.t)
    }
}

/// Plays a [`Session`] and records every feedback rendered.
#[derive(Debug, Clone, Default)]
pub struct ReplayDevice {
    session: Session,
    log: Vec<(DeviceCommand, Feedback)>,
    pending: Option<DeviceCommand>,
}

impl ReplayDevice {
    /// A device playing `session` from its start.
    pub fn new(session: Session) -> Self {
        Self {
            session,
            log: Vec::new(),
            pending: None,
        }
    }

    /// The session played.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// Commands issued and the feedback rendered after each, in order.
    pub fn rendered(&self) -> &[(DeviceCommand, Feedback)] {
        &self.log
    }

    /// Write the recording as CSV
    /// `t,insertion,rotation,fx,fy,fz,tx,ty,tz` (s, m, rad, N, N m); it reads
    /// back with [`Session::load`]. Numbers are written in Rust's shortest
    /// round-trip form, so a re-read session is bit-identical.
    pub fn write_csv(&self, path: &Path) -> std::io::Result<()> {
        std::fs::write(path, self.to_csv())
    }

    /// The recording as CSV text (see [`ReplayDevice::write_csv`]).
    pub fn to_csv(&self) -> String {
        let mut s = String::from("t,insertion,rotation,fx,fy,fz,tx,ty,tz\n");
        for (c, f) in &self.log {
            s.push_str(&format!(
                "{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?}\n",
                f.t, c.insertion, c.rotation, f.force.x, f.force.y, f.force.z, f.torque.x, f.torque.y, f.torque.z
            ));
        }
        s
    }
}

impl HapticDevice for ReplayDevice {
    fn command(&mut self, t: f64) -> DeviceCommand {
        let c = self.session.timeline.command_at(t);
        self.pending = Some(c);
        c
    }
    fn render(&mut self, feedback: &Feedback) {
        let c = self
            .pending
            .take()
            .unwrap_or_else(|| self.session.timeline.command_at(feedback.t));
        self.log.push((c, *feedback));
    }
}
