//! # surgbench-chainmail: the generalized 3D chain-mail guidewire
//!
//! The spatially varying six-DOF guidewire of the chain-mail seed paper
//! ("generalized 3D chain-mails", after Gibson 1997, *3D ChainMail*, and
//! Li & Brodlie 2003, *Soft object modelling with generalised ChainMail*),
//! implemented as written: a geometric model with no mass, no forces and no
//! energy, only valid boxes between neighbours ([`rules::valid_box`]),
//! propagation of moves along the chain, relaxation towards the
//! shape-preserving position, SDF collision with the paper's friction
//! factor, a per-step blood-flow displacement and the paper's haptic force.
//! SI units throughout (m, s, N, Pa, kg, rad).
//!
//! The harness calls [`ChainmailFactory`] (id `chainmail`). What the model
//! is and is not:
//! - the paper writes the boxes axis-aligned in **world axes** (`frame=0`);
//!   that rule is not rotation-invariant (rigidly moving a scene changes the
//!   answer, by 1.4 mm in the test) and keeps every link within about
//!   `atan(beta)` of its rest direction, so the wire cannot follow a curved
//!   vessel. The default `frame=1` aligns the boxes with the base clamp: the
//!   paper's rule exactly on scenes whose rod starts along +x (every rod
//!   statics scene), and it moves rigidly with the scene, as the harness's
//!   conformance suite requires of every model;
//! - `frame=2` ([`BoxFrame::Link`], the default for a rod with rest
//!   curvature) puts the boxes and rest offsets in each sponsor link's body
//!   frame turned by the rest curvature, resolves wall contact inside the
//!   relaxation iterations and holds a pre-curved (J) rest shape exactly.
//!   Its boxes still bound each link's bend by about `atan(beta)`; with the
//!   weight-calibrated `beta` the default nitinol body may bend by ~0.2 deg
//!   per 5 mm link, so it cannot follow a 35 mm aortic arch: the wall then
//!   compresses/stretches links past the harness's 5 % watchdog;
//!   After friction, one length-restoring pass (boxes swept from the clamp,
//!   then the wall) keeps friction from compressing links; on
//!   `coronary-tortuous` (`beta_mapping=1`, 40 segments) the stretch
//!   watchdog still trips at 43.7 s: the tip meets the wall ~25 deg head-on
//!   while its box lets it turn ~6 deg from its neighbour, so no position
//!   of the tip satisfies both box and wall and the wall wins (tip link
//!   -7.9 %);
//! - gravity is a displacement `g dt^2` per step, so a sag is an equilibrium
//!   of that displacement against the boxes and the relaxation: it depends
//!   on `dt`, `iterations` and `segments`, not only on the material;
//! - `beta` comes from the material by [`mapping`]: by default
//!   (`beta_mapping=0`) with one constant calibrated on the gravity
//!   cantilever ([`calibration::calibration_scene`]); `beta_mapping=1` bounds
//!   each link's bend by `Delta eps_y / r`, the largest elastic curvature of
//!   the core (nothing fitted): it can follow a vessel but no longer sags
//!   like the cantilever (see [`mapping`] for both and their trade-off);
//! - no twist dynamics: a base rotation turns the first tip element about the
//!   clamp axis and the frames carry the rotation rigidly; dead tip forces
//!   and torques have no meaning here and are refused;
//! - the hand force is the paper's `F_feedback = k (F_friction + F_internal)`
//!   with `k = E A / Delta` by default (extra `haptic_k`), on the hand along
//!   the friction corrections and `k (l_t - l_{t-1})` along the first link
//!   (a compressed first link pushes the hand back). A sticking contact
//!   removes a whole step's motion, so with the default `k` it gives
//!   forces of kN: the paper's formula has no physical scale.
//!
//! Measured (tests in `tests/chainmail.rs`): settled gravity sag over
//! Euler–Bernoulli is 1.000 at the calibration fidelity (segments 20,
//! dt 0.01 s, 10 sweeps), 0.138 at 40 segments, 0.045 at dt 1 ms, 0.72 at
//! 40 sweeps; a rigid motion of a scene changes the world-axis answer by
//! 1.4 mm and the base-axis answer by 2e-16 m.
//!
//! ```
//! use surgbench_chainmail::ChainmailFactory;
//! use surgbench_core::{DeviceCommand, Fidelity, ModelFactory, RodBody, Scene, Vec3};
//! let mut scene = Scene::empty("sag");
//! scene.bodies.push(RodBody::uniform(0.2, 5e-4, 5e10, 0.3, 6450.0).into());
//! scene.gravity = Vec3::new(0.0, 0.0, -9.81);
//! let mut model = ChainmailFactory.build(&scene, &Fidelity::default()).unwrap();
//! model.step(0.01, &DeviceCommand::default()).unwrap();
//! assert!(model.observe().rods[0].tip().z < 0.0);
//! ```

