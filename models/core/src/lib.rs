//! # surgbench-core: the contract every model implements
//!
//! A model crate implements [`ModelFactory`] (what it can do, how to build it)
//! and [`Model`] (step and observe). The harness builds a [`Scene`] from a
//! scenario, asks each registered factory to [`ModelFactory::check`] it, builds
//! the model at a [`Fidelity`], steps it with [`DeviceCommand`]s from the
//! scene's [`ControlTimeline`] and scores its [`Observation`]s.
//!
//! Units are SI throughout: metres, kilograms, seconds, newtons, pascals,
//! radians.
//!
//! ```
//! use surgbench_core::{Capability, Scene};
//! let scene = Scene::empty("demo");
//! assert!(scene.required_capabilities().is_empty());
//! assert!(!Capability::Rod.describe().is_empty());
//! ```

/// Banded symmetric positive-definite (Cholesky) solver shared by the rod models.
pub mod band;
pub mod beam;
pub mod capability;
pub mod contact;
pub mod coupling;
pub mod error;
pub mod fidelity;
pub mod flow;
pub mod frames;
pub mod haptic;
pub mod io;
pub mod material;
pub mod mesh;
pub mod model;
pub mod motion;
pub mod needle;
pub mod observation;
pub mod rng;
pub mod rod;
pub mod scene;
pub mod sdf;
pub mod settings;
pub mod sphere_contact;
pub mod statics;
pub mod vessel;

pub use capability::{Capability, Family};
pub use error::{BuildError, SimError, Unsupported};
pub use fidelity::{Fidelity, Setting};
pub use flow::FlowField;
pub use material::SolidMaterial;
pub use mesh::TetMesh;
pub use model::{EnergyProbe, Model, ModelFactory, StepStats, resolve};
pub use needle::NeedleTissue;
pub use observation::{ContactObs, EnergyObs, Observation, RodObs, TissueObs};
pub use scene::{
    Body, ContactParams, ControlKey, ControlTimeline, DeviceCommand, Environment, LoadRamp, RodBody, RodSection,
    RodVelocity, Scene, Settle, SphereIndenter, TissueBody, TissueRegion,
};
pub use sdf::Sdf;
pub use settings::{Choice, FidelityKey, KeyKind, Settings, Span};

/// 3-vector of `f64` (SI units).
pub type Vec3 = nalgebra::Vector3<f64>;
/// Rotation matrix / material frame (columns are the frame's axes).
pub type Mat3 = nalgebra::Matrix3<f64>;
/// Rigid transform.
pub type Iso3 = nalgebra::Isometry3<f64>;
