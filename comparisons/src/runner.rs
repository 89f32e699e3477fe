//! Running one scenario x model x fidelity: warm-up, per-step timing,
//! stability watchdogs, scoring, and the files `run-one` writes.
//!
//! Only `Model::step` is inside the timed region; observing, watchdogs and
//! scoring are outside it. Repeats rebuild the model from scratch and must
//! reproduce the first run bit for bit, or the run is marked failed.

use crate::scenario::{Params, Scenario, ScenarioRun, Scorer, UsageError};
use nalgebra::UnitQuaternion;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;
use surgbench_core::{
    BuildError, DeviceCommand, Fidelity, Iso3, LoadRamp, ModelFactory, Observation, Scene, Setting, Settings, Vec3,
};
use surgbench_reports::{End, FidelityValue, NodeState, Outcome, Status};

/// A run cannot count as settled before this many steps: a model at rest
/// before the load acts must not pass for one at equilibrium. A step after
/// the first that begins once the scene's inputs are held and leaves a
/// state that has moved exactly where it was ([`unmoved`]) is equilibrium
/// at any step count: a quasi-static model that solved the whole load in
/// one step settles at its second.
const MIN_SETTLE_STEPS: usize = 10;

/// Relative settle tolerance: besides the scene's absolute speed bound, a
/// run is settled only when `v t <= SETTLE_REL |u|`, with `v` the largest
/// node speed or rod-surface spin speed, `t` the time run and `|u|` the
/// largest displacement from the initial state ([`max_displacement`]). A
/// transient decaying with time constant `tau` still has about `v tau` to
/// go, and `tau <= t` once it has decayed, so the rule bounds the distance
/// left to equilibrium by `SETTLE_REL` of the displacement whatever the
/// scene's length and time scales (an absolute speed alone let a rod at
/// E = 1e20 Pa, whose whole deflection is 1e-13 m, pass after 10 steps).
/// 1e-3: a tenth of the 2 % the static closed-form scenes target (the
/// patch test's 1e-6 is for solvers that reach an exact fixed point, which
/// settles by the fixed-point rule, not by a speed).
const SETTLE_REL: f64 = 1e-3;

/// Largest displacement (m) of `cur` from `first`: of a rod or tissue
/// node, or of a point on a rod's surface as its frames turned (a rod
/// twisting in place moves no node).
fn max_displacement(first: &Observation, cur: &Observation, radii: &[f64]) -> f64 {
    let rods = first
        .rods
        .iter()
        .zip(&cur.rods)
        .flat_map(|(a, b)| a.nodes.iter().zip(&b.nodes));
    let tissues = first
        .tissues
        .iter()
        .zip(&cur.tissues)
        .flat_map(|(a, b)| a.nodes.iter().zip(&b.nodes));
    let nodes = rods.chain(tissues).map(|(a, b)| (b - a).norm()).fold(0.0, f64::max);
    nodes.max(surface_turn(first, cur, radii))
}

/// Whether a step left every rod node and frame and every tissue node
/// bit for bit where it was: a fixed point of the model's step.
fn unmoved(prev: &Observation, cur: &Observation) -> bool {
    let rods = prev.rods.len() == cur.rods.len()
        && prev
            .rods
            .iter()
            .zip(&cur.rods)
            .all(|(a, b)| a.nodes == b.nodes && a.frames == b.frames);
    let tissues = prev.tissues.len() == cur.tissues.len()
        && prev.tissues.iter().zip(&cur.tissues).all(|(a, b)| a.nodes == b.nodes);
    rods && tissues
}

/// The fastest a point on a rod's surface moves as its material frames turn
/// from `prev` to `cur` over `dt` (m/s): per edge, the rotation angle of
/// `prev^T cur` over `dt`, times the rod's radius (`radii`, scene order).
/// A rod twisting in place moves no node, so node speeds alone would call
/// it settled before its twist has spread. The angle is `atan2(|axial|,
/// (tr - 1)/2)` of the relative rotation, accurate for small angles where
/// `acos` of the trace loses half the digits.
fn surface_spin_speed(prev: &Observation, cur: &Observation, dt: f64, radii: &[f64]) -> f64 {
    surface_turn(prev, cur, radii) / dt
}