pub mod calibration;
pub mod mapping;
pub mod rules;
pub mod volume;
pub mod wire;

pub use rules::LinkParams;
pub use wire::{BoxFrame, ChainmailWire, WireConfig};

use surgbench_core::{
    BuildError, Capability, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Unsupported, Vec3,
};

/// Default links over the free length.
pub const DEFAULT_SEGMENTS: usize = 20;
/// Default relaxation sweeps per step.
pub const DEFAULT_ITERATIONS: usize = 10;
/// Default time step (s): 100 Hz, the graphics-rate regime the paper targets
/// ("real-time"); at 1 kHz the gravity step `g dt^2` is 100 times smaller
/// and the relaxation dominates every sag.
pub const DEFAULT_DT: f64 = 1e-2;

/// Default lattice spacing of a moving vessel's volumetric chain-mail (m):
/// three cells across a 1.5 mm coronary lumen radius.
pub const DEFAULT_VESSEL_SPACING: f64 = 5e-4;
/// Default compression/stretch slack of the vessel's links (dimensionless).
pub const DEFAULT_VESSEL_SLACK: f64 = 0.1;
/// Default shear limit of the vessel's links (dimensionless).
pub const DEFAULT_VESSEL_BETA: f64 = 0.1;

/// The chain-mail guidewire's factory (model id `chainmail`).
#[derive(Debug, Clone, Copy, Default)]
pub struct ChainmailFactory;

const CAPABILITIES: &[Capability] = &[
    Capability::Rod,
    Capability::Twist,
    Capability::VaryingProperties,
    Capability::RestCurvature,
    Capability::Insertion,
    Capability::VesselContact,
    Capability::Friction,
    Capability::Flow,
    Capability::MovingVessel,
    Capability::HapticForce,
];

const KEYS: &[FidelityKey] = &[
    FidelityKey {
        name: "frame",
        doc: "valid-box axes: 2 = each sponsor's link frame (rest offsets in the body frame; needed for rest curvature and curved vessels; default with rest curvature or beta_mapping=1), 1 = base-clamp axes (default otherwise, rotation-invariant), 0 = world axes exactly as the paper writes them",
    },
    FidelityKey {
        name: "beta",
        doc: "uniform shear limit beta >= 0 for every link, replacing the material mapping (alpha_min = alpha_max = 1)",
    },
    FidelityKey {
        name: "beta_mapping",
        doc: "material -> box mapping: 0 = weight-calibrated (default; calibrated on the gravity cantilever, bends ~0.2 deg per 5 mm link), 1 = navigation (per-link bend limit Delta eps_y / r from the core's recoverable strain; nothing fitted; use with frame=2 in vessels)",
    },
    FidelityKey {
        name: "yield_strain",
        doc: "recoverable strain eps_y of the core for beta_mapping=1 (default 0.06, superelastic nitinol; ~0.004 for stainless steel)",
    },
    FidelityKey {
        name: "vessel_spacing",
        doc: "moving vessels: spacing h (m) of the volumetric chain-mail lattice of wall and blood elements (default 0.5 mm)",
    },
    FidelityKey {
        name: "vessel_slack",
        doc: "moving vessels: compression/stretch slack s of the vessel's links, alpha_min = 1 - s, alpha_max = 1 + s (default 0.1)",
    },
    FidelityKey {
        name: "vessel_beta",
        doc: "moving vessels: shear limit beta of the vessel's links (default 0.1)",
    },
    FidelityKey {
        name: "haptic_k",
        doc: "haptic gain k (N/m) of F_feedback = k (friction displacement + first-link length change); default E A / Delta",
    },
];

