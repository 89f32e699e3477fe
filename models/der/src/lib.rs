//! # surgbench-der: discrete elastic rod (guidewire, catheter, needle)
//!
//! The discrete elastic rod of Bergou et al. 2008 ("Discrete Elastic Rods")
//! with the implicit time stepping of Bergou et al. 2010 ("Discrete Viscous
//! Threads"): centerline nodes plus one twist angle per edge, reference
//! frames parallel-transported in time, stretching, anisotropic bending with
//! natural curvature, and twisting. It is the harness's reference rod.
//!
//! * [`DerRod`]: the rod as a library object (build from a
//!   [`surgbench_core::RodBody`], step, solve statics, observe);
//! * [`DerFactory`] / [`DerModel`]: the harness contract (`id = "der"`);
//! * [`energy`]: the energy terms with exact derivatives;
//! * [`band`]: the `O(n)` banded Cholesky solver (re-exported from
//!   [`surgbench_core::band`], where the rod models share it).
//!
//! Units are SI (m, kg, s, N, Pa, rad).
//!
//! ```
//! use surgbench_core::{DeviceCommand, RodBody, Vec3};
//! use surgbench_der::DerRod;
//! let body = RodBody::uniform(0.1, 2e-4, 5e10, 0.3, 6450.0);
//! let mut rod = DerRod::from_body(&body, 20).unwrap();
//! rod.gravity = Vec3::new(0.0, 0.0, -9.81);
//! rod.solve_static(&DeviceCommand::default()).unwrap();
//! assert!(rod.node(rod.num_nodes() - 1).z < 0.0);
//! ```

pub mod energy;
mod factory;
mod model;
pub mod rod;

pub use factory::DerFactory;
pub use model::DerModel;
pub use rod::{DerParams, DerRod, Integrator, TwistDynamics};
pub use surgbench_core::band;
