//! A lumen whose wall has moved: the rest lumen's signed distance minus the
//! wall's normal displacement, interpolated smoothly between the wall's
//! sample points. The lumen a rod sees inside a deforming tissue (coupled
//! runs: `crate::coupling`).
//!
//! With `phi_0` the rest lumen (exact SDF, gradient `n` pointing into the
//! wall) and `d_i = (x_i - X_i) . n(X_i)` the outward normal displacement of
//! wall node `i` (rest `X_i`, now `x_i`), the moved lumen is
//!
//! ```text
//! phi(p) = phi_0(p) - delta(f(p)),   f(p) = p - phi_0(p) n(p)   (the foot point on the rest wall)
//! delta(f) = sum_i W_i(f) d_i / (sum_i W_i(f) + eps)
//! ```
//!
//! with Wendland's C2 kernel `W(q) = (1 - q)^4 (4 q + 1)`, `q = |f - X_i| / h`
//! (Wendland 1995, Adv. Comput. Math. 4:389): Shepard interpolation of the
//! wall's normal displacement over the rest wall, smooth (C2 where `phi_0`
//! is) so a Newton solver sees continuous contact normals. `eps`
//! (`SHEPARD_FLOOR`) takes `delta` smoothly to zero past the sampled wall
//! (a tube's end caps) instead of jumping to the last node's value.
//!
//! Assumptions, stated where they bind: the wall moves little against its
//! curvature radius and the kernel radius (`|d| << h`), so the new wall is
//! first order in the displacement (`phi` at a moved node `x_i` is
//! `O(|u|^2 / R + |d_i - delta_i|)`; [`DisplacedLumen::fit_error`] measures
//! it); tangential wall motion is not seen (a frictionless wall does not
//! feel it). The Hessian drops the second derivative of the foot point (a
//! Gauss-Newton term of order `|grad delta|`): it steers Newton, the
//! distance and gradient are exact for the formula above.

use super::{GeometryError, Sdf};
use crate::{Mat3, Vec3};
use std::sync::Arc;

/// Shepard's denominator floor (dimensionless, against `W(0) = 1`): biases
/// `delta` by at most this fraction where a wall point has neighbours
/// (their weights sum to ~1 or more) and takes it to zero off the wall.
pub const SHEPARD_FLOOR: f64 = 1e-3;

/// The rest wall's sample points: positions, normals and a search grid; the
/// fixed part of a [`DisplacedLumen`], shared by every step's lumen.
#[derive(Debug)]
pub struct WallSamples {
    rest: Arc<dyn Sdf>,
    points: Vec<Vec3>,
    normals: Vec<Vec3>,
    h: f64,
    grid: CellGrid,
}

