//! Helpers shared by the integration tests.
#![allow(dead_code)]

use surgbench_core::Vec3;

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
