//! A model written in Python, through the same contract as the Rust
//! models: [`PyFactory`] builds an instance of the user's class and
//! [`PyModel`] forwards `step` and `observe` to it, so the harness's
//! runner, watchdogs, scorers and reports treat it as any other model.
//!
//! The class's protocol (see the package's `register_model`):
//! `build(scene)` (a [`SceneView`]), `step(dt, command) -> None | dict`
//! and `observe() -> dict`. An exception in `build`, `step` or `observe`
//! is a bug of the model, as a panic is of a Rust model: the run is
//! `failed` with the exception's message. `surgbench.Unsupported` from
//! `build` makes the run `unsupported` with its reason, and
//! `surgbench.Diverged` from `step` stops it as `unstable`.

use crate::convert::{to_floats, to_points, to_vec3};
use crate::scene::{SceneView, command_dict};
use crate::{Diverged, Unsupported, UsageError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::collections::BTreeMap;
use surgbench_core::{
    BuildError, Capability, ContactObs, DeviceCommand, EnergyObs, Family, Fidelity, Mat3, Model, ModelFactory,
    Observation, RodObs, Scene, Setting, Settings, SimError, StepStats, TissueObs,
};

/// A registered Python model class.
pub struct PyFactory {
    class: Py<PyAny>,
    id: &'static str,
    description: &'static str,
    family: Family,
    capabilities: &'static [Capability],
    defaults: Fidelity,
}

impl PyFactory {
    /// The factory of `class` under `id`: `family` and `capabilities` by
    /// name (as `surgbench list` prints them), `defaults` its settings,
    /// which must include `dt` (s). The description says the model is
    /// Python, so reports do.
    pub fn new(
        class: Py<PyAny>,
        id: &str,
        description: &str,
        family: &str,
        capabilities: &[String],
        defaults: &BTreeMap<String, Setting>,
    ) -> PyResult<Self> {
        let family = Family::from_name(family)
            .ok_or_else(|| UsageError::new_err(format!("unknown family `{family}` (rod, tissue or coupled)")))?;
        let caps = capabilities
            .iter()
            .map(|c| {
                Capability::from_name(c).ok_or_else(|| {
                    let known: Vec<_> = Capability::ALL.iter().map(|c| c.name()).collect();
                    UsageError::new_err(format!("unknown capability `{c}` (known: {})", known.join(", ")))
                })
            })
            .collect::<PyResult<Vec<_>>>()?;
        let mut fid = Fidelity::default();
        for (k, v) in defaults {
            fid.set_setting(k, v.clone())
                .map_err(|e| UsageError::new_err(format!("default `{k}`: {}", e.0)))?;
        }
        if !fid.extras.is_empty() {
            let names: Vec<_> = fid.extras.keys().cloned().collect();
            return Err(UsageError::new_err(format!(
                "a Python model takes the common settings only (segments, mesh_level, dt, iterations), not {}",
                names.join(", ")
            )));
        }
        if fid.dt.is_none() {
            return Err(UsageError::new_err("defaults must give the model's time step `dt` (s)"));
        }
        Ok(Self {
            class,
            id: Box::leak(id.to_string().into_boxed_str()),
            description: Box::leak(format!("(Python) {description}").into_boxed_str()),
            family,
            capabilities: Box::leak(caps.into_boxed_slice()),
            defaults: fid,
        })
    }
}

/// An exception of the model's code: printed with its traceback to stderr
/// (where a batch keeps a failed run's messages), then a panic, which the
/// harness turns into a `failed` run.
fn model_bug(py: Python<'_>, id: &str, what: &str, e: PyErr) -> ! {
    let msg = e.to_string();
    e.display(py);
    panic!("Python model `{id}` raised in {what}: {msg}");
}

impl ModelFactory for PyFactory {
    fn id(&self) -> &'static str {
        self.id
    }

    fn description(&self) -> &'static str {
        self.description
    }

    fn family(&self) -> Family {
        self.family
    }

    fn capabilities(&self) -> &'static [Capability] {
        self.capabilities
    }

    fn default_fidelity(&self, _scene: &Scene) -> Fidelity {
        self.defaults.clone()
    }

    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let dt = settings.fidelity().dt.unwrap_or(f64::NAN);
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(BuildError::BadParameter {
                name: "dt".into(),
                reason: format!("must be > 0 s, got {dt}"),
            });
        }
        Python::attach(|py| {
            let made = self.class.bind(py).call0().and_then(|obj| {
                obj.call_method1("build", (SceneView::new(scene, settings),))
                    .map(|_| obj)
            });
            match made {
                Ok(obj) => Ok(Box::new(PyModel {
                    obj: obj.unbind(),
                    id: self.id,
                    dt,
                    t: 0.0,
                }) as Box<dyn Model>),
                Err(e) if e.is_instance_of::<Unsupported>(py) => {
                    Err(BuildError::Unsupported(surgbench_core::Unsupported {
                        reason: e.value(py).to_string(),
                    }))
                }
                Err(e) => model_bug(py, self.id, "build", e),
            }
        })
    }
}

