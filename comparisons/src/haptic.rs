//! The fixed-rate haptic loop: step a model at 1 kHz (or any rate) against
//! the wall clock on its own thread and report deadline misses, latency
//! percentiles and jitter.
//!
//! Tick `k` is scheduled at `start + k / rate`. At each tick the loop asks
//! the device for its command at simulated time `t_{k+1} = (k + 1) / rate`,
//! advances the model by one period (in `ceil(period / model.dt())` equal
//! substeps), observes it and renders the hand force and torque. Then it
//! sleeps (and spins for the last 100 us) until the next tick.
//!
//! - *latency*: wall time from a tick's scheduled start to its render;
//! - *deadline miss*: a tick whose render came after the next tick's
//!   scheduled start (the device would have rendered stale force);
//! - *jitter*: how late ticks start, `actual - scheduled` (s), summarized by
//!   its mean and maximum.
//!
//! The simulated result does not depend on timing: the model sees the same
//! commands and time steps however late a tick runs, so two runs render
//! bit-identical feedback (checked in `tests/vessel_haptic.rs`).

use crate::runner::short;
use crate::scenario::UsageError;
use std::fmt;
use std::time::{Duration, Instant};
use surgbench_core::haptic::{Feedback, HapticDevice};
use surgbench_core::{DeviceCommand, Model};
use surgbench_reports::Status;

/// What one haptic loop measured.
#[derive(Debug, Clone, Default)]
pub struct HapticReport {
    /// Loop rate (Hz).
    pub rate_hz: f64,
    /// Requested duration (s).
    pub duration_s: f64,
    /// Ticks run.
    pub ticks: usize,
    /// Model substeps per tick.
    pub substeps: usize,
    /// Ticks that rendered after the next tick's deadline.
    pub deadline_misses: usize,
    /// Median latency, scheduled start to render (ms).
    pub latency_p50_ms: f64,
    /// 95th percentile latency (ms).
    pub latency_p95_ms: f64,
    /// 99th percentile latency (ms).
    pub latency_p99_ms: f64,
    /// Largest latency (ms).
    pub latency_max_ms: f64,
    /// Mean lateness of tick starts (ms).
    pub jitter_mean_ms: f64,
    /// Largest lateness of a tick start (ms).
    pub jitter_max_ms: f64,
    /// Wall time of the whole loop (s).
    pub wall_s: f64,
    /// Why the loop stopped early (a model error), if it did.
    pub stopped: Option<String>,
    /// Commands sent to the model, one per tick.
    pub commands: Vec<DeviceCommand>,
    /// Feedback rendered, one per tick.
    pub feedback: Vec<Feedback>,
}

impl HapticReport {
    /// This loop as a row of the report's `haptic.csv`; `fidelity` is the
    /// fidelity the model ran at.
    pub fn row(&self, model: &str, scenario: &str, fidelity: &str) -> surgbench_reports::HapticRow {
        surgbench_reports::HapticRow {
            model: model.into(),
            scenario: scenario.into(),
            fidelity: fidelity.into(),
            status: if self.stopped.is_some() {
                Status::Stopped
            } else {
                Status::Ok
            },
            reason: self.stopped.clone().unwrap_or_default(),
            rate_hz: self.rate_hz,
            duration_s: self.duration_s,
            ticks: Some(self.ticks as f64),
            substeps: Some(self.substeps as f64),
            deadline_misses: Some(self.deadline_misses as f64),
            latency_p50_ms: Some(self.latency_p50_ms),
            latency_p99_ms: Some(self.latency_p99_ms),
            latency_max_ms: Some(self.latency_max_ms),
            jitter_max_ms: Some(self.jitter_max_ms),
        }
    }

    /// Fraction of ticks that missed their deadline.
    pub fn miss_ratio(&self) -> f64 {
        if self.ticks == 0 {
            0.0
        } else {
            self.deadline_misses as f64 / self.ticks as f64
        }
    }
}

impl fmt::Display for HapticReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{:<22} {:>14}", "metric", "value")?;
        writeln!(f, "{:<22} {:>14.1}", "rate (Hz)", self.rate_hz)?;
        writeln!(f, "{:<22} {:>14}", "ticks", self.ticks)?;
        writeln!(f, "{:<22} {:>14}", "substeps per tick", self.substeps)?;
        writeln!(
            f,
            "{:<22} {:>14}",
            "deadline misses",
            format!("{} ({:.2}%)", self.deadline_misses, 100.0 * self.miss_ratio())
        )?;
        for (name, v) in [
            ("latency p50 (ms)", self.latency_p50_ms),
            ("latency p95 (ms)", self.latency_p95_ms),
            ("latency p99 (ms)", self.latency_p99_ms),
            ("latency max (ms)", self.latency_max_ms),
            ("jitter mean (ms)", self.jitter_mean_ms),
            ("jitter max (ms)", self.jitter_max_ms),
        ] {
            writeln!(f, "{name:<22} {v:>14.4}")?;
        }
        writeln!(f, "{:<22} {:>14.3}", "wall time (s)", self.wall_s)?;
        if let Some(s) = &self.stopped {
            writeln!(f, "stopped early: {s}")?;
        }
        Ok(())
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// Sleep until `t`, then spin for the last 100 us (sleep alone wakes late).
fn wait_until(t: Instant) {
    let spin = Duration::from_micros(100);
    loop {
        let now = Instant::now();
        if now >= t {
            return;
        }
        let left = t - now;
        if left > spin {
            std::thread::sleep(left - spin);
        } else {
            std::hint::spin_loop();
        }
    }
}

