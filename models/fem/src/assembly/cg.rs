//! The preconditioned conjugate gradient of [`super::System`]: the
//! operator `A = c_k K + c_m diag(mass)` on the free DOFs, block-Jacobi or
//! cached-factor preconditioning, and chunked reductions that make the
//! result independent of the thread count.

use super::*;

/// Nodes per parallel work item and per partial sum of the CG kernels. Fixed,
/// so every reduction adds the same partial sums in the same order for any
/// thread count (bit-identical results).
const CG_CHUNK: usize = 64;

/// Reused CG vectors (full DOF length) and per-chunk partial sums: a CG
/// solve allocates nothing after the first one.
#[derive(Default)]
pub(super) struct CgWork {
    r: Vec<f64>,
    /// Preconditioned residual; also scratch of the plain factor solve.
    pub z: Vec<f64>,
    p: Vec<f64>,
    ap: Vec<f64>,
    part: Vec<[f64; 2]>,
}

/// The operator `A = c_k K + c_m diag(mass)` on the free DOFs: rows of
/// constrained DOFs are zeroed by `mask` (1 free, 0 constrained); columns
/// need no masking because every vector CG applies it to is zero there.
pub(super) struct Op<'a> {
    pub pat: &'a Pattern,
    pub k: &'a [M3],
    pub c_k: f64,
    pub mass: &'a [f64],
    pub c_m: f64,
    pub mask: &'a [f64],
}

impl Op<'_> {
    /// `y = A x` (block CSR, one pass over the blocks); returns `x . y`
    /// summed per [`CG_CHUNK`] and then in chunk order. On x86-64 CPUs with
    /// AVX2 and FMA (checked at run time) the block products use 4-lane
    /// fused multiply-adds ([`block_rows_fma`]); otherwise scalar code
    /// ([`block_rows`]). Both are deterministic; they differ from each other
    /// in round-off (fused vs separate rounding).
    fn apply_dot(&self, x: &[f64], y: &mut [f64], part: &mut [[f64; 2]]) -> f64 {
        #[cfg(target_arch = "x86_64")]
        let simd = pulp::x86::V3::try_new();
        y.par_chunks_mut(3 * CG_CHUNK)
            .zip(part.par_iter_mut())
            .enumerate()
            .for_each(|(c, (yc, pc))| {
                let n0 = c * CG_CHUNK;
                #[cfg(target_arch = "x86_64")]
                if let Some(simd) = simd {
                    pc[0] = simd.vectorize(|| block_rows_fma(simd, self, x, n0, yc));
                    return;
                }
                pc[0] = block_rows(self, x, n0, yc);
            });
        part.iter().map(|p| p[0]).sum()
    }

    /// `y_n = mask_n (c_k s_n + c_m m_n x_n)` for the `s_n = (K x)_n` of
    /// node `n`; returns `x_n . y_n`.
    #[inline(always)]
    fn finish_row(&self, n: usize, s: [f64; 3], x: &[f64], yn: &mut [f64]) -> f64 {
        let cm = self.c_m * self.mass[n];
        let (xn, mn) = (&x[3 * n..3 * n + 3], &self.mask[3 * n..3 * n + 3]);
        yn[0] = mn[0] * (self.c_k * s[0] + cm * xn[0]);
        yn[1] = mn[1] * (self.c_k * s[1] + cm * xn[1]);
        yn[2] = mn[2] * (self.c_k * s[2] + cm * xn[2]);
        xn[0] * yn[0] + xn[1] * yn[1] + xn[2] * yn[2]
    }
}