/// The farthest a point on a rod's surface moved as its material frames
/// turned from `prev` to `cur` (m): per edge, the rotation angle of
/// `prev^T cur` times the rod's radius (`radii`, scene order).
fn surface_turn(prev: &Observation, cur: &Observation, radii: &[f64]) -> f64 {
    let mut farthest: f64 = 0.0;
    for ((p, c), r) in prev.rods.iter().zip(&cur.rods).zip(radii) {
        for (fp, fc) in p.frames.iter().zip(&c.frames) {
            let m = fp.transpose() * fc;
            let axial = Vec3::new(m[(2, 1)] - m[(1, 2)], m[(0, 2)] - m[(2, 0)], m[(1, 0)] - m[(0, 1)]);
            let angle = (0.5 * axial.norm()).atan2(0.5 * (m.trace() - 1.0));
            farthest = farthest.max(angle.abs() * r);
        }
    }
    farthest
}

/// Most model steps one run (or one haptic loop) may take: 1e8. A run's
/// buffers grow with its steps (12 bytes a step for the timing and solver
/// iteration records, so at most about 1.2 GB here, 2.4 GB while a vector
/// doubles), and at the fastest models' ~1 us a step 1e8 steps are
/// minutes of work, hours for most: a run past the bound comes from a
/// mistyped duration, time step or material constant (the models' stable
/// time step shrinks with stiffness and lightness), so it is refused as a
/// usage error before anything runs or is written.
pub const MAX_STEPS: usize = 100_000_000;

/// `v` for a message: plain in [1e-3, 1e4), else scientific with four
/// significant digits (`1e300`, `1.435e-151`).
pub(crate) fn short(v: f64) -> String {
    if v == 0.0 || (1e-3..1e4).contains(&v.abs()) || !v.is_finite() {
        return format!("{v}");
    }
    let s = format!("{v:.3e}");
    let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
    format!("{mantissa}e{exp}")
}

/// The number of steps of `duration` (s) at `dt` (s), `ceil(duration / dt)`
/// and at least 1, or a usage error naming both and [`MAX_STEPS`] when it
/// is larger than the bound (or `dt` is not a positive number).
pub fn check_steps(duration: f64, dt: f64) -> Result<usize, UsageError> {
    let steps = (duration / dt).ceil().max(1.0);
    if !(dt > 0.0 && steps <= MAX_STEPS as f64) {
        return Err(UsageError(format!(
            "duration {} s at dt {} s is {} steps, more than the {MAX_STEPS:.0e} steps a run may take (shorten the duration or raise dt; a stiffer or lighter material needs a smaller stable dt)",
            short(duration),
            short(dt),
            short(steps)
        )));
    }
    Ok(steps as usize)
}

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Full repeats of the run (timings pooled; results must be identical).
    pub repeats: usize,
    /// After the first repeat, a further one starts only while the repeats
    /// so far (builds included) took less than this wall time (s): a long
    /// run's hundreds of steps already give its ms/step distribution, and
    /// its repeats would cost more than they tell. Infinite: always
    /// `repeats`. The repeats done are the summary's `repeats`.
    pub repeat_budget_s: f64,
    /// Steps excluded from timing at the start of each repeat.
    pub warmup: usize,
    /// Keep roughly this many samples of the time series.
    pub samples: usize,
    /// Largest relative edge stretch before the stretch watchdog trips.
    pub stretch_limit: f64,
}

impl Default for RunOptions {
    fn default() -> Self {
        Self {
            repeats: 1,
            repeat_budget_s: f64::INFINITY,
            warmup: 5,
            samples: 400,
            stretch_limit: 0.05,
        }
    }
}

pub use surgbench_reports::{RunSummary, Sample};

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

/// Peak resident set size (MB) from `/proc/self/status` (`VmHWM`), if any.
pub fn peak_rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Work done on the bodies by the operator's hand (J), integrated along the
/// run by the trapezoidal rule, so the energy watchdog can tell injected
/// energy from energy the hand put in.
///
/// The clamp of a single rod moves by `d insertion` along its base tangent
/// (local +x of `RodBody::base`, or of the commanded `base_pose`) and turns
/// by `d rotation` about it; the hand feels `Observation::hand_force` and
/// `hand_torque`, so it does `W = -int (F . dx + tau . dtheta)` on the rod.
/// A tissue whose driven nodes share one displacement `d` moves by
/// `d load * d`. Scenes where the clamp motion is not one rigid motion
/// (several driven bodies, non-uniform driven displacements) are not
/// accounted (`None`): their watchdog sees the raw energy growth.
///
/// A rod whose tip force follows a `LoadRamp` changes its dead-load
/// potential `V = -s(t) F . x_tip` while the tip stands still; that energy,
/// `-int s'(t) F . x_tip dt`, is counted here too (trapezoidal in `x_tip`).
/// A ramped tip torque has no potential the models report and is not counted.
#[derive(Debug, Clone)]
pub struct HandWork {
    drive: Drive,
    last: Option<(Vec3, UnitQuaternion<f64>, Vec3, Vec3)>,
    /// The one rod's ramped tip load, if any.
    ramp: Option<RampedLoad>,
    /// Work done so far (J).
    pub work: f64,
}

