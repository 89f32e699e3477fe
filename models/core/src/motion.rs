//! Prescribed vessel motion: a lumen that moves and deforms over time (a
//! coronary on the beating heart), for scenes where the wall is driven by
//! something the wire cannot push back (the myocardium).
//!
//! A [`VesselMotion`] maps each point `X` of the rest lumen to
//! `x = X + u(X, t)` (m, s). The lumen at time `t` is the rest lumen's
//! level set pulled back through that map, `phi_t(x) = phi_0(X(x, t))`
//! ([`MovingSdf`]): exact on the wall (its zero set is the moved wall), with
//! gradient `F^-T grad phi_0` (`F = I + du/dX`, the chain rule). It is a level
//! set, not a distance: `|grad phi_t|` differs from 1 by at most `|du/dX|`
//! (a few per cent for heart motion), which scales a penalty's stiffness, not
//! where the wall is. A blood-flow field moves with the vessel
//! ([`crate::flow::MovingFlow`]: the rest field carried along plus the wall's velocity).
//!
//! Models that support it list [`crate::Capability::MovingVessel`]; they
//! query [`crate::Environment::vessel_at`] at the time of each step and
//! measure friction slip against the wall's own motion ([`carried`]).
//!
//! ```
//! use std::sync::Arc;
//! use surgbench_core::motion::{CardiacMotion, VesselMotion};
//! use surgbench_core::Vec3;
//! // 5 mm transverse (z) swing at 1.2 Hz, ramping in over x in [10, 40] mm.
//! let m = CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::z(), 0.01, 0.03, 5e-3, 1.2).unwrap();
//! let half_period = 0.5 / 1.2;
//! let u = m.displacement(&Vec3::new(0.05, 0.0, 0.0), half_period);
//! assert!((u.z - 5e-3).abs() < 1e-15);
//! let x = Vec3::new(0.05, 0.0, 0.0) + u;
//! assert!((m.rest_point(&x, half_period) - Vec3::new(0.05, 0.0, 0.0)).norm() < 1e-15);
//! ```

use crate::sdf::Sdf;
use crate::{Iso3, Mat3, Vec3};
use std::f64::consts::PI;
use std::sync::Arc;

/// A prescribed motion of the vessel: `x = X + u(X, t)` for every point `X`
/// of the rest lumen (SI units). The map must stay invertible
/// (`|du/dX| < 1`): [`VesselMotion::rest_point`] inverts it.
pub trait VesselMotion: Send + Sync + std::fmt::Debug {
    /// Displacement `u(X, t)` (m) of the rest point `X` at time `t` (s).
    fn displacement(&self, x_rest: &Vec3, t: f64) -> Vec3;

    /// Velocity `du/dt (X, t)` (m/s) of the rest point `X`.
    fn velocity(&self, x_rest: &Vec3, t: f64) -> Vec3;

    /// Deformation gradient `F = I + du/dX` at `(X, t)`.
    fn deformation_gradient(&self, x_rest: &Vec3, t: f64) -> Mat3;

    /// The rest point `X` with `X + u(X, t) = x`. Default: Newton iteration
    /// on `X + u(X) - x = 0` from `X = x` (quadratic convergence while the
    /// map is invertible); motions with a closed-form inverse override it.
    fn rest_point(&self, x: &Vec3, t: f64) -> Vec3 {
        let mut xr = *x;
        for _ in 0..20 {
            let r = xr + self.displacement(&xr, t) - x;
            if r.norm() <= 1e-15 * (1.0 + x.norm()) {
                break;
            }
            let f = self.deformation_gradient(&xr, t);
            match f.try_inverse() {
                Some(fi) => xr -= fi * r,
                None => break,
            }
        }
        xr
    }

    /// The part of the pulled-back level set's Hessian that comes from the
    /// spatial change of `F`: `Hess phi_t = F^-T H_0 F^-1 + extra`, with
    /// `g0 = grad phi_0 (X)` (1/m). Zero (the default) is exact for motions
    /// whose `F` is uniform in space (rigid or homogeneous ones).
    fn hessian_extra(&self, x_rest: &Vec3, t: f64, g0: &Vec3) -> Mat3 {
        let _ = (x_rest, t, g0);
        Mat3::zeros()
    }
}