/// Rows `n0..` of `A x` into `yc` (scalar); returns their `x . y`.
fn block_rows(op: &Op, x: &[f64], n0: usize, yc: &mut [f64]) -> f64 {
    let (row_ptr, col, k) = (&op.pat.row_ptr, &op.pat.col, op.k);
    let xs = x.as_chunks::<3>().0;
    let mut d = 0.0;
    for (l, yn) in yc.chunks_exact_mut(3).enumerate() {
        let n = n0 + l;
        let (r0, r1) = (row_ptr[n], row_ptr[n + 1]);
        let (mut s0, mut s1, mut s2) = (0.0, 0.0, 0.0);
        for (&m, a) in col[r0..r1].iter().zip(&k[r0..r1]) {
            let xm = xs[m];
            // nalgebra stores M3 column-major: `a[j]` is column j.
            let a = &a.data.0;
            s0 += a[0][0] * xm[0] + a[1][0] * xm[1] + a[2][0] * xm[2];
            s1 += a[0][1] * xm[0] + a[1][1] * xm[1] + a[2][1] * xm[2];
            s2 += a[0][2] * xm[0] + a[1][2] * xm[1] + a[2][2] * xm[2];
        }
        d += op.finish_row(n, [s0, s1, s2], x, yn);
    }
    d
}

/// [`block_rows`] with AVX2/FMA: every block's three columns (lanes 0-2;
/// lane 3 unused) times the broadcast entries of `x_m`, accumulated with
/// fused multiply-adds (one rounding per product-sum).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn block_rows_fma(simd: pulp::x86::V3, op: &Op, x: &[f64], n0: usize, yc: &mut [f64]) -> f64 {
    use pulp::f64x4;
    let (row_ptr, col, k) = (&op.pat.row_ptr, &op.pat.col, op.k);
    let xs = x.as_chunks::<3>().0;
    let mut d = 0.0;
    for (l, yn) in yc.chunks_exact_mut(3).enumerate() {
        let n = n0 + l;
        let (r0, r1) = (row_ptr[n], row_ptr[n + 1]);
        let mut acc = simd.splat_f64x4(0.0);
        for (&m, a) in col[r0..r1].iter().zip(&k[r0..r1]) {
            let [c0, c1, c2] = &a.data.0;
            let xm = xs[m];
            acc = simd.mul_add_f64x4(f64x4(c0[0], c0[1], c0[2], 0.0), simd.splat_f64x4(xm[0]), acc);
            acc = simd.mul_add_f64x4(f64x4(c1[0], c1[1], c1[2], 0.0), simd.splat_f64x4(xm[1]), acc);
            acc = simd.mul_add_f64x4(f64x4(c2[0], c2[1], c2[2], 0.0), simd.splat_f64x4(xm[2]), acc);
        }
        d += op.finish_row(n, [acc.0, acc.1, acc.2], x, yn);
    }
    d
}

/// Preconditioner of [`pcg`].
pub(super) enum Precond<'a> {
    /// Inverse 3x3 diagonal blocks (identity rows on constrained DOFs).
    Jacobi(&'a [M3]),
    /// A cached Cholesky factor (of an earlier matrix).
    Factor { chol: &'a mut CholState, dofs: &'a [usize] },
}

/// Preconditioned conjugate gradient (Hestenes and Stiefel 1952; Saad 2003,
/// "Iterative Methods for Sparse Linear Systems", Alg. 9.1) on the free DOFs
/// of `A`. One iteration is three passes over the vectors: `A p` fused with
/// `p . A p`; the `x`, `r` updates fused with the block-Jacobi `z = M^-1 r`
/// and the sums `r . z`, `r . r`; and `p = z + beta p`. All reductions go
/// through fixed chunks (thread-count independent). Returns
/// `(iterations, |r| / |b|)`.
pub(super) fn pcg(
    op: &Op,
    mut pre: Precond,
    w: &mut CgWork,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
) -> (usize, f64) {
    let Some(bnorm) = cg_start(op, w, b, x) else {
        return (0, 0.0);
    };
    let mask = op.mask;
    let (mut rz, rr) = precond_sums(&mut pre, mask, w);
    let mut rel = rr.sqrt() / bnorm;
    w.p.copy_from_slice(&w.z);
    let mut it = 0;
    while rel > tol && it < max_iter {
        let pap = op.apply_dot(&w.p, &mut w.ap, &mut w.part);
        if !(pap > 0.0) {
            break;
        }
        let alpha = rz / pap;
        let (rz_new, rr) = match &mut pre {
            Precond::Jacobi(jac) => jacobi_update(jac, mask, alpha, w, x),
            Precond::Factor { .. } => {
                let rr = residual_update(alpha, w, x);
                if rr.sqrt() / bnorm <= tol {
                    // Converged: skip the triangular solves, whose `z` only
                    // a next iteration would use (one of the two costly
                    // operations of an iteration).
                    it += 1;
                    rel = rr.sqrt() / bnorm;
                    break;
                }
                precond_sums(&mut pre, mask, w)
            }
        };
        let beta = rz_new / rz;
        rz = rz_new;
        w.p.par_iter_mut()
            .with_min_len(1024)
            .zip(w.z.par_iter())
            .for_each(|(p, z)| *p = z + beta * *p);
        it += 1;
        rel = rr.sqrt() / bnorm;
    }
    (it, rel)
}