/// A rod's ramped tip load as the energy watchdog accounts it.
#[derive(Debug, Clone)]
struct RampedLoad {
    ramp: LoadRamp,
    /// Full tip force (N, world frame).
    force: Vec3,
    /// Scale and tip position (m) at the last recorded step.
    last: Option<(f64, Vec3)>,
}

/// How the hand moves the bodies.
#[derive(Debug, Clone, Copy)]
enum Drive {
    /// One rod clamped at this pose (overridden by a commanded base pose).
    Rod(Iso3),
    /// One tissue whose driven nodes all move by `load * d` (m).
    Tissue(Vec3),
    /// Not one rigid clamp motion: not accounted.
    Unknown,
}

impl HandWork {
    /// Set up for `scene`, before its first step.
    pub fn new(scene: &Scene) -> Self {
        let rods: Vec<_> = scene.rods().collect();
        let tissues: Vec<_> = scene.tissues().filter(|t| !t.driven_nodes.is_empty()).collect();
        let drive = match (rods.as_slice(), tissues.as_slice()) {
            ([rod], []) => Drive::Rod(rod.base),
            ([], [t]) => {
                let d = t.driven_nodes[0].1;
                if t.driven_nodes.iter().all(|(_, e)| *e == d) {
                    Drive::Tissue(d)
                } else {
                    Drive::Unknown
                }
            }
            _ => Drive::Unknown,
        };
        let ramp = match rods.as_slice() {
            [rod] if rod.tip_force != Vec3::zeros() => rod.tip_load_ramp.clone().map(|ramp| RampedLoad {
                ramp,
                force: rod.tip_force,
                last: None,
            }),
            _ => None,
        };
        Self {
            drive,
            last: None,
            ramp,
            work: 0.0,
        }
    }

    /// Clamp position (m) and orientation under `cmd`.
    fn clamp(&self, cmd: &DeviceCommand) -> Option<(Vec3, UnitQuaternion<f64>)> {
        match self.drive {
            Drive::Rod(base) => {
                let pose = cmd.base_pose.unwrap_or(base);
                let tangent = pose.rotation * Vec3::x();
                let turn = UnitQuaternion::from_scaled_axis(cmd.rotation * tangent);
                Some((pose.translation.vector + cmd.insertion * tangent, turn * pose.rotation))
            }
            Drive::Tissue(d) => Some((cmd.load * d, UnitQuaternion::identity())),
            Drive::Unknown => None,
        }
    }

    /// Account for the step that ended with `cmd` applied and `obs` observed
    /// (call once with the initial command and observation first).
    pub fn record(&mut self, cmd: &DeviceCommand, obs: &Observation) {
        if let (Some(r), Some(tip)) = (&mut self.ramp, obs.rods.first().map(|r| r.tip())) {
            let s = r.ramp.scale_at(obs.time);
            if let Some((s0, tip0)) = r.last {
                self.work -= (s - s0) * r.force.dot(&(0.5 * (tip + tip0)));
            }
            r.last = Some((s, tip));
        }
        let Some((x, q)) = self.clamp(cmd) else {
            return;
        };
        let (f, tau) = (obs.hand_force, obs.hand_torque);
        if let Some((x0, q0, f0, tau0)) = &self.last {
            let dtheta = (q * q0.inverse()).scaled_axis();
            self.work -= 0.5 * ((f + f0).dot(&(x - x0)) + (tau + tau0).dot(&dtheta));
        }
        self.last = Some((x, q, f, tau));
    }
}

/// The watchdogs: the first one that trips, with what it saw. `hand_work`
/// (J) is the work the hand did on the bodies so far: only energy beyond it
/// counts as growth.
fn watchdog(obs: &Observation, run: &ScenarioRun, e0: f64, hand_work: f64, opts: &RunOptions) -> Option<String> {
    if !obs.is_finite() {
        return Some("non-finite state".into());
    }
    let bound = 10.0 * run.length_scale();
    for r in &obs.rods {
        if let Some(x) = r.nodes.iter().find(|x| x.norm() > bound) {
            return Some(format!("node left the scene: |x| = {:.3e} m > {bound:.3e} m", x.norm()));
        }
        if r.max_stretch.abs() > opts.stretch_limit {
            return Some(format!("stretch {:.3e} > {}", r.max_stretch, opts.stretch_limit));
        }
    }
    let de = obs.energy.total() - e0 - hand_work;
    let limit = 10.0 * run.energy_scale();
    if de > limit {
        return Some(format!(
            "energy grew by {de:.3e} J beyond the hand's work ({hand_work:.3e} J) > {limit:.3e} J"
        ));
    }
    let pen = obs.max_penetration();
    if pen > run.penetration_limit() {
        return Some(format!("penetration {pen:.3e} m > {:.3e} m", run.penetration_limit()));
    }
    None
}

