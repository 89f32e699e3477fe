//! Two-way parallel, thread-count independent triangular solves with an
//! `f32` copy of faer's supernodal Cholesky factor `P A P^T = L L^T`: the
//! preconditioner of the stale-factor PCG ([`crate::assembly::System::solve_factor_pcg`]).
//!
//! faer 0.24's supernodal solve walks the supernodes one after the other
//! and passes its `Par` only to the dense kernels of each supernode, which
//! are too small to gain from threads (and its parallel kernels change the
//! round-off with the thread count). Here the supernodal elimination tree
//! is cut instead: the supernodes near the root (the "top", e.g. the first
//! separators of a nested-dissection ordering) are kept together, and the
//! subtrees hanging below them are dealt into two bins of about equal
//! factor size. The two bins share no unknowns except the top ones:
//!
//! * forward (`L y = b`): each bin eliminates its own supernodes and
//!   accumulates its updates of the top unknowns in its own buffer; the top
//!   right-hand side is then `b_top + acc_0 + acc_1` (this order), and the
//!   top supernodes are eliminated;
//! * backward (`L^T x = y`): the top supernodes first, then each bin reads
//!   the top values and back-substitutes its own supernodes.
//!
//! The two bins run under `rayon::join`, so in any thread pool (one thread
//! or two) every floating-point operation is the same: results are
//! bit-identical for any thread count. The dense kernels are plain column
//! loops (axpy forward, dot products with eight fixed partial sums
//! backward) without fused multiply-adds, so the AVX2 build (pulp's `V3`,
//! checked at run time) and the scalar build give the same bits as well.

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{SymbolicCholesky, SymbolicCholeskyRaw};

/// One supernode in a part's local numbering.
struct Snode {
    /// Local index of its first column.
    off: usize,
    /// Columns.
    ncols: usize,
    /// Offset of its values (column-major, `ncols + pat.len()` rows) in the factor.
    val: usize,
    /// Local indices of its off-diagonal rows.
    pat: Vec<u32>,
}

/// The supernodes of one bin, or of the top.
struct Part {
    /// Full-DOF index of every local unknown it owns (gather/scatter).
    src: Vec<usize>,
    /// Supernodes, children before parents.
    snodes: Vec<Snode>,
    /// Work vector: own unknowns, then (bins) the top's unknowns.
    buf: Vec<f32>,
    /// Scratch of the longest off-diagonal pattern.
    tmp: Vec<f32>,
}

/// The supernode of every factor column of `sn`.
fn snode_of_columns(sn: &SymbolicSupernodalCholesky<usize>) -> Vec<usize> {
    let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
    let mut snode_of = vec![0usize; sn.nrows()];
    for s in 0..sn.n_supernodes() {
        snode_of[begin[s]..end[s]].fill(s);
    }
    snode_of
}

/// The supernodal elimination tree: the parent of a supernode owns its
/// first off-diagonal row, and parents come after their children.
struct Tree {
    /// Supernodes.
    ns: usize,
    /// Supernode of every column.
    snode_of: Vec<usize>,
    children: Vec<Vec<usize>>,
    roots: Vec<usize>,
    /// Factor values of each supernode's subtree.
    work: Vec<usize>,
}

