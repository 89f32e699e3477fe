//! Signed distance fields: the shared collision interface. Negative inside
//! the vessel lumen (where a wire may be), positive in or beyond the wall;
//! the gradient is the unit normal pointing out of the lumen into the wall.
//! Units are SI (metres).
//!
//! Implementations:
//! - [`StraightTube`]: an infinite straight tube (closed form);
//! - [`SweptTube`]: a tube swept along a G1 centreline of straight lines and
//!   circular arcs (built with [`CenterlineBuilder`]), radius varying
//!   linearly in arclength, closed by hemispherical caps at both ends;
//! - [`SdfUnion`]: the union (pointwise `min`) of lumens, e.g. the branches
//!   of a bifurcation;
//! - [`TransformedSdf`]: any SDF moved rigidly;
//! - [`MeshSdf`]: exact distance to a closed triangle mesh through parry3d
//!   (slow: microseconds per query; for building grids and checking them);
//! - [`level_surface`]: the zero level set of any SDF as triangles (for a
//!   collision engine that needs the wall as a mesh);
//! - [`VoxelSdf`]: a regular grid sampled by trilinear interpolation with the
//!   interpolant's analytic gradient (the fast path for models), built from
//!   any SDF or mesh, cacheable to disk.
//!
//! ```
//! use surgbench_core::sdf::{CenterlineBuilder, Sdf};
//! use surgbench_core::Vec3;
//! // 10 mm straight, then a quarter turn of radius 20 mm towards +y; lumen radius 2 mm.
//! let tube = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
//!     .line(0.01)
//!     .arc(0.02, std::f64::consts::FRAC_PI_2, Vec3::y())
//!     .build_constant(2e-3)
//!     .unwrap();
//! assert!((tube.distance(&Vec3::new(0.005, 0.0, 0.0)) + 2e-3).abs() < 1e-15);
//! assert!((tube.distance(&Vec3::new(0.005, 0.0, 3e-3)) - 1e-3).abs() < 1e-15);
//! ```

use crate::{Iso3, Mat3, Vec3};
use std::fmt;
use std::sync::Arc;

mod cubic;
mod displaced;
mod mesh;
mod surface;
mod swept;
mod voxel;

pub use cubic::CubicVoxelSdf;
pub use displaced::{DisplacedLumen, SHEPARD_FLOOR, WallSamples};
pub use mesh::MeshSdf;
pub use surface::{level_surface, lumen_radius_at};
pub use swept::*;
pub use voxel::*;

/// Step (m) of the central differences of [`Sdf::gradient`] that the
/// default [`Sdf::hessian`] takes. Truncation error relative to the Hessian
/// is about `(h / rho)^2` with `rho` the smallest length of the geometry at
/// the point (distance to a tube's axis, bend radius, voxel spacing):
/// <= 1e-4 for the sub-millimetre and larger features of vessels
/// (`rho >= 0.1 mm`). Rounding: an analytic gradient is accurate to about
/// `eps |p| / rho` (1e-12 for `|p| <= 1 m`, `rho >= 0.1 mm`), giving an
/// absolute Hessian error ~1e-6 1/m against curvatures >= 1 1/m; the
/// default finite-difference gradient (step 1e-7 m, error ~1e-9) gives
/// ~1e-3 1/m, still far below the curvature of any vessel wall.
pub const HESSIAN_FD_STEP: f64 = 1e-6;

