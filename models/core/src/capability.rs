//! What a scene needs and a model supports ([`Capability`]), and the broad
//! kind of a model ([`Family`]) reports group by.

/// Broad kind of a model, for grouping in reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Family {
    /// 1D rods: guidewires, catheters, needles.
    Rod,
    /// 3D deformable solids.
    Tissue,
    /// Rods coupled with tissue (needle insertion).
    Coupled,
    /// A rod model and a tissue model composed by the harness (an
    /// instrument in a deformable vessel: `der+fem`, ...).
    Pair,
}

impl Family {
    /// The family called `name` ([`Family::name`]), if any.
    pub fn from_name(name: &str) -> Option<Family> {
        [Family::Rod, Family::Tissue, Family::Coupled, Family::Pair]
            .into_iter()
            .find(|f| f.name() == name)
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Family::Rod => "rod",
            Family::Tissue => "tissue",
            Family::Coupled => "coupled",
            Family::Pair => "pair",
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
    /// A body started moving (`RodBody::initial_velocity`,
    /// `TissueBody::initial_velocity`): free vibration needs momentum.
    InitialVelocity,
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
    /// A tissue that takes forces on its contact surface from an instrument
    /// and reports where that surface is (`TissueBody::contact_surface`).
    SurfaceForces,
    /// A rod whose lumen the harness replaces before every step (the
    /// tissue's current inner wall, in a coupled run).
    DeformableLumen,
    /// A tissue made of several materials (`TissueBody::regions`: skin,
    /// capsule, an inclusion).
    MaterialRegions,
}

impl Capability {
    /// Every capability, in declaration order.
    pub const ALL: [Capability; 21] = [
        Capability::Rod,
        Capability::Twist,
        Capability::TipForce,
        Capability::LoadRamp,
        Capability::VaryingProperties,
        Capability::RestCurvature,
        Capability::Insertion,
        Capability::InitialVelocity,
        Capability::Tissue,
        Capability::PressureLoad,
        Capability::RollerConstraint,
        Capability::TissueContact,
        Capability::NeedleTissue,
        Capability::VesselContact,
        Capability::Friction,
        Capability::Flow,
        Capability::MovingVessel,
        Capability::HapticForce,
        Capability::SurfaceForces,
        Capability::DeformableLumen,
        Capability::MaterialRegions,
    ];

    /// The capability called `name` ([`Capability::name`]), if any.
    pub fn from_name(name: &str) -> Option<Capability> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }

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
            Capability::InitialVelocity => "started moving: an initial velocity field (free vibration)",
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
            Capability::SurfaceForces => "forces from an instrument on the tissue's contact surface",
            Capability::DeformableLumen => "a lumen replaced every step (a deforming vessel wall)",
            Capability::MaterialRegions => "tissue of several materials (layers, inclusions)",
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
            Capability::InitialVelocity => "initial-velocity",
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
            Capability::SurfaceForces => "surface-forces",
            Capability::DeformableLumen => "deformable-lumen",
            Capability::MaterialRegions => "material-regions",
        }
    }
}