impl Tree {
    /// The tree of the supernodal factor `sn`.
    fn new(sn: &SymbolicSupernodalCholesky<usize>) -> Self {
        let ns = sn.n_supernodes();
        let val_ptr = sn.col_ptr_for_val();
        let snode_of = snode_of_columns(sn);
        let pattern = |s: usize| sn.supernode(s).pattern();
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); ns];
        let mut roots = Vec::new();
        for s in 0..ns {
            match pattern(s).first() {
                Some(&r) => children[snode_of[r]].push(s),
                None => roots.push(s),
            }
        }
        let mut work: Vec<usize> = (0..ns).map(|s| val_ptr[s + 1] - val_ptr[s]).collect();
        for s in 0..ns {
            if let Some(&r) = pattern(s).first() {
                work[snode_of[r]] += work[s];
            }
        }
        Self {
            ns,
            snode_of,
            children,
            roots,
            work,
        }
    }

    /// The part of every supernode (0, 1: bins; 2: top). Moves the largest
    /// subtree's root into the top, one at a time, and keeps the cut with
    /// the shortest critical path (top plus the heavier bin); stops once the
    /// top holds half the factor.
    fn cut(&self) -> Vec<u8> {
        let (work, children) = (&self.work, &self.children);
        let deal = |subtrees: &[usize]| -> ([usize; 2], Vec<(usize, usize)>) {
            let mut order = subtrees.to_vec();
            order.sort_by_key(|&s| (std::cmp::Reverse(work[s]), s));
            let mut load = [0usize; 2];
            let mut assign = Vec::with_capacity(order.len());
            for s in order {
                let b = usize::from(load[1] < load[0]);
                load[b] += work[s];
                assign.push((s, b));
            }
            (load, assign)
        };
        let all: usize = self.roots.iter().map(|&s| work[s]).sum();
        let mut subtrees = self.roots.clone();
        let mut top: Vec<usize> = Vec::new();
        let mut top_work = 0;
        let mut best = (usize::MAX, 0, Vec::new());
        while 2 * top_work <= all {
            let (load, assign) = deal(&subtrees);
            let path = top_work + load[0].max(load[1]);
            if path < best.0 {
                best = (path, top.len(), assign);
            }
            let Some((k, &big)) = subtrees.iter().enumerate().max_by_key(|&(_, &s)| (work[s], s)) else {
                break;
            };
            subtrees.swap_remove(k);
            top.push(big);
            top_work += work[big] - children[big].iter().map(|&c| work[c]).sum::<usize>();
            subtrees.extend(&children[big]);
        }
        let mut owner = vec![2u8; self.ns];
        for (root, b) in best.2 {
            let mut stack = vec![root];
            while let Some(s) = stack.pop() {
                owner[s] = b as u8;
                stack.extend(&children[s]);
            }
        }
        owner
    }

    /// The three parts (bin 0, bin 1, top) of the cut `owner`, each in its
    /// local numbering (its supernodes in increasing order); `full(col)` is
    /// the full-DOF index of factor column `col`.
    fn parts(&self, sn: &SymbolicSupernodalCholesky<usize>, owner: &[u8], full: impl Fn(usize) -> usize) -> Vec<Part> {
        let ns = self.ns;
        let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
        let val_ptr = sn.col_ptr_for_val();
        let pattern = |s: usize| sn.supernode(s).pattern();
        let mut local = vec![0usize; sn.nrows()];
        let mut parts: Vec<Part> = (0..3)
            .map(|_| Part {
                src: Vec::new(),
                snodes: Vec::new(),
                buf: Vec::new(),
                tmp: Vec::new(),
            })
            .collect();
        for s in 0..ns {
            let p = &mut parts[owner[s] as usize];
            for col in begin[s]..end[s] {
                local[col] = p.src.len();
                p.src.push(full(col));
            }
        }
        let n_top = parts[2].src.len();
        for s in 0..ns {
            let o = owner[s] as usize;
            let n_own = parts[o].src.len();
            let pat: Vec<u32> = pattern(s)
                .iter()
                .map(|&r| {
                    let ro = owner[self.snode_of[r]] as usize;
                    debug_assert!(ro == o || ro == 2, "supernode {s} (part {o}) updates part {ro}");
                    (if ro == o { local[r] } else { n_own + local[r] }) as u32
                })
                .collect();
            let p = &mut parts[o];
            p.tmp.resize(p.tmp.len().max(pat.len()), 0.0);
            p.snodes.push(Snode {
                off: local[begin[s]],
                ncols: end[s] - begin[s],
                val: val_ptr[s],
                pat,
            });
        }
        for (o, p) in parts.iter_mut().enumerate() {
            p.buf = vec![0.0; p.src.len() + if o < 2 { n_top } else { 0 }];
        }
        parts
    }
}

