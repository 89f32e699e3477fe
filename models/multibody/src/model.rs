//! [`MultibodyModel`]: a [`RigidChain`] stepped and observed by the harness.

use crate::chain::RigidChain;
use std::collections::BTreeMap;
use surgbench_core::{DeviceCommand, Model, Observation, SimError, StepStats};

/// A [`RigidChain`] built for one scene, stepped by the harness.
pub struct MultibodyModel {
    /// The chain (public so callers can inspect or drive it directly).
    pub chain: RigidChain,
    dt: f64,
}

impl MultibodyModel {
    /// Wrap a chain stepped at `dt` (s).
    pub fn new(chain: RigidChain, dt: f64) -> Self {
        Self { chain, dt }
    }
}

impl Model for MultibodyModel {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.chain.step(dt, cmd)?;
        // rapier reports neither iterations nor a residual per step.
        Ok(StepStats {
            iterations: 1,
            residual: 0.0,
            converged: true,
        })
    }

    fn observe(&self) -> Observation {
        let (hand_force, hand_torque) = self.chain.hand_wrench();
        Observation {
            time: self.chain.time(),
            rods: vec![self.chain.rod_obs()],
            tissues: Vec::new(),
            contacts: Vec::new(),
            hand_force,
            hand_torque,
            energy: self.chain.energies(),
            constraint_residual: None,
        }
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    /// How far rapier's spherical-joint coordinates (what its springs act
    /// on) are from the true relative rotations (rad), and how far the
    /// joints have opened (m, impulse joints).
    fn diagnostics(&self) -> BTreeMap<String, f64> {
        BTreeMap::from([
            ("joint_coord_drift_rad".into(), self.chain.coord_drift()),
            ("joint_gap_max_m".into(), self.chain.max_joint_gap()),
        ])
    }
}
