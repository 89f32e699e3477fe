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
//!
//! faer's numeric factorization and triangular solves run with `Par::Seq`:
//! faer 0.24's supernodal code loops over the supernodes in sequence and
//! hands `Par` only to each supernode's dense kernels. Measured on the
//! bench block (examples/factor_cost.rs) `Par::rayon(2)` gave no
//! measurable gain in either, and its results differ in round-off from
//! `Par::Seq`, which would break the bit-identity across thread counts.
//! The parallel piece is instead the `f32` preconditioner solve of the
//! stale-factor PCG ([`crate::supernodal`]), which is thread-count
//! independent by construction.

use crate::element::UPPER;
use crate::material::M3;
use crate::supernodal::{SparseColumn, SparseForward, SplitSolve};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Par, Side};
use rayon::prelude::*;
use surgbench_core::Vec3;

mod cg;
mod ordering;
mod solve;

use cg::{CgWork, Op, Precond, pcg};

/// Sparsity pattern of the node graph and the fixed-slot reduction maps.
#[derive(Debug, Clone)]
pub struct Pattern {
    /// Number of nodes.
    pub n: usize,
    /// Block CSR row pointers (per node).
    pub row_ptr: Vec<usize>,
    /// Block CSR column (node) indices, sorted within each row.
    pub col: Vec<usize>,
    /// For every block on or above the diagonal (`col >= row`), its element
    /// sources in element order, each `2 (10 e + UPPER[a'][b']) + t`: the
    /// element's upper block `(a', b') = (min, max)(a, b)`, transposed when
    /// `t = 1` (`a > b`). Blocks below the diagonal have no sources.
    blk_ptr: Vec<usize>,
    blk_src: Vec<u32>,
    /// Pairs `(lower block, its transpose above the diagonal)`.
    mirror: Vec<(u32, u32)>,
    /// For every node, the element-slot sources `4 e + a`, in element order.
    node_ptr: Vec<usize>,
    node_src: Vec<u32>,
    /// Index of the diagonal block of every row.
    pub diag: Vec<usize>,
    /// Node coordinates the pattern was built with (m; rest mesh), for the
    /// geometric [`Pattern::nested_dissection`].
    coords: Vec<Vec3>,
}

impl Pattern {
    /// Build from the tets over the nodes `coords` (rest positions; only
    /// [`Pattern::nested_dissection`] reads them).
    pub fn new(coords: &[Vec3], tets: &[[usize; 4]]) -> Self {
        let n = coords.len();
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
                    if t[a] <= t[b] {
                        let u = UPPER[a.min(b)][a.max(b)];
                        blk_lists[find(t[a], t[b])].push((2 * (10 * e + u) + usize::from(a > b)) as u32);
                    }
                }
            }
        }
        let mut mirror = Vec::new();
        for r in 0..n {
            for bi in row_ptr[r]..row_ptr[r + 1] {
                if col[bi] < r {
                    mirror.push((bi as u32, find(col[bi], r) as u32));
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
            mirror,
            node_ptr,
            node_src,
            diag,
            coords: coords.to_vec(),
        }
    }

    /// Number of 3x3 blocks.
    pub fn nnz_blocks(&self) -> usize {
        self.col.len()
    }

    /// Sum per-element blocks into the block CSR values (fixed order) of a
    /// symmetric matrix: `elem(e, u)` is element `e`'s upper block
    /// `u = UPPER[a][b]` (`a <= b`). Blocks on and above the diagonal are
    /// summed; those below are the transposes of their mirrors (exactly
    /// what summing the elements' transposed blocks in the same order gives).
    pub fn reduce_matrix(&self, elem: impl Fn(usize, usize) -> M3 + Sync, out: &mut [M3]) {
        out.par_iter_mut().with_min_len(256).enumerate().for_each(|(bi, o)| {
            let (p0, p1) = (self.blk_ptr[bi], self.blk_ptr[bi + 1]);
            if p0 == p1 {
                return;
            }
            let mut s = M3::zeros();
            for &src in &self.blk_src[p0..p1] {
                let (eu, t) = (src as usize >> 1, src & 1 == 1);
                let k = elem(eu / 10, eu % 10);
                s += if t { k.transpose() } else { k };
            }
            *o = s;
        });
        for &(lo, up) in &self.mirror {
            out[lo as usize] = out[up as usize].transpose();
        }
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
}

/// Largest node set [`Pattern::nested_dissection`] does not split further.
pub const ND_LEAF: usize = 8;

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
    /// Geometric nested dissection on the node graph
    /// ([`Pattern::nested_dissection`]), expanded to DOFs.
    NestedDissection,
    /// Whichever of [`Ordering::Amd`] and [`Ordering::NestedDissection`]
    /// gives the factor fewer non-zeros, decided once by both symbolic
    /// analyses (cheap next to one numeric factorization). Neither wins
    /// everywhere: on the bench block (12,960 tets) nested dissection has
    /// 2.27 M non-zeros against AMD's 2.86 M (factorization 339 M against
    /// 517 M instructions, examples/factor_cost.rs); on the thin Lamé tube
    /// coordinate bisection cuts badly and AMD's step costs 23 % fewer
    /// instructions (the instruction gate's fem workload).
    Auto,
}

