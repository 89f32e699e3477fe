//! # surgbench-pbd: position-based dynamics models
//!
//! Two models of what most interactive surgical simulators ship, both solved
//! with XPBD compliance (Macklin, Müller & Chentanez 2016) so that material
//! stiffness does not depend on the time step or iteration count once the
//! iteration has converged:
//!
//! * [`PbdRodFactory`] (`pbd-rod`): the position-and-orientation based Cosserat
//!   rod of Kugelstadt & Schömer 2016, with vessel contact and position-level
//!   Coulomb friction (Macklin et al. 2014);
//! * [`PbdTissueFactory`] (`pbd-tissue`): tetrahedral tissue with edge-distance
//!   and tetrahedral volume constraints, solved by colour-ordered Gauss-Seidel
//!   on `threads` workers with bit-identical results for any count
//!   ([`color`]), and optional hash-table local activation of the box around
//!   the tool;
//! * [`GhostSurface`] (library feature, no harness scene uses it yet): the
//!   inner-wall triangles of a tet vessel wall, carried by its nodes, for
//!   catheter collision ([`PbdTissue::collide_particles`]).
//!
//! Units are SI throughout (m, kg, s, N, Pa, rad).
//!
//! ```
//! use surgbench_core::{ModelFactory, RodBody, Scene, Fidelity, Vec3, DeviceCommand};
//! use surgbench_pbd::PbdRodFactory;
//! let mut scene = Scene::empty("sag");
//! scene.bodies.push(RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0).into());
//! scene.gravity = Vec3::new(0.0, 0.0, -9.81);
//! let mut fid = Fidelity::default();
//! fid.segments = Some(10);
//! let mut model = PbdRodFactory.build(&scene, &fid).unwrap();
//! model.step(1e-3, &DeviceCommand::default()).unwrap();
//! assert!(model.observe().rods[0].tip().z < 0.0);
//! ```

pub mod color;
mod factory;
pub mod ghost;
pub mod hash;
pub mod rod;
#[cfg(test)]
pub(crate) mod testrng;
pub mod tissue;

pub use factory::{PbdRodFactory, PbdTissueFactory};
pub use ghost::{GhostSurface, SurfaceHit, project_particle_triangle};
pub use hash::BoxHash;
pub use rod::{PbdRod, RodSettings, RodSolver};
pub use tissue::{
    ContactParticle, ParticleContact, PbdTissue, StaticInfo, StaticParams, TissueSettings, project_volume,
};

/// Range checks of the core knobs both PBD models read: `dt` (s) and
/// `iterations`. Their own keys (`substeps`, `damping`, ...) declare their
/// ranges in the factories' key tables, checked by `surgbench_core::resolve`.
pub(crate) fn check_solver_knobs(dt: f64, iterations: usize) -> Result<(), surgbench_core::BuildError> {
    use surgbench_core::BuildError;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(BuildError::bad("dt", format!("must be > 0 s, got {dt}")));
    }
    if iterations == 0 || iterations > 1_000_000 {
        return Err(BuildError::bad(
            "iterations",
            format!("must be in 1..=1e6, got {iterations}"),
        ));
    }
    Ok(())
}
