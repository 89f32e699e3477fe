//! The two traits a model crate implements.
//!
//! [`ModelFactory`] says what a model can do and builds it; [`Model`] steps
//! and observes. Optional hooks have default methods, so a minimal model
//! implements `step` and `observe` and nothing else. [`resolve`] checks a
//! scene and fidelity against a factory once; the harness calls it, and so
//! does [`ModelFactory::build`] for library callers.

use crate::Vec3;
use crate::capability::{Capability, Family};
use crate::error::{BuildError, SimError, Unsupported};
use crate::fidelity::Fidelity;
use crate::observation::Observation;
use crate::scene::{DeviceCommand, Scene};
use crate::sdf::Sdf;
use crate::settings::{FidelityKey, Settings};
use std::any::Any;
use std::sync::Arc;

/// What one step cost.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepStats {
    /// Solver iterations this step (Newton, PBD, relaxation: model's choice).
    pub iterations: u32,
    /// Final solver residual (model-defined, dimensionless or SI as documented).
    pub residual: f64,
    /// Whether the solver met its tolerance.
    pub converged: bool,
}

/// A simulated model instance built for one scene at one fidelity.
pub trait Model: Send {
    /// Advance by `dt` seconds with the operator's command at the *end* of
    /// the step.
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError>;

    /// Current state, in the shared observation format.
    fn observe(&self) -> Observation;

    /// The time step the model was built for (s).
    fn dt(&self) -> f64;

    /// Energy access for the conformance suite; `None` for models without a
    /// potential (e.g. purely geometric ones).
    fn energy_probe(&mut self) -> Option<&mut dyn EnergyProbe> {
        None
    }

    /// Model-specific diagnostics of the current state (name -> value, SI,
    /// the unit in the name), e.g. the error a surface mapping adds on its
    /// own. The harness reports them beside the scenario's metrics as
    /// `diag_<name>`; they are not scored against a reference.
    fn diagnostics(&self) -> std::collections::BTreeMap<String, f64> {
        std::collections::BTreeMap::new()
    }

    /// Tissue models with [`Capability::SurfaceForces`]: current positions
    /// (m) of the scene's contact-surface nodes, in
    /// [`crate::TissueBody::surface_vertices`] order (each model maps them
    /// from its own state). `None` for other models.
    fn surface_positions(&self) -> Option<Vec<Vec3>> {
        None
    }

    /// Tissue models with [`Capability::SurfaceForces`]: forces (N, world
    /// frame) on the contact-surface nodes (same order as
    /// [`Model::surface_positions`]), acting over every following step until
    /// replaced; the model spreads them over its own degrees of freedom.
    fn set_surface_forces(&mut self, forces: &[Vec3]) -> Result<(), SimError> {
        let _ = forces;
        Err(unsupported_hook("surface forces"))
    }

    /// Rod models with [`Capability::DeformableLumen`]: the lumen (signed
    /// distance, negative inside) for every following step until replaced.
    /// The contact state a model keeps between steps (lagged friction)
    /// carries over: the wall moved, the contacts did not end.
    fn set_lumen(&mut self, lumen: Arc<dyn Sdf>) -> Result<(), SimError> {
        let _ = lumen;
        Err(unsupported_hook("a replaced lumen"))
    }

    /// A copy of everything a step changes, for a coupling that retries a
    /// step ([`Model::restore_state`]); `None` if the model cannot.
    fn save_state(&self) -> Option<Box<dyn Any + Send>> {
        None
    }

    /// Go back to a state [`Model::save_state`] returned.
    fn restore_state(&mut self, state: &(dyn Any + Send)) -> Result<(), SimError> {
        let _ = state;
        Err(unsupported_hook("restoring a saved state"))
    }
}

/// [`Model::restore_state`] for a model that saves a whole copy of itself
/// (`save_state` = `Some(Box::new(self.clone()))`): `model` becomes the
/// saved copy; a state of another type is an error naming `what`.
pub fn restore_clone<T: Clone + 'static>(
    model: &mut T,
    state: &(dyn Any + Send),
    what: &str,
    t: f64,
) -> Result<(), SimError> {
    let saved = state.downcast_ref::<T>().ok_or_else(|| SimError::SolverFailed {
        t,
        reason: format!("{what}: not a saved {what} state"),
    })?;
    model.clone_from(saved);
    Ok(())
}

/// The error of a coupling hook a model does not implement.
fn unsupported_hook(what: &str) -> SimError {
    SimError::SolverFailed {
        t: f64::NAN,
        reason: format!("this model does not take {what}"),
    }
}

/// Generalized coordinates, potential energy and forces: the conformance
/// suite checks forces = -dE/dq by finite differences (SOFA's ForceField test).
pub trait EnergyProbe {
    /// Generalized coordinates (model-defined order, SI units).
    fn coords(&self) -> Vec<f64>;
    /// Set the generalized coordinates (same order as [`EnergyProbe::coords`]).
    fn set_coords(&mut self, q: &[f64]);
    /// Potential energy at the current coordinates (J).
    fn potential(&self) -> f64;
    /// Generalized forces `-dE/dq` at the current coordinates.
    fn forces(&self) -> Vec<f64>;
    /// Indices of coordinates that are free (not fixed by boundary conditions).
    fn free(&self) -> Vec<usize>;
}