impl HapticReport {
    /// Fill the latency percentiles and jitter from every tick's latency
    /// and start lateness (s).
    fn summarize(&mut self, mut latency: Vec<f64>, lateness: &[f64]) {
        latency.sort_by(f64::total_cmp);
        self.latency_p50_ms = 1e3 * percentile(&latency, 0.5);
        self.latency_p95_ms = 1e3 * percentile(&latency, 0.95);
        self.latency_p99_ms = 1e3 * percentile(&latency, 0.99);
        self.latency_max_ms = 1e3 * latency.last().copied().unwrap_or(f64::NAN);
        self.jitter_mean_ms = 1e3 * lateness.iter().sum::<f64>() / lateness.len().max(1) as f64;
        self.jitter_max_ms = 1e3 * lateness.iter().copied().fold(0.0, f64::max);
    }
}

/// Run `model` against `device` at `rate_hz` for `duration_s` seconds of
/// wall (and simulated) time on a dedicated thread; see the module docs.
/// The device is borrowed, so a [`surgbench_core::haptic::ReplayDevice`]
/// can write its recording afterwards. A model error stops the loop and is
/// reported in [`HapticReport::stopped`]; a loop of more model steps than
/// [`crate::runner::MAX_STEPS`] is a usage error.
pub fn run_haptic_loop(
    model: Box<dyn Model>,
    device: &mut dyn HapticDevice,
    rate_hz: f64,
    duration_s: f64,
) -> Result<HapticReport, UsageError> {
    let (ticks, substeps) = loop_plan(model.dt(), rate_hz, duration_s)?;
    std::thread::scope(|scope| {
        let handle = std::thread::Builder::new()
            .name("haptic-loop".into())
            .spawn_scoped(scope, move || {
                let rep = HapticReport {
                    rate_hz,
                    duration_s,
                    substeps,
                    ..Default::default()
                };
                tick_loop(model, device, rep, ticks)
            })
            .map_err(|e| UsageError(format!("cannot start the haptic thread: {e}")))?;
        handle
            .join()
            .map_err(|_| UsageError("the haptic thread panicked (a model panicked inside step or observe)".into()))
    })
}

/// The loop's ticks and model steps per tick for a model of time step `mdt`
/// (s); a rate, duration or step count out of range is a usage error.
fn loop_plan(mdt: f64, rate_hz: f64, duration_s: f64) -> Result<(usize, usize), UsageError> {
    if !(rate_hz > 0.0 && rate_hz.is_finite() && rate_hz <= 1e6) {
        return Err(UsageError(format!("haptic rate must be in (0, 1e6] Hz, got {rate_hz}")));
    }
    if !(duration_s > 0.0 && duration_s.is_finite()) {
        return Err(UsageError(format!("haptic duration must be > 0 s, got {duration_s}")));
    }
    let ticks = (duration_s * rate_hz).round().max(1.0);
    let period = 1.0 / rate_hz;
    let substeps = if mdt > 0.0 && mdt.is_finite() {
        (period / mdt * (1.0 - 1e-12)).ceil().max(1.0)
    } else {
        1.0
    };
    // The model steps of the whole loop, bounded like a run's.
    let max = crate::runner::MAX_STEPS as f64;
    if !(ticks * substeps <= max) {
        return Err(UsageError(format!(
            "haptic loop of {} s at {} Hz with the model's dt {} s is {} ticks of {} steps, more than the {max:.0e} steps a run may take (shorten --duration or raise dt)",
            short(duration_s),
            short(rate_hz),
            short(mdt),
            short(ticks),
            short(substeps)
        )));
    }
    Ok((ticks as usize, substeps as usize))
}

/// The body of the haptic thread: `ticks` ticks of `rep.substeps` model
/// steps each at `rep.rate_hz`, filling `rep`.
fn tick_loop(
    mut model: Box<dyn Model>,
    device: &mut dyn HapticDevice,
    mut rep: HapticReport,
    ticks: usize,
) -> HapticReport {
    let period = 1.0 / rep.rate_hz;
    let substeps = rep.substeps;
    let dt = period / substeps as f64;
    // Grown as the loop goes, like a run's records.
    let (mut latency, mut lateness) = (Vec::new(), Vec::new());
    let start = Instant::now();
    'ticks: for k in 0..ticks {
        let scheduled = start + Duration::from_secs_f64(k as f64 * period);
        wait_until(scheduled);
        lateness.push((Instant::now() - scheduled).as_secs_f64());
        let t = (k + 1) as f64 * period;
        let cmd = device.command(t);
        for _ in 0..substeps {
            if let Err(e) = model.step(dt, &cmd) {
                rep.stopped = Some(e.to_string());
                break 'ticks;
            }
        }
        let obs = model.observe();
        let fb = Feedback {
            t,
            force: obs.hand_force,
            torque: obs.hand_torque,
        };
        device.render(&fb);
        let done = Instant::now();
        latency.push((done - scheduled).as_secs_f64());
        if done > scheduled + Duration::from_secs_f64(period) {
            rep.deadline_misses += 1;
        }
        rep.commands.push(cmd);
        rep.feedback.push(fb);
        rep.ticks = k + 1;
    }
    rep.wall_s = start.elapsed().as_secs_f64();
    rep.summarize(latency, &lateness);
    rep
}