impl ModelFactory for ChainmailFactory {
    fn id(&self) -> &'static str {
        "chainmail"
    }
    fn description(&self) -> &'static str {
        "generalized 3D chain-mail guidewire (geometric valid boxes + relaxation; boxes in the clamp frame, the paper's world axes with frame=0)"
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
    /// Segments, dt and sweeps as the calibration used them; a rod with rest
    /// curvature gets the link-frame boxes (`frame=2`), the only frame that
    /// can hold a curved rest shape.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let mut f = Fidelity {
            segments: Some(DEFAULT_SEGMENTS),
            dt: Some(DEFAULT_DT),
            iterations: Some(DEFAULT_ITERATIONS),
            ..Default::default()
        };
        let curved = scene
            .rods()
            .any(|r| r.sections.iter().any(|s| s.rest_curvature != [0.0, 0.0]));
        if curved {
            f.extras.insert("frame".into(), 2.0);
        }
        f
    }

    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        surgbench_core::model::check_capabilities(self.id(), self.capabilities(), scene)?;
        if scene.rods().count() != 1 || scene.tissues().count() != 0 {
            return Err(Unsupported::new("chainmail simulates exactly one rod and no tissue"));
        }
        let rod = scene.rods().next().expect("one rod");
        if rod.tip_torque != Vec3::zeros() {
            return Err(Unsupported::new(
                "chainmail has no torsional stiffness: a dead tip torque has no meaning (only base rotation)",
            ));
        }
        let c = scene.environment.contact.friction_static;
        if c > 1.0 {
            return Err(Unsupported::new(format!(
                "the chain-mail friction factor needs 0 <= C_f <= 1, scene has {c}"
            )));
        }
        Ok(())
    }

    fn build(&self, scene: &Scene, fidelity: &Fidelity) -> Result<Box<dyn Model>, BuildError> {
        self.check(scene)?;
        scene.validate().map_err(|e| BuildError::bad("scene", e))?;
        fidelity
            .check_extras(KEYS)
            .map_err(|e| BuildError::bad("fidelity", e.to_string()))?;
        let f = self.default_fidelity(scene).merged(fidelity);
        let beta_mapping = mapping::BetaMapping::from_codes(
            f.extra("beta_mapping", 0.0),
            f.extra("yield_strain", mapping::NITINOL_RECOVERABLE_STRAIN),
        )
        .map_err(|e| BuildError::bad("beta_mapping", e))?;
        // the navigation mapping bounds the bend between successive links:
        // only the link-frame boxes mean that, so it defaults to them
        let frame_default = match beta_mapping {
            mapping::BetaMapping::Navigation { .. } => 2.0,
            mapping::BetaMapping::Weight => 1.0,
        };
        let frame_code = f.extra("frame", frame_default);
        let frame = BoxFrame::from_code(frame_code)
            .ok_or_else(|| BuildError::bad("frame", format!("must be 0, 1 or 2, got {frame_code}")))?;
        let rod = scene.rods().next().expect("checked: one rod");
        if frame != BoxFrame::Link && rod.sections.iter().any(|s| s.rest_curvature != [0.0, 0.0]) {
            return Err(BuildError::Unsupported(Unsupported::new(
                "rest curvature needs the link-frame boxes (frame=2): world/base-axis boxes keep every link near the clamp direction",
            )));
        }
        let beta_override = f.extras.get("beta").copied();
        if let Some(b) = beta_override
            && (b.is_nan() || b < 0.0)
        {
            return Err(BuildError::bad("beta", format!("must be >= 0, got {b}")));
        }
        let cfg = WireConfig {
            segments: f.segments.unwrap_or(DEFAULT_SEGMENTS),
            iterations: f.iterations.unwrap_or(DEFAULT_ITERATIONS),
            dt: f.dt.unwrap_or(DEFAULT_DT),
            frame,
            beta_constant: mapping::BETA_CONSTANT,
            beta_mapping,
            beta_override,
            haptic_k: f.extras.get("haptic_k").copied(),
        };
        let mut w = ChainmailWire::new(rod, scene.gravity, &scene.environment, &cfg)
            .map_err(|e| BuildError::bad("chainmail", e))?;
        if let (Some(sdf), Some(motion)) = (&scene.environment.vessel, &scene.environment.vessel_motion) {
            let slack = f.extra("vessel_slack", DEFAULT_VESSEL_SLACK);
            if !(0.0..1.0).contains(&slack) {
                return Err(BuildError::bad(
                    "vessel_slack",
                    format!("must be in [0, 1), got {slack}"),
                ));
            }
            // the wire's reach: its length plus the deepest feed, plus a
            // margin of the lattice's own width around the tip
            let feed = scene.control.keys.iter().map(|k| k.insertion).fold(0.0, f64::max);
            let spacing = f.extra("vessel_spacing", DEFAULT_VESSEL_SPACING);
            let lcfg = volume::LatticeConfig {
                spacing,
                reach: rod.length + feed + 10.0 * spacing,
                links: LinkParams {
                    alpha_min: 1.0 - slack,
                    alpha_max: 1.0 + slack,
                    beta: f.extra("vessel_beta", DEFAULT_VESSEL_BETA),
                },
                iterations: cfg.iterations,
            };
            let lat = volume::VesselLattice::new(sdf.clone(), motion.clone(), &rod.base, &lcfg)
                .map_err(|e| BuildError::bad("vessel_spacing", e))?;
            w.set_vessel_lattice(lat);
        }
        Ok(Box::new(w))
    }
}