/// The samples binned in cubic cells of edge `h` over their bounding box,
/// stored compressed (cell `c`'s samples are `items[start[c]..start[c + 1]]`,
/// in sample order): a lookup is an index computation, where a hash map of
/// cells hashed each of a query's 27 cells (47 % of a coupled step at
/// 60,672 wall tets, measured with perf).
#[derive(Debug)]
struct CellGrid {
    lo: [i64; 3],
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl CellGrid {
    fn new(points: &[Vec3], h: f64) -> Self {
        let cells: Vec<[i64; 3]> = points.iter().map(|p| cell(p, h)).collect();
        let mut lo = [i64::MAX; 3];
        let mut hi = [i64::MIN; 3];
        for c in &cells {
            for k in 0..3 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        if cells.is_empty() {
            (lo, hi) = ([0; 3], [-1; 3]);
        }
        let dims = [0, 1, 2].map(|k| (hi[k] - lo[k] + 1).max(0) as usize);
        let mut g = Self {
            lo,
            dims,
            start: vec![0; dims[0] * dims[1] * dims[2] + 1],
            items: vec![0; points.len()],
        };
        let index: Vec<usize> = cells.iter().map(|c| g.index(c).expect("inside its own box")).collect();
        for &k in &index {
            g.start[k + 1] += 1;
        }
        for k in 0..g.start.len() - 1 {
            g.start[k + 1] += g.start[k];
        }
        let mut next = g.start.clone();
        for (i, &k) in index.iter().enumerate() {
            g.items[next[k] as usize] = i as u32;
            next[k] += 1;
        }
        g
    }

    /// Linear index of cell `c`, `None` outside the box.
    fn index(&self, c: &[i64; 3]) -> Option<usize> {
        let mut at = [0usize; 3];
        for k in 0..3 {
            let d = c[k] - self.lo[k];
            if d < 0 || d >= self.dims[k] as i64 {
                return None;
            }
            at[k] = d as usize;
        }
        Some(at[0] + self.dims[0] * (at[1] + self.dims[1] * at[2]))
    }

    /// The samples of cell `c` (empty outside the box).
    fn get(&self, c: &[i64; 3]) -> &[u32] {
        match self.index(c) {
            Some(k) => &self.items[self.start[k] as usize..self.start[k + 1] as usize],
            None => &[],
        }
    }
}

/// A kernel weight and its first two derivatives in `f` (unscaled).
struct Weight {
    w: f64,
    grad: Vec3,
    hess: Mat3,
}

impl WallSamples {
    /// Sample the wall of `rest` at `points` (m, on the rest wall) with
    /// kernel radius `h` (m): it must exceed the longest wall edge so that
    /// every wall point has a sample within reach.
    pub fn new(rest: Arc<dyn Sdf>, points: Vec<Vec3>, h: f64) -> Result<Self, GeometryError> {
        if !(h > 0.0 && h.is_finite()) {
            return Err(GeometryError(format!("kernel radius must be > 0 m, got {h}")));
        }
        let mut normals = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            let g = rest.gradient(p);
            let n = g.norm();
            if !(n > 0.0 && n.is_finite()) {
                return Err(GeometryError(format!("no wall normal at sample {i} ({p:?})")));
            }
            normals.push(g / n);
        }
        let grid = CellGrid::new(&points, h);
        Ok(Self {
            rest,
            points,
            normals,
            h,
            grid,
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Kernel radius (m).
    pub fn radius(&self) -> f64 {
        self.h
    }

    /// The rest lumen.
    pub fn rest(&self) -> &Arc<dyn Sdf> {
        &self.rest
    }

    /// Outward normal displacement `(x_i - X_i) . n_i` (m) of every sample,
    /// from the samples' current positions `current` (same order).
    pub fn normal_displacements(&self, current: &[Vec3]) -> Vec<f64> {
        self.points
            .iter()
            .zip(&self.normals)
            .zip(current)
            .map(|((x0, n), x)| (x - x0).dot(n))
            .collect()
    }

    /// The foot point of `p` on the rest wall, `f = p - phi_0 n`, with
    /// `phi_0`, `n` and the Jacobian `df/dp = I - n n^T - phi_0 H_0`.
    fn foot(&self, p: &Vec3) -> (Vec3, f64, Vec3, Mat3) {
        let (phi, g) = self.rest.distance_gradient(p);
        let f = p - g * phi;
        let j = Mat3::identity() - g * g.transpose() - self.rest.hessian(p) * phi;
        (f, phi, g, j)
    }

    /// Every sample within the kernel radius of `f` with its weight and
    /// derivatives, in a fixed order (cells, then insertion).
    fn weights(&self, f: &Vec3, mut visit: impl FnMut(usize, &Weight)) {
        let c = cell(f, self.h);
        let h2 = self.h * self.h;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    for &i in self.grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        let r = f - self.points[i as usize];
                        let q = r.norm() / self.h;
                        if q >= 1.0 {
                            continue;
                        }
                        // W = (1-q)^4 (4q+1), W'/q = -20 (1-q)^3,
                        // W'' = 20 (1-q)^2 (4q-1); with u = r / |r|:
                        // grad W = (W'/q) r / h^2,
                        // Hess W = ((W'/q) I + (W'' - W'/q) u u^T) / h^2.
                        let m = 1.0 - q;
                        let w = m.powi(4) * (4.0 * q + 1.0);
                        let wq = -20.0 * m.powi(3);
                        let w2 = 20.0 * m * m * (4.0 * q - 1.0);
                        let mut hess = Mat3::identity() * (wq / h2);
                        if q > 0.0 {
                            let u = r / (q * self.h);
                            hess += u * u.transpose() * ((w2 - wq) / h2);
                        }
                        visit(
                            i as usize,
                            &Weight {
                                w,
                                grad: r * (wq / h2),
                                hess,
                            },
                        );
                    }
                }
            }
        }
    }

