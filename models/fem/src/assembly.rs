//! Sparse assembly in 3x3 block CSR and the linear solvers.
//!
//! Determinism across thread counts: every element writes its force and
//! stiffness contributions into its own fixed slots; each node (for forces)
//! and each block (for the matrix) then sums its contributions in element
//! order. No floating-point sum depends on how work is split.
//!
//! The free-DOF system (constrained DOFs eliminated) is solved either with
//! faer's sparse Cholesky (symbolic analysis once, numeric refactorization
//! without allocation, reused while the matrix does not change), or with a
//! block-Jacobi preconditioned conjugate gradient on the block CSR matrix.

use crate::material::M3;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Par, Side};
use rayon::prelude::*;
use surgbench_core::Vec3;

/// Sparsity pattern of the node graph and the fixed-slot reduction maps.
#[derive(Debug, Clone)]
pub struct Pattern {
    /// Number of nodes.
    pub n: usize,
    /// Block CSR row pointers (per node).
    pub row_ptr: Vec<usize>,
    /// Block CSR column (node) indices, sorted within each row.
    pub col: Vec<usize>,
    /// For every block, the element-slot sources `16 e + 4 a + b`, in element order.
    blk_ptr: Vec<usize>,
    blk_src: Vec<u32>,
    /// For every node, the element-slot sources `4 e + a`, in element order.
    node_ptr: Vec<usize>,
    node_src: Vec<u32>,
    /// Index of the diagonal block of every row.
    pub diag: Vec<usize>,
}

impl Pattern {
    /// Build from the tets over `n` nodes.
    pub fn new(n: usize, tets: &[[usize; 4]]) -> Self {
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
        for t in tets {
            for &a in t {
                adj[a].extend_from_slice(t);
            }
        }
        let mut row_ptr = vec![0];
        let mut col = Vec::new();
        for a in adj.iter_mut() {
            a.sort_unstable();
            a.dedup();
            col.extend_from_slice(a);
            row_ptr.push(col.len());
        }
        let find =
            |r: usize, c: usize| row_ptr[r] + col[row_ptr[r]..row_ptr[r + 1]].binary_search(&c).expect("in pattern");
        let diag: Vec<usize> = (0..n).map(|i| find(i, i)).collect();
        let mut blk_lists: Vec<Vec<u32>> = vec![Vec::new(); col.len()];
        let mut node_lists: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (e, t) in tets.iter().enumerate() {
            for a in 0..4 {
                node_lists[t[a]].push((4 * e + a) as u32);
                for b in 0..4 {
                    blk_lists[find(t[a], t[b])].push((16 * e + 4 * a + b) as u32);
                }
            }
        }
        let flatten = |lists: Vec<Vec<u32>>| {
            let mut ptr = vec![0];
            let mut src = Vec::new();
            for l in lists {
                src.extend(l);
                ptr.push(src.len());
            }
            (ptr, src)
        };
        let (blk_ptr, blk_src) = flatten(blk_lists);
        let (node_ptr, node_src) = flatten(node_lists);
        Self {
            n,
            row_ptr,
            col,
            blk_ptr,
            blk_src,
            node_ptr,
            node_src,
            diag,
        }
    }

    /// Number of 3x3 blocks.
    pub fn nnz_blocks(&self) -> usize {
        self.col.len()
    }

    /// Sum per-element blocks into the block CSR values (fixed order).
    pub fn reduce_matrix(&self, elem: impl Fn(usize, usize) -> M3 + Sync, out: &mut [M3]) {
        out.par_iter_mut().with_min_len(256).enumerate().for_each(|(bi, o)| {
            let mut s = M3::zeros();
            for &src in &self.blk_src[self.blk_ptr[bi]..self.blk_ptr[bi + 1]] {
                let src = src as usize;
                s += elem(src / 16, src % 16);
            }
            *o = s;
        });
    }

