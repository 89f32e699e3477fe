//! Rod statics: cantilever under gravity, cantilever under a tip load,
//! torque transfer. Shared conventions: base clamped at the origin, rod along
//! +x, gravity and transverse loads along -z; SI units.
//!
//! Default material: a nitinol-like wire (E = 50 GPa, nu = 0.3,
//! rho = 6450 kg/m^3, radius 0.5 mm) 0.1 m long, so that the gravity
//! cantilever sags 0.25% of its length (small deflection).

use super::super::elastica::{self, Elastica};
use crate::scenario::{ParamSpec, Params, Range, Scenario, ScenarioRun, UsageError, sweep_of};
use std::collections::BTreeMap;
use std::f64::consts::PI;
use surgbench_core::frames::signed_angle;
use surgbench_core::{ControlTimeline, Family, Fidelity, Observation, RodBody, RodObs, Scene, Settle, Vec3};

const fn p(name: &'static str, default: f64, unit: &'static str, range: Range, doc: &'static str) -> ParamSpec {
    ParamSpec {
        name,
        default,
        unit,
        range,
        doc,
    }
}

const LENGTH: ParamSpec = p("length", 0.1, "m", Range::Positive, "free length of the rod");
const RADIUS: ParamSpec = p(
    "radius",
    5e-4,
    "m",
    Range::Positive,
    "radius of the solid circular section",
);
const YOUNG: ParamSpec = p("youngs_modulus", 5e10, "Pa", Range::Positive, "Young's modulus");
const POISSON: ParamSpec = p(
    "poisson_ratio",
    0.3,
    "1",
    Range::Open(-1.0, 0.5),
    "Poisson ratio (G = E/(2(1+nu)))",
);
const DENSITY: ParamSpec = p("density", 6450.0, "kg/m^3", Range::Positive, "density");
const SETTLE: ParamSpec = p(
    "settle_tol",
    1e-8,
    "m/s",
    Range::Positive,
    "static equilibrium when every node is slower than this",
);
const DURATION: ParamSpec = p(
    "duration",
    5.0,
    "s",
    Range::Positive,
    "longest simulated time to reach equilibrium",
);

/// Rod geometry and material resolved from parameters.
#[derive(Debug, Clone, Copy)]
struct RodCase {
    length: f64,
    radius: f64,
    e: f64,
    nu: f64,
    rho: f64,
}

impl RodCase {
    fn from(p: &Params) -> Self {
        Self {
            length: p.get("length"),
            radius: p.get("radius"),
            e: p.get("youngs_modulus"),
            nu: p.get("poisson_ratio"),
            rho: p.get("density"),
        }
    }
    fn ei(&self) -> f64 {
        self.e * PI * self.radius.powi(4) / 4.0
    }
    fn gj(&self) -> f64 {
        self.e / (2.0 * (1.0 + self.nu)) * PI * self.radius.powi(4) / 2.0
    }
    fn weight_per_length(&self, g: f64) -> f64 {
        self.rho * PI * self.radius * self.radius * g
    }
    fn body(&self) -> RodBody {
        RodBody::uniform(self.length, self.radius, self.e, self.nu, self.rho)
    }
    fn scene(&self, name: &str, p: &Params) -> Scene {
        let mut s = Scene::empty(name);
        s.duration = p.get("duration");
        s.settle = Some(Settle {
            velocity_tol: p.get("settle_tol"),
            min_time: 0.0,
        });
        s
    }
}

/// The free-rod nodes (arclength >= 0) of the first rod, with arclengths.
fn free_nodes(obs: &Observation) -> Option<(&RodObs, Vec<(f64, Vec3)>)> {
    let r = obs.rods.first()?;
    let l = r.arclength.last().copied().unwrap_or(1.0).abs().max(1e-300);
    let v = r
        .arclength
        .iter()
        .zip(&r.nodes)
        .filter(|(s, _)| **s >= -1e-12 * l)
        .map(|(s, x)| (*s, *x))
        .collect();
    Some((r, v))
}

