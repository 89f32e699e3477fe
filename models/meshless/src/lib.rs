//! # surgbench-meshless: point-primitive tissue with MLS surface mapping
//!
//! The model of the vascular-tissue seed ("fast and accurate vascular tissue
//! simulation based on the point primitive method"), implemented so the
//! harness can check its claims. Model id `meshless` ([`MeshlessFactory`]).
//!
//! * Point primitives are the nodes of the scene's tet mesh, with volume a
//!   quarter of each adjacent tet's volume and mass `density * volume`.
//! * Elasticity by MLS deformation gradients over a poly6 neighbourhood of
//!   per-node radius (the local cell size, so graded meshes work),
//!   St Venant–Kirchhoff, with hourglass control ([`elastic`], after Müller
//!   et al. 2004, SCA, and Ganzenmüller 2015).
//! * Optional PBD corrections of the seed: edge stretching and virtual-tet
//!   energy constraints ([`pbd`], fidelity `pbd=1`).
//! * Surface = boundary faces of the mesh; its vertices follow the nodes
//!   through an MLS map with a linear basis and cubic-spline weight ([`mls`]).
//! * Follower pressure loads on boundary triangles with their exact load
//!   stiffness ([`pressure`], Bonet & Wood Sec. 6.5).
//! * Frictionless contact with a rigid sphere by a node penalty in the
//!   implicit integrators' Newton objective ([`contact`]).
//! * Symplectic Euler, backward Euler or quasi-static stepping ([`model`]).
//! * `variant=seed` runs the seed's own configuration: symplectic Euler at
//!   half the Courant step ([`seed_dt`]), the PBD corrections on, no
//!   hourglass control; `variant=harness` (the default) is the harness's.
//!
//! Units are SI throughout (m, kg, s, N, Pa).
//!
//! ```
//! use surgbench_core::{mesh, Fidelity, ModelFactory, Scene, SolidMaterial, TissueBody, Vec3};
//! use surgbench_meshless::MeshlessFactory;
//! let m = mesh::block(Vec3::new(0.01, 0.01, 0.01), [3, 3, 3]);
//! let mat = SolidMaterial { youngs_modulus: 1e4, poisson_ratio: 0.3, density: 1000.0 };
//! let mut scene = Scene::empty("demo");
//! scene.bodies.push(surgbench_core::Body::Tissue(TissueBody::new(m, mat)));
//! assert!(MeshlessFactory.check(&scene).is_ok());
//! assert!(MeshlessFactory.build(&scene, &Fidelity::default()).is_ok());
//! ```

pub mod contact;
pub mod elastic;
mod factory;
pub mod kdtree;
pub mod kernel;
pub mod mls;
pub mod model;
pub mod pbd;
pub mod pressure;

pub use contact::SphereContact;
pub use elastic::{PointElastic, StateCache};
pub use factory::{MESHLESS_KEYS, MeshlessFactory, SEED_COURANT_FRACTION, seed_dt};
pub use mls::MlsMap;
pub use model::{Integrator, MappingError, MeshlessSettings, MeshlessTissue, local_edge_lengths, longest_edges};
pub use pbd::PbdConstraints;
pub use pressure::PressureLoad;