    /// Sum per-element nodal vectors into node vectors (fixed order).
    pub fn reduce_vector(&self, elem: impl Fn(usize, usize) -> Vec3 + Sync, out: &mut [Vec3]) {
        out.par_iter_mut().with_min_len(256).enumerate().for_each(|(i, o)| {
            let mut s = Vec3::zeros();
            for &src in &self.node_src[self.node_ptr[i]..self.node_ptr[i + 1]] {
                let src = src as usize;
                s += elem(src / 4, src % 4);
            }
            *o = s;
        });
    }

    /// Reverse Cuthill-McKee ordering of the node graph (Cuthill and McKee
    /// 1969; George 1971): breadth-first from a pseudo-peripheral node,
    /// neighbours by increasing degree, then reversed. Returns the nodes in
    /// the new order (`order[k]` = old node index).
    pub fn rcm(&self) -> Vec<usize> {
        let n = self.n;
        let deg = |i: usize| self.row_ptr[i + 1] - self.row_ptr[i];
        let mut visited = vec![false; n];
        let mut order = Vec::with_capacity(n);
        let bfs = |start: usize, visited: &mut Vec<bool>, order: &mut Vec<usize>| -> usize {
            let first = order.len();
            visited[start] = true;
            order.push(start);
            let mut head = first;
            let mut last = start;
            while head < order.len() {
                let v = order[head];
                head += 1;
                last = v;
                let mut nb: Vec<usize> = self.col[self.row_ptr[v]..self.row_ptr[v + 1]]
                    .iter()
                    .copied()
                    .filter(|&u| !visited[u])
                    .collect();
                nb.sort_by_key(|&u| (deg(u), u));
                for u in nb {
                    visited[u] = true;
                    order.push(u);
                }
            }
            last
        };
        for s in 0..n {
            if visited[s] {
                continue;
            }
            // Pseudo-peripheral start: the last node reached by a BFS.
            let mut tmp_vis = visited.clone();
            let mut tmp = Vec::new();
            let far = bfs(s, &mut tmp_vis, &mut tmp);
            bfs(far, &mut visited, &mut order);
        }
        order.reverse();
        order
    }
}

/// Which linear solver the Newton steps use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LinearSolver {
    /// faer sparse Cholesky `L L^T` with the given fill ordering.
    Cholesky(Ordering),
    /// Block-Jacobi preconditioned conjugate gradient: relative residual
    /// tolerance and iteration cap.
    Cg {
        /// Stop when `|r| <= tol |b|`.
        tol: f64,
        /// Iteration cap.
        max_iter: usize,
    },
}

/// Fill-reducing ordering for the Cholesky factorization.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ordering {
    /// faer's approximate minimum degree.
    Amd,
    /// Reverse Cuthill-McKee on the node graph, expanded to DOFs.
    Rcm,
}

impl Default for LinearSolver {
    fn default() -> Self {
        LinearSolver::Cholesky(Ordering::Amd)
    }
}

/// The free-DOF system `A = c_m M + c_k K` built from block CSR values.
pub struct System {
    /// Free flag per DOF (`3 node + axis`).
    pub free: Vec<bool>,
    /// Free index per DOF (`usize::MAX` when constrained).
    fidx: Vec<usize>,
    /// DOF of every free index.
    dofs: Vec<usize>,
    /// CSC (upper triangle) of the free system.
    sym: SymbolicSparseColMat<usize>,
    /// For every CSC entry: block index and offset `3 j + i` inside it.
    src: Vec<(u32, u8)>,
    vals: Vec<f64>,
    chol: Option<CholState>,
    /// Block-Jacobi inverses (CG).
    jac: Vec<M3>,
    /// Statistics: numeric factorizations, CG iterations.
    pub factorizations: usize,
    /// Total CG iterations so far.
    pub cg_iterations: usize,
}

struct CholState {
    symbolic: SymbolicCholesky<usize>,
    l: Vec<f64>,
    mem: MemBuffer,
    valid: bool,
}

