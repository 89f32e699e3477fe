//! Rod scenes without a vessel: the statics (cantilever under gravity,
//! cantilever under a tip load, torque transfer) and the free vibration of a
//! cantilever. Shared conventions: base clamped at the origin, rod along
//! +x, gravity and transverse loads along -z; SI units.
//!
//! Default material: a nitinol-like wire (E = 50 GPa, nu = 0.3,
//! rho = 6450 kg/m^3, radius 0.5 mm) 0.1 m long, so that the gravity
//! cantilever sags 0.25% of its length (small deflection).

mod cantilever_gravity;
mod cantilever_tip_load;
mod cantilever_vibration;
mod torque_transfer;

pub use super::oscillation::TipTrack;
pub use cantilever_gravity::{CANTILEVER_GRAVITY, GravityParams};
pub use cantilever_tip_load::{CANTILEVER_TIP_LOAD, TipLoadParams};
pub use cantilever_vibration::{CANTILEVER_VIBRATION, VibrationParams};
pub use torque_transfer::{TORQUE_TRANSFER, TorqueParams};

use crate::references::elastica::Elastica;
use crate::scenario::{Metrics, ParamSpec, Range, Scenario, Sweep};
use std::f64::consts::PI;
use surgbench_core::{Observation, RodBody, RodObs, Scene, Settle, Vec3};

/// Every rod scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![
        &CANTILEVER_GRAVITY,
        &CANTILEVER_TIP_LOAD,
        &TORQUE_TRANSFER,
        &CANTILEVER_VIBRATION,
    ]
}

/// The sweep every rod statics scene runs: 10 to 80 segments.
const SEGMENTS: Sweep = Sweep::Knob("segments", &[10.0, 20.0, 40.0, 80.0]);

const fn p(name: &'static str, default: f64, unit: &'static str, range: Range, doc: &'static str) -> ParamSpec {
    ParamSpec::new(name, default, unit, range, doc)
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
    "static equilibrium when every node, and every point of the rod's surface as its frames turn, is slower than this",
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

/// The [`RodCase`] of a rod scenario's parameter struct (every one has
/// `length`, `radius`, `youngs_modulus`, `poisson_ratio` and `density`).
macro_rules! rod_case {
    ($p:expr) => {
        RodCase {
            length: $p.length,
            radius: $p.radius,
            e: $p.youngs_modulus,
            nu: $p.poisson_ratio,
            rho: $p.density,
        }
    };
}
use rod_case;

impl RodCase {
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
    /// A static scene: `duration` (s) bounds the wait for every node to be
    /// slower than `settle_tol` (m/s).
    fn scene(&self, name: &str, duration: f64, settle_tol: f64) -> Scene {
        let mut s = Scene::empty(name);
        s.duration = duration;
        s.settle = Some(Settle {
            velocity_tol: settle_tol,
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
fn score_elastica(obs: &Observation, e: &Elastica, total_load: f64) -> Metrics {
    let mut m = Metrics::new();
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