/// Cholesky with the automatic fill ordering ([`Ordering::Auto`]).
impl Default for LinearSolver {
    fn default() -> Self {
        LinearSolver::Cholesky(Ordering::Auto)
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
    /// 1.0 on free DOFs, 0.0 on constrained ones (CG row masking).
    mask: Vec<f64>,
    /// CG vectors, reused across solves.
    work: CgWork,
    /// Statistics: numeric factorizations, CG iterations.
    pub factorizations: usize,
    /// Total CG iterations so far.
    pub cg_iterations: usize,
    /// Precondition the stale-factor PCG with an f32 copy of the factor.
    single: bool,
}

struct CholState {
    symbolic: SymbolicCholesky<usize>,
    l: Vec<f64>,
    mem: MemBuffer,
    valid: bool,
    /// Free-DOF right-hand side buffer of the triangular solves.
    rhs: Vec<f64>,
    /// Single-precision copy of `l` (empty unless
    /// [`System::set_single_precision_preconditioner`]).
    l32: Vec<f32>,
    /// Single-precision right-hand side buffer.
    rhs32: Vec<f32>,
    /// The two-way cut of the supernodal factor for the `f32` solves
    /// (`None` for a simplicial factor: faer's solve).
    split: Option<SplitSolve>,
    /// Sparse forward solves of the supernodal factor, built on the first
    /// [`System::gram`] (`None` before it, and for a simplicial factor):
    /// solves that never ask for one do not pay for it.
    sparse: Option<SparseForward>,
    /// This numeric factorization's [`System::factor_id`].
    id: u64,
}

/// Source of [`System::factor_id`]s: unique within the process, so a
/// caller can tell a factor from every other, of any model.
static NEXT_FACTOR_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

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
        let mask = free.iter().map(|&f| if f { 1.0 } else { 0.0 }).collect();
        Self {
            mask,
            work: CgWork::default(),
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
            single: false,
        }
    }

    /// Whether the stale-factor PCG ([`System::solve_factor_pcg`]) applies
    /// an `f32` copy of the Cholesky factor (made after every numeric
    /// factorization) instead of the `f64` factor. The triangular solves
    /// read half the bytes and run twice the SIMD lanes; the CG itself
    /// (residuals, products with `A`, stopping test) stays in `f64`, so it
    /// reaches the same tolerance: a preconditioner only has to be close
    /// to `A^-1`, and a stale factor already differs from the current
    /// matrix by far more than `f32` rounding (about `6e-8` relative).
    /// Direct solves ([`System::solve_cholesky`]) always use the `f64` factor.
    pub fn set_single_precision_preconditioner(&mut self, on: bool) {
        self.single = on;
        if let Some(c) = &mut self.chol {
            c.set_single(on);
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

    /// Factor values in the two bins and the top of the `f32` solve's cut
    /// ([`crate::supernodal::SplitSolve`]), once analysed.
    pub fn split_values(&self) -> Option<[usize; 3]> {
        self.chol.as_ref().and_then(|c| c.split.as_ref()).map(|s| s.values)
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

    /// `G[a][b] = b_a^T A^-1 b_b` (row-major `k x k`) for right-hand sides
    /// given by their non-zeros `(full DOF, value)` (constrained DOFs
    /// ignored), by sparse forward solves with the cached supernodal factor
    /// ([`SparseForward`]); `None` without a valid supernodal factor (then
    /// solve the columns in full, [`Self::solve_cholesky_many`]).
    pub fn gram(&mut self, rhs: &[Vec<(usize, f64)>]) -> Option<Vec<f64>> {
        let c = self.chol.as_mut().filter(|c| c.valid)?;
        if c.sparse.is_none() {
            c.sparse = SparseForward::new(&c.symbolic, &self.dofs, self.free.len());
        }
        Some(c.sparse.as_mut()?.gram(&c.l, rhs))
    }

    /// The columns `L^-1 P b` of sparse right-hand sides with the cached
    /// supernodal factor ([`SparseForward::columns`]), with the factor's
    /// [`Self::factor_id`]; `None` as for [`Self::gram`].
    pub fn forward_columns(&mut self, rhs: &[Vec<(usize, f64)>]) -> Option<(u64, Vec<SparseColumn>)> {
        let c = self.chol.as_mut().filter(|c| c.valid)?;
        if c.sparse.is_none() {
            c.sparse = SparseForward::new(&c.symbolic, &self.dofs, self.free.len());
        }
        let cols = c.sparse.as_mut()?.columns(&c.l, rhs);
        Some((c.id, cols))
    }

    /// Identity of the valid numeric factorization (`None` without one):
    /// a new one, of this system or any other, has a new id, so products
    /// with a factor can be kept while the id stays.
    pub fn factor_id(&self) -> Option<u64> {
        self.chol.as_ref().filter(|c| c.valid).map(|c| c.id)
    }

    /// The forward half of a solve with the cached supernodal factor,
    /// `u = L^-1 P r` ([`SparseForward::forward`]), and the factor's
    /// [`Self::factor_id`]; `None` as for [`Self::gram`].
    pub fn forward_half(&mut self, r: &[f64]) -> Option<(u64, Vec<f64>)> {
        if !self.has_supernodal_factor() {
            return None;
        }
        let c = self.chol.as_ref()?;
        let u = c.sparse.as_ref()?.forward(&c.l, r);
        Some((c.id, u))
    }

    /// Whether a valid supernodal factor is cached (what [`Self::gram`],
    /// [`Self::forward_columns`] and the two halves need); builds their
    /// sparse solver on the first call.
    pub fn has_supernodal_factor(&mut self) -> bool {
        let Some(c) = self.chol.as_mut().filter(|c| c.valid) else {
            return false;
        };
        if c.sparse.is_none() {
            c.sparse = SparseForward::new(&c.symbolic, &self.dofs, self.free.len());
        }
        c.sparse.is_some()
    }

    /// The backward half, `z = P^T L^-T u` on the free DOFs of `z`
    /// ([`SparseForward::backward`]; `u` overwritten); `None` (and nothing
    /// written) without a valid supernodal factor.
    pub fn backward_half(&mut self, u: &mut [f64], z: &mut [f64]) -> Option<()> {
        let c = self.chol.as_mut().filter(|c| c.valid)?;
        c.sparse.as_ref()?.backward(&c.l, u, z);
        Some(())
    }

    /// Whether a valid numeric factorization is cached.
    pub fn has_factorization(&self) -> bool {
        self.chol.as_ref().is_some_and(|c| c.valid)
    }

    /// Stop offering the cached factorization ([`Self::has_factorization`]
    /// turns false until the next [`Self::factorize`]): a solve that must
    /// depend only on its own inputs (a restored state steps as the saved
    /// one did) starts without a factor from earlier work.
    pub fn forget_factorization(&mut self) {
        if let Some(c) = &mut self.chol {
            c.valid = false;
        }
    }

    /// Symbolic Cholesky analysis of the free-DOF pattern under `ordering`
    /// (not [`Ordering::Auto`], which [`Self::factorize`] resolves).
    fn symbolic(&self, pat: &Pattern, ordering: Ordering) -> Result<SymbolicCholesky<usize>, String> {
        let perm_storage;
        let ord = match ordering {
            Ordering::Amd | Ordering::Auto => SymmetricOrdering::Amd,
            Ordering::Rcm | Ordering::NestedDissection => {
                let nodes = if ordering == Ordering::Rcm {
                    pat.rcm()
                } else {
                    pat.nested_dissection()
                };
                let mut fwd = Vec::with_capacity(self.n_free());
                for node in nodes {
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
        factorize_symbolic_cholesky(self.sym.as_ref(), Side::Upper, ord, CholeskySymbolicParams::default())
            .map_err(|e| format!("symbolic Cholesky failed: {e:?}"))
    }

    /// Numeric Cholesky of the current values (symbolic analysis on first use).
    pub fn factorize(&mut self, pat: &Pattern, ordering: Ordering) -> Result<(), String> {
        if self.chol.is_none() {
            let symbolic = match ordering {
                Ordering::Auto => {
                    let amd = self.symbolic(pat, Ordering::Amd)?;
                    let nd = self.symbolic(pat, Ordering::NestedDissection)?;
                    // Ties keep AMD (the ordering that needs no coordinates).
                    if nd.len_val() < amd.len_val() { nd } else { amd }
                }
                o => self.symbolic(pat, o)?,
            };
            let req = symbolic
                .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
                .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq))
                .or(symbolic.solve_in_place_scratch::<f32>(1, Par::Seq));
            let mem = MemBuffer::try_new(req).map_err(|_| "out of memory for Cholesky workspace".to_string())?;
            let l = vec![0.0; symbolic.len_val()];
            self.chol = Some(CholState {
                l,
                mem,
                valid: false,
                rhs: vec![0.0; self.dofs.len()],
                l32: Vec::new(),
                rhs32: vec![0.0; self.dofs.len()],
                split: SplitSolve::new(&symbolic, &self.dofs),
                sparse: None,
                id: 0,
                symbolic,
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
        c.id = NEXT_FACTOR_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        c.set_single(self.single);
        self.factorizations += 1;
        Ok(())
    }
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