impl System {
    /// Build the free-DOF pattern for the constrained-DOF mask `free`.
    pub fn new(pat: &Pattern, free: Vec<bool>) -> Self {
        let mut fidx = vec![usize::MAX; free.len()];
        let mut dofs = Vec::new();
        for (d, &f) in free.iter().enumerate() {
            if f {
                fidx[d] = dofs.len();
                dofs.push(d);
            }
        }
        let nf = dofs.len();
        let mut col_ptr = vec![0usize];
        let mut row_idx = Vec::new();
        let mut src = Vec::new();
        for &cd in &dofs {
            let (cn, ci) = (cd / 3, cd % 3);
            for bi in pat.row_ptr[cn]..pat.row_ptr[cn + 1] {
                let m = pat.col[bi];
                for j in 0..3 {
                    let rd = 3 * m + j;
                    if free[rd] && fidx[rd] <= fidx[cd] {
                        row_idx.push(fidx[rd]);
                        // Block (cn, m) entry (ci, j) = K[cd, rd] = K[rd, cd].
                        src.push((bi as u32, (3 * j + ci) as u8));
                    }
                }
            }
            col_ptr.push(row_idx.len());
        }
        let sym = SymbolicSparseColMat::new_checked(nf, nf, col_ptr, None, row_idx);
        let nv = src.len();
        Self {
            free,
            fidx,
            dofs,
            sym,
            src,
            vals: vec![0.0; nv],
            chol: None,
            jac: Vec::new(),
            factorizations: 0,
            cg_iterations: 0,
        }
    }

    /// Number of free DOFs.
    pub fn n_free(&self) -> usize {
        self.dofs.len()
    }

    /// Free index of a DOF, if free.
    pub fn free_index(&self, dof: usize) -> Option<usize> {
        let i = self.fidx[dof];
        (i != usize::MAX).then_some(i)
    }

    /// Non-zeros of the Cholesky factor, once analysed.
    pub fn factor_nnz(&self) -> Option<usize> {
        self.chol.as_ref().map(|c| c.symbolic.len_val())
    }

    /// Set new matrix values `c_k K + c_m diag(mass)` (K in block CSR).
    /// Invalidates the current numeric factorization.
    pub fn set_values(&mut self, pat: &Pattern, k: &[M3], c_k: f64, mass: &[f64], c_m: f64) {
        let vals = &mut self.vals;
        let src = &self.src;
        vals.par_iter_mut()
            .with_min_len(1024)
            .zip(src.par_iter())
            .for_each(|(v, &(bi, off))| {
                *v = c_k * k[bi as usize][off as usize];
            });
        // Mass on the diagonal entries.
        if c_m != 0.0 {
            let col_ptr = self.sym.col_ptr();
            let row_idx = self.sym.row_idx();
            for (f, &d) in self.dofs.iter().enumerate() {
                // The diagonal is the last entry of its (upper) column.
                let last = col_ptr[f + 1] - 1;
                debug_assert_eq!(row_idx[last], f);
                self.vals[last] += c_m * mass[d / 3];
            }
        }
        if let Some(c) = &mut self.chol {
            c.valid = false;
        }
        self.set_block_jacobi(pat, k, c_k, mass, c_m);
    }

    /// Block-Jacobi preconditioner of `c_k K + c_m diag(mass)` for
    /// [`System::solve_cg`]: the inverse of every node's 3x3 diagonal block
    /// restricted to its free DOFs (all [`System::set_values`] does for CG).
    pub fn set_block_jacobi(&mut self, pat: &Pattern, k: &[M3], c_k: f64, mass: &[f64], c_m: f64) {
        let free = &self.free;
        self.jac.resize(pat.n, M3::identity());
        self.jac
            .par_iter_mut()
            .with_min_len(256)
            .enumerate()
            .for_each(|(n, out)| {
                let mut b = k[pat.diag[n]] * c_k + M3::identity() * (c_m * mass[n]);
                for i in 0..3 {
                    if !free[3 * n + i] {
                        b.set_row(i, &nalgebra::RowVector3::zeros());
                        b.set_column(i, &nalgebra::Vector3::zeros());
                        b[(i, i)] = 1.0;
                    }
                }
                *out = b.try_inverse().unwrap_or_else(M3::identity);
            });
    }

