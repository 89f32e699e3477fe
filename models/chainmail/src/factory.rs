//! The harness factory of the chain-mail guidewire: [`ChainmailFactory`]
//! (`id = "chainmail"`), its capabilities, fidelity keys and defaults.

use crate::rules::LinkParams;
use crate::wire::{BoxFrame, ChainmailWire, WireConfig};
use crate::{mapping, volume};
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Settings, Unsupported,
    Vec3,
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
    FidelityKey::choice(
        "frame",
        "axes of the valid boxes",
        &[
            Choice::new("world", "world axes exactly as the paper writes them"),
            Choice::new(
                "clamp",
                "the base clamp's axes (default without rest curvature or with beta_mapping=weight; rotation-invariant)",
            ),
            Choice::new(
                "link",
                "each sponsor's link frame, rest offsets in the body frame (needed for rest curvature and curved vessels; default with rest curvature or beta_mapping=navigation)",
            ),
        ],
    ),
    FidelityKey::number(
        "beta",
        "uniform shear limit beta for every link, replacing the material mapping (alpha_min = alpha_max = 1)",
    )
    .at_least(0.0),
    FidelityKey::choice(
        "beta_mapping",
        "material -> box mapping",
        &[
            Choice::new(
                "weight",
                "weight-calibrated (default in static scenes; its one constant fitted on a 0.1 m gravity cantilever at 20 segments and dt = 10 ms, not a scored scene; resolution-bound: sag / Euler-Bernoulli 0.14 at 40 segments; bends ~0.2 deg per 5 mm link)",
            ),
            Choice::new(
                "navigation",
                "per-link bend limit Delta eps_y / r from the core's recoverable strain; nothing fitted; default in dynamic scenes with a vessel (with frame=link)",
            ),
        ],
    ),
    FidelityKey::number(
        "yield_strain",
        "recoverable strain eps_y of the core for beta_mapping=navigation (default 0.06, superelastic nitinol; ~0.004 for stainless steel)",
    )
    .above(0.0),
    FidelityKey::number(
        "vessel_spacing",
        "moving vessels: spacing h (m) of the volumetric chain-mail lattice of wall and blood elements (default 0.5 mm)",
    )
    .above(0.0),
    FidelityKey::number(
        "vessel_slack",
        "moving vessels: compression/stretch slack s of the vessel's links, alpha_min = 1 - s, alpha_max = 1 + s (default 0.1)",
    ),
    FidelityKey::number(
        "vessel_beta",
        "moving vessels: shear limit beta of the vessel's links (default 0.1)",
    )
    .at_least(0.0),
    FidelityKey::number(
        "haptic_k",
        "haptic gain k (N/m) of F_feedback = k (friction displacement + first-link length change); default E A / Delta",
    )
    .above(0.0),
];

/// The names of `frame`, as box frames.
const FRAMES: &[(&str, BoxFrame)] = &[
    ("world", BoxFrame::World),
    ("clamp", BoxFrame::Base),
    ("link", BoxFrame::Link),
];

/// The names of `beta_mapping`: whether it is the navigation mapping.
const MAPPINGS: &[(&str, bool)] = &[("weight", false), ("navigation", true)];

