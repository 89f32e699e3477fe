//! The harness contract of [`MeshlessTissue`]: stepping, observation,
//! diagnostics and the conformance energy probe.

use super::*;
use crate::elastic::StateCache;
use surgbench_core::coupling::check_surface_forces;
use surgbench_core::statics::LoadStepper;
use surgbench_core::{DeviceCommand, EnergyProbe, Model, Observation, SimError, StepStats, TissueObs, Vec3};

impl Model for MeshlessTissue {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        SimError::check_dt(self.time, dt)?;
        let n = self.x.len();
        let xn = self.x.clone();
        let last_load = self.load_scale;
        self.load_scale = cmd.load;
        if let Some(c) = &mut self.contact {
            c.set_load(cmd.load);
        }
        let stats = match self.set.integrator {
            Integrator::SymplecticEuler => {
                self.explicit_step(dt, cmd.load);
                StepStats {
                    iterations: 0,
                    residual: 0.0,
                    converged: true,
                }
            }
            Integrator::BackwardEuler => self.implicit_step(&xn, dt, cmd.load)?,
            Integrator::QuasiStatic => self.static_step(&xn, dt, last_load, cmd.load)?,
        };
        if let Some(pbd) = &self.pbd {
            let w: Vec<f64> = (0..n)
                .map(|i| {
                    if self.axis_free[i] == Vec3::zeros() {
                        0.0
                    } else {
                        1.0 / self.mass[i]
                    }
                })
                .collect();
            self.pbd_residual = pbd.project(&mut self.x, &w, &self.axis_free, self.set.iterations);
        }
        for i in 0..n {
            self.v[i] = (self.x[i] - xn[i]) / dt;
        }
        self.time += dt;
        if let Some(reason) = self.check_state() {
            return Err(SimError::Diverged { t: self.time, reason });
        }
        let x = std::mem::take(&mut self.x);
        self.internal_forces(&x);
        self.pressure_forces(&x);
        self.x = x;
        self.forces_at_x = true;
        self.hand_force = self
            .driven
            .iter()
            .map(|&(i, _)| self.forces[i] + self.pforces[i] + self.gravity * self.mass[i])
            .sum::<Vec3>()
            + self.contact.as_ref().map_or(Vec3::zeros(), |c| c.reaction(&self.x));
        Ok(stats)
    }

    fn observe(&self) -> Observation {
        let inverted = (0..self.x.len())
            .filter(|&i| !(self.el.deformation_gradient(i, &self.x).determinant() > 0.0))
            .count();
        Observation {
            time: self.time,
            tissues: vec![TissueObs {
                rest: self.el.rest.clone(),
                nodes: self.x.clone(),
                velocities: self.v.clone(),
                volume_error: self.volume_error(),
                inverted,
                rest_dihedral_deg: None,
            }],
            hand_force: self.hand_force,
            energy: self.energies(),
            constraint_residual: self.pbd.as_ref().map(|_| self.pbd_residual),
            ..Default::default()
        }
    }

    fn dt(&self) -> f64 {
        self.set.dt
    }

    fn energy_probe(&mut self) -> Option<&mut dyn EnergyProbe> {
        Some(self)
    }

    /// The contact surface where the seed puts it: the MLS map of the nodes
    /// at the surface particles (Sec. "surface update" of the meshless seed).
    fn surface_positions(&self) -> Option<Vec<Vec3>> {
        (!self.contact_particles.is_empty()).then(|| {
            self.contact_particles
                .iter()
                .map(|&k| self.mls.map_one(k, &self.x))
                .collect()
        })
    }

    /// Forces on the MLS surface particles, spread over the nodes by the
    /// transpose of the map (`f_j = sum_k phi_j(p_k) f_k`: the nodal forces
    /// that do the same virtual work), replacing the previous ones.
    fn set_surface_forces(&mut self, forces: &[Vec3]) -> Result<(), SimError> {
        check_surface_forces(self.contact_particles.len(), forces).map_err(|e| SimError::SolverFailed {
            t: self.time,
            reason: format!("meshless: {e}"),
        })?;
        self.external.iter_mut().for_each(|f| *f = Vec3::zeros());
        for (&k, f) in self.contact_particles.iter().zip(forces) {
            for (j, phi) in self.mls.shape_functions(k) {
                self.external[j] += f * phi;
            }
        }
        Ok(())
    }

    /// The whole model: a coupling retrying a step restores it.
    fn save_state(&self) -> Option<Box<dyn std::any::Any + Send>> {
        Some(Box::new(self.clone()))
    }

    fn restore_state(&mut self, state: &(dyn std::any::Any + Send)) -> Result<(), SimError> {
        let t = self.time;
        surgbench_core::model::restore_clone(self, state, "meshless", t)
    }

    /// The MLS surface's distance from the node surface it maps (m):
    /// `mls_surface_error_rms_m`, `mls_surface_error_max_m` over the surface
    /// particles, the error the mapping adds on its own in this state.
    /// Quasi-static runs add the load increments their load stepping
    /// solved (`load_increments`) and the Newton solves it retried with
    /// half the increment (`load_increment_failures`).
    fn diagnostics(&self) -> std::collections::BTreeMap<String, f64> {
        let e = self.surface_mapping_errors();
        let mut d: std::collections::BTreeMap<String, f64> = [
            ("mls_surface_error_rms_m".to_string(), e.rms),
            ("mls_surface_error_max_m".to_string(), e.max),
        ]
        .into();
        if self.set.integrator == Integrator::QuasiStatic {
            d.insert("load_increments".into(), self.load_stepping.0 as f64);
            d.insert("load_increment_failures".into(), self.load_stepping.1 as f64);
        }
        d
    }
}