/// The cut of a supernodal factor into a top and two bins (see the module docs).
pub struct SplitSolve {
    top: Part,
    bins: [Part; 2],
    /// Factor values in bin 0, bin 1 and the top.
    pub values: [usize; 3],
}

impl SplitSolve {
    /// Cut the supernodal elimination tree of `symbolic` (`None` when faer
    /// chose a simplicial factorization). `dofs[i]` is the full-DOF index of
    /// free unknown `i`.
    pub fn new(symbolic: &SymbolicCholesky<usize>, dofs: &[usize]) -> Option<Self> {
        let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
            return None;
        };
        let tree = Tree::new(sn);
        let owner = tree.cut();
        let perm = symbolic.perm().map(|p| p.arrays().0);
        let full = |col: usize| dofs[perm.map_or(col, |f| f[col])];
        let mut parts = tree.parts(sn, &owner, full);
        let top = parts.pop().expect("three parts");
        let b1 = parts.pop().expect("three parts");
        let b0 = parts.pop().expect("three parts");
        let val_ptr = sn.col_ptr_for_val();
        let mut values = [0; 3];
        for s in 0..tree.ns {
            values[owner[s] as usize] += val_ptr[s + 1] - val_ptr[s];
        }
        Some(Self {
            top,
            bins: [b0, b1],
            values,
        })
    }

    /// `z = A_0^-1 r` with the `f32` factor values `l` (faer's supernodal
    /// layout): `r`, `z` full DOF vectors, `z`'s constrained entries untouched.
    pub fn solve(&mut self, l: &[f32], r: &[f64], z: &mut [f64]) {
        let Self { top, bins, .. } = self;
        let [b0, b1] = bins;
        let forward_bin = |p: &mut Part| {
            let n_own = p.src.len();
            for (v, &d) in p.buf.iter_mut().zip(&p.src) {
                *v = r[d] as f32;
            }
            p.buf[n_own..].fill(0.0);
            with_simd(|| {
                for s in &p.snodes {
                    forward(l, s, &mut p.buf, &mut p.tmp);
                }
            });
        };
        rayon::join(|| forward_bin(b0), || forward_bin(b1));
        let (n0, n1) = (b0.src.len(), b1.src.len());
        for (k, (v, &d)) in top.buf.iter_mut().zip(&top.src).enumerate() {
            *v = (r[d] as f32 + b0.buf[n0 + k]) + b1.buf[n1 + k];
        }
        with_simd(|| {
            for s in &top.snodes {
                forward(l, s, &mut top.buf, &mut top.tmp);
            }
            for s in top.snodes.iter().rev() {
                backward(l, s, &mut top.buf, &mut top.tmp);
            }
        });
        let top_x = &top.buf;
        let backward_bin = |p: &mut Part| {
            let n_own = p.src.len();
            p.buf[n_own..].copy_from_slice(top_x);
            with_simd(|| {
                for s in p.snodes.iter().rev() {
                    backward(l, s, &mut p.buf, &mut p.tmp);
                }
            });
        };
        rayon::join(|| backward_bin(b0), || backward_bin(b1));
        for p in [&*b0, &*b1, &*top] {
            for (v, &d) in p.buf.iter().zip(&p.src) {
                z[d] = f64::from(*v);
            }
        }
    }
}

/// Run `f` compiled for AVX2 (pulp's `V3`) when the CPU has it: the
/// kernels below are inlined into it and vectorize with 8 `f32` lanes.
#[inline(always)]
fn with_simd(f: impl FnOnce()) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        return simd.vectorize(f);
    }
    f()
}

