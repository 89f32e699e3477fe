//! # surgbench-multibody: the engine baseline (rapier3d rigid chain)
//!
//! What a simulator builder gets from a physics engine without writing a
//! rod solver: the rod as a chain of rigid links on rapier3d, joined by
//! spherical joints whose springs carry the rod's bending (`EI / h`) and
//! twisting (`GJ / h`) stiffness, the clamp turned by the operator.
//! CathSim builds its guidewire this way from MuJoCo capsules and joints;
//! here it runs on the same scenes as the dedicated rod models.
//!
//! * [`RigidChain`]: the chain as a library object (build from a
//!   [`surgbench_core::RodBody`], step, observe); its module documents the
//!   discretization and what rapier does with it;
//! * [`MultibodyFactory`] / [`MultibodyModel`]: the harness contract
//!   (`id = "multibody"`).
//!
//! Units are SI (m, kg, s, N, Pa, rad).

mod chain;
mod factory;
mod model;

pub use chain::{ChainParams, JointKind, RigidChain};
pub use factory::MultibodyFactory;
pub use model::MultibodyModel;