/// A signed distance `phi(p)` (m) and its gradient (unit normal pointing out
/// of the lumen, into the wall).
pub trait Sdf: Send + Sync + std::fmt::Debug {
    /// Signed distance at `p` (m).
    fn distance(&self, p: &Vec3) -> f64;
    /// Gradient of the distance at `p`; unit length where the SDF is exact.
    fn gradient(&self, p: &Vec3) -> Vec3 {
        let h = 1e-7;
        let mut g = Vec3::zeros();
        for k in 0..3 {
            let mut a = *p;
            let mut b = *p;
            a[k] += h;
            b[k] -= h;
            g[k] = (self.distance(&a) - self.distance(&b)) / (2.0 * h);
        }
        g
    }
    /// Distance and gradient together (one closest-point search for the
    /// analytic vessels; the contact response needs both).
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        (self.distance(p), self.gradient(p))
    }
    /// Hessian of the distance at `p` (1/m, symmetric). For an exact SDF it
    /// is the curvature of the level set through `p` (principal curvatures
    /// across the normal, 0 along it), e.g. the stiffness a contact penalty
    /// `P(phi)` gains from a curved wall, `P'(phi) Hess phi`.
    ///
    /// Default: central differences of [`Sdf::gradient`] over
    /// [`HESSIAN_FD_STEP`] (step and error justified there), symmetrised.
    /// Within that step of a kink of the gradient (a medial axis, the seam
    /// of a union, a voxel face) it returns the jump of the gradient over
    /// the stencil, not a curvature. Analytic overrides: [`StraightTube`],
    /// [`SweptTube`], [`TransformedSdf`], [`SdfUnion`] and the vessels of
    /// [`crate::vessel`].
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let mut m = Mat3::zeros();
        for k in 0..3 {
            let mut a = *p;
            let mut b = *p;
            a[k] += HESSIAN_FD_STEP;
            b[k] -= HESSIAN_FD_STEP;
            // The step actually taken (the coordinates are rounded).
            let h = a[k] - b[k];
            m.set_column(k, &((self.gradient(&a) - self.gradient(&b)) / h));
        }
        (m + m.transpose()) * 0.5
    }
}

/// A geometry could not be built: the message names the offending value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GeometryError(pub String);

impl fmt::Display for GeometryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GeometryError {}

/// A straight tube of radius `radius` (m) along the line through `origin` with
/// direction `axis`: the simplest analytic vessel.
#[derive(Debug, Clone, Copy)]
pub struct StraightTube {
    /// A point on the axis.
    pub origin: Vec3,
    /// Unit axis direction.
    pub axis: Vec3,
    /// Lumen radius (m).
    pub radius: f64,
}

impl Sdf for StraightTube {
    fn distance(&self, p: &Vec3) -> f64 {
        let d = p - self.origin;
        (d - self.axis * d.dot(&self.axis)).norm() - self.radius
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let d = p - self.origin;
        let r = d - self.axis * d.dot(&self.axis);
        let n = r.norm();
        (n - self.radius, if n > 0.0 { r / n } else { Vec3::zeros() })
    }
    /// `(I - a a^T - n n^T) / rho`: `rho` the distance from the axis `a`,
    /// `n` the radial unit vector (zero on the axis, where `phi` has a kink).
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let d = p - self.origin;
        let r = d - self.axis * d.dot(&self.axis);
        let rho = r.norm();
        if !(rho > 0.0) {
            return Mat3::zeros();
        }
        let n = r / rho;
        (Mat3::identity() - self.axis * self.axis.transpose() - n * n.transpose()) / rho
    }
}

/// An SDF moved rigidly: `phi'(p) = phi(T^-1 p)`.
#[derive(Debug, Clone)]
pub struct TransformedSdf {
    inner: Arc<dyn Sdf>,
    iso: Iso3,
}

impl TransformedSdf {
    /// Wrap `inner`, moved by `iso`.
    pub fn new(inner: Arc<dyn Sdf>, iso: Iso3) -> Self {
        Self { inner, iso }
    }
}

impl Sdf for TransformedSdf {
    fn distance(&self, p: &Vec3) -> f64 {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        self.inner.distance(&q)
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        self.iso.rotation * self.inner.gradient(&q)
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        let (d, g) = self.inner.distance_gradient(&q);
        (d, self.iso.rotation * g)
    }
    /// `R H(T^-1 p) R^T` with `R` the rotation of the transform.
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        let r = self.iso.rotation.to_rotation_matrix();
        r.matrix() * self.inner.hessian(&q) * r.matrix().transpose()
    }
}

/// Union of lumens: `phi = min_i phi_i`, gradient of the minimizing part.
/// Exact outside the union; inside, `|phi|` is a lower bound of the distance
/// to the union's wall (enough for contact, which only acts near `phi = 0`).
#[derive(Debug, Clone)]
pub struct SdfUnion {
    /// The lumens joined.
    pub parts: Vec<Arc<dyn Sdf>>,
}