/// What became of one repeat.
struct Repeat {
    steps: usize,
    wall_s: f64,
    t: f64,
    times_ms: Vec<f64>,
    iters: Vec<u32>,
    end: End,
    trip: Option<(String, f64)>,
    series: Vec<Sample>,
    last: Observation,
    /// The scenario's metrics of `last` with this repeat's run-wide sums
    /// (`None` when `last` is not finite).
    errors: Option<BTreeMap<String, f64>>,
    /// The scenario's measured points in `last` (empty when it has none or
    /// `last` is not finite).
    markers: Vec<surgbench_reports::Marker>,
    /// The tip path in its bend plane at `last` (empty when the scene
    /// scores none or `last` is not finite).
    plane_path: Vec<surgbench_reports::PlanePoint>,
}

impl Repeat {
    /// Before the first step, from the initial observation. The per-step
    /// records grow as the run goes: a run that stops early (a watchdog, a
    /// settled scene) never pays for its whole duration.
    fn start(scene: &Scene, first: Observation) -> Self {
        Repeat {
            steps: 0,
            wall_s: 0.0,
            t: 0.0,
            times_ms: Vec::new(),
            iters: Vec::new(),
            end: if scene.settle.is_some() {
                End::TimeLimit
            } else {
                End::Duration
            },
            trip: None,
            series: Vec::new(),
            last: first,
            errors: None,
            markers: Vec::new(),
            plane_path: Vec::new(),
        }
    }
}

/// One point of the time series: tip, hand load, energy and primary error.
fn sample(obs: &Observation, scorer: &dyn Scorer, primary: &str) -> Sample {
    let rod_tip = || {
        let tip = obs.rods.first().map(|r| r.tip()).unwrap_or_default();
        [tip.x, tip.y, tip.z]
    };
    Sample {
        t: obs.time,
        tip: scorer.tracked_point(obs).unwrap_or_else(rod_tip),
        hand_force: [obs.hand_force.x, obs.hand_force.y, obs.hand_force.z],
        hand_torque: [obs.hand_torque.x, obs.hand_torque.y, obs.hand_torque.z],
        energy: obs.energy.total(),
        error: scorer.score(obs).get(primary).copied().unwrap_or(f64::NAN),
        reference_tip: scorer.reference_tip_at(obs.time).unwrap_or([f64::NAN; 3]),
        force: scorer.force_point(obs).map_or([f64::NAN; 2], |(f, r)| [f, r]),
        depth: scorer.force_depth(obs).unwrap_or(f64::NAN),
    }
}

