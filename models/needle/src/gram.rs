//! The tissue's share of the Delassus matrix, kept across steps while the
//! tissue's factor stays.
//!
//! The tissue share of `W` between coupling points `i` and `j` is
//! `J_i A^-1 J_j^T` (the Schur complement of the coupled system, seed
//! Eq. 7): in world axes it depends only on the tissue factor `A = L L^T`
//! and on the two points' tet nodes and barycentric weights, not on the
//! needle frames (those rotate the 3x3 block afterwards). Shaft points are
//! fixed tissue material points, so while the factor stays (a lazy
//! Jacobian keeps it for many steps, `lazy_threshold`) only a point that
//! is new this step, in practice the tip's new channel end, needs forward
//! solves `y = L^-1 P J^T` and dot products with the kept columns; the
//! others' blocks are reused. A new factor (or a rebuilt tissue, which
//! factors anew) drops everything.

use nalgebra::{DMatrix, Matrix3};
use surgbench_fem::FemModel;
use surgbench_fem::supernodal::SparseColumn;

/// A tissue point by its tet's nodes and the exact bits of its weights.
type Key = ([usize; 4], [u64; 4]);

/// Forward-solved columns of the points of recent steps and their blocks.
#[derive(Default)]
pub(crate) struct TissueGram {
    /// The factor the columns belong to.
    factor: Option<u64>,
    keys: Vec<Key>,
    /// Per point, `L^-1 P J^T` for a unit force along world x, y, z.
    cols: Vec<[SparseColumn; 3]>,
    /// `blocks[a][b]` (b <= a): the world-axes block `J_a A^-1 J_b^T`.
    blocks: Vec<Vec<Matrix3<f64>>>,
    /// Slot of each point of the last [`Self::world`] call.
    current: Vec<usize>,
    /// Points forward-solved and points whose columns were reused, over
    /// the run.
    pub solved: usize,
    pub reused: usize,
}

impl TissueGram {
    /// The world-axes tissue share (`3m x 3m`, symmetric) for the points
    /// `stencils` (tet nodes, barycentric weights) with `fem`'s current
    /// factor; `None` where that factor is not supernodal (the caller
    /// solves in full). Afterwards only these points are kept.
    pub fn world(&mut self, fem: &mut FemModel, stencils: &[([usize; 4], [f64; 4])]) -> Option<DMatrix<f64>> {
        let id = fem.factor_id()?;
        if self.factor != Some(id) {
            *self = Self {
                factor: Some(id),
                solved: self.solved,
                reused: self.reused,
                ..Self::default()
            };
        }
        let keys: Vec<Key> = stencils.iter().map(|(n, w)| (*n, w.map(f64::to_bits))).collect();
        let mut slots: Vec<Option<usize>> = keys.iter().map(|k| self.keys.iter().position(|q| q == k)).collect();
        // A point twice in one step (two points in one tet at the same
        // weights) is solved once.
        let mut missing: Vec<usize> = Vec::new();
        for (i, k) in keys.iter().enumerate() {
            if slots[i].is_none() && !missing.iter().any(|&j| keys[j] == *k) {
                missing.push(i);
            }
        }
        if !missing.is_empty() {
            let rhs: Vec<Vec<(usize, f64)>> = missing
                .iter()
                .flat_map(|&i| {
                    let (nodes, w) = stencils[i];
                    (0..3).map(move |c| (0..4).map(|a| (3 * nodes[a] + c, w[a])).collect())
                })
                .collect();
            let (got, cols) = fem.forward_columns(&rhs)?;
            debug_assert_eq!(Some(got), self.factor, "the factor changed between two calls");
            let mut cols = cols.into_iter();
            for &i in &missing {
                let y = [(); 3].map(|_| cols.next().expect("three columns per point"));
                let row = (0..=self.cols.len())
                    .map(|b| {
                        let other = if b == self.cols.len() { &y } else { &self.cols[b] };
                        Matrix3::from_fn(|r, c| y[r].dot(&other[c]))
                    })
                    .collect();
                self.blocks.push(row);
                self.cols.push(y);
                self.keys.push(keys[i]);
            }
            self.solved += missing.len();
        }
        self.reused += stencils.len() - missing.len();
        for (slot, k) in slots.iter_mut().zip(&keys) {
            *slot = slot.or_else(|| self.keys.iter().position(|q| q == k));
        }
        let slots: Vec<usize> = slots.into_iter().map(|s| s.expect("every point has a slot")).collect();
        let m = stencils.len();
        let mut w = DMatrix::zeros(3 * m, 3 * m);
        for (i, &a) in slots.iter().enumerate() {
            for (j, &b) in slots.iter().enumerate() {
                let blk = if b <= a {
                    self.blocks[a][b]
                } else {
                    self.blocks[b][a].transpose()
                };
                w.fixed_view_mut::<3, 3>(3 * i, 3 * j).copy_from(&blk);
            }
        }
        self.keep(&slots);
        Some(w)
    }

    /// The columns `L^-1 P J_i^T` (world x, y, z) of point `i` of the last
    /// [`Self::world`] call, valid with the factor that call used.
    pub fn columns(&self, i: usize) -> &[SparseColumn; 3] {
        &self.cols[self.current[i]]
    }

    /// Drop every slot not in `used` (the points of this call, which
    /// [`Self::columns`] then finds), keeping the others' order.
    fn keep(&mut self, used: &[usize]) {
        let n = self.keys.len();
        let kept: Vec<usize> = (0..n).filter(|s| used.contains(s)).collect();
        self.current = used
            .iter()
            .map(|s| kept.binary_search(s).expect("a used slot is kept"))
            .collect();
        if kept.len() == n {
            return;
        }
        self.blocks = kept
            .iter()
            .enumerate()
            .map(|(a2, &a)| kept[..=a2].iter().map(|&b| self.blocks[a][b]).collect())
            .collect();
        select(&mut self.keys, &kept);
        select(&mut self.cols, &kept);
    }
}

/// Keep the entries `kept` (ascending) of `v`, in order.
fn select<T>(v: &mut Vec<T>, kept: &[usize]) {
    let mut old: Vec<Option<T>> = std::mem::take(v).into_iter().map(Some).collect();
    *v = kept.iter().map(|&s| old[s].take().expect("kept once")).collect();
}
