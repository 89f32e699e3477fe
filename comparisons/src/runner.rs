//! Running one scenario x model x fidelity: warm-up, per-step timing,
//! stability watchdogs, scoring, and the files `run-one` writes.
//!
//! Only `Model::step` is inside the timed region; observing, watchdogs and
//! scoring are outside it. Repeats rebuild the model from scratch and must
//! reproduce the first run bit for bit, or the run is marked failed.

use crate::scenario::{Params, Scenario, ScenarioRun, Scorer, UsageError};
use nalgebra::UnitQuaternion;
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;
use std::time::Instant;
use surgbench_core::{BuildError, DeviceCommand, Fidelity, Iso3, LoadRamp, ModelFactory, Observation, Scene, Vec3};

/// A run cannot count as settled before this many steps: a model at rest
/// before the load acts must not pass for one at equilibrium.
const MIN_SETTLE_STEPS: usize = 10;

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Full repeats of the run (timings pooled; results must be identical).
    pub repeats: usize,
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
            warmup: 5,
            samples: 400,
            stretch_limit: 0.05,
        }
    }
}

/// One sample of the time series (`observables.csv`).
#[derive(Debug, Clone, Copy, Serialize)]
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
    /// Primary error at this time.
    pub error: f64,
}

/// Everything measured in one run; serialised as `summary.json`.
#[derive(Debug, Clone, Serialize, Default)]
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
    pub fidelity: BTreeMap<String, f64>,
    /// Resolved fidelity as a string.
    pub fidelity_string: String,
    /// `ok`, `unstable`, `unsupported`, `failed`.
    pub status: String,
    /// Why, when not ok.
    pub reason: String,
    /// `settled`, `time-limit`, `duration`, `watchdog`, or empty.
    pub end: String,
    /// Steps taken (first repeat).
    pub steps: usize,
    /// Simulated time reached (s).
    pub sim_time_s: f64,
    /// Median wall time of one step after warm-up (ms).
    pub ms_per_step_median: Option<f64>,
    /// 95th percentile (ms).
    pub ms_per_step_p95: Option<f64>,
    /// Steps per wall second.
    pub steps_per_s: Option<f64>,
    /// Simulated seconds per wall second (> 1 is faster than real time).
    pub real_time_factor: Option<f64>,
    /// Mean solver iterations per step.
    pub solver_iters_mean: Option<f64>,
    /// Largest solver iteration count.
    pub solver_iters_max: Option<f64>,
    /// Peak resident memory of the process (MB), where the OS tells.
    pub peak_rss_mb: Option<f64>,
    /// Model build time (ms).
    pub build_ms: Option<f64>,
    /// Wall time of every step of the first repeat (s): time to solution.
    pub solve_wall_s: Option<f64>,
    /// No watchdog tripped.
    pub stable: bool,
    /// First watchdog that tripped, with what it saw.
    pub watchdog: String,
    /// When it tripped (s).
    pub watchdog_t: Option<f64>,
    /// Headline error metric name.
    pub primary_error: String,
    /// Error metrics against the reference.
    pub errors: BTreeMap<String, f64>,
    /// Final tip position (m).
    pub tip: Option<[f64; 3]>,
    /// Reference tip position (m).
    pub reference_tip: Option<[f64; 3]>,
    /// Repeats run.
    pub repeats: usize,
    /// Time series (not in summary.json; written to observables.csv).
    #[serde(skip)]
    pub series: Vec<Sample>,
    /// Final observation (not serialised; written to final_state.csv).
    #[serde(skip)]
    pub final_obs: Option<Observation>,
}

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
/// `d insertion * d`. Scenes where the clamp motion is not one rigid motion
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
    /// One tissue whose driven nodes all move by `insertion * d` (m).
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
            Drive::Tissue(d) => Some((cmd.insertion * d, UnitQuaternion::identity())),
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
    end: String,
    trip: Option<(String, f64)>,
    series: Vec<Sample>,
    last: Observation,
    /// The scenario's metrics of `last` with this repeat's run-wide sums
    /// (`None` when `last` is not finite).
    errors: Option<BTreeMap<String, f64>>,
}

