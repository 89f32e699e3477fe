//! The harness factory of the discrete elastic rod: [`DerFactory`]
//! (`id = "der"`), its capabilities, fidelity keys and defaults (the time
//! step of static scenes from the first cantilever bending period).

use crate::model::DerModel;
use crate::rod::{DEFAULT_FRICTION_CREEP, DEFAULT_SUBSTEP_DEPTH, DerParams, DerRod, Integrator, TwistDynamics};
use surgbench_core::beam::first_bending_frequency;
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Settings, Unsupported,
};

const CAPABILITIES: &[Capability] = &[
    Capability::Rod,
    Capability::Twist,
    Capability::TipForce,
    Capability::LoadRamp,
    Capability::VaryingProperties,
    Capability::RestCurvature,
    Capability::Insertion,
    Capability::InitialVelocity,
    Capability::VesselContact,
    Capability::Friction,
    Capability::Flow,
    Capability::MovingVessel,
    Capability::HapticForce,
    Capability::DeformableLumen,
];

const KEYS: &[FidelityKey] = &[
    FidelityKey::choice(
        "integrator",
        "time integrator",
        &[
            Choice::new("backward-euler", "backward Euler (default, except free vibration)"),
            Choice::new(
                "newmark",
                "Newmark beta=1/4 gamma=1/2 (default in dynamic scenes without vessel or blood)",
            ),
        ],
    ),
    FidelityKey::switch(
        "dynamic_twist",
        "0 = quasi-static twist (default), 1 = rotational inertia rho J |e|",
    ),
    FidelityKey::number("damping", "mass-proportional viscous damping (1/s), default 0").at_least(0.0),
    FidelityKey::number(
        "tolerance",
        "Newton tolerance on the update (positions / rod length, angles in rad), default 1e-9",
    )
    .between(0.0, 1.0),
    FidelityKey::number(
        "friction_creep",
        "stick-slip width of the smoothed friction as a creep speed (m/s), default 1e-6",
    )
    .above(0.0),
    FidelityKey::number(
        "substep_depth",
        "largest number of step halvings when Newton fails, default 6 (dt/64)",
    )
    .whole(0.0, 20.0),
];

/// The names of `integrator`, as the rod's integrators.
const INTEGRATORS: &[(&str, Integrator)] = &[
    ("backward-euler", Integrator::BackwardEuler),
    ("newmark", Integrator::Newmark),
];

/// Default number of segments over the free length.
pub const DEFAULT_SEGMENTS: usize = 40;

/// Default time step for dynamic scenes (s): the 1 kHz haptic rate.
pub const DEFAULT_DT: f64 = 1e-3;

/// Factory of the discrete elastic rod (`id = "der"`).
#[derive(Debug, Clone, Copy, Default)]
pub struct DerFactory;

/// First cantilever bending period `2 pi / omega_1` (s) of the base section
/// ([`first_bending_frequency`]), used to pick the statics time step.
fn first_period(scene: &Scene) -> Option<f64> {
    let rod = scene.rods().next()?;
    let s = rod.section_at(0.0);
    let w = first_bending_frequency(s, rod.length);
    let t = 2.0 * std::f64::consts::PI / w;
    t.is_finite().then_some(t)
}

impl ModelFactory for DerFactory {
    fn id(&self) -> &'static str {
        "der"
    }
    fn description(&self) -> &'static str {
        "discrete elastic rod (Bergou 2008/2010), implicit Newton with banded Cholesky"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn capabilities(&self) -> &'static [Capability] {
        CAPABILITIES
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        KEYS
    }

    /// 40 segments, 25 Newton iterations; `dt` = 1 ms for dynamic scenes, and
    /// a quarter of the first bending period (at most `duration / 50`) for
    /// statics scenes, where backward Euler then damps the transient fast.
    /// Backward Euler also damps contact and friction chatter in dynamic
    /// scenes with a vessel; a rod vibrating freely (dynamic, no vessel, no
    /// blood) takes Newmark instead, which conserves its energy where
    /// backward Euler removes `1 - exp(-pi omega dt)` of the amplitude per
    /// period.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let dt = match (scene.settle, first_period(scene)) {
            (Some(_), Some(t)) => (0.25 * t).min(scene.duration / 50.0),
            _ => DEFAULT_DT,
        };
        let mut f = Fidelity {
            segments: Some(DEFAULT_SEGMENTS),
            mesh_level: None,
            dt: Some(dt),
            iterations: Some(25),
            extras: Default::default(),
        };
        let env = &scene.environment;
        if scene.settle.is_none() && env.vessel.is_none() && env.flow.is_none() {
            f.extras.insert("integrator".into(), "newmark".into());
        }
        f
    }

    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        surgbench_core::model::check_one_rod(self.id(), self.capabilities(), scene)
    }

    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let f = settings.fidelity();
        let body = scene.rods().next().expect("checked: one rod");
        let mut rod = DerRod::from_body(body, f.segments.unwrap_or(DEFAULT_SEGMENTS))?;
        let dt = f.dt.unwrap_or(DEFAULT_DT);
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(BuildError::bad("dt", format!("must be > 0 s, got {dt}")));
        }
        // Ranges are declared on the keys (KEYS) and checked by `resolve`.
        let damping = settings.number_or("damping", 0.0);
        let tolerance = settings.number_or("tolerance", 1e-9);
        let creep = settings.number_or("friction_creep", DEFAULT_FRICTION_CREEP);
        let depth = settings.number_or("substep_depth", DEFAULT_SUBSTEP_DEPTH as f64);
        rod.params = DerParams {
            integrator: settings.pick("integrator", INTEGRATORS, Integrator::BackwardEuler)?,
            twist: if settings.switch("dynamic_twist", false) {
                TwistDynamics::Dynamic
            } else {
                TwistDynamics::QuasiStatic
            },
            damping,
            max_iterations: f.iterations.unwrap_or(25),
            tolerance,
            friction_creep: creep,
            max_substep_depth: depth as usize,
        };
        rod.gravity = scene.gravity;
        rod.set_environment(&scene.environment);
        if let Some(v) = &body.initial_velocity {
            rod.set_initial_velocity(v);
        }
        Ok(Box::new(DerModel::new(rod, dt)))
    }
}
