//! A step split open for monolithic coupling (the needle seed's Algorithm 1:
//! Chentanez et al. 2009): one Newton iteration of the step's incremental
//! potential from the warm start (the linearly implicit scheme the seed uses
//! for its needle), with the caller's constraint forces on the right-hand
//! side. The matrix is the rod's banded Hessian (positions and twist
//! interleaved, half-bandwidth 10): twist stays implicit, which keeps the
//! block symmetric and banded as the seed's explicit twist does.

use super::*;
use surgbench_core::{DeviceCommand, SimError};

impl DerRod {
    /// Start a coupled step of `dt` (s) with the clamp at `cmd` at its end:
    /// inertia and loads of the step, warm start `q_n + dt v_n`, gradient
    /// [`DerRod::linear_residual`] and the factorized Hessian there. A
    /// Hessian that is not positive definite drops its compressive terms
    /// (projected Newton, as [`DerRod::step`] does).
    pub fn begin_linear_step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<(), SimError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: format!("time step must be > 0 s, got {dt}"),
            });
        }
        if self.vessel.is_some() {
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: "a coupled rod step does not model vessel contact".into(),
            });
        }
        self.prepare_step(dt, cmd);
        self.anchor_frames();
        self.external_forces();
        self.eval(Eval::Full);
        if self.band.factor(0.0).is_err() {
            self.drop_compressive_stiffness();
            self.band.factor(0.0).map_err(|_| SimError::SolverFailed {
                t: self.time,
                reason: "rod Hessian not positive definite in a coupled step".into(),
            })?;
        }
        self.prev_cmd = *cmd;
        Ok(())
    }

    /// Gradient of the step's incremental potential at the warm start over
    /// the free DOFs (N, N m): the uncoupled increment is `-H^{-1} g`.
    pub fn linear_residual(&self) -> &[f64] {
        &self.res
    }

    /// `H^{-1} b` over the free DOFs with the step's factor.
    pub fn solve_linear(&self, b: &mut [f64]) {
        self.band.solve(b);
    }

    /// `y = H x` over the free DOFs with the step's Hessian (the one
    /// [`Self::solve_linear`] inverts): the product of an iterative solver.
    pub fn apply_linear(&self, x: &[f64], y: &mut [f64]) {
        self.band.mul(x, y);
    }

    /// The diagonal of the step's Hessian over the free DOFs (Jacobi).
    pub fn linear_diagonal(&self) -> Vec<f64> {
        (0..self.band.dim()).map(|i| self.band.get(i, i)).collect()
    }

    /// Number of free DOFs (the length of the vectors above).
    pub fn free_dofs(&self) -> usize {
        self.q.len() - CLAMPED_DOFS
    }

    /// Free-DOF index of node `k`'s first coordinate, `None` for the two
    /// clamped nodes.
    pub fn node_dof(&self, k: usize) -> Option<usize> {
        (k >= 2 && k < self.n).then(|| 4 * k - CLAMPED_DOFS)
    }

    /// Arclength of every node at rest (m; node 1 is the clamp point, 0).
    pub fn rest_arclength(&self) -> &[f64] {
        &self.arclength
    }

    /// Finish the step with the increment `dz` over the free DOFs:
    /// positions, frames, velocities, time.
    pub fn end_linear_step(&mut self, dt: f64, dz: &[f64]) -> Result<(), SimError> {
        for (f, d) in dz.iter().enumerate() {
            self.q[f + CLAMPED_DOFS] += d;
        }
        self.update_frames();
        self.finish_step(dt)
    }
}
