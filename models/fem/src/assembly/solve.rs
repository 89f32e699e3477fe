//! The linear solves of a [`System`]: sparse Cholesky, block-Jacobi PCG and
//! the stale-factor PCG, with the factor solves they apply.

use super::*;
use crate::material::M3;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::LltRef;
use faer::{Conj, MatMut, Par};

impl System {
    /// Solve `A x = b` on the free DOFs with the cached factorization;
    /// `b` (full DOF vector, constrained entries ignored) is overwritten by `x`
    /// (constrained entries set to zero).
    pub fn solve_cholesky(&mut self, b: &mut [f64]) {
        let c = self.chol.as_mut().expect("factorize first");
        let mut z = std::mem::take(&mut self.work.z);
        z.clear();
        z.resize(b.len(), 0.0);
        c.solve_full(&self.dofs, b, &mut z);
        b.copy_from_slice(&z);
        self.work.z = z;
    }

    /// [`Self::solve_cholesky`] for `k` right-hand sides at once: `b` holds
    /// `k` full DOF vectors back to back and is overwritten by the
    /// solutions. One blocked triangular solve serves every column, which
    /// the supernodal factor does much faster than `k` single solves.
    pub fn solve_cholesky_many(&mut self, b: &mut [f64], k: usize) {
        let c = self.chol.as_mut().expect("factorize first");
        let (n, nf) = (b.len() / k.max(1), self.dofs.len());
        let mut rhs = vec![0.0; nf * k];
        for (col, out) in b.chunks_exact(n).zip(rhs.chunks_exact_mut(nf)) {
            for (v, &d) in out.iter_mut().zip(&self.dofs) {
                *v = col[d];
            }
        }
        let mut mem = MemBuffer::new(c.symbolic.solve_in_place_scratch::<f64>(k, Par::Seq));
        LltRef::new(&c.symbolic, &c.l).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut rhs, nf, k),
            Par::Seq,
            MemStack::new(&mut mem),
        );
        b.fill(0.0);
        for (col, x) in b.chunks_exact_mut(n).zip(rhs.chunks_exact(nf)) {
            for (v, &d) in x.iter().zip(&self.dofs) {
                col[d] = *v;
            }
        }
    }

    /// Block-Jacobi PCG on `A = c_k K + c_m M` (block CSR `k`) restricted to
    /// the free DOFs. `x` holds the initial guess (warm start) and receives
    /// the solution. Returns `(iterations, relative residual)`.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_cg(
        &mut self,
        pat: &Pattern,
        k: &[M3],
        c_k: f64,
        mass: &[f64],
        c_m: f64,
        b: &[f64],
        x: &mut [f64],
        tol: f64,
        max_iter: usize,
    ) -> (usize, f64) {
        let op = Op {
            pat,
            k,
            c_k,
            mass,
            c_m,
            mask: &self.mask,
        };
        let out = pcg(&op, Precond::Jacobi(&self.jac), &mut self.work, b, x, tol, max_iter);
        self.cg_iterations += out.0;
        out
    }

    /// PCG on `A = c_k K + c_m M` preconditioned by the cached Cholesky
    /// factor of an earlier matrix (the lazy update's stale factorization).
    /// Returns `None` when no factorization is cached.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_factor_pcg(
        &mut self,
        pat: &Pattern,
        k: &[M3],
        c_k: f64,
        mass: &[f64],
        c_m: f64,
        b: &[f64],
        x: &mut [f64],
        tol: f64,
        max_iter: usize,
    ) -> Option<(usize, f64)> {
        if !self.has_factorization() {
            return None;
        }
        let op = Op {
            pat,
            k,
            c_k,
            mass,
            c_m,
            mask: &self.mask,
        };
        let chol = self.chol.as_mut().expect("checked above");
        let pre = Precond::Factor { chol, dofs: &self.dofs };
        let out = pcg(&op, pre, &mut self.work, b, x, tol, max_iter);
        self.cg_iterations += out.0;
        Some(out)
    }
}

impl CholState {
    /// Make (`on`) or drop the `f32` copy of the factor.
    pub(super) fn set_single(&mut self, on: bool) {
        self.l32.clear();
        if on {
            self.l32.extend(self.l.iter().map(|&v| v as f32));
        }
    }

    /// The preconditioner `z = A_0^-1 r` of the stale-factor PCG: with the
    /// `f32` copy of the factor when there is one (solve in `f32`, `r`
    /// rounded to `f32`, `z` widened back), else [`CholState::solve_full`].
    #[inline(never)]
    pub(super) fn solve_precond(&mut self, dofs: &[usize], r: &[f64], z: &mut [f64]) {
        if self.l32.is_empty() {
            return self.solve_full(dofs, r, z);
        }
        if let Some(split) = &mut self.split {
            return split.solve(&self.l32, r, z);
        }
        let rhs = &mut self.rhs32;
        for (v, &d) in rhs.iter_mut().zip(dofs) {
            *v = r[d] as f32;
        }
        let n = rhs.len();
        LltRef::new(&self.symbolic, &self.l32).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, 1),
            Par::Seq,
            MemStack::new(&mut self.mem),
        );
        for (v, &d) in rhs.iter().zip(dofs) {
            z[d] = f64::from(*v);
        }
    }

    /// `z = A_0^-1 r` on the free DOFs with the cached factor (`r`, `z` full
    /// DOF vectors; `z`'s constrained entries are left untouched).
    #[inline(never)]
    pub(super) fn solve_full(&mut self, dofs: &[usize], r: &[f64], z: &mut [f64]) {
        let rhs = &mut self.rhs;
        for (v, &d) in rhs.iter_mut().zip(dofs) {
            *v = r[d];
        }
        let n = rhs.len();
        LltRef::new(&self.symbolic, &self.l).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, n, 1),
            Par::Seq,
            MemStack::new(&mut self.mem),
        );
        for (v, &d) in rhs.iter().zip(dofs) {
            z[d] = *v;
        }
    }
}
