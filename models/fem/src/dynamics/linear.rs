//! The linear solve of one Newton iteration of a dynamic step (Cholesky
//! with factor reuse, or block-Jacobi CG; the parent module docs describe
//! the policy).

use super::*;
use crate::assembly::{LinearSolver, Ordering};
use crate::element::Jacobian;
use crate::material::M3;
use surgbench_core::SimError;

impl FemModel {
    /// Solve the Newton system `(c_k K + H_c + c_m M) dx = r` (`coef` =
    /// `(c_k, c_m)`) by the configured solver (module docs), starting the
    /// iterative solves from `guess`; `updated` Jacobian blocks changed in
    /// this evaluation. Records CG iterations, the last relative residual
    /// and whether the solve met its tolerance in `lin`.
    pub(super) fn linear_solve(
        &mut self,
        r: &[f64],
        guess: Vec<f64>,
        hc: &ContactBlocks,
        coef: (f64, f64),
        updated: usize,
        lin: &mut LinearStats,
        t_end: f64,
    ) -> Result<Vec<f64>, SimError> {
        let (c_k, c_m) = coef;
        let kc = hc.apply(&self.solid.kmat);
        match self.p.solver {
            LinearSolver::Cholesky(ord) => {
                let mut dx = r.to_vec();
                let same = self.cached == Some((c_k, c_m)) && self.sys.has_factorization();
                self.factor_stale |= updated > 0 || kc.is_some() || self.factor_has_contact;
                if same && !self.factor_stale {
                    // No block changed since the factorization: reuse it as is.
                    self.sys.solve_cholesky(&mut dx);
                    return Ok(dx);
                }
                if same
                    && self.p.factor_reuse
                    && let Some(sol) = self.stale_factor_pcg(r, guess, kc.as_deref(), coef, lin)
                {
                    return Ok(sol);
                }
                self.refactorize(hc, kc.as_deref(), coef, ord, t_end)?;
                self.sys.solve_cholesky(&mut dx);
                lin.res = 0.0;
                Ok(dx)
            }
            LinearSolver::Cg { tol, max_iter } => {
                // Only the block-Jacobi preconditioner is needed (no CSC values).
                let mut sol = guess;
                let (sys, solid) = (&mut self.sys, &self.solid);
                let kmat = kc.as_deref().unwrap_or(&solid.kmat);
                let (it, rel) = solid.install(|| {
                    sys.set_block_jacobi(&solid.pat, kmat, c_k, &solid.mass, c_m);
                    sys.solve_cg(&solid.pat, kmat, c_k, &solid.mass, c_m, r, &mut sol, tol, max_iter)
                });
                lin.cg_its += it;
                lin.res = rel;
                lin.all_met &= rel <= tol;
                Ok(sol)
            }
        }
    }

    /// Some blocks changed since the factorization: the stale factor
    /// preconditions CG on the current matrix (`kc`, or the elastic one) to
    /// `reuse_tol` in at most [`REUSE_ITERS`] iterations. The solution if it
    /// got there, else `None` (the caller refactorizes).
    pub(super) fn stale_factor_pcg(
        &mut self,
        r: &[f64],
        guess: Vec<f64>,
        kc: Option<&[M3]>,
        (c_k, c_m): (f64, f64),
        lin: &mut LinearStats,
    ) -> Option<Vec<f64>> {
        let reuse_tol = self.p.reuse_tol;
        let mut sol = guess;
        let (sys, solid) = (&mut self.sys, &self.solid);
        let kmat = kc.unwrap_or(&solid.kmat);
        let out = solid.install(|| {
            sys.solve_factor_pcg(
                &solid.pat,
                kmat,
                c_k,
                &solid.mass,
                c_m,
                r,
                &mut sol,
                reuse_tol,
                REUSE_ITERS,
            )
        });
        let (it, rel) = out?;
        lin.cg_its += it;
        lin.res = rel;
        // The factor has aged: refresh it on the next step.
        self.excess_solves += it.saturating_sub(1);
        if self.excess_solves > REFRESH_EXCESS {
            self.cached = None;
        }
        (rel <= reuse_tol).then_some(sol)
    }

    /// Set the matrix `c_k K + H_c + c_m M` (`kc` with contact, else the
    /// elastic `K`) and factorize it; an indefinite exact Hessian
    /// (neo-Hookean) is re-evaluated projected and factorized again.
    pub(super) fn refactorize(
        &mut self,
        hc: &ContactBlocks,
        kc: Option<&[M3]>,
        (c_k, c_m): (f64, f64),
        ord: Ordering,
        t_end: f64,
    ) -> Result<(), SimError> {
        let kmat = kc.unwrap_or(&self.solid.kmat);
        self.sys.set_values(&self.solid.pat, kmat, c_k, &self.solid.mass, c_m);
        self.factor_has_contact = kc.is_some();
        self.cached = Some((c_k, c_m));
        self.factor_stale = false;
        self.excess_solves = 0;
        if let Err(e) = self.sys.factorize(&self.solid.pat, ord) {
            // Indefinite exact Hessian (neo-Hookean): retry projected.
            self.solid.evaluate(&self.x, Some(Jacobian::Projected), 0.0);
            let kp = hc.apply(&self.solid.kmat);
            let kmat = kp.as_deref().unwrap_or(&self.solid.kmat);
            self.sys.set_values(&self.solid.pat, kmat, c_k, &self.solid.mass, c_m);
            self.cached = None;
            self.sys
                .factorize(&self.solid.pat, ord)
                .map_err(|_| SimError::SolverFailed {
                    t: t_end,
                    reason: e.clone(),
                })?;
        }
        Ok(())
    }
}
