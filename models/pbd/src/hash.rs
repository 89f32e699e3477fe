//! Hash-table spatial partition for local activation of a tet mesh (the
//! hybrid-vessel PBD seed paper's acceleration).
//!
//! The mesh's bounding box `[g_min, g_max]` is cut into boxes of edge `d`:
//! `N_x = ceil((g_max_x - g_min_x) / d)` (same for y, z), box `(i, j, k)` has
//! linear index `T(i, j, k) = i + j N_x + k N_x N_y` and lives in the bucket
//! `h = ((i u) xor (j v) xor (k w)) mod N` of a table of `N` buckets, with the
//! three large primes `u, v, w` of Teschner et al. 2003 ("Optimized Spatial
//! Hashing for Collision Detection of Deformable Objects"). Each box is
//! expanded by `span` on every side and holds every tet whose rest centroid
//! lies in the expanded box, so a tet may belong to several boxes. Buckets
//! chain `(T, tets)` entries, so hash collisions never mix boxes.

use surgbench_core::Vec3;

/// The three large primes of the box hash (Teschner et al. 2003, sec. 4.1).
pub const HASH_PRIMES: [u64; 3] = [73_856_093, 19_349_663, 83_492_791];

/// Boxes of a mesh's bounding box, with the tets of each expanded box stored
/// in a hash table.
#[derive(Debug, Clone)]
pub struct BoxHash {
    gmin: Vec3,
    d: f64,
    span: f64,
    dims: [usize; 3],
    buckets: Vec<Vec<(usize, Vec<u32>)>>,
}

impl BoxHash {
    /// Partition the bounding box of `nodes` into boxes of edge `d` (m),
    /// each expanded by `span` (m), and hash the tets of `tets` into them.
    /// `d` must be > 0 and `span` >= 0 (the caller validates).
    pub fn new(nodes: &[Vec3], tets: &[[usize; 4]], d: f64, span: f64) -> Self {
        let mut gmin = Vec3::repeat(f64::INFINITY);
        let mut gmax = Vec3::repeat(f64::NEG_INFINITY);
        for p in nodes {
            gmin = gmin.inf(p);
            gmax = gmax.sup(p);
        }
        if nodes.is_empty() {
            gmin = Vec3::zeros();
            gmax = Vec3::zeros();
        }
        let dims = [0, 1, 2].map(|a| (((gmax[a] - gmin[a]) / d).ceil() as usize).max(1));
        let nboxes = dims[0] * dims[1] * dims[2];
        let mut h = Self {
            gmin,
            d,
            span,
            dims,
            buckets: vec![Vec::new(); nboxes.max(1)],
        };
        for (t, tet) in tets.iter().enumerate() {
            let c = tet.iter().map(|&i| nodes[i]).sum::<Vec3>() / 4.0;
            let lo = h.box_of(&(c - Vec3::repeat(span)));
            let hi = h.box_of(&(c + Vec3::repeat(span)));
            for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        let (bmin, bmax) = h.expanded_bounds([i, j, k]);
                        if (0..3).all(|a| c[a] >= bmin[a] && c[a] <= bmax[a]) {
                            h.insert([i, j, k], t as u32);
                        }
                    }
                }
            }
        }
        h
    }

    fn insert(&mut self, b: [usize; 3], t: u32) {
        let key = self.linear_index(b);
        let hb = self.hash(b);
        let bucket = &mut self.buckets[hb];
        match bucket.iter_mut().find(|(k, _)| *k == key) {
            Some((_, v)) => v.push(t),
            None => bucket.push((key, vec![t])),
        }
    }

    /// Box counts `(N_x, N_y, N_z)`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Box edge `d` (m).
    pub fn box_size(&self) -> f64 {
        self.d
    }

    /// Box holding `p` (clamped to the grid).
    pub fn box_of(&self, p: &Vec3) -> [usize; 3] {
        [0, 1, 2].map(|a| {
            let f = ((p[a] - self.gmin[a]) / self.d).floor();
            if f.is_nan() || f < 0.0 {
                0
            } else {
                (f as usize).min(self.dims[a] - 1)
            }
        })
    }

    /// `T(i, j, k) = i + j N_x + k N_x N_y`.
    pub fn linear_index(&self, b: [usize; 3]) -> usize {
        b[0] + b[1] * self.dims[0] + b[2] * self.dims[0] * self.dims[1]
    }

    /// The box `(i, j, k)` of linear index `key` ([`Self::linear_index`]'s
    /// inverse).
    pub fn box_at(&self, key: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [key % nx, (key / nx) % ny, key / (nx * ny)]
    }

    /// Bucket `((i u) xor (j v) xor (k w)) mod N`.
    pub fn hash(&self, b: [usize; 3]) -> usize {
        let [u, v, w] = HASH_PRIMES;
        let h = (b[0] as u64).wrapping_mul(u) ^ (b[1] as u64).wrapping_mul(v) ^ (b[2] as u64).wrapping_mul(w);
        (h % self.buckets.len() as u64) as usize
    }

    /// Tets of the expanded box `b` (indices into the mesh's tets).
    pub fn tets(&self, b: [usize; 3]) -> &[u32] {
        let key = self.linear_index(b);
        self.buckets[self.hash(b)]
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v.as_slice())
            .unwrap_or(&[])
    }

    /// Bounds of box `b` without the span (m).
    pub fn core_bounds(&self, b: [usize; 3]) -> (Vec3, Vec3) {
        let lo = self.gmin + Vec3::new(b[0] as f64, b[1] as f64, b[2] as f64) * self.d;
        (lo, lo + Vec3::repeat(self.d))
    }

    /// Bounds of box `b` expanded by the span (m).
    pub fn expanded_bounds(&self, b: [usize; 3]) -> (Vec3, Vec3) {
        let (lo, hi) = self.core_bounds(b);
        (lo - Vec3::repeat(self.span), hi + Vec3::repeat(self.span))
    }
}
