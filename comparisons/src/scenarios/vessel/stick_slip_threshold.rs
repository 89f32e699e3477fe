//! `stick-slip-threshold`: a wire resting in a tube, pulled by a ramped
//! force; the force at which it first slips against Coulomb's `mu_s N`.

use super::*;
use crate::params;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, Sweep, UsageError,
};
use std::sync::Arc;
use surgbench_core::Family;
use surgbench_core::sdf::StraightTube;

params! {
    /// Parameters of `stick-slip-threshold`.
    pub struct StickParams {
        wire_radius: P_WIRE_RADIUS,
        youngs_modulus: ParamSpec::new(
            "youngs_modulus",
            1e6,
            "Pa",
            Range::Positive,
            "wire Young's modulus (soft, so the elastic ramp is slow)",
        ),
        density: P_DENSITY,
        poisson_ratio: P_POISSON,
        length: ParamSpec::new("length", 0.1, "m", Range::Positive, "wire length lying in the tube"),
        friction_static: ParamSpec::new(
            "friction_static",
            0.3,
            "1",
            Range::Positive,
            "static friction coefficient mu_s",
        ),
        friction_dynamic: ParamSpec::new(
            "friction_dynamic",
            0.2,
            "1",
            Range::NonNegative,
            "dynamic friction coefficient mu_d (<= mu_s)",
        ),
        gravity: ParamSpec::new(
            "gravity",
            9.81,
            "m/s^2",
            Range::Positive,
            "gravity along -z presses the wire on the wall",
        ),
        tube_radius: ParamSpec::new("tube_radius", 2e-3, "m", Range::Positive, "lumen radius (axis along +x)"),
        settle_time: ParamSpec::new("settle_time", 0.3, "s", Range::Positive, "rest before pulling"),
        pull_speed: ParamSpec::new("pull_speed", 1e-3, "m/s", Range::Positive, "clamp retraction speed"),
        pull_time: ParamSpec::new("pull_time", 0.3, "s", Range::Positive, "duration of the pull"),
        slip_tol: ParamSpec::new("slip_tol", 1e-6, "m", Range::Positive, "tip displacement that counts as slipping"),
    }
}

struct StickRun {
    wire_radius: f64,
    weight: f64,
    mu_s: f64,
    mu_d: f64,
    settle: f64,
    tail_from: f64,
    slip_tol: f64,
}

/// One stick-slip run's own sums: the tip's anchor after
/// settling, the slip (time, largest force held before it), creep before
/// the load neared the threshold, and the force while sliding.
#[derive(Default)]
struct StickSums {
    anchor: Option<Vec3>,
    slip_at: Option<(f64, f64)>,
    stick_force_max: f64,
    creep_max: f64,
    loaded: bool,
    tail_sum: f64,
    tail_n: usize,
}

impl StickRun {
    /// Coulomb threshold `mu_s N` (N).
    fn threshold(&self) -> f64 {
        self.mu_s * self.weight
    }
}

impl StickSums {
    /// Add one observation with the wire's tip at `tip` pulled by `f` (N,
    /// the wire pulls the clamp along +x).
    fn add(&mut self, run: &StickRun, obs: &Observation, tip: Vec3, f: f64) {
        if obs.time < run.settle {
            return;
        }
        let anchor = *self.anchor.get_or_insert(tip);
        let moved = (tip - anchor).norm();
        if self.slip_at.is_none() {
            if moved > run.slip_tol {
                self.slip_at = Some((obs.time, self.stick_force_max));
            } else {
                self.stick_force_max = self.stick_force_max.max(f);
            }
        }
        // Creep: tip motion before the force first came near mu_s N.
        if f >= 0.95 * run.threshold() {
            self.loaded = true;
        }
        if !self.loaded {
            self.creep_max = self.creep_max.max(moved);
        }
        if obs.time >= run.tail_from {
            self.tail_sum += f;
            self.tail_n += 1;
        }
    }
}

