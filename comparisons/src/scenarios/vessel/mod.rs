//! Vascular navigation scenarios: a guidewire pushed, pulled and rotated
//! through procedural vessels ([`surgbench_core::vessel`]). SI units.
//!
//! Conventions (shared with the rod scenarios): the rod's base clamp
//! ([`RodBody::base`]) sits on the vessel centreline 5 mm after the vessel's
//! start, the wire leaving along the base's local +x, down the lumen; the
//! operator feeds it with [`ControlTimeline`] keys `insertion` (m,
//! cumulative) and `rotation` (rad, cumulative, about the base tangent).
//! Contact margin = wire radius (the SDF acts on the wire's centreline).
//! The default guidewire is 0.89 mm (0.035") in diameter with a stiff body
//! (nitinol-like, E = 50 GPa) and a soft 3 cm tip (E = 1 GPa) as two
//! [`RodSection`]s.
//!
//! **Trajectory metrics.** Metrics over a whole run (time to reach a
//! target, maximum penetration, mean and peak hand force, tension averaged
//! over a pulling window) are sums each run's [`Scorer`] keeps over the
//! observation after every step ([`Scorer::observe_step`]); a fresh scorer
//! serves each run and each repeat.
//!
//! Scenarios: `arch-insertion`, `branch-selection`, `flow-drift`,
//! `capstan`, `stick-slip-threshold`, `coronary-tortuous`, `coronary-beating`,
//! `vessel-mesh-insertion` (any lumen given as a closed surface: `--mesh`).

mod arch_insertion;
mod branch_selection;
mod capstan;
mod coronary_beating;
mod coronary_tortuous;
mod flow_drift;
mod mesh_insertion;
mod stick_slip_threshold;

pub use arch_insertion::{ARCH_INSERTION, ArchParams};
pub use branch_selection::{BRANCH_SELECTION, BranchParams};
pub use capstan::{CAPSTAN, CapstanParams};
pub use coronary_beating::{BeatingParams, CORONARY_BEATING};
pub use coronary_tortuous::{CORONARY_TORTUOUS, CoronaryParams};
pub use flow_drift::{FLOW_DRIFT, FlowParams};
pub use mesh_insertion::{MESH_INSERTION, MeshInsertionParams, builtin_surface, builtin_tube};
pub use stick_slip_threshold::{STICK_SLIP_THRESHOLD, StickParams, chain_threshold, elastic_bar_force};

use crate::references::TipTrajectory;
use crate::scenario::{FeedLimit, Metrics, ParamSpec, Range, Reference, Scenario, ScenarioRun, Scorer, UsageError};
use std::f64::consts::PI;
use std::sync::Arc;
use surgbench_core::sdf::Sdf;
use surgbench_core::{ContactParams, ControlKey, ControlTimeline, Iso3, Observation, RodBody, RodSection, Scene, Vec3};

/// Every vessel scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![
        &ARCH_INSERTION,
        &BRANCH_SELECTION,
        &FLOW_DRIFT,
        &CAPSTAN,
        &STICK_SLIP_THRESHOLD,
        &CORONARY_TORTUOUS,
        &CORONARY_BEATING,
        &MESH_INSERTION,
    ]
}

/// Guidewire radius: 0.89 mm (0.035 inch) diameter.
pub const WIRE_RADIUS: f64 = 0.445e-3;
/// Arclength of the base clamp from the vessel's start (m).
pub const ENTRY_S: f64 = 5e-3;

const P_WIRE_RADIUS: ParamSpec = ParamSpec::new(
    "wire_radius",
    WIRE_RADIUS,
    "m",
    Range::Positive,
    "guidewire radius (0.89 mm diameter)",
);
const P_BODY_E: ParamSpec = ParamSpec::new(
    "body_youngs_modulus",
    5e10,
    "Pa",
    Range::Positive,
    "Young's modulus of the wire body (nitinol-like)",
);
const P_TIP_E: ParamSpec = ParamSpec::new(
    "tip_youngs_modulus",
    1e9,
    "Pa",
    Range::Positive,
    "Young's modulus of the soft tip",
);
const P_TIP_LEN: ParamSpec = ParamSpec::new(
    "tip_length",
    0.03,
    "m",
    Range::Positive,
    "length of the soft tip section",
);
const P_DENSITY: ParamSpec = ParamSpec::new("density", 6450.0, "kg/m^3", Range::Positive, "wire density");
const P_POISSON: ParamSpec = ParamSpec::new("poisson_ratio", 0.3, "1", Range::Open(-1.0, 0.5), "Poisson ratio");
const P_MU_S: ParamSpec = ParamSpec::new(
    "friction_static",
    0.1,
    "1",
    Range::NonNegative,
    "static friction coefficient wire-wall",
);
const P_MU_D: ParamSpec = ParamSpec::new(
    "friction_dynamic",
    0.08,
    "1",
    Range::NonNegative,
    "dynamic friction coefficient (<= static)",
);
const P_GRAVITY: ParamSpec = ParamSpec::new(
    "gravity",
    0.0,
    "m/s^2",
    Range::NonNegative,
    "gravity along -z (0: neglected)",
);

