//! A dynamic step split open for monolithic coupling (the needle seed's
//! Algorithm 1: Chentanez et al. 2009): the caller linearizes the step,
//! solves with the step's matrix as often as it needs (the Schur complement
//! of the coupling constraints), adds its constraint forces to the
//! right-hand side and hands back the final increment. One Newton iteration
//! (the linearly implicit scheme, as the seed), Newmark or backward Euler,
//! the Cholesky factor reused while no Jacobian block changed.

use super::*;
use crate::supernodal::SparseColumn;

/// One linearized step of a [`FemModel`]: `A dx = r + f_c`, with
/// `A = c_k K + c_m M` on the free DOFs and `r` the dynamic residual at the
/// start of the step (N per DOF, local coordinates are only shifted, so
/// forces and increments are the same in world coordinates).
pub struct LinearStep {
    xn: Vec<Vec3>,
    u: Update,
    r: Vec<f64>,
    c_k: f64,
    c_m: f64,
    t_end: f64,
}

impl LinearStep {
    /// The residual `r` (N per DOF, `3 * nodes` entries; the constrained
    /// DOFs' entries are ignored by [`FemModel::solve_linear`]).
    pub fn residual(&self) -> &[f64] {
        &self.r
    }
}

impl FemModel {
    /// Start a coupled step of `dt` (s) with the driven nodes at load `s`:
    /// evaluate forces and the warped stiffness at the start of the step and
    /// factorize `A` unless the cached factor is still exact. Only the
    /// Cholesky solver, a dynamic integrator and no sphere contact.
    pub fn begin_linear_step(&mut self, dt: f64, s: f64) -> Result<LinearStep, SimError> {
        self.begin_linear_step_with(dt, s, true)
    }

    /// [`Self::begin_linear_step`], factorizing `A` only if `factor`: a
    /// caller that solves by [`Self::apply_linear`] alone (an iterative
    /// solver) skips the Cholesky. A skipped factorization leaves no stale
    /// factor behind: the next factored step refactorizes.
    pub fn begin_linear_step_with(&mut self, dt: f64, s: f64, factor: bool) -> Result<LinearStep, SimError> {
        if !(dt > 0.0 && dt.is_finite() && s.is_finite()) {
            return Err(self.fail(format!("bad step dt={dt} s, command {s}")));
        }
        let LinearSolver::Cholesky(ord) = self.p.solver else {
            return Err(self.fail("a coupled step needs the direct (Cholesky) solver"));
        };
        if self.p.integrator == Integrator::QuasiStatic || self.contact.is_some() {
            return Err(self.fail("a coupled step needs a dynamic integrator and no sphere contact"));
        }
        let t_end = self.t + dt;
        let xn = self.x.clone();
        let u = self.update_rules(dt);
        let (alpha, beta) = (self.p.rayleigh_mass, self.p.rayleigh_stiffness);
        let c_m = u.c_a + alpha * u.c_v;
        let c_k = 1.0 + beta * u.c_v;
        self.set_constrained(s);
        let jac = match self.p.law {
            Law::NeoHookean => Jacobian::Exact,
            _ => Jacobian::Warped,
        };
        let st = self.solid.evaluate(&self.x, Some(jac), self.p.lazy_threshold);
        self.inverted = st.inverted;
        self.last_updated = st.updated;
        let r = self.dynamic_residual(&u, &xn, s);
        let exact = self.cached == Some((c_k, c_m)) && self.sys.has_factorization();
        let stale = !exact || st.updated > 0 || self.factor_has_contact;
        if !factor {
            if stale {
                self.cached = None;
            }
        } else if stale {
            let none = ContactBlocks {
                at: Vec::new(),
                blocks: Vec::new(),
                c_k,
            };
            self.refactorize(&none, None, (c_k, c_m), ord, t_end)?;
        }
        Ok(LinearStep {
            xn,
            u,
            r,
            c_k,
            c_m,
            t_end,
        })
    }

    /// `y = A x` on the free DOFs with the step's matrix `A = c_k K + c_m M`
    /// (`x`, `y`: `3 * nodes` entries; `x` must be zero on constrained DOFs,
    /// `y` is zero there). The product of the CG solver of the tissue.
    pub fn apply_linear(&mut self, step: &LinearStep, x: &[f64], y: &mut [f64]) {
        self.sys.apply(
            &self.solid.pat,
            &self.solid.kmat,
            step.c_k,
            &self.solid.mass,
            step.c_m,
            x,
            y,
        );
    }

    /// The diagonal of the step's `A` (`3 * nodes` entries, 1 on
    /// constrained DOFs): a Jacobi preconditioner.
    pub fn linear_diagonal(&self, step: &LinearStep) -> Vec<f64> {
        let pat = &self.solid.pat;
        let mut d = vec![1.0; 3 * pat.n];
        for n in 0..pat.n {
            let Some(bi) = (pat.row_ptr[n]..pat.row_ptr[n + 1]).find(|&bi| pat.col[bi] == n) else {
                continue;
            };
            for c in 0..3 {
                if self.sys.free[3 * n + c] {
                    d[3 * n + c] = step.c_k * self.solid.kmat[bi][(c, c)] + step.c_m * self.solid.mass[n];
                }
            }
        }
        d
    }