impl Trajectory for StickRun {
    type Sums = StickSums;
    fn wire_radius(&self) -> f64 {
        self.wire_radius
    }
    fn add(&self, sums: &mut StickSums, obs: &Observation, tip: &Vec3) {
        // The wire resists the pull: it pulls the clamp along +x.
        sums.add(self, obs, *tip, obs.hand_force.x);
    }
    fn metrics(&self, t: &StickSums, _: &Common, _: &Observation, _: &Vec3, m: &mut Metrics) {
        let run = self;
        let threshold = run.threshold();
        m.insert("threshold_ref_n".into(), threshold);
        m.insert("slipped".into(), t.slip_at.is_some() as u8 as f64);
        // Without a slip the threshold was never found: the error is the
        // shortfall of the largest force that held (1 if none was measured).
        let measured = t.slip_at.map_or(t.stick_force_max, |s| s.1);
        m.insert("threshold_n".into(), measured);
        m.insert("threshold_error_rel".into(), (measured - threshold).abs() / threshold);
        if let Some((ts, _)) = t.slip_at {
            m.insert("slip_time_s".into(), ts);
        }
        m.insert("creep_before_threshold_m".into(), t.creep_max);
        if t.tail_n > 0 {
            let sliding = t.tail_sum / t.tail_n as f64;
            m.insert("sliding_force_n".into(), sliding);
            if run.mu_d > 0.0 {
                let r = run.mu_d * run.weight;
                m.insert("sliding_force_error_rel".into(), (sliding - r).abs() / r);
            }
        }
    }
}

/// A wire lying on the floor of a straight tube under gravity, pulled back
/// slowly by the clamp: the tip must not move until the hand force reaches
/// `mu_s N` (N = the wire's weight) and must slide at `mu_d N` after.
pub const STICK_SLIP_THRESHOLD: Declared<StickParams> = Declared {
    info: ScenarioInfo {
        id: "stick-slip-threshold",
        description: "wire resting on a tube wall under gravity, pulled slowly: static threshold mu_s N, sliding at mu_d N",
        family: Family::Rod,
        reference: "Coulomb: no tip motion below mu_s N, sliding force mu_d N, N = rho A L g (displacement-controlled pull)",
        primary_error: "threshold_error_rel",
        params: StickParams::SPECS,
        sweep: Sweep::Knob("segments", &[10.0, 20.0, 40.0, 80.0]),
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &StickParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    let r = p.wire_radius;
    let big_r = p.tube_radius;
    check_lumen(r, big_r, "tube")?;
    let (mu_s, mu_d) = (p.friction_static, p.friction_dynamic);
    if mu_d > mu_s {
        return Err(UsageError(format!(
            "friction_dynamic {mu_d} must not exceed friction_static {mu_s}"
        )));
    }
    let (l, g, rho, e) = (p.length, p.gravity, p.density, p.youngs_modulus);
    let mut rod = RodBody::uniform(l, r, e, p.poisson_ratio, rho);
    // Lying on the floor: the centreline one wire radius above the wall.
    rod.base = Iso3::translation(0.0, 0.0, -(big_r - r));
    let tube = StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: big_r,
    };
    let (ts, vp, tp) = (p.settle_time, p.pull_speed, p.pull_time);
    let weight = rho * PI * r * r * l * g;
    let ea = e * PI * r * r;
    // A uniformly loaded elastic bar slips entirely when the clamp has
    // moved mu_s w L^2 / (2 EA): the pull must go well past that.
    let needed = mu_s * weight * l / (2.0 * ea);
    if vp * tp < 3.0 * needed {
        return Err(UsageError(format!(
            "pull of {:.3e} m is shorter than 3x the elastic slack {needed:.3e} m before full slip: raise pull_speed or pull_time",
            vp * tp
        )));
    }
    let contact = contact(mu_s, mu_d, r)?;
    let mut scene = wire_scene(STICK_SLIP_THRESHOLD.info.id, ts + tp, rod, Arc::new(tube), contact);
    scene.gravity = Vec3::new(0.0, 0.0, -g);
    scene.control = timeline(&[(0.0, 0.0, 0.0), (ts, 0.0, 0.0), (ts + tp, -vp * tp, 0.0)]);
    scene.validate().map_err(UsageError)?;
    let run = StickRun {
        wire_radius: r,
        weight,
        mu_s,
        mu_d,
        settle: ts,
        tail_from: ts + 0.7 * tp,
        slip_tol: p.slip_tol,
    };
    Ok(vessel_run(scene, run, weight * (big_r + vp * tp), 0.2))
}