/// Guidewire material and geometry resolved from parameters.
#[derive(Debug, Clone, Copy)]
struct Wire {
    radius: f64,
    body_e: f64,
    tip_e: f64,
    tip_len: f64,
    rho: f64,
    nu: f64,
}

/// The [`Wire`] of a vessel scenario's parameter struct (every one has
/// `wire_radius`, `body_youngs_modulus`, `tip_youngs_modulus`,
/// `tip_length`, `density` and `poisson_ratio`).
macro_rules! wire {
    ($p:expr) => {
        Wire {
            radius: $p.wire_radius,
            body_e: $p.body_youngs_modulus,
            tip_e: $p.tip_youngs_modulus,
            tip_len: $p.tip_length,
            rho: $p.density,
            nu: $p.poisson_ratio,
        }
    };
}
use wire;

impl Wire {
    fn section(&self, until: f64, e: f64, curvature: [f64; 2]) -> RodSection {
        RodSection {
            until,
            radius: self.radius,
            youngs_modulus: e,
            poisson_ratio: self.nu,
            density: self.rho,
            rest_curvature: curvature,
        }
    }
    /// Body + soft tip, `length` m free, clamped at `base`.
    fn rod(&self, length: f64, base: Iso3) -> Result<RodBody, UsageError> {
        if !(length > self.tip_len) {
            return Err(UsageError(format!(
                "initial free length {length} m must exceed tip_length {} m (the body section must exist)",
                self.tip_len
            )));
        }
        Ok(RodBody {
            length,
            sections: vec![
                self.section(length - self.tip_len, self.body_e, [0.0; 2]),
                self.section(length, self.tip_e, [0.0; 2]),
            ],
            base,
            tip_force: Vec3::zeros(),
            tip_torque: Vec3::zeros(),
            tip_load_ramp: None,
            initial_velocity: None,
        })
    }
    /// [`Wire::rod`] with the last `j_len` m of the soft tip pre-curved to
    /// `kappa` (1/m) towards the clamp's local y (a J or angled tip);
    /// `kappa = 0` leaves the tip straight.
    fn rod_with_j(&self, length: f64, base: Iso3, j_len: f64, kappa: f64) -> Result<RodBody, UsageError> {
        let mut rod = self.rod(length, base)?;
        if kappa == 0.0 {
            return Ok(rod);
        }
        if !(j_len > 0.0 && j_len < self.tip_len) {
            return Err(UsageError(format!(
                "j_length {j_len} m must be in (0, tip_length = {} m)",
                self.tip_len
            )));
        }
        let tip = rod.sections.pop().expect("two sections");
        rod.sections
            .push(self.section(length - j_len, tip.youngs_modulus, [0.0; 2]));
        // Darboux component on d2 turns the tangent towards +d1 (local y).
        rod.sections
            .push(self.section(length, tip.youngs_modulus, [0.0, kappa]));
        Ok(rod)
    }
    fn body_ei(&self) -> f64 {
        self.body_e * PI * self.radius.powi(4) / 4.0
    }
}

/// Wire-wall contact with static and dynamic friction coefficients (the
/// dynamic one no larger) and the contact `margin` (m).
fn contact(friction_static: f64, friction_dynamic: f64, margin: f64) -> Result<ContactParams, UsageError> {
    let c = ContactParams {
        friction_static,
        friction_dynamic,
        margin,
    };
    if c.friction_dynamic > c.friction_static {
        return Err(UsageError(format!(
            "friction_dynamic {} must not exceed friction_static {}",
            c.friction_dynamic, c.friction_static
        )));
    }
    Ok(c)
}