impl ModelFactory for ChainmailFactory {
    fn id(&self) -> &'static str {
        "chainmail"
    }
    fn description(&self) -> &'static str {
        "generalized 3D chain-mail guidewire (geometric valid boxes + relaxation; boxes in the clamp frame, the paper's world axes with frame=world)"
    }
    /// The weight mapping's one constant ([`crate::mapping::BETA_CONSTANT`],
    /// fitted by [`crate::calibration`]).
    fn fitted(&self) -> Option<&'static str> {
        Some(
            "beta_mapping=weight (the default in static scenes): C = 1214.297 in beta = C w Delta^3 / (E I), fitted so that a 0.1 m gravity cantilever (r = 0.5 mm, E = 50 GPa) at 20 segments and dt = 10 ms sags as Euler-Bernoulli; resolution-bound: at 40 segments the 0.2 m cantilever sags 0.14 of Euler-Bernoulli. beta_mapping=navigation fits nothing",
        )
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
    /// curvature gets the link-frame boxes (`frame=link`), the only frame
    /// that can hold a curved rest shape.
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
            f.extras.insert("frame".into(), "link".into());
        }
        // Navigation (a dynamic run in a vessel) takes the bend limit from
        // the core's recoverable strain: with the weight-calibrated mapping
        // the wire trips the stretch watchdog in arch-insertion (1.89 s),
        // branch-selection (2.15 s) and vessel-mesh-insertion (0.69 s) at the
        // defaults; with this one all three run to the end. Static scenes keep
        // the weight mapping (with the navigation mapping flow-drift trips
        // the watchdog at 0.01 s).
        if scene.settle.is_none() && scene.environment.vessel.is_some() {
            f.extras.insert("beta_mapping".into(), "navigation".into());
        }
        f
    }

    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        if scene.rods().any(|r| r.initial_velocity.is_some()) {
            return Err(Unsupported::new(
                "the chain-mail is geometric: it has no momentum (gravity is a per-step displacement), so it cannot start with a velocity or vibrate freely",
            ));
        }
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

    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let f = settings.fidelity();
        let beta_mapping = if settings.pick("beta_mapping", MAPPINGS, false)? {
            mapping::BetaMapping::navigation(settings.number_or("yield_strain", mapping::NITINOL_RECOVERABLE_STRAIN))
                .map_err(|e| BuildError::bad("yield_strain", e))?
        } else {
            mapping::BetaMapping::Weight
        };
        // the navigation mapping bounds the bend between successive links:
        // only the link-frame boxes mean that, so it defaults to them
        let frame_default = match beta_mapping {
            mapping::BetaMapping::Navigation { .. } => BoxFrame::Link,
            mapping::BetaMapping::Weight => BoxFrame::Base,
        };
        let frame = settings.pick("frame", FRAMES, frame_default)?;
        let rod = scene.rods().next().expect("checked: one rod");
        if frame != BoxFrame::Link && rod.sections.iter().any(|s| s.rest_curvature != [0.0, 0.0]) {
            return Err(BuildError::Unsupported(Unsupported::new(
                "rest curvature needs the link-frame boxes (frame=link): world/clamp-axis boxes keep every link near the clamp direction",
            )));
        }
        // `beta` >= 0, like the other numeric keys' ranges, is declared in
        // the key table and checked by `surgbench_core::resolve`.
        let beta_override = settings.number("beta");
        let cfg = WireConfig {
            segments: f.segments.unwrap_or(DEFAULT_SEGMENTS),
            iterations: f.iterations.unwrap_or(DEFAULT_ITERATIONS),
            dt: f.dt.unwrap_or(DEFAULT_DT),
            frame,
            beta_constant: mapping::BETA_CONSTANT,
            beta_mapping,
            beta_override,
            haptic_k: settings.number("haptic_k"),
        };
        let mut w = ChainmailWire::new(rod, scene.gravity, &scene.environment, &cfg)
            .map_err(|e| BuildError::bad("chainmail", e))?;
        if let (Some(sdf), Some(motion)) = (&scene.environment.vessel, &scene.environment.vessel_motion) {
            let slack = settings.number_or("vessel_slack", DEFAULT_VESSEL_SLACK);
            if !(0.0..1.0).contains(&slack) {
                return Err(BuildError::bad(
                    "vessel_slack",
                    format!("must be in [0, 1), got {slack}"),
                ));
            }
            // the wire's reach: its length plus the deepest feed, plus a
            // margin of the lattice's own width around the tip
            let feed = scene.control.keys.iter().map(|k| k.insertion).fold(0.0, f64::max);
            let spacing = settings.number_or("vessel_spacing", DEFAULT_VESSEL_SPACING);
            let lcfg = volume::LatticeConfig {
                spacing,
                reach: rod.length + feed + 10.0 * spacing,
                links: LinkParams {
                    alpha_min: 1.0 - slack,
                    alpha_max: 1.0 + slack,
                    beta: settings.number_or("vessel_beta", DEFAULT_VESSEL_BETA),
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