/// The current position at `t1` (s) of the wall point that was at `x` (m) at
/// `t0`: `X + u(X, t1)` with `X` its rest point. Friction anchors ride on it,
/// so a wire stuck to a moving wall is carried, not dragged.
pub fn carried(motion: &dyn VesselMotion, x: &Vec3, t0: f64, t1: f64) -> Vec3 {
    let xr = motion.rest_point(x, t0);
    xr + motion.displacement(&xr, t1)
}

/// Heart-beat motion of a vessel: a transverse swing
/// `u(X, t) = A s(t) w(X) e`, `s(t) = (1 - cos 2 pi f t) / 2` (starting at rest
/// with zero velocity), `w` a C1 smoothstep `3 xi^2 - 2 xi^3` of
/// `xi = ((X - o) . d - a) / L` clamped to `[0, 1]`: nothing moves before
/// `a` along `d` (the ostium, where the guiding catheter sits), the full
/// amplitude after `a + L`. With `e` perpendicular to `d` the inverse map is
/// closed-form (`w` is constant along `e`): `X = x - A s(t) w(x) e`.
///
/// The coronaries ride on the heart, which moves by millimetres: it
/// translates 4.9 +- 1.9 mm (range 2.4-8.0 mm) caudally with each breath
/// (Shechter et al. 2004, "Respiratory motion of the heart from free breathing
/// coronary angiograms", IEEE TMI 23(8):1046-1056), and over a heartbeat the
/// proximal coronaries stay within 1 mm for only 65-112 ms (Shechter, Resar &
/// McVeigh 2005, Med Phys 32(1):255-262). The scenario states the amplitude
/// and rate it uses.
#[derive(Debug, Clone, PartialEq)]
pub struct CardiacMotion {
    origin: Vec3,
    along: Vec3,
    swing: Vec3,
    start: f64,
    ramp: f64,
    amplitude: f64,
    frequency: f64,
}

impl CardiacMotion {
    /// Motion along unit `swing` (perpendicular to unit `along`) of amplitude
    /// `amplitude` (m) at `frequency` (Hz), ramping in from `start` to
    /// `start + ramp` (m) along `along` measured from `origin`.
    pub fn new(
        origin: Vec3,
        along: Vec3,
        swing: Vec3,
        start: f64,
        ramp: f64,
        amplitude: f64,
        frequency: f64,
    ) -> Result<Self, String> {
        let (ad, sd) = (along.norm(), swing.norm());
        if !((ad - 1.0).abs() < 1e-12 && (sd - 1.0).abs() < 1e-12 && along.dot(&swing).abs() < 1e-12) {
            return Err(format!(
                "cardiac motion needs unit, perpendicular directions; got along {along:?}, swing {swing:?}"
            ));
        }
        if !(ramp > 0.0 && start.is_finite() && amplitude.is_finite() && amplitude >= 0.0 && frequency >= 0.0) {
            return Err(format!(
                "cardiac motion needs ramp > 0 m, finite start, amplitude >= 0 m, frequency >= 0 Hz; got {ramp}, {start}, {amplitude}, {frequency}"
            ));
        }
        // The map stays invertible while |du/dX| = A max|w'| / L = 1.5 A / L < 1.
        if 1.5 * amplitude >= ramp {
            return Err(format!(
                "cardiac motion amplitude {amplitude} m over a {ramp} m ramp folds the vessel (needs 1.5 A < L)"
            ));
        }
        Ok(Self {
            origin,
            along,
            swing,
            start,
            ramp,
            amplitude,
            frequency,
        })
    }

    /// Largest `|du/dX|` over space and time (dimensionless): how far the
    /// level set is from a distance.
    pub fn max_strain(&self) -> f64 {
        1.5 * self.amplitude / self.ramp
    }

    fn xi(&self, x: &Vec3) -> f64 {
        ((x - self.origin).dot(&self.along) - self.start) / self.ramp
    }

    /// `(w, w', w'')` of the smoothstep at `xi` (derivatives in `xi`).
    fn weight(xi: f64) -> (f64, f64, f64) {
        if xi <= 0.0 {
            (0.0, 0.0, 0.0)
        } else if xi >= 1.0 {
            (1.0, 0.0, 0.0)
        } else {
            (xi * xi * (3.0 - 2.0 * xi), 6.0 * xi * (1.0 - xi), 6.0 - 12.0 * xi)
        }
    }

