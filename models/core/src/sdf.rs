//! Signed distance fields: the shared collision interface. Negative inside
//! the vessel lumen (where a wire may be), positive in or beyond the wall.

use crate::{Iso3, Vec3};
use std::sync::Arc;

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
}

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
        let d = p - self.origin;
        let r = d - self.axis * d.dot(&self.axis);
        let n = r.norm();
        if n > 0.0 { r / n } else { Vec3::zeros() }
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
}
