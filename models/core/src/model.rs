//! The two traits a model crate implements.
//!
//! [`ModelFactory`] says what a model can do and builds it; [`Model`] steps
//! and observes. Optional hooks have default methods, so a minimal model
//! implements `step` and `observe` and nothing else.

use crate::error::{BuildError, SimError, Unsupported};
use crate::fidelity::{Fidelity, FidelityKey};
use crate::observation::Observation;
use crate::scene::{DeviceCommand, Scene};

/// Broad kind of a model, for grouping in reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Family {
    /// 1D rods: guidewires, catheters, needles.
    Rod,
    /// 3D deformable solids.
    Tissue,
    /// Rods coupled with tissue (needle insertion).
    Coupled,
}

impl Family {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Family::Rod => "rod",
            Family::Tissue => "tissue",
            Family::Coupled => "coupled",
        }
    }
}

/// A feature a scene may need and a model may support.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Capability {
    /// Simulates a 1D rod.
    Rod,
    /// Resolves twist (base rotation, torques).
    Twist,
    /// Dead force at the rod tip.
    TipForce,
    /// Tip loads that change over time (`RodBody::tip_load_ramp`).
    LoadRamp,
    /// Properties varying along the rod.
    VaryingProperties,
    /// Natural (rest) curvature.
    RestCurvature,
    /// Wire fed in or pulled back at the base.
    Insertion,
    /// 3D deformable solid.
    Tissue,
    /// Pressure (follower) loads on tissue boundary faces.
    PressureLoad,
    /// Nodes held along some axes only (rollers, symmetry, plane strain).
    RollerConstraint,
    /// Frictionless unilateral contact of a tissue with a rigid sphere
    /// (`TissueBody::indenter`).
    TissueContact,
    /// Rod-tissue coupling.
    NeedleTissue,
    /// Contact with a vessel wall (SDF).
    VesselContact,
    /// Coulomb friction at contacts.
    Friction,
    /// Blood-flow drag.
    Flow,
    /// A vessel that moves and deforms over time (`Environment::vessel_motion`).
    MovingVessel,
    /// Reports a hand force/torque a haptic device can render.
    HapticForce,
}

impl Capability {
    /// One-line description.
    pub fn describe(self) -> &'static str {
        match self {
            Capability::Rod => "1D rod (guidewire, catheter, needle)",
            Capability::Twist => "twist: base rotation and torques",
            Capability::TipForce => "dead force on the rod tip",
            Capability::LoadRamp => "tip loads that change over time",
            Capability::VaryingProperties => "stiffness, radius or density varying along the rod",
            Capability::RestCurvature => "natural (pre-shaped) curvature",
            Capability::Insertion => "insertion/retraction at the base",
            Capability::Tissue => "3D deformable tissue",
            Capability::PressureLoad => "pressure loads on tissue faces",
            Capability::RollerConstraint => "nodes held along some axes only (rollers, symmetry planes)",
            Capability::TissueContact => "frictionless contact of tissue with a rigid sphere (indenter)",
            Capability::NeedleTissue => "needle-tissue coupling",
            Capability::VesselContact => "contact with a vessel wall",
            Capability::Friction => "Coulomb friction",
            Capability::Flow => "blood-flow drag",
            Capability::MovingVessel => "a vessel moving over time (beating heart)",
            Capability::HapticForce => "hand force/torque for haptic rendering",
        }
    }

    /// kebab-case name used in listings and the report.
    pub fn name(self) -> &'static str {
        match self {
            Capability::Rod => "rod",
            Capability::Twist => "twist",
            Capability::TipForce => "tip-force",
            Capability::LoadRamp => "load-ramp",
            Capability::VaryingProperties => "varying-properties",
            Capability::RestCurvature => "rest-curvature",
            Capability::Insertion => "insertion",
            Capability::Tissue => "tissue",
            Capability::PressureLoad => "pressure-load",
            Capability::RollerConstraint => "roller-constraint",
            Capability::TissueContact => "tissue-contact",
            Capability::NeedleTissue => "needle-tissue",
            Capability::VesselContact => "vessel-contact",
            Capability::Friction => "friction",
            Capability::Flow => "flow",
            Capability::MovingVessel => "moving-vessel",
            Capability::HapticForce => "haptic-force",
        }
    }
}