/// Builds a model for a scene; one per model variant, registered in the
/// harness's registry with one line.
pub trait ModelFactory: Send + Sync {
    /// Stable id (`der`, `chainmail`, ...), used on the command line.
    fn id(&self) -> &'static str;
    /// One-line human description.
    fn description(&self) -> &'static str;
    /// What the model's settings fit to data instead of deriving: the
    /// constant, the case it was fitted on (never a scored scene) and the
    /// settings it applies to. The report lists it beside the results, so a
    /// reader knows which numbers rest on a calibration. `None`: nothing fitted.
    fn fitted(&self) -> Option<&'static str> {
        None
    }
    /// Family for grouping.
    fn family(&self) -> Family;
    /// What the model can simulate.
    fn capabilities(&self) -> &'static [Capability];
    /// Model-specific fidelity extras it accepts, each a number, a switch
    /// or a choice by name; [`resolve`] rejects any other.
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        &[]
    }
    /// Fidelity used for knobs the caller leaves unset.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity;

    /// Defaults that depend on what the caller chose: called by [`resolve`]
    /// with the request and the merged fidelity (defaults overlaid with the
    /// request), before the extras are checked. E.g. a tissue model whose
    /// static default is one step to the whole load restores the dynamic
    /// time step when the caller picks a dynamic integrator and no `dt`.
    /// The default changes nothing.
    fn complete_defaults(&self, _scene: &Scene, _requested: &Fidelity, _merged: &mut Fidelity) {}

    /// Can the model run this scene? Default: every required capability is
    /// supported; otherwise [`Unsupported`] names the missing ones.
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        check_capabilities(self.id(), self.capabilities(), scene)
    }

    /// Build the model from `settings` [`resolve`]d for `scene`: the scene
    /// is supported and valid, the settings are the defaults overlaid with
    /// the request, every extra declared and every choice a declared name.
    /// The model checks only its own ranges and combinations.
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError>;

    /// Build the model at `fidelity` (unset knobs take the model's
    /// defaults): [`resolve`], then [`ModelFactory::build_resolved`]. The
    /// entry point for library code; not meant to be overridden.
    fn build(&self, scene: &Scene, fidelity: &Fidelity) -> Result<Box<dyn Model>, BuildError> {
        let settings = resolve(self, scene, fidelity)?;
        self.build_resolved(scene, &settings)
    }
}

/// Resolve a run once: the requested extras are keys `factory` declares
/// with values they take, `factory` supports `scene` ([`ModelFactory::check`]),
/// the scene is valid, and the model's defaults for the scene are overlaid
/// with the request. A bad knob (named, or `fidelity` when undeclared) or
/// scene is [`BuildError::BadParameter`], a scene the model cannot run
/// [`BuildError::Unsupported`].
pub fn resolve<F: ModelFactory + ?Sized>(
    factory: &F,
    scene: &Scene,
    requested: &Fidelity,
) -> Result<Settings, BuildError> {
    let keys = factory.fidelity_keys();
    requested.build_check_extras(keys)?;
    factory.check(scene)?;
    scene.validate().map_err(|e| BuildError::bad("scene", e))?;
    let mut merged = factory.default_fidelity(scene).merged(requested);
    factory.complete_defaults(scene, requested, &mut merged);
    Settings::new(merged, keys)
}

/// `Ok` if `have` covers every capability `scene` requires; otherwise
/// [`Unsupported`] naming the missing ones. The default
/// [`ModelFactory::check`]; factories with extra conditions call it first.
pub fn check_capabilities(id: &str, have: &[Capability], scene: &Scene) -> Result<(), Unsupported> {
    let missing: Vec<&str> = scene
        .required_capabilities()
        .into_iter()
        .filter(|c| !have.contains(c))
        .map(|c| c.name())
        .collect();
    if missing.is_empty() {
        Ok(())
    } else {
        Err(Unsupported::new(format!("{id} does not model: {}", missing.join(", "))))
    }
}

/// [`ModelFactory::check`] of a model of one rod and nothing else: the
/// scene has exactly one rod and no tissue, and `have` covers what it
/// requires ([`check_capabilities`]).
pub fn check_one_rod(id: &str, have: &[Capability], scene: &Scene) -> Result<(), Unsupported> {
    let rods = scene.rods().count();
    if rods != 1 {
        return Err(Unsupported::new(format!(
            "{id} simulates exactly one rod, the scene has {rods}"
        )));
    }
    if scene.tissues().next().is_some() {
        return Err(Unsupported::new(format!("{id} does not model tissue bodies")));
    }
    check_capabilities(id, have, scene)
}