/// Forward elimination of one supernode: `x_s = L_ss^-1 x_s`, then
/// `x_pat -= L_ps x_s` (column by column).
#[inline(always)]
fn forward(l: &[f32], s: &Snode, buf: &mut [f32], tmp: &mut [f32]) {
    let (c, p) = (s.ncols, s.pat.len());
    let m = c + p;
    let tmp = &mut tmp[..p];
    tmp.fill(0.0);
    let xs = &mut buf[s.off..s.off + c];
    for j in 0..c {
        let col = &l[s.val + j * m..s.val + (j + 1) * m];
        let xj = xs[j] / col[j];
        xs[j] = xj;
        for (x, &a) in xs[j + 1..].iter_mut().zip(&col[j + 1..c]) {
            *x -= a * xj;
        }
        for (t, &a) in tmp.iter_mut().zip(&col[c..]) {
            *t += a * xj;
        }
    }
    for (&i, &t) in s.pat.iter().zip(tmp.iter()) {
        buf[i as usize] -= t;
    }
}

/// Back substitution of one supernode: `x_s = L_ss^-T (x_s - L_ps^T x_pat)`.
#[inline(always)]
fn backward(l: &[f32], s: &Snode, buf: &mut [f32], tmp: &mut [f32]) {
    let (c, p) = (s.ncols, s.pat.len());
    let m = c + p;
    let tmp = &mut tmp[..p];
    for (t, &i) in tmp.iter_mut().zip(&s.pat) {
        *t = buf[i as usize];
    }
    let xs = &mut buf[s.off..s.off + c];
    for j in (0..c).rev() {
        let col = &l[s.val + j * m..s.val + (j + 1) * m];
        let v = xs[j] - dot(&col[j + 1..c], &xs[j + 1..]) - dot(&col[c..], tmp);
        xs[j] = v / col[j];
    }
}

/// `a . b` with eight fixed partial sums (lane `k` takes the entries
/// `k mod 8`), added in a fixed order: vectorizes, and gives the same bits
/// with or without SIMD.
#[inline(always)]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (a8, ar) = a.as_chunks::<8>();
    let (b8, br) = b[..a.len()].as_chunks::<8>();
    for (x, y) in a8.iter().zip(b8) {
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    for (k, (x, y)) in ar.iter().zip(br).enumerate() {
        acc[k] += x * y;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]))
}

/// Forward elimination `y = L^-1 P b` with faer's `f64` supernodal factor
/// for right-hand sides with a few non-zeros (a point force spread over the
/// four nodes of a tet), and the Gram matrix `G = Y^T Y = B^T A^-1 B` of
/// several such `b`: the tissue's share of a coupling's Delassus matrix
/// without a full solve per column.
///
/// Only the supernodes on the elimination-tree paths from the non-zeros to
/// the root are touched (Gilbert & Peierls, SIAM J. Sci. Stat. Comput. 9,
/// 1988: the non-zeros of `L^-1 b` are the tree ancestors of those of `b`);
/// with a nested-dissection ordering those paths are a small part of the
/// factor. Half of a full solve (no back substitution) at most, usually far
/// less. Sequential, with fixed summation orders: the same bits for any
/// thread count.
pub struct SparseForward {
    /// Factor column of every full DOF (`usize::MAX` for a constrained one).
    col_of: Vec<usize>,
    /// Supernode of every factor column.
    snode_of: Vec<usize>,
    /// Parent supernode (`usize::MAX` for a root).
    parent: Vec<usize>,
    /// Supernodes in faer's order, columns and pattern in factor numbering.
    snodes: Vec<Snode>,
    /// Supernodes of bin 0, bin 1 and the top of [`Tree::cut`], each
    /// ascending, for the two-way parallel full sweeps.
    parts: [Vec<usize>; 3],
    /// Scratch: the columns being eliminated, and a mark per supernode.
    x: Vec<f64>,
    mark: Vec<bool>,
}

