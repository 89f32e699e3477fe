//! `capstan`: a wire pulled through a curved tube with friction; the
//! tension ratio against the capstan law `exp(mu theta)`.

use super::*;
use crate::params;
use crate::references::capstan_ratio;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, Sweep, UsageError,
};
use std::sync::Arc;
use surgbench_core::Family;
use surgbench_core::LoadRamp;
use surgbench_core::sdf::CenterlineBuilder;

params! {
    /// Parameters of `capstan`.
    pub struct CapstanParams {
        wire_radius: P_WIRE_RADIUS,
        youngs_modulus: ParamSpec::new(
            "youngs_modulus",
            2e8,
            "Pa",
            Range::Positive,
            "wire Young's modulus (soft: bending negligible against tension)",
        ),
        density: P_DENSITY,
        poisson_ratio: P_POISSON,
        friction: ParamSpec::new(
            "friction",
            0.3,
            "1",
            Range::NonNegative,
            "friction coefficient mu (static = dynamic)",
        ),
        wrap_angle: ParamSpec::new(
            "wrap_angle",
            PI / 2.0,
            "rad",
            Range::Closed(0.05, PI),
            "angle theta the tube turns by",
        ),
        tip_force: ParamSpec::new(
            "tip_force",
            1.0,
            "N",
            Range::Positive,
            "dead force on the tip along the exit direction once threaded: far-end tension T_in",
        ),
        bend_radius: ParamSpec::new("bend_radius", 15e-3, "m", Range::Positive, "centreline radius of the bend"),
        tube_radius: ParamSpec::new(
            "tube_radius",
            0.7e-3,
            "m",
            Range::Positive,
            "lumen radius (tight, so the wire cannot buckle)",
        ),
        insert_speed: ParamSpec::new(
            "insert_speed",
            0.02,
            "m/s",
            Range::Positive,
            "feed speed while threading the wire through the bend",
        ),
        pull_speed: ParamSpec::new("pull_speed", 0.01, "m/s", Range::Positive, "retraction speed while measuring"),
        pull_length: ParamSpec::new("pull_length", 0.01, "m", Range::Positive, "length pulled back"),
    }
}

const CAPSTAN_EXIT: f64 = 40e-3;
/// Straight before the bend beyond what the feed needs (m).
const CAPSTAN_SLACK: f64 = 10e-3;
/// How far the tip is threaded past the bend (m).
const CAPSTAN_THREAD: f64 = 15e-3;
/// Time over which the tip tension rises once the wire is threaded (s).
const CAPSTAN_RAMP: f64 = 0.1;
/// Rest at full tension before the pull (s).
const CAPSTAN_DWELL: f64 = 0.1;

struct CapstanRun {
    wire_radius: f64,
    t_in: f64,
    ratio_ref: f64,
    window: (f64, f64),
    axis: Vec3,
    bending: f64,
}

impl CapstanRun {
    /// Tension at the hand (N): the wire pulls the clamp down the lumen.
    fn tension(&self, obs: &Observation) -> f64 {
        obs.hand_force.dot(&self.axis)
    }
}

/// The hand tension summed over the pulling window (N) and its samples.
#[derive(Default)]
struct Window {
    sum: f64,
    n: usize,
}

impl Trajectory for CapstanRun {
    type Sums = Window;
    fn wire_radius(&self) -> f64 {
        self.wire_radius
    }
    fn add(&self, w: &mut Window, obs: &Observation, _: &Vec3) {
        if obs.time >= self.window.0 && obs.time <= self.window.1 {
            w.sum += self.tension(obs);
            w.n += 1;
        }
    }
    /// Inside the pull window, where the capstan law holds: the hand's
    /// tension against `T_in exp(mu theta)`.
    fn force_point(&self, obs: &Observation) -> Option<(f64, f64)> {
        let (from, to) = self.window;
        (obs.time >= from && obs.time <= to).then(|| (self.tension(obs), self.t_in * self.ratio_ref))
    }
    fn metrics(&self, w: &Window, _: &Common, obs: &Observation, _: &Vec3, m: &mut Metrics) {
        let now = self.tension(obs) / self.t_in;
        let ratio = if w.n > 0 { w.sum / w.n as f64 / self.t_in } else { now };
        m.insert("tension_ratio".into(), ratio);
        m.insert("tension_ratio_ref".into(), self.ratio_ref);
        m.insert(
            "tension_ratio_error_rel".into(),
            (ratio - self.ratio_ref).abs() / self.ratio_ref,
        );
        m.insert(
            "tension_ratio_now_error_rel".into(),
            (now - self.ratio_ref).abs() / self.ratio_ref,
        );
        m.insert("window_samples".into(), w.n as f64);
        m.insert("bending_over_tension".into(), self.bending);
    }
}