/// Step the model through the scene once (at most `max_steps` steps, from
/// [`check_steps`]), timing each step and watching it.
fn run_repeat(
    model: &mut dyn surgbench_core::Model,
    run: &ScenarioRun,
    primary: &str,
    opts: &RunOptions,
    record: bool,
    max_steps: usize,
) -> Repeat {
    let scene = run.scene();
    let dt = model.dt();
    let every = (max_steps / opts.samples.max(1)).max(1);
    let first = model.observe();
    let initial = first.clone();
    let e0 = first.energy.total();
    let mut hand = HandWork::new(scene);
    hand.record(&scene.control.command_at(0.0), &first);
    let mut scorer = run.scorer();
    let mut rep = Repeat::start(scene, first);
    if record {
        rep.series.push(sample(&rep.last, scorer.as_ref(), primary));
    }
    // The widest section of each rod: its surface moves fastest as it turns.
    let radii: Vec<f64> = scene
        .rods()
        .map(|r| r.sections.iter().map(|s| s.radius).fold(0.0, f64::max))
        .collect();
    let held_from = scene.inputs_held_from();
    for k in 0..max_steps {
        let t = (k + 1) as f64 * dt;
        let cmd = scene.control.command_at(t);
        let start = Instant::now();
        let res = model.step(dt, &cmd);
        let ms = start.elapsed().as_secs_f64() * 1e3;
        rep.wall_s += ms / 1e3;
        rep.steps = k + 1;
        rep.t = t;
        match res {
            Err(e) => {
                rep.trip = Some((e.to_string(), t));
                rep.end = End::Watchdog;
                break;
            }
            Ok(stats) => {
                if k >= opts.warmup {
                    rep.times_ms.push(ms);
                }
                rep.iters.push(stats.iterations);
            }
        }
        let obs = model.observe();
        scorer.observe_step(&obs);
        hand.record(&cmd, &obs);
        if let Some(w) = watchdog(&obs, run, e0, hand.work, opts) {
            rep.trip = Some((w, t));
            rep.end = End::Watchdog;
            rep.last = obs;
            break;
        }
        let settled = scene.settle.is_some_and(|s| {
            if t < s.min_time {
                return false;
            }
            // Each measure once per step, and only when the rule reaches it.
            let disp = std::cell::OnceCell::new();
            let displacement = || *disp.get_or_init(|| max_displacement(&initial, &obs, &radii));
            // A fixed point counts once the model has moved at all: one that
            // ignores its loads would otherwise pass for one at equilibrium.
            let fixed_point = k >= 1
                && held_from.is_some_and(|h| k as f64 * dt >= h)
                && unmoved(&rep.last, &obs)
                && displacement() > 0.0;
            if k + 1 < MIN_SETTLE_STEPS && !fixed_point {
                return false;
            }
            let speed = obs.max_speed().max(surface_spin_speed(&rep.last, &obs, dt, &radii));
            speed < s.velocity_tol && speed * t <= SETTLE_REL * displacement()
        });
        if record && (k % every == every - 1 || settled || k + 1 == max_steps) {
            rep.series.push(sample(&obs, scorer.as_ref(), primary));
        }
        rep.last = obs;
        if settled {
            rep.end = End::Settled;
            break;
        }
    }
    if rep.last.is_finite() {
        rep.errors = Some(scorer.score(&rep.last));
        rep.markers = scorer.markers(&rep.last);
        rep.plane_path = scorer.plane_path(&rep.last);
    }
    rep
}

/// Run one scenario instance with one model at one fidelity.
///
/// Unsupported scenes and runs that trip a watchdog are results, not errors;
/// a bad fidelity knob is a [`UsageError`].
pub fn run_single(
    scenario: &dyn Scenario,
    params: &Params,
    run: &ScenarioRun,
    factory: &dyn ModelFactory,
    fidelity: &Fidelity,
    opts: &RunOptions,
) -> Result<RunSummary, UsageError> {
    let scene = run.scene();
    let (support, fid) = match surgbench_core::resolve(factory, scene, fidelity) {
        Ok(settings) => {
            let fid = settings.fidelity().clone();
            (Ok(settings), fid)
        }
        Err(BuildError::Unsupported(u)) => (Err(u.reason), factory.default_fidelity(scene).merged(fidelity)),
        Err(e) => return Err(bad_build(factory, e)),
    };
    run_checked(
        scenario,
        params,
        run,
        factory,
        support.as_ref().map_err(String::clone),
        &fid,
        opts,
    )
}

/// [`run_single`] for a scene whose model settings are already resolved
/// (`support`: the settings, or why the model cannot run the scene), with
/// `fid` the full fidelity (the model's defaults merged) to report.
pub fn run_checked(
    scenario: &dyn Scenario,
    params: &Params,
    run: &ScenarioRun,
    factory: &dyn ModelFactory,
    support: Result<&Settings, String>,
    fid: &Fidelity,
    opts: &RunOptions,
) -> Result<RunSummary, UsageError> {
    let mut s = RunSummary {
        scenario: scenario.id().into(),
        model: factory.id().into(),
        params: params.values().clone(),
        overrides: params.overrides_string(),
        fidelity: fid.pairs().into_iter().map(|(k, v)| (k, knob_value(v))).collect(),
        fidelity_string: fid.to_string(),
        outcome: Outcome {
            steps: Some(0.0),
            sim_time_s: Some(0.0),
            stable: Some(false),
            ..Default::default()
        },
        primary_error: scenario.primary_error().into(),
        reference_tip: run.reference_tip(),
        repeats: opts.repeats.max(1),
        ..Default::default()
    };
    let settings = match support {
        Ok(settings) => settings,
        Err(reason) => {
            s.status = Status::Unsupported;
            s.reason = reason;
            return Ok(s);
        }
    };
    let reps = match run_repeats(scenario, run, factory, settings, opts)? {
        Ok(reps) => reps,
        Err(reason) => {
            s.status = Status::Unsupported;
            s.reason = reason;
            return Ok(s);
        }
    };
    s.build_ms = Some(reps.build_ms);
    s.repeats = reps.done;
    record_timing(&mut s.outcome, &reps);
    record_verdict(&mut s.outcome, &reps);
    let rep = reps.first;
    if let Some(errors) = rep.errors {
        flag_non_finite(&mut s.outcome, &errors);
        s.errors = errors;
        // The model's own diagnostics, prefixed so they never shadow a
        // scenario metric.
        for (k, v) in reps.diagnostics {
            if v.is_finite() {
                s.errors.insert(format!("diag_{k}"), v);
            }
        }
        s.tip = rep.last.rods.first().map(|r| {
            let t = r.tip();
            [t.x, t.y, t.z]
        });
    }
    s.series = rep.series;
    s.final_state = final_state(&rep.last);
    s.reference_centreline = run.reference_centreline().to_vec();
    s.markers = rep.markers;
    s.plane_path = rep.plane_path;
    Ok(s)
}