/// What one step cost.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepStats {
    /// Solver iterations this step (Newton, PBD, relaxation: model's choice).
    pub iterations: u32,
    /// Final solver residual (model-defined, dimensionless or SI as documented).
    pub residual: f64,
    /// Whether the solver met its tolerance.
    pub converged: bool,
}

/// A simulated model instance built for one scene at one fidelity.
pub trait Model: Send {
    /// Advance by `dt` seconds with the operator's command at the *end* of
    /// the step.
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError>;

    /// Current state, in the shared observation format.
    fn observe(&self) -> Observation;

    /// The time step the model was built for (s).
    fn dt(&self) -> f64;

    /// Energy access for the conformance suite; `None` for models without a
    /// potential (e.g. purely geometric ones).
    fn energy_probe(&mut self) -> Option<&mut dyn EnergyProbe> {
        None
    }

    /// Model-specific diagnostics of the current state (name -> value, SI,
    /// the unit in the name), e.g. the error a surface mapping adds on its
    /// own. The harness reports them beside the scenario's metrics as
    /// `diag_<name>`; they are not scored against a reference.
    fn diagnostics(&self) -> std::collections::BTreeMap<String, f64> {
        std::collections::BTreeMap::new()
    }
}

/// Generalized coordinates, potential energy and forces: the conformance
/// suite checks forces = -dE/dq by finite differences (SOFA's ForceField test).
pub trait EnergyProbe {
    /// Generalized coordinates (model-defined order, SI units).
    fn coords(&self) -> Vec<f64>;
    /// Set the generalized coordinates (same order as [`EnergyProbe::coords`]).
    fn set_coords(&mut self, q: &[f64]);
    /// Potential energy at the current coordinates (J).
    fn potential(&self) -> f64;
    /// Generalized forces `-dE/dq` at the current coordinates.
    fn forces(&self) -> Vec<f64>;
    /// Indices of coordinates that are free (not fixed by boundary conditions).
    fn free(&self) -> Vec<usize>;
}

/// Builds a model for a scene; one per model variant, registered in the
/// harness's registry with one line.
pub trait ModelFactory: Send + Sync {
    /// Stable id (`der`, `chainmail`, ...), used on the command line.
    fn id(&self) -> &'static str;
    /// One-line human description.
    fn description(&self) -> &'static str;
    /// Family for grouping.
    fn family(&self) -> Family;
    /// What the model can simulate.
    fn capabilities(&self) -> &'static [Capability];
    /// Model-specific fidelity extras it accepts.
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        &[]
    }
    /// Fidelity used for knobs the caller leaves unset.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity;

    /// Can the model run this scene? Default: every required capability is
    /// supported; otherwise [`Unsupported`] names the missing ones.
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        check_capabilities(self.id(), self.capabilities(), scene)
    }

    /// Build the model at `fidelity` (unset knobs take the model's defaults).
    fn build(&self, scene: &Scene, fidelity: &Fidelity) -> Result<Box<dyn Model>, BuildError>;
}

/// `Ok` if `have` covers every capability `scene` requires; otherwise
/// [`Unsupported`] naming the missing ones. The default
/// [`ModelFactory::check`]; factories with extra conditions call it first.
pub fn check_capabilities(id: &str, have: &[Capability], scene: &Scene) -> Result<(), Unsupported> {
    let missing: Vec<&str> = scene
        .required_capabilities()
        .into_iter()
        .filter(|c| !have.contains(c))
        .map(|c| c.name())
        .collect();
    if missing.is_empty() {
        Ok(())
    } else {
        Err(Unsupported::new(format!("{id} does not model: {}", missing.join(", "))))
    }
}