impl SparseForward {
    /// The solver for the supernodal factor of `symbolic` (`None` for a
    /// simplicial one); `dofs[i]` is the full-DOF index of free unknown `i`
    /// and `n_dofs` the full DOF count.
    pub fn new(symbolic: &SymbolicCholesky<usize>, dofs: &[usize], n_dofs: usize) -> Option<Self> {
        let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
            return None;
        };
        let perm = symbolic.perm().map(|p| p.arrays().0);
        let mut col_of = vec![usize::MAX; n_dofs];
        for col in 0..sn.nrows() {
            col_of[dofs[perm.map_or(col, |f| f[col])]] = col;
        }
        let ns = sn.n_supernodes();
        let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
        let val_ptr = sn.col_ptr_for_val();
        let snode_of = snode_of_columns(sn);
        let snodes: Vec<Snode> = (0..ns)
            .map(|s| Snode {
                off: begin[s],
                ncols: end[s] - begin[s],
                val: val_ptr[s],
                pat: sn.supernode(s).pattern().iter().map(|&r| r as u32).collect(),
            })
            .collect();
        let parent = snodes
            .iter()
            .map(|s| s.pat.first().map_or(usize::MAX, |&r| snode_of[r as usize]))
            .collect();
        let mut parts: [Vec<usize>; 3] = Default::default();
        for (s, &o) in Tree::new(sn).cut().iter().enumerate() {
            parts[o as usize].push(s);
        }
        Some(Self {
            col_of,
            snode_of,
            parent,
            snodes,
            parts,
            x: Vec::new(),
            mark: Vec::new(),
        })
    }

    /// Forward-eliminate the columns `rhs` into `x` (column-major
    /// `nf x k`): `Y = L^-1 P B` on the supernodes of the union of their
    /// elimination-tree paths, returned in elimination order; every other
    /// entry of `x` stays zero.
    fn eliminate(&mut self, l: &[f64], rhs: &[Vec<(usize, f64)>]) -> Vec<usize> {
        let k = rhs.len();
        let nf = self.snode_of.len();
        self.mark.resize(self.snodes.len(), false);
        // Column-major `nf x k`; zero between calls.
        self.x.resize(nf * k, 0.0);
        let mut touched = Vec::new();
        for (q, b) in rhs.iter().enumerate() {
            for &(dof, v) in b {
                let col = self.col_of[dof];
                if col == usize::MAX {
                    continue;
                }
                self.x[q * nf + col] += v;
                let mut s = self.snode_of[col];
                while s != usize::MAX && !self.mark[s] {
                    self.mark[s] = true;
                    touched.push(s);
                    s = self.parent[s];
                }
            }
        }
        // Parents come after their children in faer's numbering.
        touched.sort_unstable();
        let (mut xs, mut upd) = (Vec::new(), Vec::new());
        for &s in &touched {
            self.mark[s] = false;
            let sn = &self.snodes[s];
            let (c, p) = (sn.ncols, sn.pat.len());
            // The columns with a non-zero part here, gathered as a dense
            // `c x active` block: X_s = L_ss^-1 X_s, then
            // X_pat -= L_ps X_s (faer's blocked kernels, sequential).
            let active: Vec<usize> = (0..k)
                .filter(|&q| self.x[q * nf + sn.off..q * nf + sn.off + c].iter().any(|&v| v != 0.0))
                .collect();
            if active.is_empty() {
                continue;
            }
            let ka = active.len();
            xs.clear();
            for &q in &active {
                xs.extend_from_slice(&self.x[q * nf + sn.off..q * nf + sn.off + c]);
            }
            let m = c + p;
            let lv = faer::MatRef::from_column_major_slice(&l[sn.val..sn.val + m * c], m, c);
            let mut xm = faer::MatMut::from_column_major_slice_mut(&mut xs, c, ka);
            faer::linalg::triangular_solve::solve_lower_triangular_in_place(
                lv.subrows(0, c),
                xm.as_mut(),
                faer::Par::Seq,
            );
            upd.clear();
            upd.resize(p * ka, 0.0);
            faer::linalg::matmul::matmul(
                faer::MatMut::from_column_major_slice_mut(&mut upd, p, ka),
                faer::Accum::Replace,
                lv.subrows(c, p),
                xm.as_ref(),
                1.0,
                faer::Par::Seq,
            );
            for (i, &q) in active.iter().enumerate() {
                let xq = &mut self.x[q * nf..(q + 1) * nf];
                xq[sn.off..sn.off + c].copy_from_slice(&xs[i * c..(i + 1) * c]);
                for (&r, &u) in sn.pat.iter().zip(&upd[i * p..(i + 1) * p]) {
                    xq[r as usize] -= u;
                }
            }
        }
        touched
    }

    /// `G[a][b] = b_a^T A^-1 b_b` (row-major, `k x k`, symmetric) for the
    /// right-hand sides `rhs[a]`, each given by its non-zeros `(full DOF,
    /// value)` (entries at constrained DOFs ignored), with the factor values
    /// `l` of `P A P^T = L L^T`. The supernodes on the union of the columns'
    /// paths are eliminated in order, each for every column whose part
    /// there is not zero (skipping a zero part is exact), so a supernode's
    /// values are read from memory once for all columns.
    pub fn gram(&mut self, l: &[f64], rhs: &[Vec<(usize, f64)>]) -> Vec<f64> {
        let k = rhs.len();
        let nf = self.snode_of.len();
        let touched = self.eliminate(l, rhs);
        // G = Y^T Y, Y dense over the touched supernodes' columns (in
        // order: one gemm; the upper triangle mirrored so G is exactly
        // symmetric); `x` is left zero for the next call.
        let rows: usize = touched.iter().map(|&s| self.snodes[s].ncols).sum();
        let mut dense = nalgebra::DMatrix::<f64>::zeros(rows, k);
        for (xq, mut col) in self.x.chunks_exact_mut(nf).zip(dense.column_iter_mut()) {
            let mut r0 = 0;
            for &s in &touched {
                let sn = &self.snodes[s];
                let range = sn.off..sn.off + sn.ncols;
                col.rows_mut(r0, sn.ncols).copy_from_slice(&xq[range.clone()]);
                xq[range].fill(0.0);
                r0 += sn.ncols;
            }
        }
        let gram = dense.tr_mul(&dense);
        let mut g = vec![0.0; k * k];
        for a in 0..k {
            for b in a..k {
                g[a * k + b] = gram[(a, b)];
                g[b * k + a] = gram[(a, b)];
            }
        }
        g
    }

    /// `y = L^-1 P b` of each right-hand side in `rhs` (non-zeros `(full
    /// DOF, value)`, entries at constrained DOFs ignored), each kept on the
    /// supernodes of its own elimination-tree path: `b_a^T A^-1 b_b` is then
    /// [`SparseColumn::dot`] of the two, so a caller whose factor outlives a
    /// step can keep the columns and add new ones without solving the old
    /// again. Eliminated together as in [`Self::gram`].
    pub fn columns(&mut self, l: &[f64], rhs: &[Vec<(usize, f64)>]) -> Vec<SparseColumn> {
        let nf = self.snode_of.len();
        let touched = self.eliminate(l, rhs);
        self.x
            .chunks_exact_mut(nf)
            .take(rhs.len())
            .map(|xq| {
                let mut y = SparseColumn::default();
                for &s in &touched {
                    let sn = &self.snodes[s];
                    let part = &mut xq[sn.off..sn.off + sn.ncols];
                    // Zero exactly where the path does not pass (eliminate
                    // skips those parts).
                    if part.iter().any(|&v| v != 0.0) {
                        y.offs.push(sn.off as u32);
                        y.starts.push(y.vals.len() as u32);
                        y.vals.extend_from_slice(part);
                        part.fill(0.0);
                    }
                }
                y
            })
            .collect()
    }

    /// The forward half of a full solve: `u = L^-1 P r` for a dense
    /// full-DOF `r` (constrained entries ignored), in factor column order.
    /// With [`SparseColumn::dot_dense`] a caller reads `b^T A^-1 r` off `u`
    /// for its sparse `b`, and with [`Self::backward`] finishes the solve,
    /// after subtracting columns if it likes: `A^-1 (r - B f)` in one
    /// forward and one backward sweep, not two full solves.
    ///
    /// Two-way parallel as [`SplitSolve`] (the same cut of the tree, see
    /// the module docs): each bin eliminates its subtrees into its own copy
    /// of `u`, its updates of the top's rows summed from zero there; the
    /// top's right-hand side is then `r_top + acc_0 + acc_1` (this order)
    /// and the top is eliminated. The same bits on one or two threads.
    pub fn forward(&self, l: &[f64], r: &[f64]) -> Vec<f64> {
        let mut u = vec![0.0; self.snode_of.len()];
        for (d, &col) in self.col_of.iter().enumerate() {
            if col != usize::MAX {
                u[col] = r[d];
            }
        }
        let bin = |b: usize| {
            let mut ub = vec![0.0; u.len()];
            self.copy_part(b, &u, &mut ub);
            let mut tmp = Vec::new();
            for &s in &self.parts[b] {
                forward_snode(l, &self.snodes[s], &mut ub, &mut tmp);
            }
            ub
        };
        let (u0, u1) = rayon::join(|| bin(0), || bin(1));
        self.take_bins(&mut u, [&u0, &u1]);
        for &s in &self.parts[2] {
            let sn = &self.snodes[s];
            for col in sn.off..sn.off + sn.ncols {
                u[col] = (u[col] + u0[col]) + u1[col];
            }
        }
        let mut tmp = Vec::new();
        for &s in &self.parts[2] {
            forward_snode(l, &self.snodes[s], &mut u, &mut tmp);
        }
        u
    }

    /// Copy bin `b`'s own columns from `from` to `to`.
    fn copy_part(&self, b: usize, from: &[f64], to: &mut [f64]) {
        for &s in &self.parts[b] {
            let sn = &self.snodes[s];
            to[sn.off..sn.off + sn.ncols].copy_from_slice(&from[sn.off..sn.off + sn.ncols]);
        }
    }

    /// Each bin's own columns from its copy into `u`.
    fn take_bins(&self, u: &mut [f64], bins: [&[f64]; 2]) {
        for (b, ub) in bins.into_iter().enumerate() {
            self.copy_part(b, ub, u);
        }
    }

    /// The backward half: `z = P^T L^-T u` on the free DOFs of the full
    /// vector `z` (its constrained entries untouched); `u` (factor column
    /// order, from [`Self::forward`]) is overwritten. The top first, then
    /// the two bins side by side, each reading the top's values.
    pub fn backward(&self, l: &[f64], u: &mut [f64], z: &mut [f64]) {
        let mut tmp = Vec::new();
        for &s in self.parts[2].iter().rev() {
            backward_snode(l, &self.snodes[s], u, &mut tmp);
        }
        let shared: &[f64] = u;
        let bin = |b: usize| {
            let mut ub = shared.to_vec();
            let mut tmp = Vec::new();
            for &s in self.parts[b].iter().rev() {
                backward_snode(l, &self.snodes[s], &mut ub, &mut tmp);
            }
            ub
        };
        let (u0, u1) = rayon::join(|| bin(0), || bin(1));
        self.take_bins(u, [&u0, &u1]);
        for (d, &col) in self.col_of.iter().enumerate() {
            if col != usize::MAX {
                z[d] = u[col];
            }
        }
    }
}