/// One instance of a Python model class.
pub struct PyModel {
    obj: Py<PyAny>,
    id: &'static str,
    dt: f64,
    /// Simulated time (s) after the steps taken.
    t: f64,
}

impl Model for PyModel {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        SimError::check_dt(self.t, dt)?;
        Python::attach(|py| {
            let ret = command_dict(py, cmd).and_then(|c| self.obj.call_method1(py, "step", (dt, c)));
            match ret {
                Ok(r) => {
                    self.t += dt;
                    match step_stats(r.bind(py)) {
                        Ok(s) => Ok(s),
                        Err(e) => model_bug(py, self.id, "step's return value", e),
                    }
                }
                Err(e) if e.is_instance_of::<Diverged>(py) => Err(SimError::Diverged {
                    t: self.t + dt,
                    reason: e.value(py).to_string(),
                }),
                Err(e) => model_bug(py, self.id, "step", e),
            }
        })
    }

    fn observe(&self) -> Observation {
        Python::attach(|py| {
            let obs = self
                .obj
                .call_method0(py, "observe")
                .and_then(|o| observation(o.bind(py), self.t));
            obs.unwrap_or_else(|e| model_bug(py, self.id, "observe", e))
        })
    }

    fn dt(&self) -> f64 {
        self.dt
    }
}

/// `step`'s return value: `None`, or `{"iterations", "residual", "converged"}`.
fn step_stats(r: &Bound<'_, PyAny>) -> PyResult<StepStats> {
    let mut s = StepStats {
        iterations: 0,
        residual: 0.0,
        converged: true,
    };
    if r.is_none() {
        return Ok(s);
    }
    let d = r.cast::<PyDict>()?;
    if let Some(v) = d.get_item("iterations")? {
        s.iterations = v.extract()?;
    }
    if let Some(v) = d.get_item("residual")? {
        s.residual = v.extract()?;
    }
    if let Some(v) = d.get_item("converged")? {
        s.converged = v.extract()?;
    }
    Ok(s)
}

/// A required key of an observation dict.
fn required<'py>(d: &Bound<'py, PyDict>, key: &str, of: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?
        .ok_or_else(|| pyo3::exceptions::PyKeyError::new_err(format!("{of} has no `{key}`")))
}

