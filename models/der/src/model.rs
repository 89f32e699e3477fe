//! [`DerModel`]: a [`DerRod`] stepped and observed by the harness.

use crate::rod::DerRod;
use std::any::Any;
use std::sync::Arc;
use surgbench_core::{DeviceCommand, EnergyProbe, Model, Observation, Sdf, SimError, StepStats};

/// A [`DerRod`] built for one scene, stepped by the harness.
#[derive(Debug, Clone)]
pub struct DerModel {
    /// The rod (public so callers can inspect or drive it directly).
    pub rod: DerRod,
    dt: f64,
}

impl DerModel {
    /// Wrap a rod stepped at `dt` (s).
    pub fn new(rod: DerRod, dt: f64) -> Self {
        Self { rod, dt }
    }
}

impl Model for DerModel {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.rod.step(dt, cmd)
    }

    fn observe(&self) -> Observation {
        let (hand_force, hand_torque) = self.rod.hand_wrench();
        Observation {
            time: self.rod.time(),
            rods: vec![self.rod.rod_obs()],
            tissues: Vec::new(),
            contacts: self.rod.contacts().to_vec(),
            hand_force,
            hand_torque,
            energy: self.rod.energies(),
            constraint_residual: None,
        }
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn energy_probe(&mut self) -> Option<&mut dyn EnergyProbe> {
        Some(&mut self.rod)
    }

    fn set_lumen(&mut self, lumen: Arc<dyn Sdf>) -> Result<(), SimError> {
        self.rod.replace_lumen(lumen);
        Ok(())
    }

    /// The whole rod (its state is its positions, velocities, frames and
    /// lagged contacts; the lumen is shared, not copied).
    fn save_state(&self) -> Option<Box<dyn Any + Send>> {
        Some(Box::new(self.rod.clone()))
    }

    fn restore_state(&mut self, state: &(dyn Any + Send)) -> Result<(), SimError> {
        let rod = state.downcast_ref::<DerRod>().ok_or_else(|| SimError::SolverFailed {
            t: self.rod.time(),
            reason: "not a saved DER state".into(),
        })?;
        self.rod.clone_from(rod);
        Ok(())
    }
}
