//! Time stepping and statics: Newton with its step cap, substepping on
//! failure, friction and contact bookkeeping.

use super::*;
use surgbench_core::contact::LaggedFriction;
use surgbench_core::motion::carried;
use surgbench_core::{ContactObs, DeviceCommand, SimError, StepStats, Vec3};

impl DerRod {
    pub(super) fn set_free(&mut self, base: &[f64], alpha: f64) {
        for f in 0..self.dz.len() {
            self.q[f + CLAMPED_DOFS] = base[f] + alpha * self.dz[f];
        }
        self.update_frames();
    }

    /// Newton on the incremental potential from the current coordinates.
    /// Frames are re-anchored at every accepted iterate, so the gradient and
    /// the (symmetric) Hessian are exact for the merit function of the next
    /// line search.
    pub(super) fn newton(&mut self) -> Result<StepStats, SimError> {
        self.anchor_frames();
        // Dead loads are frozen during a line search (the tip torque's
        // couple depends on the configuration) and refreshed at each iterate.
        self.external_forces();
        let (mut phi, mut mag) = self.eval(Eval::Full);
        let mut base = std::mem::take(&mut self.line_base);
        let stats = self.newton_iterations(&mut base, &mut phi, &mut mag);
        self.line_base = base;
        stats
    }

    /// The Newton loop of [`Self::newton`] (`base` holds the free DOFs at the
    /// start of each line search).
    pub(super) fn newton_iterations(
        &mut self,
        base: &mut [f64],
        phi: &mut f64,
        mag: &mut f64,
    ) -> Result<StepStats, SimError> {
        let tol = self.params.tolerance;
        let mut stats = StepStats::default();
        for it in 1..=self.params.max_iterations.max(1) {
            stats.iterations = it as u32;
            self.newton_direction(it)?;
            let size = self.update_size();
            if !size.is_finite() {
                return Err(SimError::Diverged {
                    t: self.time,
                    reason: format!("non-finite Newton update at iteration {it}"),
                });
            }
            let slope: f64 = self.res.iter().zip(&self.dz).map(|(r, d)| r * d).sum();
            base.copy_from_slice(&self.q[CLAMPED_DOFS..]);
            stats.residual = size;
            if size <= tol {
                self.set_free(base, 1.0);
                stats.converged = true;
                return Ok(stats);
            }
            let Some((alpha, phi_new, mag_new)) = self.line_search(base, *phi, *mag, slope) else {
                // No decrease along the Newton direction (a non-smooth
                // corner of the SDF, or a direction the projected matrix
                // gets wrong): stop at the last accepted iterate and let
                // `step` retry with a smaller time step.
                self.set_free(base, 0.0);
                self.eval(Eval::Full);
                stats.residual = size;
                return Ok(stats);
            };
            stats.residual = size * alpha;
            if !phi_new.is_finite() {
                return Err(SimError::Diverged {
                    t: self.time,
                    reason: format!("non-finite energy in Newton iteration {it}"),
                });
            }
            self.accept_iterate(phi, mag, phi_new, mag_new);
        }
        Ok(stats)
    }

