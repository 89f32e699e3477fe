//! References the scenarios score against: closed forms (each citing its
//! source), the scikit-fem tables under `datasets/reference/` and cached
//! trajectories of converged models.

pub mod capstan;
pub mod elastica;
pub mod hertz;
pub mod lame;
pub mod scikit_fem;
pub mod tables;
pub mod trajectory;

pub use capstan::capstan_ratio;
pub use hertz::{hertz_contact_radius, hertz_force, sphere_force_exact};
pub use lame::lame_radial_displacement;
pub use scikit_fem::{BlockReference, PunchReference, VibrationReference, WallProbe, WallReference};
pub use tables::read_csv_columns;
pub use trajectory::{TipTrajectory, cached_reference};