/// Coordinates are the node positions `(x0, y0, z0, x1, ...)` (m); the
/// potential is strain + hourglass energy + the sphere contact's penalty energy
/// (sphere where the last step left it) + gravity (J); forces are `-dE/dq`
/// (N). Pressure loads are left out: a follower load on an open surface has
/// no potential ([`crate::pressure`]).
impl EnergyProbe for MeshlessTissue {
    fn coords(&self) -> Vec<f64> {
        self.x.iter().flat_map(|p| p.iter().copied()).collect()
    }
    fn set_coords(&mut self, q: &[f64]) {
        self.forces_at_x = false;
        for (i, p) in self.x.iter_mut().enumerate() {
            *p = Vec3::new(q[3 * i], q[3 * i + 1], q[3 * i + 2]);
        }
    }
    fn potential(&self) -> f64 {
        let (u, hg) = self.el.energy(&self.x);
        u + hg + self.contact.as_ref().map_or(0.0, |c| c.energy(&self.x))
            - (0..self.x.len())
                .map(|i| (self.mass[i] * self.gravity + self.external[i]).dot(&self.x[i]))
                .sum::<f64>()
    }
    fn forces(&self) -> Vec<f64> {
        let mut cache = StateCache::default();
        self.el.prepare(&self.x, &mut cache);
        let mut f = vec![Vec3::zeros(); self.x.len()];
        self.el.add_forces(&self.x, &cache, &mut f);
        if let Some(c) = &self.contact {
            let mut g = vec![Vec3::zeros(); self.x.len()];
            c.add_gradient(&self.x, &mut g);
            f.iter_mut().zip(&g).for_each(|(fi, gi)| *fi -= gi);
        }
        f.iter()
            .zip(&self.mass)
            .zip(&self.external)
            .flat_map(|((fi, m), fe)| (fi + self.gravity * *m + fe).iter().copied().collect::<Vec<_>>())
            .collect()
    }
    fn free(&self) -> Vec<usize> {
        (0..3 * self.x.len())
            .filter(|&k| self.axis_free[k / 3][k % 3] != 0.0)
            .collect()
    }
}