/// `observe()`'s dict as an [`Observation`]; `t` is the time stepped to
/// (the dict's `time`, if any, wins).
fn observation(o: &Bound<'_, PyAny>, t: f64) -> PyResult<Observation> {
    let d = o.cast::<PyDict>()?;
    let mut obs = Observation {
        time: t,
        ..Default::default()
    };
    if let Some(v) = d.get_item("time")? {
        obs.time = v.extract()?;
    }
    if let Some(rods) = d.get_item("rods")? {
        for r in rods.cast::<PyList>()?.iter() {
            obs.rods.push(rod(r.cast::<PyDict>()?)?);
        }
    }
    if let Some(tissues) = d.get_item("tissues")? {
        for t in tissues.cast::<PyList>()?.iter() {
            obs.tissues.push(tissue(t.cast::<PyDict>()?)?);
        }
    }
    if let Some(contacts) = d.get_item("contacts")? {
        for c in contacts.cast::<PyList>()?.iter() {
            let c = c.cast::<PyDict>()?;
            obs.contacts.push(ContactObs {
                point: to_vec3(&required(c, "point", "a contact")?, "contact point")?,
                force: to_vec3(&required(c, "force", "a contact")?, "contact force")?,
                penetration: required(c, "penetration", "a contact")?.extract()?,
            });
        }
    }
    if let Some(v) = d.get_item("hand_force")? {
        obs.hand_force = to_vec3(&v, "hand_force")?;
    }
    if let Some(v) = d.get_item("hand_torque")? {
        obs.hand_torque = to_vec3(&v, "hand_torque")?;
    }
    if let Some(e) = d.get_item("energy")? {
        let e = e.cast::<PyDict>()?;
        let get = |k: &str| -> PyResult<f64> { e.get_item(k)?.map_or(Ok(0.0), |v| v.extract()) };
        obs.energy = EnergyObs {
            kinetic: get("kinetic")?,
            elastic: get("elastic")?,
            external: get("external")?,
        };
    }
    if let Some(v) = d.get_item("constraint_residual")? {
        obs.constraint_residual = Some(v.extract()?);
    }
    Ok(obs)
}

/// One rod of an observation: `nodes`, `velocities`, `rest` (n, 3) and
/// `arclength` (n,) are required, `frames` (n-1, 3, 3) optional.
fn rod(d: &Bound<'_, PyDict>) -> PyResult<RodObs> {
    let nodes = to_points(&required(d, "nodes", "a rod")?, "rod nodes")?;
    let n = nodes.len();
    let velocities = to_points(&required(d, "velocities", "a rod")?, "rod velocities")?;
    let rest = to_points(&required(d, "rest", "a rod")?, "rod rest")?;
    let arclength = to_floats(&required(d, "arclength", "a rod")?, "rod arclength")?;
    if velocities.len() != n || rest.len() != n || arclength.len() != n {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "a rod's nodes, velocities, rest and arclength must have one row per node: {n}, {}, {}, {}",
            velocities.len(),
            rest.len(),
            arclength.len()
        )));
    }
    let mut frames = Vec::new();
    if let Some(f) = d.get_item("frames")? {
        let flat = to_floats(&f, "rod frames")?;
        if flat.len() != 9 * n.saturating_sub(1) {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "a rod's frames must have shape (n - 1, 3, 3): one per edge, columns (d1, d2, t)",
            ));
        }
        frames = flat.chunks(9).map(Mat3::from_row_slice).collect();
    }
    // The stretch watchdog's input, measured here from what the model gave.
    let max_stretch = nodes
        .windows(2)
        .zip(rest.windows(2))
        .map(|(x, x0)| (x[1] - x[0]).norm() / (x0[1] - x0[0]).norm() - 1.0)
        .fold(0.0f64, |m, s| if s.abs() > m.abs() { s } else { m });
    Ok(RodObs {
        arclength,
        rest,
        nodes,
        velocities,
        frames,
        max_stretch,
    })
}

/// One tissue of an observation: `nodes` and `rest` (n, 3) required;
/// `velocities` (empty for a quasi-static model), `volume_error` and
/// `inverted` optional.
fn tissue(d: &Bound<'_, PyDict>) -> PyResult<TissueObs> {
    let mut t = TissueObs {
        nodes: to_points(&required(d, "nodes", "a tissue")?, "tissue nodes")?,
        rest: to_points(&required(d, "rest", "a tissue")?, "tissue rest")?,
        ..Default::default()
    };
    if let Some(v) = d.get_item("velocities")? {
        t.velocities = to_points(&v, "tissue velocities")?;
    }
    if let Some(v) = d.get_item("volume_error")? {
        t.volume_error = v.extract()?;
    }
    if let Some(v) = d.get_item("inverted")? {
        t.inverted = v.extract()?;
    }
    Ok(t)
}