fn run_repeat(
    model: &mut dyn surgbench_core::Model,
    run: &ScenarioRun,
    primary: &str,
    opts: &RunOptions,
    record: bool,
) -> Repeat {
    let scene = run.scene();
    let dt = model.dt();
    let max_steps = (scene.duration / dt).ceil().max(1.0) as usize;
    let every = (max_steps / opts.samples.max(1)).max(1);
    let first = model.observe();
    let e0 = first.energy.total();
    let mut hand = HandWork::new(scene);
    hand.record(&scene.control.command_at(0.0), &first);
    let mut scorer = run.scorer();
    let mut rep = Repeat {
        steps: 0,
        wall_s: 0.0,
        t: 0.0,
        times_ms: Vec::with_capacity(max_steps),
        iters: Vec::with_capacity(max_steps),
        end: if scene.settle.is_some() {
            "time-limit"
        } else {
            "duration"
        }
        .into(),
        trip: None,
        series: Vec::new(),
        last: first,
        errors: None,
    };
    let sample = |obs: &Observation, scorer: &dyn Scorer| -> Sample {
        let tip = obs.rods.first().map(|r| r.tip()).unwrap_or_default();
        Sample {
            t: obs.time,
            tip: [tip.x, tip.y, tip.z],
            hand_force: [obs.hand_force.x, obs.hand_force.y, obs.hand_force.z],
            hand_torque: [obs.hand_torque.x, obs.hand_torque.y, obs.hand_torque.z],
            energy: obs.energy.total(),
            error: scorer.score(obs).get(primary).copied().unwrap_or(f64::NAN),
        }
    };
    if record {
        rep.series.push(sample(&rep.last, scorer.as_ref()));
    }
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
                rep.end = "watchdog".into();
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
            rep.end = "watchdog".into();
            rep.last = obs;
            break;
        }
        let settled = scene
            .settle
            .is_some_and(|s| k + 1 >= MIN_SETTLE_STEPS && t >= s.min_time && obs.max_speed() < s.velocity_tol);
        if record && (k % every == every - 1 || settled || k + 1 == max_steps) {
            rep.series.push(sample(&obs, scorer.as_ref()));
        }
        rep.last = obs;
        if settled {
            rep.end = "settled".into();
            break;
        }
    }
    if rep.last.is_finite() {
        rep.errors = Some(scorer.score(&rep.last));
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
    let fid = factory.default_fidelity(scene).merged(fidelity);
    let mut s = RunSummary {
        scenario: scenario.id().into(),
        model: factory.id().into(),
        params: params.values().clone(),
        overrides: params.overrides_string(),
        fidelity: fid.pairs().into_iter().collect(),
        fidelity_string: fid.to_string(),
        primary_error: scenario.primary_error().into(),
        reference_tip: run.reference_tip(),
        repeats: opts.repeats.max(1),
        ..Default::default()
    };
    if let Err(u) = factory.check(scene) {
        s.status = "unsupported".into();
        s.reason = u.reason;
        return Ok(s);
    }
    let mut times = Vec::new();
    let mut iters = Vec::new();
    let mut first: Option<Repeat> = None;
    let mut diagnostics = BTreeMap::new();
    for r in 0..opts.repeats.max(1) {
        let t0 = Instant::now();
        let mut model = match factory.build(scene, &fid) {
            Ok(m) => m,
            Err(BuildError::Unsupported(u)) => {
                s.status = "unsupported".into();
                s.reason = u.reason;
                return Ok(s);
            }
            Err(BuildError::BadParameter { name, reason }) => {
                return Err(UsageError(format!(
                    "model `{}`: bad parameter `{name}`: {reason}",
                    factory.id()
                )));
            }
        };
        if r == 0 {
            s.build_ms = Some(t0.elapsed().as_secs_f64() * 1e3);
        }
        let rep = run_repeat(model.as_mut(), run, scenario.primary_error(), opts, r == 0);
        if r == 0 {
            diagnostics = model.diagnostics();
        }
        times.extend_from_slice(&rep.times_ms);
        iters.extend(rep.iters.iter().map(|&i| i as f64));
        match &first {
            None => first = Some(rep),
            Some(f) => {
                if f.last != rep.last || f.steps != rep.steps {
                    s.status = "failed".into();
                    s.reason = format!("non-deterministic: repeat {r} differs from repeat 0");
                }
            }
        }
    }
    let rep = first.expect("at least one repeat");
    s.steps = rep.steps;
    s.sim_time_s = rep.t;
    s.solve_wall_s = Some(rep.wall_s);
    s.end = rep.end.clone();
    if !times.is_empty() {
        let mut sorted = times.clone();
        sorted.sort_by(f64::total_cmp);
        let total: f64 = times.iter().sum();
        s.ms_per_step_median = Some(percentile(&sorted, 0.5));
        s.ms_per_step_p95 = Some(percentile(&sorted, 0.95));
        s.steps_per_s = Some(times.len() as f64 / (total / 1e3));
        let dt = rep.t / rep.steps as f64;
        s.real_time_factor = Some(times.len() as f64 * dt / (total / 1e3));
    }
    if !iters.is_empty() {
        s.solver_iters_mean = Some(iters.iter().sum::<f64>() / iters.len() as f64);
        s.solver_iters_max = iters.iter().copied().reduce(f64::max);
    }
    s.peak_rss_mb = peak_rss_mb();
    s.stable = rep.trip.is_none();
    if let Some((w, t)) = &rep.trip {
        s.watchdog = w.clone();
        s.watchdog_t = Some(*t);
        if s.status.is_empty() {
            s.status = "unstable".into();
            s.reason = format!("{w} at t={t:.4} s");
        }
    }
    if s.status.is_empty() {
        s.status = "ok".into();
    }
    if let Some(errors) = rep.errors {
        s.errors = errors;
        // The model's own diagnostics, prefixed so they never shadow a
        // scenario metric.
        for (k, v) in diagnostics {
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
    s.final_obs = Some(rep.last);
    Ok(s)
}

/// Write `summary.json`, `observables.csv` and `final_state.csv` into `dir`
/// (which must exist).
pub fn write_run_files(dir: &Path, s: &RunSummary) -> std::io::Result<()> {
    let json = serde_json::to_string_pretty(s).map_err(std::io::Error::other)?;
    std::fs::write(dir.join("summary.json"), json + "\n")?;
    let mut f = std::io::BufWriter::new(std::fs::File::create(dir.join("observables.csv"))?);
    writeln!(
        f,
        "t,tip_x,tip_y,tip_z,hand_fx,hand_fy,hand_fz,hand_tx,hand_ty,hand_tz,energy,error"
    )?;
    for x in &s.series {
        let err = if x.error.is_finite() {
            format!("{:e}", x.error)
        } else {
            String::new()
        };
        writeln!(
            f,
            "{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{}",
            x.t,
            x.tip[0],
            x.tip[1],
            x.tip[2],
            x.hand_force[0],
            x.hand_force[1],
            x.hand_force[2],
            x.hand_torque[0],
            x.hand_torque[1],
            x.hand_torque[2],
            x.energy,
            err
        )?;
    }
    f.flush()?;
    let mut f = std::io::BufWriter::new(std::fs::File::create(dir.join("final_state.csv"))?);
    writeln!(f, "body,node,x0,y0,z0,x,y,z")?;
    if let Some(obs) = &s.final_obs {
        let mut body = 0;
        for r in &obs.rods {
            for (i, (x0, x)) in r.rest.iter().zip(&r.nodes).enumerate() {
                writeln!(
                    f,
                    "{body},{i},{:e},{:e},{:e},{:e},{:e},{:e}",
                    x0.x, x0.y, x0.z, x.x, x.y, x.z
                )?;
            }
            body += 1;
        }
        for t in &obs.tissues {
            for (i, (x0, x)) in t.rest.iter().zip(&t.nodes).enumerate() {
                writeln!(
                    f,
                    "{body},{i},{:e},{:e},{:e},{:e},{:e},{:e}",
                    x0.x, x0.y, x0.z, x.x, x.y, x.z
                )?;
            }
            body += 1;
        }
    }
    f.flush()
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