    /// Whether a valid numeric factorization is cached.
    pub fn has_factorization(&self) -> bool {
        self.chol.as_ref().is_some_and(|c| c.valid)
    }

    /// Numeric Cholesky of the current values (symbolic analysis on first use).
    pub fn factorize(&mut self, pat: &Pattern, ordering: Ordering) -> Result<(), String> {
        if self.chol.is_none() {
            let perm_storage;
            let ord = match ordering {
                Ordering::Amd => SymmetricOrdering::Amd,
                Ordering::Rcm => {
                    let mut fwd = Vec::with_capacity(self.n_free());
                    for node in pat.rcm() {
                        for i in 0..3 {
                            if let Some(f) = self.free_index(3 * node + i) {
                                fwd.push(f);
                            }
                        }
                    }
                    let mut inv = vec![0usize; fwd.len()];
                    for (k, &f) in fwd.iter().enumerate() {
                        inv[f] = k;
                    }
                    perm_storage = (fwd, inv);
                    SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(
                        &perm_storage.0,
                        &perm_storage.1,
                        self.n_free(),
                    ))
                }
            };
            let symbolic =
                factorize_symbolic_cholesky(self.sym.as_ref(), Side::Upper, ord, CholeskySymbolicParams::default())
                    .map_err(|e| format!("symbolic Cholesky failed: {e:?}"))?;
            let req = symbolic
                .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
                .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
            let mem = MemBuffer::try_new(req).map_err(|_| "out of memory for Cholesky workspace".to_string())?;
            let l = vec![0.0; symbolic.len_val()];
            self.chol = Some(CholState {
                symbolic,
                l,
                mem,
                valid: false,
            });
        }
        let c = self.chol.as_mut().expect("analysed above");
        let a = SparseColMatRef::new(self.sym.as_ref(), &self.vals);
        c.valid = false;
        c.symbolic
            .factorize_numeric_llt(
                &mut c.l,
                a,
                Side::Upper,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut c.mem),
                Default::default(),
            )
            .map_err(|e| format!("matrix is not positive definite ({e:?})"))?;
        c.valid = true;
        self.factorizations += 1;
        Ok(())
    }

    /// Solve `A x = b` on the free DOFs with the cached factorization;
    /// `b` (full DOF vector, constrained entries ignored) is overwritten by `x`
    /// (constrained entries set to zero).
    pub fn solve_cholesky(&mut self, b: &mut [f64]) {
        let c = self.chol.as_mut().expect("factorize first");
        let mut rhs: Vec<f64> = self.dofs.iter().map(|&d| b[d]).collect();
        let llt = LltRef::new(&c.symbolic, &c.l);
        let n = rhs.len();
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut rhs, n, 1),
            Par::Seq,
            MemStack::new(&mut c.mem),
        );
        b.iter_mut().for_each(|v| *v = 0.0);
        for (f, &d) in self.dofs.iter().enumerate() {
            b[d] = rhs[f];
        }
    }

    /// Block-Jacobi PCG on `A = c_k K + c_m M` (block CSR `k`) restricted to
    /// the free DOFs. `x` holds the initial guess (warm start) and receives
    /// the solution. Returns `(iterations, relative residual)`.
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
        let free = &self.free;
        let jac = &self.jac;
        let mut precond = |r: &[f64], z: &mut [f64]| {
            z.par_chunks_mut(3).with_min_len(256).enumerate().for_each(|(n, zn)| {
                let v = jac[n] * Vec3::new(r[3 * n], r[3 * n + 1], r[3 * n + 2]);
                for i in 0..3 {
                    zn[i] = if free[3 * n + i] { v[i] } else { 0.0 };
                }
            });
        };
        let out = pcg(pat, k, c_k, mass, c_m, free, b, x, tol, max_iter, &mut precond);
        self.cg_iterations += out.0;
        out
    }

    /// PCG on `A = c_k K + c_m M` preconditioned by the cached Cholesky
    /// factor of an earlier matrix (the lazy update's stale factorization).
    /// Returns `None` when no factorization is cached.
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
        let free = self.free.clone();
        let mut precond = |r: &[f64], z: &mut [f64]| {
            z.copy_from_slice(r);
            self.solve_cholesky(z);
        };
        let out = pcg(pat, k, c_k, mass, c_m, &free, b, x, tol, max_iter, &mut precond);
        self.cg_iterations += out.0;
        Some(out)
    }
}