    fn scale(&self, t: f64) -> f64 {
        0.5 * self.amplitude * (1.0 - (2.0 * PI * self.frequency * t).cos())
    }
}

impl VesselMotion for CardiacMotion {
    fn displacement(&self, x_rest: &Vec3, t: f64) -> Vec3 {
        self.swing * (self.scale(t) * Self::weight(self.xi(x_rest)).0)
    }
    fn velocity(&self, x_rest: &Vec3, t: f64) -> Vec3 {
        let w = 2.0 * PI * self.frequency;
        self.swing * (0.5 * self.amplitude * w * (w * t).sin() * Self::weight(self.xi(x_rest)).0)
    }
    fn deformation_gradient(&self, x_rest: &Vec3, t: f64) -> Mat3 {
        let dw = Self::weight(self.xi(x_rest)).1 / self.ramp;
        Mat3::identity() + self.swing * self.along.transpose() * (self.scale(t) * dw)
    }
    /// Closed form: `w(X) = w(x)` because `X - x` is along `e`, perpendicular to `d`.
    fn rest_point(&self, x: &Vec3, t: f64) -> Vec3 {
        x - self.swing * (self.scale(t) * Self::weight(self.xi(x)).0)
    }
    /// `grad phi_t = g0 - c w'/L d (e . g0)` with `c = A s(t)`; differentiating
    /// the `w'` factor along `d` gives `-(c w'' / L^2) (e . g0) d d^T`.
    fn hessian_extra(&self, x_rest: &Vec3, t: f64, g0: &Vec3) -> Mat3 {
        let ddw = Self::weight(self.xi(x_rest)).2;
        self.along * self.along.transpose() * (-self.scale(t) * ddw / (self.ramp * self.ramp) * self.swing.dot(g0))
    }
}

/// A motion moved rigidly with its scene: `u'(x, t) = R u(T^-1 x, t)`.
#[derive(Debug, Clone)]
pub struct TransformedMotion {
    inner: Arc<dyn VesselMotion>,
    iso: Iso3,
}

impl TransformedMotion {
    /// `inner` seen through the rigid transform `iso`.
    pub fn new(inner: Arc<dyn VesselMotion>, iso: Iso3) -> Self {
        Self { inner, iso }
    }
    fn to_inner(&self, x: &Vec3) -> Vec3 {
        self.iso.inverse_transform_point(&(*x).into()).coords
    }
    fn rot(&self) -> Mat3 {
        self.iso.rotation.to_rotation_matrix().into_inner()
    }
}

impl VesselMotion for TransformedMotion {
    fn displacement(&self, x_rest: &Vec3, t: f64) -> Vec3 {
        self.iso.rotation * self.inner.displacement(&self.to_inner(x_rest), t)
    }
    fn velocity(&self, x_rest: &Vec3, t: f64) -> Vec3 {
        self.iso.rotation * self.inner.velocity(&self.to_inner(x_rest), t)
    }
    fn deformation_gradient(&self, x_rest: &Vec3, t: f64) -> Mat3 {
        let r = self.rot();
        r * self.inner.deformation_gradient(&self.to_inner(x_rest), t) * r.transpose()
    }
    fn rest_point(&self, x: &Vec3, t: f64) -> Vec3 {
        let xr = self.inner.rest_point(&self.to_inner(x), t);
        self.iso.transform_point(&xr.into()).coords
    }
    fn hessian_extra(&self, x_rest: &Vec3, t: f64, g0: &Vec3) -> Mat3 {
        let r = self.rot();
        r * self
            .inner
            .hessian_extra(&self.to_inner(x_rest), t, &(r.transpose() * g0))
            * r.transpose()
    }
}

/// The lumen of a moving vessel frozen at time `t`: the rest SDF pulled back
/// through the motion (see the module docs for what it is and is not).
#[derive(Debug, Clone)]
pub struct MovingSdf {
    rest: Arc<dyn Sdf>,
    motion: Arc<dyn VesselMotion>,
    t: f64,
}

impl MovingSdf {
    /// The lumen of `rest` moved by `motion` at time `t` (s).
    pub fn new(rest: Arc<dyn Sdf>, motion: Arc<dyn VesselMotion>, t: f64) -> Self {
        Self { rest, motion, t }
    }
}

