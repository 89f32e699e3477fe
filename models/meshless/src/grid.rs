//! Uniform-grid neighbour search (no dependency): points are binned into
//! cubic cells of edge `radius`, a query visits the 27 cells around it.
//! Results are sorted by index, so they are deterministic.

use surgbench_core::Vec3;

/// Points binned in a dense grid of cubic cells (compressed row storage).
#[derive(Debug, Clone)]
pub struct UniformGrid {
    origin: Vec3,
    cell: f64,
    dims: [usize; 3],
    start: Vec<usize>,
    items: Vec<usize>,
    points: Vec<Vec3>,
}

impl UniformGrid {
    /// Largest number of cells the grid may allocate.
    pub const MAX_CELLS: usize = 50_000_000;

    /// Bin `points` (m) in cells of edge `radius` (m). `None` when the
    /// radius is not positive/finite or the grid would exceed
    /// [`Self::MAX_CELLS`] cells.
    pub fn new(points: &[Vec3], radius: f64) -> Option<Self> {
        if !(radius > 0.0 && radius.is_finite()) || points.is_empty() {
            return None;
        }
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for p in points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let mut dims = [1usize; 3];
        let mut total = 1usize;
        for a in 0..3 {
            let n = ((hi[a] - lo[a]) / radius).floor();
            if !(n.is_finite() && n < 1e8) {
                return None;
            }
            dims[a] = n as usize + 1;
            total = total.checked_mul(dims[a])?;
        }
        if total > Self::MAX_CELLS {
            return None;
        }
        let mut g = Self {
            origin: lo,
            cell: radius,
            dims,
            start: vec![0; total + 1],
            items: vec![0; points.len()],
            points: points.to_vec(),
        };
        let keys: Vec<usize> = points.iter().map(|p| g.key(g.cell_of(p))).collect();
        for &k in &keys {
            g.start[k + 1] += 1;
        }
        for c in 0..total {
            g.start[c + 1] += g.start[c];
        }
        let mut fill = g.start.clone();
        for (i, &k) in keys.iter().enumerate() {
            g.items[fill[k]] = i;
            fill[k] += 1;
        }
        Some(g)
    }

    fn cell_of(&self, p: &Vec3) -> [usize; 3] {
        let mut c = [0usize; 3];
        for a in 0..3 {
            let x = ((p[a] - self.origin[a]) / self.cell).floor();
            c[a] = if x <= 0.0 {
                0
            } else {
                (x as usize).min(self.dims[a] - 1)
            };
        }
        c
    }

    fn key(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Indices of the binned points strictly closer than `radius` (at most
    /// the grid's cell edge) to `p`, ascending; `out` is cleared first.
    pub fn within(&self, p: &Vec3, radius: f64, out: &mut Vec<usize>) {
        out.clear();
        let r = radius.min(self.cell);
        let c = self.cell_of(p);
        let r2 = r * r;
        for k in c[2].saturating_sub(1)..=(c[2] + 1).min(self.dims[2] - 1) {
            for j in c[1].saturating_sub(1)..=(c[1] + 1).min(self.dims[1] - 1) {
                for i in c[0].saturating_sub(1)..=(c[0] + 1).min(self.dims[0] - 1) {
                    let key = self.key([i, j, k]);
                    for &q in &self.items[self.start[key]..self.start[key + 1]] {
                        if (self.points[q] - p).norm_squared() < r2 {
                            out.push(q);
                        }
                    }
                }
            }
        }
        out.sort_unstable();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_matches_brute_force() {
        // Seeded points in a 1 x 0.5 x 0.2 box.
        let mut rng = surgbench_core::rng::SplitMix64(0x9E37_79B9);
        let pts: Vec<Vec3> = (0..500)
            .map(|_| rng.in_box(Vec3::zeros(), Vec3::new(1.0, 0.5, 0.2)))
            .collect();
        let rad = 0.13;
        let g = UniformGrid::new(&pts, rad).unwrap();
        let mut out = Vec::new();
        for p in &pts {
            g.within(p, rad, &mut out);
            let brute: Vec<usize> = (0..pts.len())
                .filter(|&q| (pts[q] - p).norm_squared() < rad * rad)
                .collect();
            assert_eq!(out, brute, "query at {p:?}");
        }
    }
}