/// Every repeat of a run: the first in full, the pooled timings of all.
struct Repeats {
    first: Repeat,
    build_ms: f64,
    diagnostics: BTreeMap<String, f64>,
    times_ms: Vec<f64>,
    iters: Vec<f64>,
    /// Repeats done (at most `RunOptions::repeats`, fewer once
    /// `RunOptions::repeat_budget_s` is spent).
    done: usize,
    /// Why the run is not reproducible, if it is not.
    nondeterministic: Option<String>,
}

/// A built model and its build time (ms).
type Built = (Box<dyn surgbench_core::Model>, f64);

/// A fresh model for the scene and its build time (ms). The inner `Err` is
/// the model's refusal to build the scene (unsupported), the outer a bad knob.
fn build_model(
    factory: &dyn ModelFactory,
    scene: &Scene,
    settings: &Settings,
) -> Result<Result<Built, String>, UsageError> {
    let t0 = Instant::now();
    match factory.build_resolved(scene, settings) {
        Ok(m) => Ok(Ok((m, t0.elapsed().as_secs_f64() * 1e3))),
        Err(BuildError::Unsupported(u)) => Ok(Err(u.reason)),
        Err(e) => Err(bad_build(factory, e)),
    }
}

/// A model's bad knob or scene as a [`UsageError`] naming the model.
fn bad_build(factory: &dyn ModelFactory, e: BuildError) -> UsageError {
    UsageError(format!("model `{}`: {e}", factory.id()))
}

/// A fidelity knob as the run summary records it.
fn knob_value(v: Setting) -> FidelityValue {
    match v {
        Setting::Number(x) => FidelityValue::Number(x),
        Setting::Choice(n) => FidelityValue::Name(n),
    }
}

/// Build and run the model `opts.repeats` times (errors as [`build_model`]).
fn run_repeats(
    scenario: &dyn Scenario,
    run: &ScenarioRun,
    factory: &dyn ModelFactory,
    settings: &Settings,
    opts: &RunOptions,
) -> Result<Result<Repeats, String>, UsageError> {
    let primary = scenario.primary_error();
    let start = Instant::now();
    let (mut model, build_ms) = match build_model(factory, run.scene(), settings)? {
        Ok(m) => m,
        Err(reason) => return Ok(Err(reason)),
    };
    // The model's own time step decides the step count: checked here too,
    // since a model may choose it from the material when no `dt` is given.
    let max_steps = check_steps(run.scene().duration, model.dt())
        .map_err(|e| UsageError(format!("model `{}`: {e}", factory.id())))?;
    let first = run_repeat(model.as_mut(), run, primary, opts, true, max_steps);
    let mut reps = Repeats {
        build_ms,
        diagnostics: model.diagnostics(),
        times_ms: first.times_ms.clone(),
        iters: first.iters.iter().map(|&i| i as f64).collect(),
        done: 1,
        nondeterministic: None,
        first,
    };
    for r in 1..opts.repeats.max(1) {
        if start.elapsed().as_secs_f64() >= opts.repeat_budget_s {
            break;
        }
        let mut model = match build_model(factory, run.scene(), settings)? {
            Ok((m, _)) => m,
            Err(reason) => return Ok(Err(reason)),
        };
        let rep = run_repeat(model.as_mut(), run, primary, opts, false, max_steps);
        reps.times_ms.extend_from_slice(&rep.times_ms);
        reps.iters.extend(rep.iters.iter().map(|&i| i as f64));
        reps.done += 1;
        if reps.first.last != rep.last || reps.first.steps != rep.steps {
            reps.nondeterministic = Some(format!("non-deterministic: repeat {r} differs from repeat 0"));
        }
    }
    Ok(Ok(reps))
}