/// Metrics of a planar cantilever against the elastica `e`.
fn score_elastica(obs: &Observation, e: &Elastica, total_load: f64) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    let Some((rod, nodes)) = free_nodes(obs) else {
        return m;
    };
    let (mut sum2, mut max) = (0.0, 0.0f64);
    for (s, x) in &nodes {
        let (rx, rz) = e.at(*s);
        let d = (x - Vec3::new(rx, 0.0, rz)).norm();
        sum2 += d * d;
        max = max.max(d);
    }
    let (tx, tz) = e.tip();
    let ref_tip = Vec3::new(tx, 0.0, tz);
    let tip = rod.tip();
    let deflection = (ref_tip - Vec3::new(e.length, 0.0, 0.0)).norm();
    m.insert("rms_node_error_m".into(), (sum2 / nodes.len().max(1) as f64).sqrt());
    m.insert("max_node_error_m".into(), max);
    m.insert("tip_error_m".into(), (tip - ref_tip).norm());
    m.insert("tip_error_rel".into(), (tip - ref_tip).norm() / deflection);
    if nodes.len() >= 2 {
        let a = nodes[nodes.len() - 2].1;
        let ang = (tip.z - a.z).atan2(tip.x - a.x);
        m.insert("tip_angle_error_rad".into(), (ang - e.tip_angle()).abs());
    }
    let f_ref = Vec3::new(0.0, 0.0, -total_load);
    m.insert(
        "hand_force_error_rel".into(),
        (obs.hand_force - f_ref).norm() / total_load,
    );
    // Torque the rod exerts on the clamp: m(0) = -EI phi'(0) e_y.
    let t_ref = Vec3::new(0.0, -e.base_moment, 0.0);
    m.insert(
        "hand_torque_error_rel".into(),
        (obs.hand_torque - t_ref).norm() / e.base_moment.abs(),
    );
    m.insert("max_stretch".into(), rod.max_stretch.abs());
    m
}

/// Clamped rod under its own weight, small deflection.
pub struct CantileverGravity;

struct CantileverRun {
    scene: Scene,
    reference: Elastica,
    eb_tip: f64,
    load: f64,
}

impl ScenarioRun for CantileverRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = score_elastica(obs, &self.reference, self.load);
        if let Some(r) = obs.rods.first() {
            m.insert(
                "tip_error_vs_euler_bernoulli_rel".into(),
                ((-r.tip().z) - self.eb_tip).abs() / self.eb_tip,
            );
        }
        m
    }
    fn energy_scale(&self) -> f64 {
        self.load * self.reference.length
    }
    fn length_scale(&self) -> f64 {
        self.reference.length
    }
    fn reference_tip(&self) -> Option<[f64; 3]> {
        let (x, z) = self.reference.tip();
        Some([x, 0.0, z])
    }
}

const GRAVITY_PARAMS: &[ParamSpec] = &[
    LENGTH,
    RADIUS,
    YOUNG,
    POISSON,
    DENSITY,
    p("gravity", 9.81, "m/s^2", Range::Positive, "gravity along -z"),
    SETTLE,
    DURATION,
];

impl Scenario for CantileverGravity {
    fn id(&self) -> &'static str {
        "cantilever-gravity"
    }
    fn description(&self) -> &'static str {
        "clamped rod sagging under its own weight (small deflection)"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        GRAVITY_PARAMS
    }
    fn reference(&self) -> &'static str {
        "Euler-Bernoulli w(L) = q L^4/(8EI), scored against the geometrically exact elastica (shooting, 1e-10) it tends to"
    }
    fn primary_error(&self) -> &'static str {
        "tip_error_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[10.0, 20.0, 40.0, 80.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let c = RodCase::from(p);
        let g = p.get("gravity");
        let q = c.weight_per_length(g);
        let reference = elastica::solve(c.length, c.ei(), q, 0.0, 4000).map_err(|e| UsageError(e.to_string()))?;
        let mut scene = c.scene(self.id(), p);
        scene.gravity = Vec3::new(0.0, 0.0, -g);
        scene.bodies.push(c.body().into());
        Ok(Box::new(CantileverRun {
            scene,
            eb_tip: elastica::eb_uniform_tip(q, c.length, c.ei()),
            reference,
            load: q * c.length,
        }))
    }
}

/// Large deflection under a dead tip force (tip angle up to ~70 degrees).
pub struct CantileverTipLoad;

const TIP_PARAMS: &[ParamSpec] = &[
    LENGTH,
    RADIUS,
    YOUNG,
    POISSON,
    DENSITY,
    p(
        "tip_force",
        0.49,
        "N",
        Range::NonNegative,
        "dead tip force along -z (default: P L^2/(EI) = 2, tip angle 45 deg)",
    ),
    p("gravity", 0.0, "m/s^2", Range::NonNegative, "gravity along -z"),
    SETTLE,
    DURATION,
];

