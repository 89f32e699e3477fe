//! The harness factory of the rigid chain: [`MultibodyFactory`]
//! (`id = "multibody"`), its capabilities, settings by name and defaults.

use crate::chain::{ChainParams, JointKind, RigidChain};
use crate::model::MultibodyModel;
use surgbench_core::sdf::{level_surface, lumen_radius_at};
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Settings, Unsupported,
    Vec3,
};

/// What the chain simulates. Not: a moving vessel (rapier's triangle mesh
/// would have to be rebuilt each step to follow a non-rigid motion) or a
/// deforming one; scenes that need them are refused with the list.
/// Friction is rapier's Coulomb cone with one coefficient, the scene's
/// dynamic one: a wire sticks until `mu_d N`, not `mu_s N`.
const CAPABILITIES: &[Capability] = &[
    Capability::Rod,
    Capability::Twist,
    Capability::TipForce,
    Capability::LoadRamp,
    Capability::VaryingProperties,
    Capability::RestCurvature,
    Capability::Insertion,
    Capability::VesselContact,
    Capability::Friction,
    Capability::Flow,
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
                "reduced-coordinate multibody, implicit joint springs (default, except dynamic scenes with a vessel)",
            ),
            Choice::new(
                "impulse",
                "impulse joints: free bodies, iterative constraints, springs as force-based joint motors (default in dynamic scenes with a vessel, where wall contacts push a multibody's clamp off its command)",
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
    FidelityKey::number(
        "contact_hz",
        "vessel scenes: natural frequency (Hz) of rapier's soft contact against the wall; default 1/(4 dt), a quarter period per step (rapier's own default is 60 Hz)",
    )
    .at_least(1e-9),
    FidelityKey::number(
        "wall_spacing",
        "vessel scenes: grid spacing (m) of the vessel wall's triangle mesh (marching tetrahedra on the scene's SDF); default 1/8 of the clamp's distance to the wall (chord sag ~ 0.2 % of a round lumen's radius)",
    )
    .at_least(1e-9),
];

/// Fraction of the clamp's distance to the wall (about the lumen radius)
/// taken as the wall mesh's grid spacing: a chord of a circle of radius `R`
/// with length `R/8` sags `R/512` from it.
const WALL_SPACING_OF_RADIUS: f64 = 1.0 / 8.0;

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
    ///
    /// Dynamic scenes with a vessel get impulse joints: with multibody
    /// joints the 40-link wire trips the stretch watchdog in
    /// `branch-selection` (t = 2.9 s), `vessel-mesh-insertion` (1.5 s) and
    /// `capstan` (0.7 s). A likely cause, read in rapier 0.36.1's source
    /// and not verified: its contact Jacobians leave the clamp's kinematic
    /// DOFs at unit inverse mass (`Multibody::fill_jacobians` solves only
    /// the other rows), so contacts can push the clamp off its command. A
    /// multibody step is also 10 to 24 times the cost with
    /// hundreds of wall contacts. On impulse joints the same runs end `ok`
    /// (capstan still trips at 2.2 s). The static scene with a vessel
    /// (`flow-drift`, whose wire starts clear of the wall) keeps multibody
    /// joints: impulse joints at one substep open there by 17 % of a link
    /// in the first step.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let mut f = Fidelity {
            segments: Some(DEFAULT_LINKS),
            mesh_level: None,
            dt: Some(DEFAULT_DT),
            iterations: Some(1),
            extras: Default::default(),
        };
        let statics = scene.settle.is_some();
        if !statics && scene.environment.vessel.is_some() {
            f.extras.insert("joint".into(), "impulse".into());
        }
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
        let mut chain =
            RigidChain::new(body, scene.gravity, &params, rotation).map_err(|e| BuildError::bad("scene", e))?;
        if let Some(vessel) = &scene.environment.vessel {
            let clamp = body.base.translation.vector;
            let clearance = lumen_radius_at(vessel.as_ref(), &clamp)
                .ok_or_else(|| BuildError::bad("scene", "the clamp is not inside the vessel's lumen"))?;
            let spacing = settings.number_or("wall_spacing", WALL_SPACING_OF_RADIUS * clearance);
            // Everything the wire can reach: its length plus the farthest
            // the clamp is pushed, around the clamp.
            let feed = scene.control.keys.iter().map(|k| k.insertion.abs()).fold(0.0, f64::max);
            let reach = Vec3::repeat(body.length + feed + 2.0 * clearance);
            // The facets are chords of the wall, up to sqrt(3) spacing long
            // (grid diagonals): on a lumen of radius R they cut up to
            // 3 spacing^2 / (8 R) into it. The surface is moved out by
            // that much, so that a wire touching the true wall (a clamp on
            // it, a wire laid on it) is not pushed off it by the mesh.
            let level = 3.0 * spacing * spacing / (8.0 * clearance);
            // The grid in the clamp's frame: a scene moved rigidly gets
            // the same wall, moved.
            let surface = level_surface(vessel.as_ref(), level, &body.base, -reach, reach, spacing)
                .map_err(|e| BuildError::bad("wall_spacing", e))?;
            let contact = scene.environment.contact;
            chain
                .add_wall(
                    &surface,
                    contact.friction_dynamic,
                    contact.margin,
                    settings.number_or("contact_hz", 0.25 / dt),
                )
                .map_err(|e| BuildError::bad("scene", e))?;
        }
        if let Some(flow) = &scene.environment.flow {
            chain.set_flow(flow.clone());
        }
        Ok(Box::new(MultibodyModel::new(chain, dt)))
    }
}
