//! Helpers shared by the integration tests.
#![allow(dead_code)]

use surgbench_core::sdf::StraightTube;
use surgbench_core::{RodBody, Vec3};
use surgbench_der::DerRod;

/// The workspace's seeded generator.
pub use surgbench_core::rng::SplitMix64 as Rng;

/// Random vectors for the derivative checks.
pub trait RngVec {
    /// Uniform in the cube `[-s, s)^3`.
    fn vec(&mut self, s: f64) -> Vec3;
    /// A unit vector normal to `t`.
    fn normal_to(&mut self, t: &Vec3) -> Vec3;
}

impl RngVec for Rng {
    fn vec(&mut self, s: f64) -> Vec3 {
        self.in_box(Vec3::repeat(-s), Vec3::repeat(s))
    }
    fn normal_to(&mut self, t: &Vec3) -> Vec3 {
        let v = self.vec(1.0);
        (v - t * t.dot(&v)).normalize()
    }
}

/// A 0.2 m wire: radius 0.2 mm, E 50 GPa, steel density.
pub fn wire_body() -> RodBody {
    RodBody::uniform(0.2, 2e-4, 5e10, 0.3, 6450.0)
}

/// `body` cut into `segments` segments, under gravity along -z, with
/// damping 50 1/s.
pub fn sagging_wire(body: &RodBody, segments: usize) -> DerRod {
    let mut rod = DerRod::from_body(body, segments).unwrap();
    rod.gravity = Vec3::new(0.0, 0.0, -9.81);
    rod.params.damping = 50.0;
    rod
}

/// A straight tube of radius 1 mm along x through the origin.
pub fn x_tube() -> StraightTube {
    StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1e-3,
    }
}