impl SdfUnion {
    /// Index and value of the part with the smallest distance at `p`.
    pub fn closest_part(&self, p: &Vec3) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        for (i, s) in self.parts.iter().enumerate() {
            let d = s.distance(p);
            if best.is_none_or(|(_, b)| d < b) {
                best = Some((i, d));
            }
        }
        best
    }
}

impl Sdf for SdfUnion {
    fn distance(&self, p: &Vec3) -> f64 {
        self.closest_part(p).map_or(f64::INFINITY, |(_, d)| d)
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let mut best = (f64::INFINITY, Vec3::zeros());
        for s in &self.parts {
            let dg = s.distance_gradient(p);
            if dg.0 < best.0 {
                best = dg;
            }
        }
        best
    }
    /// The Hessian of the part with the smallest distance (the one whose
    /// gradient [`Sdf::gradient`] returns); zero for an empty union.
    fn hessian(&self, p: &Vec3) -> Mat3 {
        self.closest_part(p)
            .map_or(Mat3::zeros(), |(i, _)| self.parts[i].hessian(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_tube_distance_and_gradient() {
        let t = StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 1.0,
        };
        assert!((t.distance(&Vec3::new(5.0, 0.0, 3.0)) - 2.0).abs() < 1e-15);
        assert!((t.gradient(&Vec3::new(5.0, 0.0, 3.0)) - Vec3::z()).norm() < 1e-15);
    }
    /// Central differences of `sdf`'s gradient over `h` (m), unsymmetrised.
    fn fd_hessian(sdf: &dyn Sdf, p: &Vec3, h: f64) -> Mat3 {
        let mut m = Mat3::zeros();
        for k in 0..3 {
            let mut a = *p;
            let mut b = *p;
            a[k] += h;
            b[k] -= h;
            m.set_column(k, &((sdf.gradient(&a) - sdf.gradient(&b)) / (a[k] - b[k])));
        }
        m
    }

    /// `p` and its six central-difference neighbours at step `h`.
    fn stencil(p: &Vec3, h: f64) -> [Vec3; 7] {
        let e = |k: usize, s: f64| {
            let mut q = *p;
            q[k] += s * h;
            q
        };
        [*p, e(0, h), e(0, -h), e(1, h), e(1, -h), e(2, h), e(2, -h)]
    }

    /// Step of the finite-difference checks (m) and the smallest distance
    /// from a centreline the samples keep (m).
    const H: f64 = 1e-6;
    const RHO_MIN: f64 = 5e-4;
    /// Tolerance of analytic vs finite-difference Hessians (relative, in
    /// the Frobenius norm): central differences err by `h^2/6 |g'''|`, and
    /// `|g'''| / |Hess| ~ c / rho^2` with `c` of order a few for a tube, so
    /// `(h / rho_min)^2` = 4e-6 covers it; rounding of the gradient
    /// (`eps |p| / rho` ~ 1e-13) over `h` adds ~1e-10. A missing term is far
    /// larger: the bend term is `|w| / R` ~ 0.1, the radius-slope term
    /// `r' R / rho^2 / (1 / |w|)` ~ 1e-3.
    const TOL: f64 = (H / RHO_MIN) * (H / RHO_MIN);

    /// Largest relative error of `sdf.hessian` against differences of
    /// `sdf.gradient` over `count` seeded samples from `sample` that `keep`
    /// accepts (it sees the stencil, to reject points whose differences
    /// straddle a kink); also checks symmetry.
    fn worst_hessian_error(
        sdf: &dyn Sdf,
        count: usize,
        seed: u64,
        sample: impl Fn(&mut crate::rng::SplitMix64) -> Vec3,
        keep: impl Fn(&[Vec3; 7]) -> bool,
    ) -> (f64, usize) {
        let mut rng = crate::rng::SplitMix64(seed);
        let (mut worst, mut n) = (0.0f64, 0usize);
        for _ in 0..count * 50 {
            if n >= count {
                break;
            }
            let p = sample(&mut rng);
            if !keep(&stencil(&p, H)) {
                continue;
            }
            let a = sdf.hessian(&p);
            let fd = fd_hessian(sdf, &p, H);
            assert!(
                (a - a.transpose()).norm() <= 1e-12 * a.norm(),
                "hessian at {p:?} not symmetric: {a}"
            );
            let err = (a - fd).norm() / a.norm();
            assert!(err.is_finite(), "hessian at {p:?}: {a} vs differences {fd}");
            worst = worst.max(err);
            n += 1;
        }
        (worst, n)
    }

    fn straight() -> StraightTube {
        StraightTube {
            origin: Vec3::new(0.3, -0.2, 0.5),
            axis: Vec3::new(1.0, 2.0, 3.0).normalize(),
            radius: 2e-3,
        }
    }

    /// Random point within `[RHO_MIN, 4 mm]` of the straight tube's axis.
    fn near_straight(t: &StraightTube, rng: &mut crate::rng::SplitMix64) -> Vec3 {
        let v = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
        let side = (v - t.axis * t.axis.dot(&v)).normalize();
        t.origin + t.axis * (0.02 * (rng.unit() - 0.5)) + side * (RHO_MIN + 3.5e-3 * rng.unit())
    }

    /// A swept tube with lines, arcs turning two ways and a varying radius.
    fn swept() -> SweptTube {
        CenterlineBuilder::new(Vec3::new(0.01, 0.02, -0.03), Vec3::new(1.0, 0.2, 0.1))
            .line(10e-3)
            .arc(15e-3, 1.2, Vec3::z())
            .line(5e-3)
            .arc(8e-3, 2.0, Vec3::y())
            .build(&[(0.0, 2e-3), (20e-3, 1.5e-3), (40e-3, 2.5e-3)])
            .unwrap()
    }

    /// Random point of the swept tube's bounding box within 2 mm of its wall,
    /// `RHO_MIN` off the centreline and inside 0.6 of the smallest bend
    /// radius (where the closest centreline point is unique).
    fn near_swept(t: &SweptTube, rng: &mut crate::rng::SplitMix64) -> Option<Vec3> {
        let s = rng.unit() * t.length();
        let c = t.point_at(s);
        let v = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 2.0 * 4.8e-3;
        let p = c + v;
        let h = t.project(&p);
        (h.radial >= RHO_MIN && h.radial <= 0.6 * 8e-3 && h.phi.abs() <= 2e-3).then_some(p)
    }

    /// The whole stencil lies on one piece, one profile segment, and on the
    /// same side of "interior hit vs end cap": no kink of the gradient in it.
    fn swept_smooth(t: &SweptTube, st: &[Vec3; 7]) -> bool {
        let key = |p: &Vec3| {
            let (h, hit) = t.project_full(p);
            let seg = t.profile.partition_point(|q| q.0 <= h.s);
            (h.piece, seg, hit.ds_dp == Vec3::zeros())
        };
        let k0 = key(&st[0]);
        st.iter().all(|p| key(p) == k0)
    }

    #[test]
    fn analytic_hessians_match_differences_of_the_gradient() {
        let t = straight();
        let (e, n) = worst_hessian_error(&t, 200, 1, |r| near_straight(&t, r), |_| true);
        eprintln!("straight tube: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 200 && e < TOL,
            "straight tube: rel err {e:e} (tol {TOL:e}) over {n} points"
        );

        let sw = swept();
        let sample = |r: &mut crate::rng::SplitMix64| loop {
            if let Some(p) = near_swept(&sw, r) {
                return p;
            }
        };
        let (e, n) = worst_hessian_error(&sw, 400, 2, sample, |st| swept_smooth(&sw, st));
        eprintln!("swept tube: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 400 && e < TOL,
            "swept tube: rel err {e:e} (tol {TOL:e}) over {n} points"
        );

        let iso = Iso3::from_parts(
            nalgebra::Translation3::new(0.3, -0.2, 0.5),
            nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vec3::new(1.0, 2.0, 3.0)), 0.7),
        );
        let moved = TransformedSdf::new(Arc::new(swept()), iso);
        let back = |p: &Vec3| iso.inverse_transform_point(&(*p).into()).coords;
        let sample = |r: &mut crate::rng::SplitMix64| loop {
            if let Some(p) = near_swept(&sw, r) {
                return iso.transform_point(&p.into()).coords;
            }
        };
        let (e, n) = worst_hessian_error(&moved, 200, 3, sample, |st| swept_smooth(&sw, &st.map(|p| back(&p))));
        eprintln!("transformed swept tube: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 200 && e < TOL,
            "transformed tube: rel err {e:e} (tol {TOL:e}) over {n} points"
        );

        // Two straight tubes crossing at right angles; skip the seam.
        let a = straight();
        let b = StraightTube {
            axis: a.axis.cross(&Vec3::x()).normalize(),
            ..a
        };
        let u = SdfUnion {
            parts: vec![Arc::new(a), Arc::new(b)],
        };
        let sample = |r: &mut crate::rng::SplitMix64| {
            if r.unit() < 0.5 {
                near_straight(&a, r)
            } else {
                near_straight(&b, r)
            }
        };
        let same_part = |st: &[Vec3; 7]| {
            let i = u.closest_part(&st[0]).map(|x| x.0);
            let far = a.distance(&st[0]).min(b.distance(&st[0])) > -a.radius + RHO_MIN;
            far && st.iter().all(|p| u.closest_part(p).map(|x| x.0) == i)
        };
        let (e, n) = worst_hessian_error(&u, 200, 4, sample, same_part);
        eprintln!("union: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 200 && e < TOL,
            "union: rel err {e:e} (tol {TOL:e}) over {n} points"
        );
    }

