//! What a model shows the harness after each step: enough to score any
//! scenario without knowing the model.

use crate::{Mat3, Vec3};

/// One rod's state.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RodObs {
    /// Rest arclength of every node from the base clamp (m); nodes behind
    /// the clamp (ghosts) have negative arclength.
    pub arclength: Vec<f64>,
    /// Rest positions (m).
    pub rest: Vec<Vec3>,
    /// Current positions (m), base to tip.
    pub nodes: Vec<Vec3>,
    /// Node velocities (m/s).
    pub velocities: Vec<Vec3>,
    /// Material frame of every edge: columns `(d1, d2, t)`.
    pub frames: Vec<Mat3>,
    /// Largest relative edge stretch `|e|/|e_rest| - 1` (signed by magnitude).
    pub max_stretch: f64,
}

impl RodObs {
    /// Tip node position (m).
    pub fn tip(&self) -> Vec3 {
        *self.nodes.last().unwrap_or(&Vec3::zeros())
    }
    /// Material frame of the last edge.
    pub fn tip_frame(&self) -> Mat3 {
        *self.frames.last().unwrap_or(&Mat3::identity())
    }
}

/// One tissue's state.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TissueObs {
    /// Rest positions (m).
    pub rest: Vec<Vec3>,
    /// Current positions (m).
    pub nodes: Vec<Vec3>,
    /// Node velocities (m/s); empty for quasi-static models.
    pub velocities: Vec<Vec3>,
    /// Current volume over rest volume, minus one.
    pub volume_error: f64,
    /// Count of inverted elements.
    pub inverted: usize,
    /// Smallest and largest dihedral angle (degrees) of the rest mesh, from
    /// a model that changes its mesh as it runs (the needle's tip
    /// remeshing); `None` from the others.
    pub rest_dihedral_deg: Option<[f64; 2]>,
}

/// A contact point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactObs {
    /// Position (m).
    pub point: Vec3,
    /// Force the wall exerts on the body (N).
    pub force: Vec3,
    /// Penetration depth past the wall (m), >= 0.
    pub penetration: f64,
}

/// Energies (J).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnergyObs {
    /// Kinetic energy.
    pub kinetic: f64,
    /// Elastic (strain) energy.
    pub elastic: f64,
    /// Potential of gravity and dead loads.
    pub external: f64,
}

impl EnergyObs {
    /// Total mechanical energy.
    pub fn total(&self) -> f64 {
        self.kinetic + self.elastic + self.external
    }
}

/// Everything the harness reads from a model.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Observation {
    /// Simulated time (s).
    pub time: f64,
    /// Rods, in scene order.
    pub rods: Vec<RodObs>,
    /// Tissues, in scene order.
    pub tissues: Vec<TissueObs>,
    /// Contacts this step.
    pub contacts: Vec<ContactObs>,
    /// Force the body exerts on the operator's hand / clamp (N).
    pub hand_force: Vec3,
    /// Torque the body exerts on the hand / clamp about the clamp point (N m).
    pub hand_torque: Vec3,
    /// Energies.
    pub energy: EnergyObs,
    /// Constraint residual where the model has constraints.
    pub constraint_residual: Option<f64>,
}

impl Observation {
    /// Whether every number in the observation is finite.
    pub fn is_finite(&self) -> bool {
        let v = |x: &Vec3| x.iter().all(|c| c.is_finite());
        self.rods.iter().all(|r| {
            r.nodes.iter().all(v)
                && r.velocities.iter().all(v)
                && r.frames.iter().all(|m| m.iter().all(|c| c.is_finite()))
        }) && self.tissues.iter().all(|t| t.nodes.iter().all(v))
            && v(&self.hand_force)
            && v(&self.hand_torque)
            && self.energy.total().is_finite()
    }

    /// Largest penetration over all contacts (m).
    pub fn max_penetration(&self) -> f64 {
        self.contacts.iter().map(|c| c.penetration).fold(0.0, f64::max)
    }

    /// Largest node speed over all bodies (m/s).
    pub fn max_speed(&self) -> f64 {
        self.rods
            .iter()
            .flat_map(|r| r.velocities.iter())
            .chain(self.tissues.iter().flat_map(|t| t.velocities.iter()))
            .map(|v| v.norm())
            .fold(0.0, f64::max)
    }
}
