//! A voxel signed distance read by tricubic (Catmull-Rom) interpolation
//! ([`CubicVoxelSdf`]): continuous gradient across cell faces, for solvers
//! whose Newton iterations stall on the kinks of the trilinear field.

use super::*;
use crate::Vec3;

/// The samples of a [`VoxelSdf`] read by tensor-product Catmull-Rom
/// interpolation (cubic convolution with `a = -1/2`, Keys 1981, IEEE Trans.
/// ASSP 29(6):1153): it passes through the samples, reproduces quadratics,
/// errs by O(h^3) on a smooth field, and its gradient is continuous across
/// cell faces (C1), where the trilinear interpolant's jumps. The
/// gradient and Hessian are the interpolant's own derivatives (analytic).
///
/// Why it exists: a Newton contact solve (DER's) on the trilinear field
/// sees the wall normal jump at every cell face and cycles; measured on
/// `vessel-mesh-insertion` (2 mm lumen, 0.5 mm voxels): 470 Newton
/// iterations per step on the trilinear field, against 4.5 on the analytic
/// tube. Cost: 64 samples per query instead of 8.
///
/// Near the grid's faces the stencil's outer samples are clamped to the
/// grid (one-sided, first order there); outside the box the field is
/// continued by the distance to the box, as [`VoxelSdf`] does.
#[derive(Debug, Clone, PartialEq)]
pub struct CubicVoxelSdf {
    /// The samples (m).
    pub grid: VoxelSdf,
}

/// Catmull-Rom weights of the samples at offsets -1, 0, 1, 2 for local
/// coordinate `t` in [0, 1], with their first and second derivatives in t.
fn weights(t: f64) -> [[f64; 4]; 3] {
    let (t2, t3) = (t * t, t * t * t);
    [
        [
            0.5 * (-t3 + 2.0 * t2 - t),
            0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2),
        ],
        [
            0.5 * (-3.0 * t2 + 4.0 * t - 1.0),
            0.5 * (9.0 * t2 - 10.0 * t),
            0.5 * (-9.0 * t2 + 8.0 * t + 1.0),
            0.5 * (3.0 * t2 - 2.0 * t),
        ],
        [-3.0 * t + 2.0, 9.0 * t - 5.0, -9.0 * t + 4.0, 3.0 * t - 1.0],
    ]
}

impl CubicVoxelSdf {
    /// Read `grid` by tricubic interpolation.
    pub fn new(grid: VoxelSdf) -> Self {
        Self { grid }
    }

    /// Error against `exact` at `count` seeded points of the grid's box
    /// where `|exact| <= band` (m) and `keep(p)` holds (as
    /// [`VoxelSdf::error_against`]).
    pub fn error_against(
        &self,
        exact: &dyn Sdf,
        count: usize,
        seed: u64,
        band: f64,
        keep: impl Fn(&Vec3) -> bool,
    ) -> VoxelError {
        super::voxel::error_in_box(
            self,
            self.grid.origin,
            self.grid.max_corner(),
            exact,
            count,
            seed,
            band,
            keep,
        )
    }

    /// Value, gradient (1) and, if `with_hessian`, Hessian (1/m; zero
    /// otherwise) of the interpolant at `p` inside the box. Distance
    /// queries, the hot path, skip the six Hessian sums.
    fn interp(&self, p: &Vec3, with_hessian: bool) -> (f64, Vec3, Mat3) {
        let g = &self.grid;
        let h = g.spacing;
        // The cell and local coordinates the trilinear reading uses.
        let (base, t) = g.cell(p);
        let w = t.map(weights);
        // Stencil sample `o` (0..4 = offsets -1..2) along axis `a`, clamped
        // into the grid.
        let idx = |a: usize, o: usize| (base[a] + o).saturating_sub(1).min(g.dims[a] - 1);
        let (mut v, mut grad, mut hess) = (0.0, Vec3::zeros(), Mat3::zeros());
        let (wx, wy, wz) = (w[0], w[1], w[2]);
        for c in 0..4 {
            let kz = idx(2, c);
            for b in 0..4 {
                let jy = idx(1, b);
                for a in 0..4 {
                    let s = g.values[idx(0, a) + g.dims[0] * (jy + g.dims[1] * kz)];
                    v += s * wx[0][a] * wy[0][b] * wz[0][c];
                    grad.x += s * wx[1][a] * wy[0][b] * wz[0][c];
                    grad.y += s * wx[0][a] * wy[1][b] * wz[0][c];
                    grad.z += s * wx[0][a] * wy[0][b] * wz[1][c];
                    if with_hessian {
                        hess[(0, 0)] += s * wx[2][a] * wy[0][b] * wz[0][c];
                        hess[(1, 1)] += s * wx[0][a] * wy[2][b] * wz[0][c];
                        hess[(2, 2)] += s * wx[0][a] * wy[0][b] * wz[2][c];
                        hess[(0, 1)] += s * wx[1][a] * wy[1][b] * wz[0][c];
                        hess[(0, 2)] += s * wx[1][a] * wy[0][b] * wz[1][c];
                        hess[(1, 2)] += s * wx[0][a] * wy[1][b] * wz[1][c];
                    }
                }
            }
        }
        hess[(1, 0)] = hess[(0, 1)];
        hess[(2, 0)] = hess[(0, 2)];
        hess[(2, 1)] = hess[(1, 2)];
        (v, grad / h, hess / (h * h))
    }
}

impl Sdf for CubicVoxelSdf {
    fn distance(&self, p: &Vec3) -> f64 {
        self.distance_gradient(p).0
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let q = self.grid.clamp_to_box(p);
        let d = p - q;
        let n = d.norm();
        let (v, g, _) = self.interp(&q, false);
        if n > 0.0 { (v + n, d / n) } else { (v, g) }
    }
    /// The interpolant's own Hessian inside the box (bounded, continuous
    /// inside a cell); zero outside it (met only far from any lumen).
    fn hessian(&self, p: &Vec3) -> Mat3 {
        if self.grid.clamp_to_box(p) != *p {
            return Mat3::zeros();
        }
        self.interp(p, true).2
    }
}