    /// How a force at `p` spreads over the samples: `(sample, share)` with
    /// shares summing to one (Shepard weights at the foot point of `p`, the
    /// transpose of the interpolation a [`DisplacedLumen`] reads, so the
    /// spread force does the same virtual work). Empty off the sampled wall.
    pub fn spread(&self, p: &Vec3) -> Vec<(usize, f64)> {
        let (f, ..) = self.foot(p);
        let mut out = Vec::new();
        self.weights(&f, |i, w| out.push((i, w.w)));
        let sum: f64 = out.iter().map(|s| s.1).sum();
        if sum > 0.0 {
            out.iter_mut().for_each(|s| s.1 /= sum);
        } else {
            out.clear();
        }
        out
    }
}

/// Grid cell of `p` for cells of size `h`.
fn cell(p: &Vec3, h: f64) -> [i64; 3] {
    [0, 1, 2].map(|k| (p[k] / h).floor() as i64)
}

/// The rest lumen with its wall moved by the samples' normal displacements
/// (module docs).
#[derive(Debug, Clone)]
pub struct DisplacedLumen {
    wall: Arc<WallSamples>,
    disp: Vec<f64>,
}

impl DisplacedLumen {
    /// The lumen of `wall` with sample `i` moved `disp[i]` (m) along its
    /// outward normal.
    pub fn new(wall: Arc<WallSamples>, disp: Vec<f64>) -> Result<Self, GeometryError> {
        if disp.len() != wall.len() {
            return Err(GeometryError(format!(
                "{} displacements for {} wall samples",
                disp.len(),
                wall.len()
            )));
        }
        Ok(Self { wall, disp })
    }

    /// The interpolated displacement `delta` at foot point `f` with its
    /// gradient and Hessian in `f`.
    fn delta(&self, f: &Vec3, second: bool) -> (f64, Vec3, Mat3) {
        let (mut n, mut d) = (0.0, SHEPARD_FLOOR);
        let (mut gn, mut gd) = (Vec3::zeros(), Vec3::zeros());
        let (mut hn, mut hd) = (Mat3::zeros(), Mat3::zeros());
        self.wall.weights(f, |i, w| {
            let di = self.disp[i];
            n += w.w * di;
            d += w.w;
            gn += w.grad * di;
            gd += w.grad;
            if second {
                hn += w.hess * di;
                hd += w.hess;
            }
        });
        let s = n / d;
        let gs = (gn - gd * s) / d;
        let hs = if second {
            (hn - hd * s - gs * gd.transpose() - gd * gs.transpose()) / d
        } else {
            Mat3::zeros()
        };
        (s, gs, hs)
    }

    /// Largest `|phi(x_i)|` (m) over the samples at their current positions
    /// `current`: how far the interpolated wall misses the tissue's own
    /// surface nodes (0 for an exact fit).
    ///
    /// Only samples with a moved sample in their cell's neighbourhood are
    /// evaluated: elsewhere every displacement the kernel reaches is zero
    /// and the sample sits at its rest point, so `phi` is the rest SDF there
    /// (zero to round-off). A wall moved only around the instrument (local
    /// activation) then costs its moved part, not the whole wall per step.
    pub fn fit_error(&self, current: &[Vec3]) -> f64 {
        let w = &self.wall;
        let grid = &w.grid;
        let mut moved_cell = vec![false; grid.start.len() - 1];
        let mut any = false;
        for (i, x) in current.iter().enumerate() {
            if self.disp[i] != 0.0 || *x != w.points[i] {
                let c = grid
                    .index(&cell(&w.points[i], w.h))
                    .expect("a sample's cell is in the grid");
                moved_cell[c] = true;
                any = true;
            }
        }
        if !any {
            return 0.0;
        }
        let near = |p: &Vec3| {
            let c = cell(p, w.h);
            (-1..=1).any(|dz| {
                (-1..=1).any(|dy| {
                    (-1..=1).any(|dx| {
                        grid.index(&[c[0] + dx, c[1] + dy, c[2] + dz])
                            .is_some_and(|k| moved_cell[k])
                    })
                })
            })
        };
        current
            .iter()
            .zip(&w.points)
            .filter(|(_, x0)| near(x0))
            .map(|(x, _)| self.distance(x).abs())
            .fold(0.0, f64::max)
    }
}

