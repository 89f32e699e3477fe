//! Helpers shared by the integration tests.

/// The workspace's seeded generator (`signed()` in `[-1, 1)`, `signed_vec()`).
pub use surgbench_core::rng::SplitMix64 as Rng;