    /// `A^{-1} b` on the free DOFs with the step's factor (`b`: `3 * nodes`
    /// entries, constrained ones ignored; the result is zero there).
    pub fn solve_linear(&mut self, b: &mut [f64]) {
        self.sys.solve_cholesky(b);
    }

    /// [`Self::solve_linear`] for `k` right-hand sides at once (`b`: `k`
    /// vectors of `3 * nodes` entries back to back).
    pub fn solve_linear_many(&mut self, b: &mut [f64], k: usize) {
        self.sys.solve_cholesky_many(b, k);
    }

    /// `b_a^T A^-1 b_b` for every pair of sparse right-hand sides (non-zeros
    /// `(DOF, value)`), row-major, with the step's factor by sparse forward
    /// solves; `None` where the factor is not supernodal (then use
    /// [`Self::solve_linear_many`]).
    pub fn gram(&mut self, rhs: &[Vec<(usize, f64)>]) -> Option<Vec<f64>> {
        self.sys.gram(rhs)
    }

    /// The columns `L^-1 P b` of sparse right-hand sides with the step's
    /// factor, and the factor's id: `b_a^T A^-1 b_b` is the columns' dot
    /// product, valid while [`Self::factor_id`] returns the same id;
    /// `None` as for [`Self::gram`].
    pub fn forward_columns(&mut self, rhs: &[Vec<(usize, f64)>]) -> Option<(u64, Vec<SparseColumn>)> {
        self.sys.forward_columns(rhs)
    }

    /// The forward half `u = L^-1 P r` of a solve with the step's factor
    /// (factor column order) and the factor's id: `b^T A^-1 r` is
    /// [`SparseColumn::dot_dense`] of `b`'s column with `u`, and
    /// [`Self::backward_half`] finishes `A^-1 r`; `None` as for
    /// [`Self::gram`].
    pub fn forward_half(&mut self, r: &[f64]) -> Option<(u64, Vec<f64>)> {
        // In the model's own pool (its threads, warm from the step); not
        // even entered without a supernodal factor (a simplicial one is
        // small, the hand-over would cost more than the sweep).
        if !self.sys.has_supernodal_factor() {
            return None;
        }
        let Self { solid, sys, .. } = self;
        solid.install(|| sys.forward_half(r))
    }

    /// The backward half: `z = P^T L^-T u` on the free DOFs of `z` (`3 *
    /// nodes` entries, the constrained ones untouched; `u` overwritten).
    pub fn backward_half(&mut self, u: &mut [f64], z: &mut [f64]) -> Option<()> {
        let Self { solid, sys, .. } = self;
        solid.install(|| sys.backward_half(u, z))
    }

    /// Identity of the tissue matrix's current factorization (`None`
    /// without one): unique in the process, new at every factorization.
    pub fn factor_id(&self) -> Option<u64> {
        self.sys.factor_id()
    }

    /// Whether DOF `d` (`3 * node + axis`) is free.
    pub fn is_free(&self, d: usize) -> bool {
        self.sys.free[d]
    }

    /// Lumped node masses (kg).
    pub fn node_masses(&self) -> &[f64] {
        &self.solid.mass
    }

    /// Node velocities (m/s).
    pub fn velocities(&self) -> &[Vec3] {
        &self.v
    }

    /// Finish the step with the increment `dx` (m per DOF): positions,
    /// velocities and accelerations by the update rules, the driven nodes'
    /// elastic reaction (the caller's forces act on free DOFs), time.
    pub fn end_linear_step(&mut self, step: LinearStep, dx: &[f64]) -> Result<(), SimError> {
        let n = self.solid.n_nodes();
        for i in 0..n {
            self.x[i] += Vec3::new(dx[3 * i], dx[3 * i + 1], dx[3 * i + 2]);
        }
        self.finish_dynamic_step(&step.u, &step.xn, &step.r, dx, step.c_k);
        self.t = step.t_end;
        self.check_state()
    }

    /// The state after a step is one to continue from: finite positions and
    /// velocities, and no inverted element under the neo-Hookean law.
    pub(super) fn check_state(&self) -> Result<(), SimError> {
        if !self
            .x
            .iter()
            .chain(self.v.iter())
            .all(|p| p.iter().all(|c| c.is_finite()))
        {
            return Err(SimError::Diverged {
                t: self.t,
                reason: "non-finite node position or velocity".into(),
            });
        }
        if self.p.law == Law::NeoHookean && self.inverted > 0 {
            return Err(SimError::Diverged {
                t: self.t,
                reason: format!("{} elements inverted (neo-Hookean is undefined there)", self.inverted),
            });
        }
        Ok(())
    }
}