impl Scenario for CantileverTipLoad {
    fn id(&self) -> &'static str {
        "cantilever-tip-load"
    }
    fn description(&self) -> &'static str {
        "clamped rod, large deflection under a dead tip force"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        TIP_PARAMS
    }
    fn reference(&self) -> &'static str {
        "elastica by shooting (1e-10), checked against Bisshopp & Drucker (1945)"
    }
    fn primary_error(&self) -> &'static str {
        "tip_error_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[10.0, 20.0, 40.0, 80.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let c = RodCase::from(p);
        let g = p.get("gravity");
        let q = c.weight_per_length(g);
        let force = p.get("tip_force");
        if q == 0.0 && force == 0.0 {
            return Err(UsageError(
                "cantilever-tip-load needs tip_force > 0 or gravity > 0".into(),
            ));
        }
        let alpha = force * c.length * c.length / c.ei();
        if alpha > 10.0 {
            return Err(UsageError(format!(
                "tip load P L^2/(EI) = {alpha:.3} exceeds 10, past the tabulated elastica range this scenario is checked on"
            )));
        }
        let reference = elastica::solve(c.length, c.ei(), q, force, 4000).map_err(|e| UsageError(e.to_string()))?;
        let mut scene = c.scene(self.id(), p);
        scene.gravity = Vec3::new(0.0, 0.0, -g);
        let mut body = c.body();
        body.tip_force = Vec3::new(0.0, 0.0, -force);
        scene.bodies.push(body.into());
        Ok(Box::new(CantileverRun {
            scene,
            eb_tip: elastica::eb_tip_force(force, c.length, c.ei(), c.length)
                + elastica::eb_uniform_tip(q, c.length, c.ei()),
            reference,
            load: q * c.length + force,
        }))
    }
}

/// Straight rod, base rotated by a prescribed angle: the tip must follow.
pub struct TorqueTransfer;

const TORQUE_PARAMS: &[ParamSpec] = &[
    LENGTH,
    RADIUS,
    YOUNG,
    POISSON,
    DENSITY,
    p(
        "base_twist",
        PI / 2.0,
        "rad",
        Range::Any,
        "rotation of the clamp about the rod axis",
    ),
    p(
        "tip_torque",
        0.0,
        "N m",
        Range::Any,
        "dead axial torque at the tip (twist rate T/(GJ)); keep |T| L/(EI) well under pi",
    ),
    SETTLE,
    DURATION,
];

struct TorqueRun {
    scene: Scene,
    length: f64,
    twist: f64,
    torque: f64,
    gj: f64,
}

/// Wrap an angle difference to (-pi, pi].
fn wrap(a: f64) -> f64 {
    let mut x = a.rem_euclid(2.0 * PI);
    if x > PI {
        x -= 2.0 * PI;
    }
    x
}

impl ScenarioRun for TorqueRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(r) = obs.rods.first() else {
            return m;
        };
        let f = r.tip_frame();
        let (d1, t) = (f.column(0).into_owned(), f.column(2).into_owned());
        // Twist of the tip's material frame relative to the unrotated base
        // frame (d1 = +y), about the (straight) rod axis.
        let angle = signed_angle(&Vec3::y(), &d1, &t);
        m.insert("twist_error_rad".into(), wrap(angle - self.twist).abs());
        m.insert(
            "tip_position_error_m".into(),
            (r.tip() - Vec3::new(self.length, 0.0, 0.0)).norm(),
        );
        let t_ref = Vec3::new(self.torque, 0.0, 0.0);
        m.insert("hand_torque_error_nm".into(), (obs.hand_torque - t_ref).norm());
        m.insert("max_stretch".into(), r.max_stretch.abs());
        m
    }
    fn energy_scale(&self) -> f64 {
        (self.gj / self.length) * (1.0 + self.twist * self.twist)
    }
    fn length_scale(&self) -> f64 {
        self.length
    }
    fn reference_tip(&self) -> Option<[f64; 3]> {
        Some([self.length, 0.0, 0.0])
    }
}

impl Scenario for TorqueTransfer {
    fn id(&self) -> &'static str {
        "torque-transfer"
    }
    fn description(&self) -> &'static str {
        "straight rod, clamp rotated about its axis: the tip twist must follow"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        TORQUE_PARAMS
    }
    fn reference(&self) -> &'static str {
        "closed form: uniform static twist, tip angle = base_twist + T L/(GJ)"
    }
    fn primary_error(&self) -> &'static str {
        "twist_error_rad"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[10.0, 20.0, 40.0, 80.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let c = RodCase::from(p);
        let base = p.get("base_twist");
        let torque = p.get("tip_torque");
        if (torque * c.length / c.ei()).abs() > 1.0 {
            return Err(UsageError(format!(
                "tip_torque: |T| L/(EI) = {:.3} > 1 approaches torsional buckling of the cantilever; the straight-rod closed form no longer applies",
                (torque * c.length / c.ei()).abs()
            )));
        }
        let mut scene = c.scene(self.id(), p);
        scene.control = ControlTimeline::hold_rotation(base);
        let mut body = c.body();
        body.tip_torque = Vec3::new(torque, 0.0, 0.0);
        scene.bodies.push(body.into());
        Ok(Box::new(TorqueRun {
            scene,
            length: c.length,
            twist: base + torque * c.length / c.gj(),
            torque,
            gj: c.gj(),
        }))
    }
}