/// Start [`pcg`]: size and clear the work vectors, zero `x` on the
/// constrained DOFs and form `r = mask * (b - A x)`. Returns `|b|` over the
/// free DOFs, or `None` (with `x = 0`) when it is zero.
fn cg_start(op: &Op, w: &mut CgWork, b: &[f64], x: &mut [f64]) -> Option<f64> {
    let ndof = b.len();
    let nchunks = ndof.div_ceil(3 * CG_CHUNK);
    for v in [&mut w.r, &mut w.z, &mut w.p, &mut w.ap] {
        v.clear();
        v.resize(ndof, 0.0);
    }
    w.part.clear();
    w.part.resize(nchunks, [0.0; 2]);
    let mask = op.mask;
    for (v, m) in x.iter_mut().zip(mask) {
        *v *= m;
    }
    let bnorm = b.iter().zip(mask).map(|(v, m)| v * v * m).sum::<f64>().sqrt();
    if bnorm == 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return None;
    }
    let CgWork { r, part, .. } = w;
    op.apply_dot(x, r, part);
    r.par_iter_mut()
        .with_min_len(1024)
        .zip(b.par_iter().zip(mask.par_iter()))
        .for_each(|(r, (b, m))| *r = m * (b - *r));
    Some(bnorm)
}

/// `z = M^-1 r` (for block-Jacobi, [`jacobi_update`] fuses it with the
/// update pass) and the sums `[r . z, r . r]`.
fn precond_sums(pre: &mut Precond, mask: &[f64], w: &mut CgWork) -> (f64, f64) {
    let CgWork { r, z, part, .. } = w;
    match pre {
        Precond::Jacobi(jac) => {
            jacobi_sums(jac, mask, r, z, part);
        }
        Precond::Factor { chol, dofs } => {
            chol.solve_precond(dofs, r, z);
            chunk_sums(r, z, part);
        }
    }
    part.iter().fold((0.0, 0.0), |(a, b), p| (a + p[0], b + p[1]))
}

/// `x += alpha p`, `r -= alpha A p`, the block-Jacobi `z = M^-1 r` and the
/// sums `[r . z, r . r]`, in one pass.
fn jacobi_update(jac: &[M3], mask: &[f64], alpha: f64, w: &mut CgWork, x: &mut [f64]) -> (f64, f64) {
    let CgWork { r, z, p, ap, part } = w;
    x.par_chunks_mut(3 * CG_CHUNK)
        .zip(r.par_chunks_mut(3 * CG_CHUNK))
        .zip(z.par_chunks_mut(3 * CG_CHUNK))
        .zip(part.par_iter_mut())
        .enumerate()
        .for_each(|(c, (((xc, rc), zc), pc))| {
            let o = 3 * CG_CHUNK * c;
            let (pp, aa) = (&p[o..o + xc.len()], &ap[o..o + xc.len()]);
            for i in 0..xc.len() {
                xc[i] += alpha * pp[i];
                rc[i] -= alpha * aa[i];
            }
            *pc = jacobi_chunk(jac, &mask[o..o + xc.len()], c * CG_CHUNK, rc, zc);
        });
    part.iter().fold((0.0, 0.0), |(a, b), p| (a + p[0], b + p[1]))
}

