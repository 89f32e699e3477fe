//! `stick-slip-threshold`: a wire resting in a tube, pulled slowly from the
//! clamp; the hand force against Coulomb friction on an elastic wire.
//!
//! The reference (1D elastic bar on a Coulomb floor, quasi-static): a bar
//! of axial stiffness `EA`, pressed by `n = N / L` (N/m), pulled back by
//! `u0` at `s = 0`. Slip starts at the pulled end and spreads: on the slid
//! part `[0, a]` friction is kinetic, `EA u'' = mu_d n`; beyond the front
//! the bar is unstressed and sticks (its static friction carries nothing,
//! so `mu_s` never enters). With `u(a) = u'(a) = 0`:
//! `u(s) = mu_d n (a - s)^2 / (2 EA)`, so the hand force `F = EA u'(0) =
//! mu_d n a` and `u0 = mu_d n a^2 / (2 EA)`, i.e.
//!
//! ```text
//! F(u0) = sqrt(2 EA mu_d n u0)   until a = L at u0* = mu_d n L^2 / (2 EA),
//! F     = mu_d N                 after: the tip first moves at mu_d N.
//! ```
//!
//! (Derived here: the bar analogue of Cattaneo-Mindlin partial slip, a
//! slip zone growing from the loaded end.) A rigid block instead breaks loose at `mu_s N`. A chain of K nodes breaks
//! node by node, each at its own `mu_s n l`: the last one goes at `mu_d N +
//! (mu_s - mu_d) N / K`, which tends to the elastic bar's `mu_d N` at first
//! order in `1/K` and is the rigid block's `mu_s N` at K = 1
//! ([`chain_threshold`]).

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
    /// Axial stiffness EA (N).
    ea: f64,
    /// Wire length (m).
    length: f64,
    /// Clamp retraction speed (m/s).
    pull_speed: f64,
}

/// Hand force (N) of an elastic bar of axial stiffness `ea` (N), length
/// `l` (m), weight `weight` (N) on a floor of kinetic friction `mu_d`,
/// pulled back by `u0` (m): `sqrt(2 EA mu_d n u0)` while the slip front
/// spreads, `mu_d N` once it has reached the tip (module docs).
pub fn elastic_bar_force(ea: f64, l: f64, weight: f64, mu_d: f64, u0: f64) -> f64 {
    let n = weight / l;
    (2.0 * ea * mu_d * n * u0.max(0.0)).sqrt().min(mu_d * weight)
}

/// Hand force (N) at which the last of `k` equal nodes of a chain breaks
/// loose, each node carrying `N / k` and breaking at `mu_s` of it while the
/// others slide at `mu_d`: `mu_d N + (mu_s - mu_d) N / k`.
pub fn chain_threshold(weight: f64, mu_s: f64, mu_d: f64, k: usize) -> f64 {
    mu_d * weight + (mu_s - mu_d) * weight / k.max(1) as f64
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
    /// Squared and largest error (N) of the hand force against the
    /// elastic bar's curve while the slip front spreads, and the count.
    curve_e2: f64,
    curve_emax: f64,
    curve_n: usize,
}

impl StickRun {
    /// The elastic wire's threshold `mu_d N` (N): the tip first moves when
    /// the slip front reaches it (module docs).
    fn threshold(&self) -> f64 {
        self.mu_d * self.weight
    }
    /// Clamp retraction at which the slip front reaches the tip (m).
    fn full_slip(&self) -> f64 {
        self.mu_d * self.weight * self.length / (2.0 * self.ea)
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
        let u0 = run.pull_speed * (obs.time - run.settle);
        if u0 > 0.0 && u0 <= run.full_slip() {
            let e = (f - elastic_bar_force(run.ea, run.length, run.weight, run.mu_d, u0)).abs();
            self.curve_e2 += e * e;
            self.curve_emax = self.curve_emax.max(e);
            self.curve_n += 1;
        }
        let moved = (tip - anchor).norm();
        if self.slip_at.is_none() {
            if moved > run.slip_tol {
                self.slip_at = Some((obs.time, self.stick_force_max));
            } else {
                self.stick_force_max = self.stick_force_max.max(f);
            }
        }
        // Creep: tip motion before the force first came near mu_d N.
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
    /// After settling: the hand force against the elastic bar's, which is
    /// `sqrt(2 EA mu_d n u0)` while the slip front spreads and `mu_d N`
    /// from the moment it reaches the tip (sliding).
    fn force_point(&self, obs: &Observation) -> Option<(f64, f64)> {
        (obs.time >= self.settle).then(|| {
            let u0 = self.pull_speed * (obs.time - self.settle);
            let law = elastic_bar_force(self.ea, self.length, self.weight, self.mu_d, u0);
            (obs.hand_force.x, law)
        })
    }
    fn metrics(&self, t: &StickSums, _: &Common, _: &Observation, _: &Vec3, m: &mut Metrics) {
        let run = self;
        let threshold = run.threshold();
        m.insert("threshold_ref_n".into(), threshold);
        m.insert("rigid_threshold_n".into(), run.mu_s * run.weight);
        if t.curve_n > 0 {
            m.insert(
                "curve_error_rel".into(),
                (t.curve_e2 / t.curve_n as f64).sqrt() / threshold,
            );
            m.insert("curve_error_max_rel".into(), t.curve_emax / threshold);
        }
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
/// slowly by the clamp: the hand force follows the elastic bar's
/// `sqrt(2 EA mu_d n u0)` while slip spreads from the clamp, the tip first
/// moves at `mu_d N` (N = the wire's weight) and slides at `mu_d N` after.
pub const STICK_SLIP_THRESHOLD: Declared<StickParams> = Declared {
    info: ScenarioInfo {
        id: "stick-slip-threshold",
        description: "wire resting on a tube wall under gravity, pulled slowly: slip spreads from the clamp, tip moves at mu_d N (elastic wire)",
        family: Family::Rod,
        reference: "elastic bar on a Coulomb floor: F = sqrt(2 EA mu_d n u0) while slip spreads, tip moves at mu_d N, slides at mu_d N (a rigid block would hold to mu_s N)",
        primary_error: "threshold_error_rel",
        target: crate::scenario::Target::new(0.05, "5 % of the closed-form friction threshold"),
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
        ea,
        length: l,
        pull_speed: vp,
    };
    Ok(vessel_run(scene, run, weight * (big_r + vp * tp), 0.2))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bar's curve meets the sliding force where the front reaches the
    /// tip; a one-node chain is the rigid block (mu_s N); a fine chain
    /// tends to the elastic bar's mu_d N at first order in 1/K.
    #[test]
    fn references_meet_their_limits() {
        let (ea, l, w, mu_s, mu_d) = (0.62, 0.1, 4e-3, 0.3, 0.2);
        let u_star = mu_d * w * l / (2.0 * ea);
        let at = elastic_bar_force(ea, l, w, mu_d, u_star);
        assert!((at - mu_d * w).abs() <= 1e-15, "{at}");
        assert!(elastic_bar_force(ea, l, w, mu_d, 0.25 * u_star) < 0.51 * mu_d * w);
        assert_eq!(elastic_bar_force(ea, l, w, mu_d, 10.0 * u_star), mu_d * w);
        assert_eq!(chain_threshold(w, mu_s, mu_d, 1), mu_s * w);
        let e = |k| chain_threshold(w, mu_s, mu_d, k) / (mu_d * w) - 1.0;
        assert!((e(40) / e(80) - 2.0).abs() < 1e-12);
    }
}
