//! The harness factory of the rigid chain: [`MultibodyFactory`]
//! (`id = "multibody"`), its capabilities, settings by name and defaults.

use crate::chain::{ChainParams, JointKind, RigidChain};
use crate::model::MultibodyModel;
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Settings, Unsupported,
};

/// What the chain simulates in this version. Not (yet): insertion through
/// the clamp, vessel contact and friction, blood-flow drag, a moving or
/// deforming vessel: scenes that need them are refused with the list.
const CAPABILITIES: &[Capability] = &[
    Capability::Rod,
    Capability::Twist,
    Capability::TipForce,
    Capability::LoadRamp,
    Capability::VaryingProperties,
    Capability::RestCurvature,
    Capability::InitialVelocity,
    Capability::HapticForce,
];

const KEYS: &[FidelityKey] = &[
    FidelityKey::choice(
        "joint",
        "how rapier joins the links",
        &[
            Choice::new(
                "multibody",
                "reduced-coordinate multibody, implicit joint springs (default)",
            ),
            Choice::new(
                "impulse",
                "impulse joints: free bodies, iterative constraints, springs as force-based joint motors",
            ),
        ],
    ),
    FidelityKey::number(
        "substeps",
        "rapier solver substeps per step (num_solver_iterations); default 1 on static scenes, 4 (rapier's) on dynamic ones",
    )
    .whole(1.0, 256.0),
    FidelityKey::number(
        "damping",
        "damping ratio of the first bending mode from joint dampers proportional to the springs; default 1 (critical) on static scenes, 0 on dynamic ones",
    )
    .at_least(0.0),
];

const JOINTS: &[(&str, JointKind)] = &[("multibody", JointKind::Multibody), ("impulse", JointKind::Impulse)];

/// Default number of links.
pub const DEFAULT_LINKS: usize = 40;

/// Default time step (s): the 1 kHz haptic rate.
pub const DEFAULT_DT: f64 = 1e-3;

/// Factory of the rapier3d rigid chain (`id = "multibody"`).
#[derive(Debug, Clone, Copy, Default)]
pub struct MultibodyFactory;

impl ModelFactory for MultibodyFactory {
    fn id(&self) -> &'static str {
        "multibody"
    }
    fn description(&self) -> &'static str {
        "engine baseline: rigid links on rapier3d, spherical joints with EI/h and GJ/h springs (Hencky bar chain)"
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

    /// 40 links, `dt` = 1 ms, 1 inner iteration, multibody joints. On
    /// static scenes the first bending mode critically damped by the joint
    /// dampers (the settle criterion is then met within 0.13 s) and one
    /// substep: the equilibrium does not depend on it, and each substep
    /// costs a factorization of the dense generalized mass matrix (`O(n^3)`
    /// in the link count). On dynamic scenes no damping beyond the
    /// integrator's own and rapier's 4 substeps, which cut backward Euler's
    /// damping per period fourfold (`exp(-pi omega dt / substeps)` of the
    /// amplitude).
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let mut f = Fidelity {
            segments: Some(DEFAULT_LINKS),
            mesh_level: None,
            dt: Some(DEFAULT_DT),
            iterations: Some(1),
            extras: Default::default(),
        };
        let statics = scene.settle.is_some();
        f.extras
            .insert("damping".into(), if statics { 1.0 } else { 0.0 }.into());
        f.extras
            .insert("substeps".into(), if statics { 1.0 } else { 4.0 }.into());
        f
    }

    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        surgbench_core::model::check_one_rod(self.id(), self.capabilities(), scene)
    }

    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let f = settings.fidelity();
        let body = scene.rods().next().expect("checked: one rod");
        let dt = f.dt.unwrap_or(DEFAULT_DT);
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(BuildError::bad("dt", format!("must be > 0 s, got {dt}")));
        }
        let links = f.segments.unwrap_or(DEFAULT_LINKS);
        if links == 0 {
            return Err(BuildError::bad("segments", "the chain needs at least one link"));
        }
        let iterations = f.iterations.unwrap_or(1);
        if iterations == 0 {
            return Err(BuildError::bad("iterations", "must be at least 1"));
        }
        let params = ChainParams {
            links,
            joint: settings.pick("joint", JOINTS, JointKind::Multibody)?,
            substeps: settings.number_or("substeps", 4.0) as usize,
            iterations,
            damping_ratio: settings.number_or("damping", 0.0),
        };
        let rotation = scene.control.command_at(0.0).rotation;
        let chain = RigidChain::new(body, scene.gravity, &params, rotation).map_err(|e| BuildError::bad("scene", e))?;
        Ok(Box::new(MultibodyModel::new(chain, dt)))
    }
}