/// `x += alpha p`, `r -= alpha A p` and `r . r` (summed per chunk, the same
/// sums `chunk_sums` forms).
fn residual_update(alpha: f64, w: &mut CgWork, x: &mut [f64]) -> f64 {
    let CgWork { r, p, ap, part, .. } = w;
    x.par_chunks_mut(3 * CG_CHUNK)
        .zip(r.par_chunks_mut(3 * CG_CHUNK))
        .zip(part.par_iter_mut())
        .enumerate()
        .for_each(|(c, ((xc, rc), pc))| {
            let o = 3 * CG_CHUNK * c;
            let (pp, aa) = (&p[o..o + xc.len()], &ap[o..o + xc.len()]);
            let mut rr = 0.0;
            for i in 0..xc.len() {
                xc[i] += alpha * pp[i];
                rc[i] -= alpha * aa[i];
                rr += rc[i] * rc[i];
            }
            *pc = [0.0, rr];
        });
    part.iter().map(|p| p[1]).sum()
}

/// Block-Jacobi `z = mask * (J r)` for the nodes of one chunk starting at
/// node `n0`; returns `[r . z, r . r]` over the chunk.
fn jacobi_chunk(jac: &[M3], mask: &[f64], n0: usize, r: &[f64], z: &mut [f64]) -> [f64; 2] {
    let (mut rz, mut rr) = (0.0, 0.0);
    for (l, (zn, rn)) in z.chunks_exact_mut(3).zip(r.chunks_exact(3)).enumerate() {
        let j = jac[n0 + l].as_slice();
        let mn = &mask[3 * l..3 * l + 3];
        zn[0] = mn[0] * (j[0] * rn[0] + j[3] * rn[1] + j[6] * rn[2]);
        zn[1] = mn[1] * (j[1] * rn[0] + j[4] * rn[1] + j[7] * rn[2]);
        zn[2] = mn[2] * (j[2] * rn[0] + j[5] * rn[1] + j[8] * rn[2]);
        rz += rn[0] * zn[0] + rn[1] * zn[1] + rn[2] * zn[2];
        rr += rn[0] * rn[0] + rn[1] * rn[1] + rn[2] * rn[2];
    }
    [rz, rr]
}

/// [`jacobi_chunk`] over all chunks, into `part`.
fn jacobi_sums(jac: &[M3], mask: &[f64], r: &[f64], z: &mut [f64], part: &mut [[f64; 2]]) {
    z.par_chunks_mut(3 * CG_CHUNK)
        .zip(part.par_iter_mut())
        .enumerate()
        .for_each(|(c, (zc, pc))| {
            let o = 3 * CG_CHUNK * c;
            let n = zc.len();
            *pc = jacobi_chunk(jac, &mask[o..o + n], c * CG_CHUNK, &r[o..o + n], zc);
        });
}

/// Per-chunk `[r . z, r . r]` into `part`.
fn chunk_sums(r: &[f64], z: &[f64], part: &mut [[f64; 2]]) {
    r.par_chunks(3 * CG_CHUNK)
        .zip(z.par_chunks(3 * CG_CHUNK))
        .zip(part.par_iter_mut())
        .for_each(|((rc, zc), pc)| {
            let (mut rz, mut rr) = (0.0, 0.0);
            for (a, b) in rc.iter().zip(zc) {
                rz += a * b;
                rr += a * a;
            }
            *pc = [rz, rr];
        });
}

impl System {
    /// `y = A x` with `A = c_k K + c_m diag(mass)` on the free DOFs (rows of
    /// constrained DOFs zero; `x` must be zero there), by the kernel of
    /// [`pcg`]: deterministic for any thread count.
    #[allow(clippy::too_many_arguments)]
    pub fn apply(&mut self, pat: &Pattern, k: &[M3], c_k: f64, mass: &[f64], c_m: f64, x: &[f64], y: &mut [f64]) {
        let op = Op {
            pat,
            k,
            c_k,
            mass,
            c_m,
            mask: &self.mask,
        };
        let part = &mut self.work.part;
        part.clear();
        part.resize(x.len().div_ceil(3 * CG_CHUNK), [0.0; 2]);
        op.apply_dot(x, y, part);
    }
}
