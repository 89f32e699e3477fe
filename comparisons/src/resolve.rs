//! One run, resolved and validated once: scenario and model looked up,
//! parameters resolved, the fidelity's model extras checked against the
//! model's declared keys and choices, the scenario instantiated, and the
//! model's settings [`surgbench_core::resolve`]d once (does it support the
//! scene, is the scene valid, its defaults merged under the request). The
//! model's build receives those settings as they are.
//!
//! The CLI (`run-one`, `haptic`, `gate-workload`), the gate, the benches and
//! the comparison's job list all start from a [`ResolvedRun`].

use crate::registry;
use crate::runner::{self, RunOptions, RunSummary};
use crate::scenario::{Params, Scenario, ScenarioRun, UsageError};
use crate::user_mesh::UserMesh;
use surgbench_core::{BuildError, Fidelity, Model, ModelFactory, Scene, Setting, Settings};

/// A scenario x model x parameters x fidelity, ready to build and run.
pub struct ResolvedRun {
    /// The scenario.
    pub scenario: &'static dyn Scenario,
    /// The model's factory.
    pub factory: &'static dyn ModelFactory,
    /// Resolved scenario parameters.
    pub params: Params,
    /// The fidelity as requested (what the scene was instantiated at).
    pub requested: Fidelity,
    /// The instantiated scenario (scene and reference).
    pub run: ScenarioRun,
    /// The model's settings resolved for the scene, or `Err(reason)` when
    /// the model cannot run it (its `check`).
    pub support: Result<Settings, String>,
    /// The full fidelity: the model's defaults for the scene overlaid with the request.
    pub fidelity: Fidelity,
    /// The user's geometry the scene was built on (`--mesh`), if any.
    pub mesh: Option<UserMesh>,
}

impl ResolvedRun {
    /// Resolve `scenario` x `model` with parameter `overrides` at `fidelity`;
    /// an unknown id, parameter or knob, an out-of-range value, or more
    /// steps at the full fidelity's `dt` than [`runner::MAX_STEPS`], is a
    /// [`UsageError`], and so is a choice by an undeclared name. A scene the
    /// model does not support is not an error: see [`ResolvedRun::support`].
    pub fn new(
        scenario: &str,
        model: &str,
        overrides: &[(String, f64)],
        fidelity: Fidelity,
    ) -> Result<Self, UsageError> {
        Self::on_mesh(scenario, model, overrides, fidelity, None)
    }

    /// [`ResolvedRun::new`] with the scene built on the user's geometry
    /// `mesh` (`--mesh`): a scenario that takes none, a mesh of the wrong
    /// kind, or a `mesh_level` knob beside a mesh (the file fixes the mesh)
    /// is a [`UsageError`].
    pub fn on_mesh(
        scenario: &str,
        model: &str,
        overrides: &[(String, f64)],
        fidelity: Fidelity,
        mesh: Option<UserMesh>,
    ) -> Result<Self, UsageError> {
        let sc = registry::scenario(scenario)?;
        if let (Some(m), Some(level)) = (&mesh, fidelity.mesh_level) {
            return Err(UsageError(format!(
                "mesh_level={level} does not apply to a mesh read from a file ({}); leave it out",
                m.path.display()
            )));
        }
        let factory = registry::model(model)?;
        let params = Params::resolve(sc.id(), sc.params(), overrides)?;
        fidelity
            .validate_extras(factory.fidelity_keys())
            .map_err(|e| UsageError(format!("model `{model}`: {}", e.0)))?;
        let run = sc.instantiate_with(&params, &fidelity, mesh.as_ref())?;
        let support = match surgbench_core::resolve(factory, run.scene(), &fidelity) {
            Ok(settings) => Ok(settings),
            Err(BuildError::Unsupported(u)) => Err(u.reason),
            Err(e) => return Err(UsageError(format!("model `{model}`: {e}"))),
        };
        let full = match &support {
            Ok(settings) => settings.fidelity().clone(),
            Err(_) => factory.default_fidelity(run.scene()).merged(&fidelity),
        };
        if let Some(dt) = full.dt {
            runner::check_steps(run.scene().duration, dt)
                .map_err(|e| UsageError(format!("{scenario} with `{model}`: {e}")))?;
        }
        Ok(Self {
            scenario: sc,
            factory,
            params,
            requested: fidelity,
            run,
            support,
            fidelity: full,
            mesh,
        })
    }

    /// [`ResolvedRun::on_mesh`] from `KEY=VALUE` fidelity pairs.
    pub fn from_pairs<S: AsRef<str>>(
        scenario: &str,
        model: &str,
        overrides: &[(String, f64)],
        fidelity: &[S],
        mesh: Option<UserMesh>,
    ) -> Result<Self, UsageError> {
        let fid = Fidelity::parse_pairs(fidelity).map_err(|e| UsageError(e.0))?;
        Self::on_mesh(scenario, model, overrides, fid, mesh)
    }

    /// [`ResolvedRun::new`] from fidelity knobs by name.
    pub fn from_knobs<'a>(
        scenario: &str,
        model: &str,
        overrides: &[(String, f64)],
        knobs: impl IntoIterator<Item = (&'a String, &'a Setting)>,
    ) -> Result<Self, UsageError> {
        let mut fid = Fidelity::default();
        for (k, v) in knobs {
            fid.set_setting(k, v.clone()).map_err(|e| UsageError(e.0))?;
        }
        Self::new(scenario, model, overrides, fid)
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        self.run.scene()
    }

    /// A fresh model from the resolved settings, for callers that need one
    /// to go on: an unsupported scene (`"der cannot run lame-tube: ..."`)
    /// or a failed build is a [`UsageError`].
    pub fn build(&self) -> Result<Box<dyn Model>, UsageError> {
        let settings = self.support.as_ref().map_err(|reason| {
            UsageError(format!(
                "{} cannot run {}: {reason}",
                self.factory.id(),
                self.scenario.id()
            ))
        })?;
        self.factory
            .build_resolved(self.scene(), settings)
            .map_err(|e| UsageError(e.to_string()))
    }

    /// Run it with the runner (timing, watchdogs, scoring).
    pub fn run(&self, opts: &RunOptions) -> Result<RunSummary, UsageError> {
        let mut summary = runner::run_checked(
            self.scenario,
            &self.params,
            &self.run,
            self.factory,
            self.support.as_ref().map_err(String::clone),
            &self.fidelity,
            opts,
        )?;
        summary.mesh = self.mesh.as_ref().map(|m| m.path.display().to_string());
        Ok(summary)
    }
}