impl Sdf for DisplacedLumen {
    fn distance(&self, p: &Vec3) -> f64 {
        let (f, phi, ..) = self.wall.foot(p);
        phi - self.delta(&f, false).0
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let (f, phi, g, j) = self.wall.foot(p);
        let (s, gs, _) = self.delta(&f, false);
        (phi - s, g - j.transpose() * gs)
    }
    /// `H_0 - J^T H_delta J` (module docs: the foot point's second
    /// derivative is dropped).
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let (f, _, _, j) = self.wall.foot(p);
        let (_, _, hs) = self.delta(&f, true);
        self.wall.rest.hessian(p) - j.transpose() * hs * j
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::sdf::StraightTube;
    use std::f64::consts::TAU;

    /// A straight tube of radius 2 mm along x, sampled on a 1 mm x 16 ring
    /// grid over x in [0, 20] mm.
    fn tube() -> (Arc<dyn Sdf>, Vec<Vec3>) {
        let rest: Arc<dyn Sdf> = Arc::new(StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 2e-3,
        });
        let mut pts = Vec::new();
        for i in 0..=20 {
            for j in 0..16 {
                let a = TAU * j as f64 / 16.0;
                pts.push(Vec3::new(i as f64 * 1e-3, 2e-3 * a.cos(), 2e-3 * a.sin()));
            }
        }
        (rest, pts)
    }

    #[test]
    fn no_displacement_is_the_rest_lumen_and_uniform_is_a_wider_tube() {
        let (rest, pts) = tube();
        let n = pts.len();
        let wall = Arc::new(WallSamples::new(rest.clone(), pts, 2e-3).unwrap());
        let still = DisplacedLumen::new(wall.clone(), vec![0.0; n]).unwrap();
        let wide = DisplacedLumen::new(wall, vec![1e-4; n]).unwrap();
        let mut rng = SplitMix64(3);
        for _ in 0..200 {
            let p = Vec3::new(
                4e-3 + 12e-3 * rng.unit(),
                4e-3 * (rng.unit() - 0.5),
                4e-3 * (rng.unit() - 0.5),
            );
            // Zero displacement: the rest lumen to round-off.
            assert!((still.distance(&p) - rest.distance(&p)).abs() < 1e-18);
            // Uniform d: Shepard reproduces constants up to its floor, so the
            // wall moves by d (1 - eps / (sum W + eps)); sum W >= 1 on this
            // sampling within h/2 of the wall, hence the bound eps d.
            if rest.distance(&p).abs() < 1e-3 {
                let err = (wide.distance(&p) - (rest.distance(&p) - 1e-4)).abs();
                assert!(err <= SHEPARD_FLOOR * 1e-4, "at {p:?}: {err:e}");
            }
        }
    }

    /// The fit error visits only the moved part of the wall and finds the
    /// same largest miss as a pass over every sample: a local dent of three
    /// samples pushed out 0.1 mm (one of them left where it was, so the
    /// interpolated wall misses it), then the whole wall moved.
    #[test]
    fn fit_error_of_a_local_dent_is_that_of_every_sample() {
        let (rest, pts) = tube();
        let wall = Arc::new(WallSamples::new(rest, pts.clone(), 2e-3).unwrap());
        let every = |lumen: &DisplacedLumen, x: &[Vec3]| x.iter().map(|p| lumen.distance(p).abs()).fold(0.0, f64::max);
        let still = DisplacedLumen::new(wall.clone(), vec![0.0; pts.len()]).unwrap();
        assert_eq!(still.fit_error(&pts), 0.0);
        // Samples 160, 161 (x = 10 mm) moved out along their normals; 176
        // (x = 11 mm) reports a displacement but stays.
        let mut disp = vec![0.0; pts.len()];
        let mut x = pts.clone();
        for (i, d) in [(160, 1e-4), (161, 1e-4), (176, 1e-4)] {
            disp[i] = d;
            if i != 176 {
                x[i] += wall.normals[i] * d;
            }
        }
        let dent = DisplacedLumen::new(wall.clone(), disp).unwrap();
        let (local, all) = (dent.fit_error(&x), every(&dent, &x));
        // Not vacuous: the unmoved sample is missed by a good part of 0.1 mm.
        assert!(all > 1e-5, "{all:e}");
        assert_eq!(local, all);
        let moved: Vec<Vec3> = pts.iter().zip(&wall.normals).map(|(p, n)| p + n * 2e-5).collect();
        let wide = DisplacedLumen::new(wall, vec![2e-5; pts.len()]).unwrap();
        assert_eq!(wide.fit_error(&moved), every(&wide, &moved));
    }

    #[test]
    fn gradient_and_hessian_match_differences() {
        let (rest, pts) = tube();
        // A dent: samples near x = 10 mm, angle 0 pushed out by up to 0.1 mm.
        let disp: Vec<f64> = pts
            .iter()
            .map(|p| 1e-4 * (-((p.x - 0.01).powi(2) + p.y.min(0.0).powi(2) + p.z * p.z) / 4e-6).exp())
            .collect();
        let wall = Arc::new(WallSamples::new(rest, pts, 2e-3).unwrap());
        let lumen = DisplacedLumen::new(wall, disp).unwrap();
        let mut rng = SplitMix64(5);
        let h = 1e-7;
        for _ in 0..100 {
            let r = 1.2e-3 + 0.7e-3 * rng.unit();
            let a = TAU * rng.unit();
            let p = Vec3::new(6e-3 + 8e-3 * rng.unit(), r * a.cos(), r * a.sin());
            let (_, g) = lumen.distance_gradient(&p);
            let mut fd = Vec3::zeros();
            for k in 0..3 {
                let (mut u, mut v) = (p, p);
                u[k] += h;
                v[k] -= h;
                fd[k] = (lumen.distance(&u) - lumen.distance(&v)) / (u[k] - v[k]);
            }
            // Central differences: truncation (h / 1 mm)^2 ~ 1e-8, rounding
            // eps |phi| / h ~ 1e-11 relative to |g| ~ 1.
            assert!((g - fd).norm() < 1e-7, "gradient {g:?} vs {fd:?} at {p:?}");
            // The Hessian drops the foot point's second derivative, a term of
            // order |grad delta| |H_0| (|grad delta| <= 0.1 mm / 1 mm here):
            // compare to differences of the exact gradient within that.
            let hess = lumen.hessian(&p);
            let mut fdh = Mat3::zeros();
            for k in 0..3 {
                let (mut u, mut v) = (p, p);
                u[k] += 1e-6;
                v[k] -= 1e-6;
                fdh.set_column(k, &((lumen.gradient(&u) - lumen.gradient(&v)) / (u[k] - v[k])));
            }
            // The rest tube's Hessian has norm 1/r; the dropped term is
            // about |grad delta| / r <= 0.1 / r for this dent.
            assert!((hess - fdh).norm() < 0.1 / r, "hessian {hess} vs {fdh} at {p:?}");
        }
    }

    #[test]
    fn spread_shares_sum_to_one_on_the_wall_and_vanish_off_it() {
        let (rest, pts) = tube();
        let wall = WallSamples::new(rest, pts, 2e-3).unwrap();
        let on = wall.spread(&Vec3::new(0.0105, 1.9e-3, 0.2e-3));
        let sum: f64 = on.iter().map(|s| s.1).sum();
        assert!((sum - 1.0).abs() < 1e-15 && on.len() > 3);
        assert!(wall.spread(&Vec3::new(0.05, 1.9e-3, 0.0)).is_empty());
    }
}
