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
use crate::supernodal::SplitSolve;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Par, Side};
use rayon::prelude::*;
use surgbench_core::Vec3;

mod ordering;
mod solve;

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

    /// Whether a valid numeric factorization is cached.
    pub fn has_factorization(&self) -> bool {
        self.chol.as_ref().is_some_and(|c| c.valid)
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
        c.set_single(self.single);
        self.factorizations += 1;
        Ok(())
    }
}

/// Nodes per parallel work item and per partial sum of the CG kernels. Fixed,
/// so every reduction adds the same partial sums in the same order for any
/// thread count (bit-identical results).
const CG_CHUNK: usize = 64;

/// Reused CG vectors (full DOF length) and per-chunk partial sums: a CG
/// solve allocates nothing after the first one.
#[derive(Default)]
struct CgWork {
    r: Vec<f64>,
    z: Vec<f64>,
    p: Vec<f64>,
    ap: Vec<f64>,
    part: Vec<[f64; 2]>,
}

/// The operator `A = c_k K + c_m diag(mass)` on the free DOFs: rows of
/// constrained DOFs are zeroed by `mask` (1 free, 0 constrained); columns
/// need no masking because every vector CG applies it to is zero there.
struct Op<'a> {
    pat: &'a Pattern,
    k: &'a [M3],
    c_k: f64,
    mass: &'a [f64],
    c_m: f64,
    mask: &'a [f64],
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
enum Precond<'a> {
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
fn pcg(op: &Op, mut pre: Precond, w: &mut CgWork, b: &[f64], x: &mut [f64], tol: f64, max_iter: usize) -> (usize, f64) {
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
        return (0, 0.0);
    }
    let CgWork { r, z, p, ap, part } = w;
    op.apply_dot(x, r, part);
    r.par_iter_mut()
        .with_min_len(1024)
        .zip(b.par_iter().zip(mask.par_iter()))
        .for_each(|(r, (b, m))| *r = m * (b - *r));
    // `z = M^-1 r` (Jacobi fused with the update pass below when it is
    // block-Jacobi) and the sums [r . z, r . r].
    let precond = |pre: &mut Precond, r: &[f64], z: &mut [f64], part: &mut [[f64; 2]]| -> (f64, f64) {
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
    };
    let (mut rz, rr) = precond(&mut pre, r, z, part);
    let mut rel = rr.sqrt() / bnorm;
    p.copy_from_slice(z);
    let mut it = 0;
    while rel > tol && it < max_iter {
        let pap = op.apply_dot(p, ap, part);
        if !(pap > 0.0) {
            break;
        }
        let alpha = rz / pap;
        let (rz_new, rr) = match &mut pre {
            Precond::Jacobi(jac) => {
                // x += alpha p, r -= alpha A p, z = M^-1 r and the sums, in one pass.
                let jac: &[M3] = jac;
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
            Precond::Factor { .. } => {
                // x += alpha p, r -= alpha A p and r . r per chunk (the
                // same sums `chunk_sums` forms).
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
                let rr: f64 = part.iter().map(|p| p[1]).sum();
                if rr.sqrt() / bnorm <= tol {
                    // Converged: skip the triangular solves, whose `z` only
                    // a next iteration would use (one of the two costly
                    // operations of an iteration).
                    it += 1;
                    rel = rr.sqrt() / bnorm;
                    break;
                }
                precond(&mut pre, r, z, part)
            }
        };
        let beta = rz_new / rz;
        rz = rz_new;
        p.par_iter_mut()
            .with_min_len(1024)
            .zip(z.par_iter())
            .for_each(|(p, z)| *p = z + beta * *p);
        it += 1;
        rel = rr.sqrt() / bnorm;
    }
    (it, rel)
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