/// The scene `id` every vessel scenario starts from: one wire `rod` in
/// `vessel` with wire-wall `contact`, run for `duration` s. The scenario
/// adds its control, gravity, flow or wall motion.
fn wire_scene(id: &str, duration: f64, rod: RodBody, vessel: Arc<dyn Sdf>, contact: ContactParams) -> Scene {
    let mut scene = Scene::empty(id);
    scene.duration = duration;
    scene.bodies.push(rod.into());
    scene.environment.vessel = Some(vessel);
    scene.environment.contact = contact;
    scene
}

/// The wire's initial free length `l0` (m), clamped `ENTRY_S` into the
/// vessel, must end inside the `straight` segment (m) it starts in, named
/// `what` in the error.
fn check_initial_length(l0: f64, straight: f64, what: &str) -> Result<(), UsageError> {
    if l0 + ENTRY_S > straight {
        return Err(UsageError(format!(
            "initial_length {l0} m does not fit the {straight} m {what}"
        )));
    }
    Ok(())
}

/// The wire (radius `wire_radius`, m) must fit the `what` lumen of radius
/// `lumen` (m) with room to move: under 90 % of it.
fn check_lumen(wire_radius: f64, lumen: f64, what: &str) -> Result<(), UsageError> {
    if !(wire_radius < 0.9 * lumen) {
        return Err(UsageError(format!(
            "wire_radius {wire_radius} m does not fit the {what} lumen of radius {lumen} m (needs < 90%)"
        )));
    }
    Ok(())
}

/// The run-wide sums every vessel scene keeps, over the observations its
/// scorer is shown: penetration (geometric and reported), hand force and
/// torque, contacts. Each scene's scorer holds one beside its own sums.
#[derive(Debug, Clone, Default)]
struct Common {
    samples: usize,
    max_penetration: f64,
    max_reported_penetration: f64,
    force_sum: f64,
    force_max: f64,
    torque_max: f64,
    max_contacts: usize,
}

impl Common {
    /// Add one observation against the lumen `sdf` for a wire of radius `r`
    /// (m).
    fn add(&mut self, sdf: &dyn Sdf, obs: &Observation, r: f64) {
        self.samples += 1;
        self.max_penetration = self.max_penetration.max(wall_penetration(sdf, obs, r));
        self.max_reported_penetration = self.max_reported_penetration.max(obs.max_penetration());
        let f = obs.hand_force.norm();
        self.force_sum += f;
        self.force_max = self.force_max.max(f);
        self.torque_max = self.torque_max.max(obs.hand_torque.norm());
        self.max_contacts = self.max_contacts.max(obs.contacts.len());
    }

    /// The common metrics: the sums so far and the stretch of `obs`.
    fn metrics(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        m.insert("max_penetration_m".into(), self.max_penetration);
        m.insert("reported_penetration_m".into(), self.max_reported_penetration);
        m.insert("hand_force_mean_n".into(), self.force_sum / self.samples.max(1) as f64);
        m.insert("hand_force_max_n".into(), self.force_max);
        m.insert("hand_torque_max_nm".into(), self.torque_max);
        m.insert("contacts_max".into(), self.max_contacts as f64);
        if let Some(r) = obs.rods.first() {
            m.insert("max_stretch".into(), r.max_stretch.abs());
        }
        m
    }
}

/// A vessel scene scored over a whole run: the [`Common`] sums against the
/// lumen at each observation's time (the moved wall when the vessel beats)
/// plus the scene's own sums, over the observations that hold a wire tip.
trait Trajectory: Send + Sync + 'static {
    /// The scene's own run-wide sums.
    type Sums: Default;
    /// Wire radius (m): the geometric penetration is `phi + r`.
    fn wire_radius(&self) -> f64;
    /// Add one observation whose wire tip is at `tip` (m).
    fn add(&self, sums: &mut Self::Sums, obs: &Observation, tip: &Vec3);
    /// The scene's metrics of `obs` (tip at `tip`) with the sums so far, added
    /// to the common ones in `m`.
    fn metrics(&self, sums: &Self::Sums, common: &Common, obs: &Observation, tip: &Vec3, m: &mut Metrics);
    /// The converged tip path the run is scored against, if the scene has
    /// one at these parameters: the scorer then adds `tip_error_m` (now),
    /// `tip_error_rms_m` and `tip_error_max_m` (over the observed steps),
    /// and the report plots it beside the models' tips.
    fn reference(&self) -> Option<&TipTrajectory> {
        None
    }
    /// For scenes whose reference is a force law: the force the scene
    /// scores at `obs` and the law's value there (N), where the law holds
    /// ([`Scorer::force_point`]); `None` (the default) elsewhere.
    fn force_point(&self, obs: &Observation) -> Option<(f64, f64)> {
        let _ = obs;
        None
    }
}