/// Steps, simulated time and the timing statistics of `reps`.
fn record_timing(o: &mut Outcome, reps: &Repeats) {
    let rep = &reps.first;
    o.steps = Some(rep.steps as f64);
    o.sim_time_s = Some(rep.t);
    o.solve_wall_s = Some(rep.wall_s);
    o.end = rep.end;
    let times = &reps.times_ms;
    if !times.is_empty() {
        let mut sorted = times.clone();
        sorted.sort_by(f64::total_cmp);
        let total: f64 = times.iter().sum();
        o.ms_per_step_median = Some(percentile(&sorted, 0.5));
        o.ms_per_step_p95 = Some(percentile(&sorted, 0.95));
        o.ms_per_step_max = sorted.last().copied();
        o.steps_per_s = Some(times.len() as f64 / (total / 1e3));
        let dt = rep.t / rep.steps as f64;
        o.real_time_factor = Some(times.len() as f64 * dt / (total / 1e3));
    }
    let iters = &reps.iters;
    if !iters.is_empty() {
        o.solver_iters_mean = Some(iters.iter().sum::<f64>() / iters.len() as f64);
        o.solver_iters_max = iters.iter().copied().reduce(f64::max);
    }
    o.peak_rss_mb = peak_rss_mb();
}

/// Status, reason and watchdog of `reps`: a non-reproducible run failed,
/// one that tripped a watchdog is unstable, else ok.
fn record_verdict(o: &mut Outcome, reps: &Repeats) {
    if let Some(reason) = &reps.nondeterministic {
        o.status = Status::Failed;
        o.reason = reason.clone();
    }
    o.stable = Some(reps.first.trip.is_none());
    if let Some((w, t)) = &reps.first.trip {
        o.watchdog = w.clone();
        o.watchdog_t = Some(*t);
        if o.status == Status::Unset {
            o.status = Status::Unstable;
            o.reason = format!("{w} at t={t:.4} s");
        }
    }
    if o.status == Status::Unset {
        o.status = Status::Ok;
    }
}

/// A run whose state stayed finite but whose error metrics are not (an
/// infinite or NaN error against the reference: e.g. reference or phantom
/// data with a value near `f64::MAX`) has no error to report: an `ok` run
/// becomes `failed`, its reason naming the metrics, instead of `ok` with
/// the numbers missing (JSON writes NaN and infinity as `null`).
fn flag_non_finite(o: &mut Outcome, errors: &BTreeMap<String, f64>) {
    let bad: Vec<String> = errors
        .iter()
        .filter(|(_, v)| !v.is_finite())
        .map(|(k, v)| format!("{k} = {v}"))
        .collect();
    if !bad.is_empty() && o.status == Status::Ok {
        o.status = Status::Failed;
        o.reason = format!(
            "error metrics not finite ({}) although the model's state is: check the scenario's reference data",
            bad.join(", ")
        );
    }
}

/// Rest and final positions of every node, rods first, then tissues.
fn final_state(obs: &Observation) -> Vec<NodeState> {
    let bodies = obs
        .rods
        .iter()
        .map(|r| (&r.rest, &r.nodes))
        .chain(obs.tissues.iter().map(|t| (&t.rest, &t.nodes)));
    let mut out = Vec::new();
    for (body, (rest, nodes)) in bodies.enumerate() {
        for (node, (x0, x)) in rest.iter().zip(nodes).enumerate() {
            out.push(NodeState {
                body,
                node,
                rest: [x0.x, x0.y, x0.z],
                x: [x.x, x.y, x.z],
            });
        }
    }
    out
}