/// Forward elimination of supernode `sn` in `u` (factor column order):
/// `u_s = L_ss^-1 u_s`, `u_pat -= L_ps u_s` (faer's kernels, sequential).
fn forward_snode(l: &[f64], sn: &Snode, u: &mut [f64], tmp: &mut Vec<f64>) {
    let (c, p) = (sn.ncols, sn.pat.len());
    let lv = faer::MatRef::from_column_major_slice(&l[sn.val..sn.val + (c + p) * c], c + p, c);
    let xs = faer::MatMut::from_column_major_slice_mut(&mut u[sn.off..sn.off + c], c, 1);
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(lv.subrows(0, c), xs, faer::Par::Seq);
    tmp.clear();
    tmp.resize(p, 0.0);
    faer::linalg::matmul::matmul(
        faer::MatMut::from_column_major_slice_mut(tmp, p, 1),
        faer::Accum::Replace,
        lv.subrows(c, p),
        faer::MatRef::from_column_major_slice(&u[sn.off..sn.off + c], c, 1),
        1.0,
        faer::Par::Seq,
    );
    for (&r, &t) in sn.pat.iter().zip(tmp.iter()) {
        u[r as usize] -= t;
    }
}

/// Back substitution of supernode `sn` in `u`: `u_s = L_ss^-T (u_s - L_ps^T
/// u_pat)`.
fn backward_snode(l: &[f64], sn: &Snode, u: &mut [f64], tmp: &mut Vec<f64>) {
    let (c, p) = (sn.ncols, sn.pat.len());
    let lv = faer::MatRef::from_column_major_slice(&l[sn.val..sn.val + (c + p) * c], c + p, c);
    tmp.clear();
    tmp.extend(sn.pat.iter().map(|&r| u[r as usize]));
    let mut xs = faer::MatMut::from_column_major_slice_mut(&mut u[sn.off..sn.off + c], c, 1);
    faer::linalg::matmul::matmul(
        xs.as_mut(),
        faer::Accum::Add,
        lv.subrows(c, p).transpose(),
        faer::MatRef::from_column_major_slice(tmp, p, 1),
        -1.0,
        faer::Par::Seq,
    );
    faer::linalg::triangular_solve::solve_upper_triangular_in_place(lv.subrows(0, c).transpose(), xs, faer::Par::Seq);
}