impl Sdf for MovingSdf {
    fn distance(&self, p: &Vec3) -> f64 {
        self.rest.distance(&self.motion.rest_point(p, self.t))
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    /// `phi_0(X)` and `F^-T grad phi_0(X)` (chain rule through `X(x)`).
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let xr = self.motion.rest_point(p, self.t);
        let (d, g0) = self.rest.distance_gradient(&xr);
        let f = self.motion.deformation_gradient(&xr, self.t);
        let g = f.transpose().try_inverse().map_or(g0, |fit| fit * g0);
        (d, g)
    }
    /// `F^-T H_0 F^-1` plus the motion's [`VesselMotion::hessian_extra`].
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let xr = self.motion.rest_point(p, self.t);
        let f = self.motion.deformation_gradient(&xr, self.t);
        let Some(fi) = f.try_inverse() else {
            return self.rest.hessian(&xr);
        };
        let g0 = self.rest.gradient(&xr);
        fi.transpose() * self.rest.hessian(&xr) * fi + self.motion.hessian_extra(&xr, self.t, &g0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::sdf::StraightTube;

    fn motion() -> CardiacMotion {
        CardiacMotion::new(Vec3::new(0.001, 0.0, 0.0), Vec3::x(), Vec3::z(), 0.005, 0.02, 4e-3, 1.3).unwrap()
    }

    /// The closed-form inverse agrees with the default Newton inverse and
    /// maps back exactly; `carried` of a still time is the identity.
    #[test]
    fn inverse_map_round_trips() {
        let m = motion();
        let mut rng = SplitMix64(11);
        for _ in 0..200 {
            let x = Vec3::new(rng.unit() * 0.04, rng.signed() * 0.01, rng.signed() * 0.01);
            let t = rng.unit();
            let xr = m.rest_point(&x, t);
            // Rounding of a few additions of m-scale numbers.
            assert!((xr + m.displacement(&xr, t) - x).norm() < 1e-17, "{x:?} at t={t}");
            struct Generic(CardiacMotion);
            impl std::fmt::Debug for Generic {
                fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                    f.write_str("Generic")
                }
            }
            impl VesselMotion for Generic {
                fn displacement(&self, x: &Vec3, t: f64) -> Vec3 {
                    self.0.displacement(x, t)
                }
                fn velocity(&self, x: &Vec3, t: f64) -> Vec3 {
                    self.0.velocity(x, t)
                }
                fn deformation_gradient(&self, x: &Vec3, t: f64) -> Mat3 {
                    self.0.deformation_gradient(x, t)
                }
            }
            let newton = Generic(m.clone()).rest_point(&x, t);
            // Newton stops at a residual of 1e-15 relative to |x|.
            assert!((newton - xr).norm() < 1e-16, "{newton:?} vs {xr:?}");
            assert!((carried(&m, &x, t, t) - x).norm() < 1e-17);
        }
    }

    /// Velocity and deformation gradient are the derivatives of the
    /// displacement (central differences: truncation ~ h^2 u''' ~ 1e-12).
    #[test]
    fn derivatives_match_differences() {
        let m = motion();
        let mut rng = SplitMix64(5);
        for _ in 0..100 {
            let x = Vec3::new(0.004 + rng.unit() * 0.024, rng.signed() * 0.01, rng.signed() * 0.01);
            let t = rng.unit();
            let h = 1e-6;
            let v = (m.displacement(&x, t + h) - m.displacement(&x, t - h)) / (2.0 * h);
            assert!(
                (v - m.velocity(&x, t)).norm() < 1e-10 * (1.0 + v.norm()),
                "velocity at {x:?}"
            );
            let f = m.deformation_gradient(&x, t);
            for k in 0..3 {
                let mut a = x;
                let mut b = x;
                a[k] += h;
                b[k] -= h;
                let col = (m.displacement(&a, t) - m.displacement(&b, t)) / (2.0 * h);
                let e = col - (f.column(k) - Mat3::identity().column(k));
                assert!(e.norm() < 1e-8, "dU/dX column {k} at {x:?}: {e:?}");
            }
        }
    }