    /// The swept tube's Hessian has the bend term: on an arc it differs
    /// from the straight-tube formula `(I - n n^T - t t^T) / |w|` by
    /// `t t^T (R / rho - 1) / |w|`, which the check above would catch (it is
    /// ~|w|/R relative); and for a constant radius the Hessian of the exact
    /// SDF annihilates the normal.
    #[test]
    fn swept_tube_hessian_has_the_bend_term() {
        let tube = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
            .arc(10e-3, 1.0, Vec3::y())
            .build_constant(2e-3)
            .unwrap();
        // In-plane point 1.5 mm outside the centreline (away from the centre).
        let s = 5e-3;
        let n = (tube.point_at(s) - Vec3::new(0.0, 10e-3, 0.0)).normalize();
        let p = tube.point_at(s) + n * 1.5e-3;
        let t = tube.tangent_at(s);
        let w = 1.5e-3;
        let rho = 10e-3 + w;
        let expect = (Mat3::identity() - n * n.transpose() - t * t.transpose() * (10e-3 / rho)) / w;
        let got = tube.hessian(&p);
        let err = (got - expect).norm() / expect.norm();
        // Same closed form, evaluated two ways: rounding only.
        assert!(err < 1e-12, "arc hessian {got} vs closed form {expect} (rel {err:e})");
        let hn = (got * tube.gradient(&p)).norm() * w;
        assert!(hn < 1e-12, "Hess phi n = {hn:e} (relative to 1/|w|), should vanish");
    }

    /// The default `hessian` (differences of the gradient over
    /// `HESSIAN_FD_STEP`) against the analytic one of a straight tube.
    #[test]
    fn default_hessian_matches_analytic() {
        #[derive(Debug)]
        struct GradientOnly(StraightTube);
        impl Sdf for GradientOnly {
            fn distance(&self, p: &Vec3) -> f64 {
                self.0.distance(p)
            }
            fn gradient(&self, p: &Vec3) -> Vec3 {
                self.0.gradient(p)
            }
        }
        let t = straight();
        let g = GradientOnly(t);
        let mut rng = crate::rng::SplitMix64(5);
        let mut worst = 0.0f64;
        for _ in 0..200 {
            let p = near_straight(&t, &mut rng);
            let err = (g.hessian(&p) - t.hessian(&p)).norm() / t.hessian(&p).norm();
            worst = worst.max(err);
        }
        eprintln!("default FD hessian: worst rel err {worst:.2e}");
        // Same truncation bound as above: the step is H and rho >= RHO_MIN.
        assert!(worst < TOL, "default hessian rel err {worst:e} (tol {TOL:e})");
    }
}