/// A run's tip distance to its [`Trajectory::reference`] path (m): squared
/// sum and largest over the observed steps.
#[derive(Debug, Clone, Copy, Default)]
struct PathError {
    err2: f64,
    max: f64,
}

/// A [`Trajectory`] as a scenario's [`Reference`].
struct Tracks<R>(R);

/// One run's sums of a [`Trajectory`] scene.
struct Tracked<'a, R: Trajectory> {
    run: &'a R,
    scene: &'a Scene,
    common: Common,
    sums: R::Sums,
    path: PathError,
}

impl<R: Trajectory> Reference for Tracks<R> {
    fn scorer<'a>(&'a self, scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(Tracked {
            run: &self.0,
            scene,
            common: Common::default(),
            sums: R::Sums::default(),
            path: PathError::default(),
        })
    }
}

impl<R: Trajectory> Scorer for Tracked<'_, R> {
    fn observe_step(&mut self, obs: &Observation) {
        let (Some(tip), Some(lumen)) = (tip(obs), self.scene.environment.vessel_at(obs.time)) else {
            return;
        };
        self.common.add(lumen.as_ref(), obs, self.run.wire_radius());
        self.run.add(&mut self.sums, obs, &tip);
        if let Some(r) = self.run.reference() {
            let e = (tip - r.at(obs.time)).norm();
            self.path.err2 += e * e;
            self.path.max = self.path.max.max(e);
        }
    }
    fn score(&self, obs: &Observation) -> Metrics {
        let Some(tip) = tip(obs) else { return Metrics::new() };
        let mut m = self.common.metrics(obs);
        self.run.metrics(&self.sums, &self.common, obs, &tip, &mut m);
        if let Some(r) = self.run.reference() {
            m.insert("tip_error_m".into(), (tip - r.at(obs.time)).norm());
            let n = self.common.samples.max(1) as f64;
            m.insert("tip_error_rms_m".into(), (self.path.err2 / n).sqrt());
            m.insert("tip_error_max_m".into(), self.path.max);
        }
        m
    }
    fn force_point(&self, obs: &Observation) -> Option<(f64, f64)> {
        self.run.force_point(obs)
    }
    fn reference_tip_at(&self, t: f64) -> Option<[f64; 3]> {
        self.run.reference().map(|r| {
            let x = r.at(t);
            [x.x, x.y, x.z]
        })
    }
}

/// A vessel scene's instance: `run`'s trajectory scored, the penetration
/// watchdog at half the wire radius, energy (J) and length (m) scales.
fn vessel_run<R: Trajectory>(scene: Scene, run: R, energy: f64, length: f64) -> ScenarioRun {
    let limit = 0.5 * run.wire_radius();
    ScenarioRun::new(scene, Tracks(run), energy, length).with_penetration_limit(limit)
}

/// Largest depth of the wire's surface past the wall: `max(phi(x) + r, 0)`
/// over every node of every rod (m), from the geometry, not from the
/// model's own contact report.
pub(crate) fn wall_penetration(sdf: &dyn Sdf, obs: &Observation, wire_radius: f64) -> f64 {
    obs.rods
        .iter()
        .flat_map(|r| r.arclength.iter().zip(&r.nodes))
        .filter(|(s, _)| **s >= 0.0)
        .map(|(_, x)| (sdf.distance(x) + wire_radius).max(0.0))
        .fold(0.0, f64::max)
}

fn tip(obs: &Observation) -> Option<Vec3> {
    obs.rods.first().filter(|r| !r.nodes.is_empty()).map(|r| r.tip())
}

/// Timeline from `(t, insertion, rotation)` triples.
fn timeline(keys: &[(f64, f64, f64)]) -> ControlTimeline {
    ControlTimeline {
        keys: keys
            .iter()
            .map(|&(t, insertion, rotation)| ControlKey::feed(t, insertion, rotation))
            .collect(),
    }
}