    /// The moved lumen: zero on the moved wall, gradient and Hessian equal
    /// the differences of its value and gradient (step 1e-6 m: truncation
    /// ~ h^2 phi''' ~ 1e-12 / mm^2 scale, rounding 1e-16 / 1e-6).
    #[test]
    fn moving_sdf_is_the_pulled_back_level_set() {
        let tube: Arc<dyn Sdf> = Arc::new(StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 1.5e-3,
        });
        let m: Arc<dyn VesselMotion> = Arc::new(motion());
        let t = 0.3;
        let s = MovingSdf::new(tube.clone(), m.clone(), t);
        let mut rng = SplitMix64(3);
        for _ in 0..100 {
            let a = rng.unit() * 2.0 * PI;
            let xr = Vec3::new(rng.unit() * 0.03, 1.5e-3 * a.cos(), 1.5e-3 * a.sin());
            let x = xr + m.displacement(&xr, t);
            assert!(s.distance(&x).abs() < 1e-15, "moved wall point {x:?}");
            let p = x + Vec3::new(rng.signed(), rng.signed(), rng.signed()) * 5e-4;
            let h = 1e-6;
            let g = s.gradient(&p);
            let hs = s.hessian(&p);
            for k in 0..3 {
                let mut pa = p;
                let mut pb = p;
                pa[k] += h;
                pb[k] -= h;
                let dg = (s.distance(&pa) - s.distance(&pb)) / (2.0 * h);
                // truncation h^2 phi''' / 6 with phi''' ~ 1/rho^2 and rho >= 1 mm
                // from the axis here: 1e-12 * 1e6 / 6 ~ 2e-7.
                assert!((dg - g[k]).abs() < 5e-7, "gradient {k} at {p:?}: {dg} vs {}", g[k]);
                let dh = (s.gradient(&pa) - s.gradient(&pb)) / (2.0 * h);
                // Hessian entries ~ 1/r = 700 1/m; differences of a gradient
                // (|g| ~ 1) over 2e-6 m round to ~1e-10, truncation ~h^2/r^3.
                assert!(
                    (dh - hs.column(k)).norm() < 1e-3,
                    "Hessian column {k} at {p:?}: {dh:?} vs {:?}",
                    hs.column(k)
                );
            }
        }
    }

    /// Moving a scene rigidly moves its motion with it: the transformed
    /// lumen at a transformed point equals the original.
    #[test]
    fn transformed_motion_moves_with_the_scene() {
        let tube: Arc<dyn Sdf> = Arc::new(StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 1.5e-3,
        });
        let m: Arc<dyn VesselMotion> = Arc::new(motion());
        let iso = Iso3::new(Vec3::new(0.1, -0.2, 0.3), Vec3::new(0.3, -1.1, 0.7));
        let tm: Arc<dyn VesselMotion> = Arc::new(TransformedMotion::new(m.clone(), iso));
        let tt: Arc<dyn Sdf> = Arc::new(crate::sdf::TransformedSdf::new(tube.clone(), iso));
        let t = 0.27;
        let (a, b) = (MovingSdf::new(tube, m.clone(), t), MovingSdf::new(tt, tm.clone(), t));
        let mut rng = SplitMix64(9);
        for _ in 0..50 {
            let p = Vec3::new(rng.unit() * 0.03, rng.signed() * 2e-3, rng.signed() * 2e-3);
            let q = iso.transform_point(&p.into()).coords;
            assert!((a.distance(&p) - b.distance(&q)).abs() < 1e-15);
            assert!((iso.rotation * a.gradient(&p) - b.gradient(&q)).norm() < 1e-12);
            let r = iso.rotation.to_rotation_matrix().into_inner();
            assert!((r * a.hessian(&p) * r.transpose() - b.hessian(&q)).norm() < 1e-8);
            assert!((iso.rotation * m.velocity(&p, t) - tm.velocity(&q, t)).norm() < 1e-15);
        }
    }

    /// Folding amplitudes and skew directions are refused with the reason.
    #[test]
    fn bad_motions_are_refused() {
        let e = CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::z(), 0.0, 0.01, 0.01, 1.0).unwrap_err();
        assert!(e.contains("folds"), "{e}");
        let e =
            CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::new(1.0, 1.0, 0.0), 0.0, 0.01, 1e-3, 1.0).unwrap_err();
        assert!(e.contains("perpendicular"), "{e}");
    }
}