/// Write `summary.json`, `observables.csv` and `final_state.csv` into `dir`
/// (which must exist).
pub fn write_run_files(dir: &Path, s: &RunSummary) -> std::io::Result<()> {
    s.write_files(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use surgbench_core::RodBody;

    /// A rod clamp pushed into a linear spring (`k`, N/m) and turned against a
    /// torsion spring (`c`, N m/rad): the hand's work is `k s^2/2 + c theta^2/2`,
    /// integrated exactly by the trapezoidal rule because the forces are linear
    /// in the clamp motion (so the tolerance is rounding).
    #[test]
    fn hand_work_of_linear_springs_is_exact() {
        let (k, c) = (30.0, 0.002);
        let mut scene = Scene::empty("springs");
        let mut rod = RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0);
        rod.base = Iso3::rotation(Vec3::new(0.0, 0.0, 0.7));
        let tangent = rod.base.rotation * Vec3::x();
        scene.bodies.push(rod.into());
        let mut hand = HandWork::new(&scene);
        let (mut s, mut theta) = (0.0, 0.0);
        for i in 0..=100 {
            let t = i as f64 * 0.01;
            let (s1, th1) = (0.02 * t * (1.0 + t), 1.5 * t);
            let cmd = DeviceCommand {
                insertion: s1,
                rotation: th1,
                load: 0.0,
                base_pose: None,
            };
            let obs = Observation {
                hand_force: -k * s1 * tangent,
                hand_torque: -c * th1 * tangent,
                ..Default::default()
            };
            hand.record(&cmd, &obs);
            (s, theta) = (s1, th1);
        }
        let exact = 0.5 * k * s * s + 0.5 * c * theta * theta;
        assert!(
            (hand.work - exact).abs() <= 1e-12 * exact,
            "hand work {} J vs exact {exact} J",
            hand.work
        );
    }

    /// A tip held by a linear spring (`k`, N/m) to the origin under a tip
    /// force ramped from 0 to `F`: quasi-statically `x = s F / k`, and the
    /// energy `k x^2 / 2 - s F . x` falls by `F^2 / (2k)`, all of it the
    /// load change's work `-int s' F . x dt` (exact for the trapezoidal rule
    /// because x is linear in s, so the tolerance is rounding). The clamp
    /// holds still, so the hand itself does nothing.
    #[test]
    fn ramped_tip_load_work_is_counted() {
        let (k, f) = (40.0, Vec3::new(0.3, -0.2, 0.5));
        let mut rod = RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0);
        rod.tip_force = f;
        rod.tip_load_ramp = Some(surgbench_core::LoadRamp::linear(0.1, 0.6));
        let mut scene = Scene::empty("ramp");
        scene.bodies.push(rod.clone().into());
        let mut hand = HandWork::new(&scene);
        let energy = |x: Vec3, s: f64| 0.5 * k * x.norm_squared() - s * f.dot(&x);
        let x_at = |t: f64| rod.tip_force_at(t) / k;
        for i in 0..=80 {
            let t = i as f64 * 0.01;
            let obs = Observation {
                time: t,
                rods: vec![surgbench_core::RodObs {
                    nodes: vec![Vec3::zeros(), x_at(t)],
                    ..Default::default()
                }],
                ..Default::default()
            };
            hand.record(&DeviceCommand::default(), &obs);
        }
        let de = energy(x_at(0.8), 1.0) - energy(x_at(0.0), 0.0);
        assert!(
            (de + f.norm_squared() / (2.0 * k)).abs() <= 1e-12,
            "closed form: energy change {de} J"
        );
        assert!(
            (hand.work - de).abs() <= 1e-12 * de.abs(),
            "ramp work {} J vs energy change {de} J",
            hand.work
        );
    }

    /// Two rods: the clamp motion is not one rigid motion, so nothing is
    /// accounted and the watchdog sees the raw energy.
    /// The step bound: inside it the count is `ceil(duration / dt)`; past it
    /// (or at a dt that is not a positive number) a usage error names the
    /// duration, the dt and the bound.
    #[test]
    fn short_numbers_for_messages() {
        assert_eq!(short(5.0), "5");
        assert_eq!(short(1e300), "1e300");
        assert_eq!(short(1.435194819406226e-151), "1.435e-151");
        assert_eq!(short(1e9), "1e9");
    }

    #[test]
    fn step_bound_is_a_usage_error() {
        // Powers of two for dt: the quotients below are exact.
        assert_eq!(check_steps(1.0, 0.25), Ok(4));
        assert_eq!(check_steps(1e-6, 0.25), Ok(1));
        assert_eq!(check_steps(5e7, 0.5), Ok(MAX_STEPS));
        for (duration, dt) in [
            (5e7 + 0.5, 0.5),
            (1e300, 1e-3),
            (1.0, 1e-300),
            (1e9, 1e-3),
            (1.0, 0.0),
            (1.0, f64::NAN),
        ] {
            let e = check_steps(duration, dt).expect_err("past the bound").0;
            assert!(
                e.contains(&format!("duration {} s", short(duration))) && e.contains("1e8 steps"),
                "duration {duration}, dt {dt}: {e}"
            );
        }
    }

    #[test]
    fn hand_work_is_not_guessed_for_two_rods() {
        let mut scene = Scene::empty("two");
        scene.bodies.push(RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0).into());
        scene.bodies.push(RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0).into());
        let mut hand = HandWork::new(&scene);
        for i in 0..3 {
            let cmd = DeviceCommand {
                insertion: i as f64 * 0.01,
                ..Default::default()
            };
            let obs = Observation {
                hand_force: Vec3::new(-1.0, 0.0, 0.0),
                ..Default::default()
            };
            hand.record(&cmd, &obs);
        }
        assert_eq!(hand.work, 0.0);
    }
}