impl MeshlessTissue {
    /// Symplectic Euler step of length `dt` (s): velocities from the forces
    /// at the current positions, then positions; the held nodes follow the
    /// command's `load`.
    fn explicit_step(&mut self, dt: f64, load: f64) {
        let n = self.x.len();
        let x = std::mem::take(&mut self.x);
        if !self.forces_at_x {
            self.internal_forces(&x);
        }
        self.pressure_forces(&x);
        self.x = x;
        for i in 0..n {
            let f = self.forces[i] + self.pforces[i];
            let a = f / self.mass[i] + self.gravity - self.v[i] * self.damping;
            self.v[i] = (self.v[i] + a * dt).component_mul(&self.axis_free[i]);
            self.x[i] += self.v[i] * dt;
        }
        let mut x = std::mem::take(&mut self.x);
        self.apply_targets(&mut x, load);
        self.x = x;
    }

    /// Quasi-static step from the equilibrium `xn` at the command
    /// `last_load` to the command `load`, by the adaptive load stepping the
    /// FEM model uses ([`LoadStepper`]); a Newton solve fails when it has
    /// not converged in 50 iterations. Should the stepper give up, the
    /// step reports an unconverged solve of the whole remaining change
    /// from the last equilibrium (the failed solve itself when it was that
    /// one), as a single Newton solve did before.
    fn static_step(&mut self, xn: &[Vec3], dt: f64, last_load: f64, load: f64) -> Result<StepStats, SimError> {
        let mut steps = LoadStepper::new(last_load, load);
        let mut x_ok = xn.to_vec();
        let mut iterations = 0;
        let mut stats = loop {
            let hi = steps.target();
            let mut stats = self.solve_at(&x_ok, dt, hi)?;
            iterations += stats.iterations;
            if stats.converged {
                if steps.converged(stats.iterations as usize) {
                    break stats;
                }
                x_ok.clone_from(&self.x);
            } else if steps.failed() {
                self.x.clone_from(&x_ok);
            } else if hi == load {
                break stats;
            } else {
                self.x.clone_from(&x_ok);
                stats = self.solve_at(&x_ok, dt, load)?;
                iterations += stats.iterations;
                break stats;
            }
        };
        self.load_stepping.0 += steps.increments;
        self.load_stepping.1 += steps.failures;
        stats.iterations = iterations;
        Ok(stats)
    }

    /// Newton from the current positions with the load factor `load`
    /// (pressure, sphere position, held nodes).
    fn solve_at(&mut self, xn: &[Vec3], dt: f64, load: f64) -> Result<StepStats, SimError> {
        self.load_scale = load;
        if let Some(c) = &mut self.contact {
            c.set_load(load);
        }
        self.implicit_step(xn, dt, load)
    }

    /// Backward Euler (or quasi-static) step from `xn` of length `dt` (s):
    /// Newton-CG on the step's objective with the held nodes at the command
    /// `load`.
    fn implicit_step(&mut self, xn: &[Vec3], dt: f64, load: f64) -> Result<StepStats, SimError> {
        let n = self.x.len();
        let dynamic = self.set.integrator == Integrator::BackwardEuler;
        let xt: Vec<Vec3> = if dynamic {
            (0..n).map(|i| xn[i] + self.v[i] * dt).collect()
        } else {
            Vec::new()
        };
        let mut x = std::mem::take(&mut self.x);
        self.apply_targets(&mut x, load);
        self.x = x;
        let (a_in, a_damp) = if dynamic {
            (1.0 / (dt * dt), self.damping / dt)
        } else {
            (0.0, 0.0)
        };
        let info = self.newton(xn, &xt, a_in, a_damp);
        let stats = StepStats {
            iterations: info.iterations,
            residual: info.residual,
            converged: info.converged,
        };
        if !info.residual.is_finite() {
            return Err(SimError::Diverged {
                t: self.time + dt,
                reason: "Newton residual is not finite".into(),
            });
        }
        Ok(stats)
    }
}