/// A flexible wire pulled back through a curved tube against a dead tip
/// force: the capstan (Euler-Eytelwein) law `T_out / T_in = exp(mu theta)`.
pub const CAPSTAN: Declared<CapstanParams> = Declared {
    info: ScenarioInfo {
        id: "capstan",
        description: "soft wire threaded through a bend of wrap angle theta, loaded by a tip tension (ramped once threaded) and pulled back",
        family: Family::Rod,
        reference: "capstan law T_out / T_in = exp(mu theta) (valid when EI / (R^2 T_in) << 1, reported as bending_over_tension)",
        primary_error: "tension_ratio_error_rel",
        target: crate::scenario::Target::new(0.05, "5 % of the capstan (Euler-Eytelwein) tension ratio"),
        params: CapstanParams::SPECS,
        sweep: Sweep::Knob("segments", &[20.0, 40.0, 80.0]),
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &CapstanParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    let r = p.wire_radius;
    let lumen = p.tube_radius;
    check_lumen(r, lumen, "tube")?;
    let (mu, theta, rc) = (p.friction, p.wrap_angle, p.bend_radius);
    if !(rc > 2.0 * lumen) {
        return Err(UsageError(format!(
            "bend_radius {rc} m must exceed twice the tube_radius {lumen} m"
        )));
    }
    // The wire starts straight in the entry and is fed until its tip is
    // CAPSTAN_THREAD past the bend; the clamp moves with the feed, so the
    // straight must hold the clamp's whole travel (rc theta + thread +
    // the tip's start short of the bend) plus slack, and the wire starts
    // that long: the clamp ends CAPSTAN_SLACK / 2 short of the bend.
    let entry = rc * theta + CAPSTAN_THREAD + CAPSTAN_SLACK;
    let l0 = entry - CAPSTAN_SLACK / 2.0;
    // The tube starts ENTRY_S behind the clamp.
    let tube = CenterlineBuilder::new(Vec3::new(-ENTRY_S, 0.0, 0.0), Vec3::x())
        .line(ENTRY_S + entry)
        .arc(rc, theta, Vec3::y())
        .line(CAPSTAN_EXIT)
        .build_constant(lumen)
        .map_err(|e| UsageError(e.to_string()))?;
    let exit_dir = Vec3::new(theta.cos(), theta.sin(), 0.0);
    let t_in = p.tip_force;
    let e = p.youngs_modulus;
    let mut rod = RodBody::uniform(l0, r, e, p.poisson_ratio, p.density);
    rod.tip_force = exit_dir * t_in;
    // Thread the tip into the exit segment, dwell, pull back.
    let ins = entry + rc * theta + CAPSTAN_THREAD - l0;
    let feed_limit = FeedLimit {
        start: 0.0,
        straight: entry,
        what: "entry straight",
    };
    feed_limit.check(ins)?;
    let (vi, vp, lp) = (p.insert_speed, p.pull_speed, p.pull_length);
    if lp >= CAPSTAN_THREAD - 1e-3 {
        return Err(UsageError(format!(
            "pull_length {lp} m would pull the tip back into the bend (max {} m)",
            CAPSTAN_THREAD - 1e-3
        )));
    }
    let t1 = ins / vi;
    // The tension is applied only once the wire is threaded (a dead
    // force on the tip while it is fed would drag it across the entry
    // straight into the wall): it ramps up over CAPSTAN_RAMP, then the
    // wire dwells before the pull.
    rod.tip_load_ramp = Some(LoadRamp::linear(t1, t1 + CAPSTAN_RAMP));
    let t2 = t1 + CAPSTAN_RAMP + CAPSTAN_DWELL;
    let t3 = t2 + lp / vp;
    // One coefficient: static and dynamic friction are the same.
    let contact = contact(mu, mu, r)?;
    let mut scene = wire_scene(CAPSTAN.info.id, t3, rod, Arc::new(tube), contact);
    scene.control = timeline(&[(0.0, 0.0, 0.0), (t1, ins, 0.0), (t2, ins, 0.0), (t3, ins - lp, 0.0)]);
    scene.validate().map_err(UsageError)?;
    let ei = e * PI * r.powi(4) / 4.0;
    let ratio_ref = capstan_ratio(mu, theta);
    let energy = t_in * ratio_ref * (ins + l0) + ei * (ins + l0) / (rc * rc);
    let run = CapstanRun {
        wire_radius: r,
        t_in,
        ratio_ref,
        // Measure over the last 60% of the pull: past the stick-to-slip transient.
        window: (t2 + 0.4 * (t3 - t2), t3),
        axis: Vec3::x(),
        bending: ei / (rc * rc * t_in),
    };
    Ok(vessel_run(scene, run, energy, 0.1).with_feed_limit(feed_limit))
}