    /// Solve for the Newton update `self.dz = -H^-1 res` of iteration `it`,
    /// dropping the compressive stiffness if the matrix is not positive definite.
    fn newton_direction(&mut self, it: usize) -> Result<(), SimError> {
        for f in 0..self.dz.len() {
            self.dz[f] = -self.res[f];
        }
        let mut dz = std::mem::take(&mut self.dz);
        let solved = if self.band.factor(0.0).is_ok() {
            self.band.solve(&mut dz);
            Ok(0.0)
        } else {
            self.drop_compressive_stiffness();
            self.band.factor_and_solve(&mut dz, 0.0)
        };
        self.dz = dz;
        if solved.is_err() {
            let finite = self.res.iter().all(|r| r.is_finite());
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: format!(
                    "Newton matrix not positive definite even with a shift (iteration {it}, residual finite: {finite}, stretch {:.2e})",
                    self.max_stretch()
                ),
            });
        }
        Ok(())
    }

    /// Size of the Newton update: the largest node displacement relative to
    /// the rod length (Euclidean, so the test does not depend on the
    /// orientation of the scene) or twist update (rad).
    fn update_size(&self) -> f64 {
        let mut size: f64 = 0.0;
        for k in 2..self.n {
            let f = 4 * k - CLAMPED_DOFS;
            let dx = (self.dz[f].powi(2) + self.dz[f + 1].powi(2) + self.dz[f + 2].powi(2)).sqrt();
            size = size.max(dx / self.length);
            if f + 3 < self.dz.len() {
                size = size.max(self.dz[f + 3].abs());
            }
        }
        size
    }

    /// Backtracking line search (Armijo) on the incremental potential along
    /// `self.dz` from `base` (potential `phi`, magnitude `mag`, directional
    /// derivative `slope`), skipped when the predicted decrease is at the
    /// rounding level of the potential (there the full Newton step is the
    /// right one). Returns the step fraction with the potential and magnitude
    /// there, fully evaluated, or `None` if nothing decreases.
    fn line_search(&mut self, base: &[f64], phi: f64, mag: f64, slope: f64) -> Option<(f64, f64, f64)> {
        let noise = 1e-13 * mag;
        let search = slope < -1e3 * noise;
        // Step control in contact scenes: the largest fraction of the
        // Newton step that moves no node too far (see `step_cap`).
        let mut alpha = if self.vessel.is_some() { self.step_cap() } else { 1.0 };
        let alpha_min = 1e-3 * alpha;
        self.set_free(base, alpha);
        let (mut phi_new, mut mag_new) = self.eval(Eval::Full);
        let mut backtracked = false;
        let armijo = |alpha: f64, phi_new: f64| phi_new <= phi + 1e-4 * alpha * slope + noise;
        while search && !armijo(alpha, phi_new) && alpha > alpha_min {
            alpha *= 0.5;
            self.set_free(base, alpha);
            (phi_new, mag_new) = self.eval(Eval::Energy);
            backtracked = true;
        }
        if search && !armijo(alpha, phi_new) {
            return None;
        }
        if backtracked {
            (phi_new, mag_new) = self.eval(Eval::Full);
        }
        Some((alpha, phi_new, mag_new))
    }

    /// Accept the iterate: re-anchor the frame transport there, refresh the
    /// dead loads and move their change into `phi` and the residual.
    fn accept_iterate(&mut self, phi: &mut f64, mag: &mut f64, phi_new: f64, mag_new: f64) {
        self.anchor_frames();
        *phi = phi_new;
        *mag = mag_new;
        std::mem::swap(&mut self.fext, &mut self.fext_prev);
        self.external_forces();
        for g in 0..self.q.len() {
            let d = self.fext[g] - self.fext_prev[g];
            if d != 0.0 {
                *phi -= d * (self.q[g] - self.q0[g]);
                if g >= CLAMPED_DOFS {
                    self.res[g - CLAMPED_DOFS] -= d;
                }
            }
        }
    }

    /// Advance by `dt` (s) with the clamp at `cmd` at the end of the step.
    ///
    /// Adaptive substepping: if the Newton solve of the step does not
    /// converge within [`DerParams::max_iterations`] (or fails, or leaves a
    /// non-finite or collapsed state), the state is restored and the step is
    /// retried as two steps of `dt/2` with the clamp command interpolated
    /// linearly between the previous command and `cmd`, recursively down to
    /// `dt / 2^max_substep_depth`. At the deepest level an unconverged
    /// substep is accepted (reported as `converged = false`) if its state is
    /// sane; a failed one ends the run with its error. The returned
    /// [`StepStats`] sums the Newton iterations over all substeps, with the
    /// largest final update and `converged` only if every substep converged;
    /// [`DerRod::last_substeps`] tells how many substeps were taken.
    pub fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        SimError::check_dt(self.time, dt)?;
        let c0 = self.prev_cmd;
        let mut acc = StepStats {
            iterations: 0,
            residual: 0.0,
            converged: true,
        };
        self.substeps = 0;
        self.substep_depth = 0;
        self.advance(dt, &c0, cmd, 0, &mut acc)?;
        self.prev_cmd = *cmd;
        Ok(acc)
    }

    /// Substeps taken by the last [`DerRod::step`] (1 when the step
    /// converged at once) and the deepest halving used (0 = none).
    pub fn last_substeps(&self) -> (usize, usize) {
        (self.substeps, self.substep_depth)
    }

    /// One step of `dt` from the clamp at `c0` to `c1`, retried as two
    /// half steps on failure (see [`DerRod::step`]).
    pub(super) fn advance(
        &mut self,
        dt: f64,
        c0: &DeviceCommand,
        c1: &DeviceCommand,
        depth: usize,
        acc: &mut StepStats,
    ) -> Result<(), SimError> {
        if self.snaps.len() <= depth {
            self.snaps.resize_with(depth + 1, Snapshot::default);
        }
        let mut snap = std::mem::take(&mut self.snaps[depth]);
        self.save(&mut snap);
        let res = self.single_step(dt, c1);
        let retry = depth < self.params.max_substep_depth && !matches!(res, Ok(st) if st.converged);
        if retry {
            self.restore(&snap);
        }
        self.snaps[depth] = snap;
        if retry {
            let cm = interpolate_command(c0, c1, 0.5, &self.base);
            self.advance(0.5 * dt, c0, &cm, depth + 1, acc)?;
            return self.advance(0.5 * dt, &cm, c1, depth + 1, acc);
        }
        let st = res?;
        acc.iterations += st.iterations;
        acc.residual = acc.residual.max(st.residual);
        acc.converged &= st.converged;
        self.substeps += 1;
        self.substep_depth = self.substep_depth.max(depth);
        Ok(())
    }

    /// Save the state a step changes.
    pub(super) fn save(&self, s: &mut Snapshot) {
        fn copy<T: Copy>(dst: &mut Vec<T>, src: &[T]) {
            dst.clear();
            dst.extend_from_slice(src);
        }
        copy(&mut s.q, &self.q);
        copy(&mut s.qdot, &self.qdot);
        copy(&mut s.qddot, &self.qddot);
        copy(&mut s.a1, &self.a1);
        copy(&mut s.tan, &self.tan);
        copy(&mut s.rtwist, &self.rtwist);
        copy(&mut s.lag, &self.lag);
        s.accel_valid = self.accel_valid;
        s.time = self.time;
    }

    /// Restore a state saved by [`Self::save`].
    pub(super) fn restore(&mut self, s: &Snapshot) {
        self.q.copy_from_slice(&s.q);
        self.qdot.copy_from_slice(&s.qdot);
        self.qddot.copy_from_slice(&s.qddot);
        self.a1.copy_from_slice(&s.a1);
        self.tan.copy_from_slice(&s.tan);
        self.rtwist.copy_from_slice(&s.rtwist);
        self.lag.copy_from_slice(&s.lag);
        self.accel_valid = s.accel_valid;
        self.time = s.time;
    }

    /// Scale `beta` of the constant-velocity warm start `q0 + beta dt v`:
    /// 1 without a vessel, else the largest value that moves no node farther
    /// than its [`Self::move_allowance`].
    fn prediction_scale(&self, dt: f64) -> f64 {
        if self.vessel.is_some() {
            let mut beta: f64 = 1.0;
            for k in 2..self.n {
                let v = self.node_velocity(k).norm() * dt;
                if v > 0.0 {
                    beta = beta.min(self.move_allowance(k) / v);
                }
            }
            beta
        } else {
            1.0
        }
    }

    /// One implicit step without retries.
    pub(super) fn single_step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.prepare_step(dt, cmd);
        let stats = self.newton()?;
        self.finish_step(dt)?;
        Ok(stats)
    }

    /// Everything a step does before its solve: the inertia and loads of the
    /// step, the warm start, the clamp at `cmd`, frames transported.
    pub(super) fn prepare_step(&mut self, dt: f64, cmd: &DeviceCommand) {
        let newmark = self.params.integrator == Integrator::Newmark;
        let c = self.params.damping;
        self.anchor_frames();
        if newmark && !self.accel_valid {
            self.init_acceleration();
        }
        // Backward Euler and Newmark both impose equilibrium at the end of
        // the step: the dead tip loads act with their value at t + dt.
        self.load_scale = self.tip_load_scale(self.time + dt);
        if let Some(env) = &self.moving {
            self.vessel = env.vessel_at(self.time + dt);
            self.flow = env.flow_at(self.time + dt);
        }
        self.q0.copy_from_slice(&self.q);
        let ndof = self.q.len();
        for g in 0..ndof {
            let (q, v, a) = (self.q[g], self.qdot[g], self.qddot[g]);
            if newmark {
                self.qtilde[g] = q + dt * v + 0.25 * dt * dt * a;
                self.lin[g] = c * v;
            } else {
                self.qtilde[g] = q + dt * v;
                self.lin[g] = 0.0;
            }
        }
        self.inertia = Some(if newmark {
            Inertia {
                ka: 4.0 / (dt * dt),
                kc: 2.0 * c / dt,
            }
        } else {
            Inertia {
                ka: 1.0 / (dt * dt),
                kc: c / dt,
            }
        });
        self.begin_friction(dt);
        self.begin_drag(dt, newmark);
        // Warm start from the constant-velocity prediction `q0 + dt v`: a
        // node sliding steadily along the wall starts past the stick band of
        // its friction, so Newton does not first treat it as stuck.
        // In contact scenes the prediction is scaled down so that no node
        // moves farther than the step control of `newton` allows (a fast
        // node would otherwise start deep in, or through, the wall).
        let beta = self.prediction_scale(dt);
        for g in CLAMPED_DOFS..ndof {
            self.q[g] += beta * dt * self.qdot[g];
        }
        self.apply_clamp(cmd);
        self.update_frames();
    }

    /// Everything a step does after its solve: velocities (and
    /// accelerations) from the solved positions, time, contact forces and
    /// the lagged contact state, the sanity check.
    pub(super) fn finish_step(&mut self, dt: f64) -> Result<(), SimError> {
        let newmark = self.params.integrator == Integrator::Newmark;
        let ndof = self.q.len();
        for g in 0..ndof {
            let m = if g < CLAMPED_DOFS { 0.0 } else { self.dof_mass(g) };
            if newmark && m > 0.0 {
                let a = 4.0 / (dt * dt) * (self.q[g] - self.q0[g] - dt * self.qdot[g]) - self.qddot[g];
                self.qdot[g] += 0.5 * dt * (self.qddot[g] + a);
                self.qddot[g] = a;
            } else {
                self.qdot[g] = (self.q[g] - self.q0[g]) / dt;
                self.qddot[g] = 0.0;
            }
        }
        self.accel_valid = newmark;
        self.time += dt;
        self.finish_contacts();
        self.check_finite()
    }

    /// Static equilibrium with the clamp at `cmd` (no inertia, no friction;
    /// the normal contact penalty acts if a vessel is set; the tip loads
    /// scaled by their ramp at the current time [`DerRod::time`]):
    /// Newton on `E - F . q` from the current state (at least 100 iterations,
    /// large loads need many damped steps), velocities set to zero.
    pub fn solve_static(&mut self, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.anchor_frames();
        self.inertia = None;
        self.load_scale = self.tip_load_scale(self.time);
        self.q0.copy_from_slice(&self.q);
        self.apply_clamp(cmd);
        self.update_frames();
        let keep = self.params.max_iterations;
        self.params.max_iterations = keep.max(100);
        let stats = self.newton();
        self.params.max_iterations = keep;
        let stats = stats?;
        self.prev_cmd = *cmd;
        self.qdot.iter_mut().for_each(|v| *v = 0.0);
        self.accel_valid = false;
        self.check_finite()?;
        Ok(stats)
    }

    /// Newmark needs the acceleration at the start: `a = (F - grad E - c m v)/m`.
    pub(super) fn init_acceleration(&mut self) {
        let g = self.elastic_gradient();
        self.load_scale = self.tip_load_scale(self.time);
        self.external_forces();
        for k in 0..self.q.len() {
            let m = if k < CLAMPED_DOFS { 0.0 } else { self.dof_mass(k) };
            self.qddot[k] = if m > 0.0 {
                (self.fext[k] - g[k]) / m - self.params.damping * self.qdot[k]
            } else {
                0.0
            };
        }
        self.accel_valid = true;
    }

    /// Freeze the friction of the coming step: the lagged normal force and
    /// normal of every node in contact at the end of the last step, `mu_s`
    /// for a node that stuck and `mu_d` for one that slid, anchored at the
    /// node's start-of-step position.
    pub(super) fn begin_friction(&mut self, dt: f64) {
        if self.vessel.is_none() {
            return;
        }
        let motion = self.moving.as_ref().and_then(|e| e.vessel_motion.clone());
        self.friction_eps = self.params.friction_creep * dt;
        let (mu_s, mu_d) = (self.contact.friction_static, self.contact.friction_dynamic);
        for k in 2..self.n {
            let lag = self.lag[k];
            let mu = if lag.sliding { mu_d } else { mu_s };
            self.friction[k] = if lag.force > 0.0 && mu > 0.0 {
                LaggedFriction {
                    normal: lag.normal,
                    anchor: match &motion {
                        Some(m) => carried(m.as_ref(), &self.node(k), self.time, self.time + dt),
                        None => self.node(k),
                    },
                    bound: mu * lag.force,
                }
            } else {
                LaggedFriction::NONE
            };
        }
    }

    /// After the solve: the contact forces of the converged step (penalty
    /// plus friction, both part of the solve) and the lagged state for the
    /// next step's friction. Nothing is moved.
    pub(super) fn finish_contacts(&mut self) {
        self.contacts.clear();
        let Some(sdf) = self.vessel.clone() else {
            return;
        };
        for k in 2..self.n {
            let x = self.node(k);
            let fr = self.friction[k];
            let mut force = Vec3::zeros();
            let mut sliding = false;
            if fr.bound > 0.0 {
                let fe = fr.eval(&x, self.friction_eps);
                force -= fe.gradient;
                sliding = fe.slip >= self.friction_eps;
            }
            let phi = sdf.distance(&x);
            let d = phi + self.contact.margin;
            let mut lag = ContactLag::NONE;
            if d > 0.0 {
                let g = sdf.gradient(&x);
                let gn = g.norm();
                if gn > 0.0 && gn.is_finite() {
                    let normal = g / gn;
                    let lambda = penalty(self.contact_stiffness, self.contact_onset, d).1;
                    force -= normal * lambda;
                    lag = ContactLag {
                        force: lambda,
                        normal,
                        sliding,
                    };
                }
            }
            self.lag[k] = lag;
            if d > 0.0 || fr.bound > 0.0 {
                self.contacts.push(ContactObs {
                    point: x,
                    force,
                    penetration: phi.max(0.0),
                });
            }
        }
    }

    pub(super) fn check_finite(&self) -> Result<(), SimError> {
        // An edge at half or double its rest length is a failed simulation
        // (the wire is near-inextensible), not a state to continue from.
        if !self.q.iter().chain(&self.qdot).all(|v| v.is_finite()) {
            return Err(SimError::Diverged {
                t: self.time,
                reason: "non-finite rod state".into(),
            });
        }
        let s = self.max_stretch();
        if s.abs() > 0.5 {
            return Err(SimError::Diverged {
                t: self.time,
                reason: format!("edge stretched by {:.0}%", 100.0 * s),
            });
        }
        Ok(())
    }
}
