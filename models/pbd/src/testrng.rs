//! Seeded test data for the unit tests: the workspace's generator plus
//! random unit quaternions for the rod's frame tests.

use nalgebra::Quaternion;
pub(crate) use surgbench_core::rng::SplitMix64 as Rng;

/// Unit quaternion (normalised point of `[-1, 1)^4`; not uniform on the sphere).
pub(crate) fn quat(rng: &mut Rng) -> Quaternion<f64> {
    Quaternion::new(rng.signed(), rng.signed(), rng.signed(), rng.signed()).normalize()
}