/// One forward-eliminated column `y = L^-1 P b` of
/// [`SparseForward::columns`]: its parts on the supernodes of its path, in
/// elimination order.
#[derive(Debug, Clone, Default)]
pub struct SparseColumn {
    /// Factor column of each part's first entry (one part per supernode
    /// of the path, ascending).
    offs: Vec<u32>,
    starts: Vec<u32>,
    vals: Vec<f64>,
}

impl SparseColumn {
    /// `y_a . y_b = b_a^T A^-1 b_b`, over the supernodes both paths share
    /// (in elimination order, each part summed in order: the same bits
    /// whichever other columns were eliminated with either).
    pub fn dot(&self, other: &Self) -> f64 {
        let (mut i, mut j, mut sum) = (0, 0, 0.0);
        while i < self.offs.len() && j < other.offs.len() {
            match self.offs[i].cmp(&other.offs[j]) {
                std::cmp::Ordering::Less => i += 1,
                std::cmp::Ordering::Greater => j += 1,
                std::cmp::Ordering::Equal => {
                    let a = &self.vals[self.starts[i] as usize..self.end(i)];
                    let b = &other.vals[other.starts[j] as usize..other.end(j)];
                    sum += a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
                    i += 1;
                    j += 1;
                }
            }
        }
        sum
    }

    /// `y . u` for a dense `u` in factor column order
    /// ([`SparseForward::forward`]): `b^T A^-1 r`.
    pub fn dot_dense(&self, u: &[f64]) -> f64 {
        let mut sum = 0.0;
        for (i, &off) in self.offs.iter().enumerate() {
            let off = off as usize;
            let a = &self.vals[self.starts[i] as usize..self.end(i)];
            sum += a.iter().zip(&u[off..]).map(|(x, y)| x * y).sum::<f64>();
        }
        sum
    }

    /// `u -= alpha y` for a dense `u` in factor column order.
    pub fn sub_from(&self, alpha: f64, u: &mut [f64]) {
        for (i, &off) in self.offs.iter().enumerate() {
            let off = off as usize;
            let a = &self.vals[self.starts[i] as usize..self.end(i)];
            u[off..off + a.len()]
                .iter_mut()
                .zip(a)
                .for_each(|(x, y)| *x -= alpha * y);
        }
    }

    fn end(&self, i: usize) -> usize {
        self.starts.get(i + 1).map_or(self.vals.len(), |&e| e as usize)
    }
}