/// Preconditioned conjugate gradient (Hestenes and Stiefel 1952) on the
/// free DOFs of `A = c_k K + c_m diag(mass)`; reductions in fixed chunks.
fn pcg(
    pat: &Pattern,
    k: &[M3],
    c_k: f64,
    mass: &[f64],
    c_m: f64,
    free: &[bool],
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iter: usize,
    precond: &mut dyn FnMut(&[f64], &mut [f64]),
) -> (usize, f64) {
    let matvec = |x: &[f64], y: &mut [f64]| {
        y.par_chunks_mut(3).with_min_len(128).enumerate().for_each(|(n, yn)| {
            let mut s = Vec3::zeros();
            for bi in pat.row_ptr[n]..pat.row_ptr[n + 1] {
                let m = pat.col[bi];
                s += k[bi] * Vec3::new(x[3 * m], x[3 * m + 1], x[3 * m + 2]);
            }
            s = s * c_k + Vec3::new(x[3 * n], x[3 * n + 1], x[3 * n + 2]) * (c_m * mass[n]);
            for i in 0..3 {
                yn[i] = if free[3 * n + i] { s[i] } else { 0.0 };
            }
        });
    };
    let ndof = b.len();
    for (v, &f) in x.iter_mut().zip(free) {
        if !f {
            *v = 0.0;
        }
    }
    let mut r = vec![0.0; ndof];
    matvec(x, &mut r);
    for i in 0..ndof {
        r[i] = if free[i] { b[i] - r[i] } else { 0.0 };
    }
    let bn: Vec<f64> = b.iter().zip(free).map(|(v, &f)| if f { *v } else { 0.0 }).collect();
    let bnorm = dot(&bn, &bn).sqrt();
    if bnorm == 0.0 {
        x.iter_mut().for_each(|v| *v = 0.0);
        return (0, 0.0);
    }
    let mut z = vec![0.0; ndof];
    precond(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; ndof];
    let mut it = 0;
    let mut rel = dot(&r, &r).sqrt() / bnorm;
    while rel > tol && it < max_iter {
        matvec(&p, &mut ap);
        let pap = dot(&p, &ap);
        if !(pap > 0.0) {
            break;
        }
        let alpha = rz / pap;
        x.par_iter_mut()
            .with_min_len(1024)
            .zip(p.par_iter())
            .for_each(|(x, p)| *x += alpha * p);
        r.par_iter_mut()
            .with_min_len(1024)
            .zip(ap.par_iter())
            .for_each(|(r, a)| *r -= alpha * a);
        precond(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut()
            .with_min_len(1024)
            .zip(z.par_iter())
            .for_each(|(p, z)| *p = z + beta * *p);
        it += 1;
        rel = dot(&r, &r).sqrt() / bnorm;
    }
    (it, rel)
}

/// Dot product summed in fixed chunks, so the result does not depend on
/// the number of threads.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    const CHUNK: usize = 1024;
    let partial: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>())
        .collect();
    partial.iter().sum()
}
