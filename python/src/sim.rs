//! Stepping a model by hand: `Simulation(scenario, model, params,
//! settings)` builds the model for the resolved scene; `step(n, command)`
//! advances it with the GIL released; `state()` and `observe()` read it.
//! Nothing is scored and no watchdog runs: this is the model alone, as a
//! simulator embedding it would drive it.

use crate::convert::{points, vec3};
use crate::scene::command_dict;
use crate::{SimulationError, UsageError};
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::collections::BTreeMap;
use std::sync::{Mutex, PoisonError};
use surgbench_core::{ControlTimeline, DeviceCommand, Model, Observation, Vec3};

/// One model built for one scene, stepped by the caller.
#[pyclass(module = "surgbench")]
pub struct Simulation {
    /// The model (a `Mutex` only to make the class `Sync`; stepping takes
    /// `&mut self`, so it is never contended).
    model: Mutex<Box<dyn Model>>,
    control: ControlTimeline,
    dt: f64,
    steps: usize,
    last: Observation,
}

/// A command dict (`insertion` m, `rotation` rad, `load` 1; missing keys
/// take the scene's timeline at `t`).
fn command_of(d: &Bound<'_, PyDict>, timeline: DeviceCommand) -> PyResult<DeviceCommand> {
    let mut c = timeline;
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        let x: f64 = v.extract()?;
        match key.as_str() {
            "insertion" => c.insertion = x,
            "rotation" => c.rotation = x,
            "load" => c.load = x,
            _ => {
                return Err(UsageError::new_err(format!(
                    "unknown command key `{key}` (insertion, rotation, load)"
                )));
            }
        }
    }
    Ok(c)
}

/// A body's `nodes`, `rest` (m) and `velocities` (m/s) as (n, 3) arrays.
fn body_dict<'py>(py: Python<'py>, nodes: &[Vec3], rest: &[Vec3], velocities: &[Vec3]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("nodes", points(py, nodes))?;
    d.set_item("rest", points(py, rest))?;
    d.set_item("velocities", points(py, velocities))?;
    Ok(d)
}

#[pymethods]
impl Simulation {
    /// Build `model` for `scenario` with parameter overrides `params` (SI)
    /// and `settings` (fidelity knobs by name): a bad input or a scene the
    /// model cannot run is a `UsageError`.
    #[new]
    #[pyo3(signature = (scenario, model, params=None, settings=None))]
    fn new(
        scenario: &str,
        model: &str,
        params: Option<BTreeMap<String, f64>>,
        settings: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let resolved = crate::resolve(scenario, model, params, settings)?;
        let model = resolved.build().map_err(crate::usage)?;
        let dt = model.dt();
        let last = model.observe();
        Ok(Self {
            model: Mutex::new(model),
            control: resolved.scene().control.clone(),
            dt,
            steps: 0,
            last,
        })
    }

    /// Advance `n` steps of `dt` (the model's time step unless given, s).
    /// `command` (a dict) overrides the scene's timeline for these steps;
    /// without it each step takes the timeline's command at its end time.
    /// A failed step raises `SimulationError` (the steps before it stay).
    #[pyo3(signature = (n=1, command=None, dt=None))]
    fn step(&mut self, py: Python<'_>, n: usize, command: Option<&Bound<'_, PyDict>>, dt: Option<f64>) -> PyResult<()> {
        let dt = dt.unwrap_or(self.dt);
        let t_end = (self.steps + n) as f64 * self.dt;
        let fixed = match command {
            Some(d) => Some(command_of(d, self.control.command_at(t_end))?),
            None => None,
        };
        let model = self.model.get_mut().unwrap_or_else(PoisonError::into_inner);
        let (control, start) = (&self.control, self.steps);
        let base_dt = self.dt;
        let done = py.detach(|| {
            for k in 0..n {
                let t = (start + k + 1) as f64 * base_dt;
                let cmd = fixed.unwrap_or_else(|| control.command_at(t));
                if let Err(e) = model.step(dt, &cmd) {
                    return (k, Some(e.to_string()));
                }
            }
            (n, None)
        });
        self.steps += done.0;
        self.last = model.observe();
        match done.1 {
            Some(msg) => Err(SimulationError::new_err(msg)),
            None => Ok(()),
        }
    }

    /// Steps taken.
    #[getter]
    fn steps(&self) -> usize {
        self.steps
    }

    /// Simulated time (s) as the model reports it.
    #[getter]
    fn t(&self) -> f64 {
        self.last.time
    }

    /// The model's time step (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.dt
    }

    /// Node positions (m), shape (nodes, 3): every rod, then every tissue.
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let all: Vec<_> = self
            .last
            .rods
            .iter()
            .flat_map(|r| r.nodes.iter())
            .chain(self.last.tissues.iter().flat_map(|t| t.nodes.iter()))
            .copied()
            .collect();
        points(py, &all)
    }

    /// Force the bodies exert on the operator's hand (N), shape (3,).
    #[getter]
    fn hand_force<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec3(py, &self.last.hand_force)
    }

    /// Torque the bodies exert on the hand about the clamp (N m), shape (3,).
    #[getter]
    fn hand_torque<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec3(py, &self.last.hand_torque)
    }

    /// The scene's command at time `t` (s).
    fn command_at<'py>(&self, py: Python<'py>, t: f64) -> PyResult<Bound<'py, PyDict>> {
        command_dict(py, &self.control.command_at(t))
    }

    /// The whole observation: `time`, `rods` and `tissues` (dicts of (n, 3)
    /// arrays), `contacts`, `hand_force`, `hand_torque`, `energy` (J).
    fn observe<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let o = &self.last;
        let d = PyDict::new(py);
        d.set_item("time", o.time)?;
        let rods = PyList::empty(py);
        for r in &o.rods {
            let rd = body_dict(py, &r.nodes, &r.rest, &r.velocities)?;
            rd.set_item("arclength", PyArray1::from_slice(py, &r.arclength))?;
            rd.set_item("max_stretch", r.max_stretch)?;
            rods.append(rd)?;
        }
        d.set_item("rods", rods)?;
        let tissues = PyList::empty(py);
        for t in &o.tissues {
            let td = body_dict(py, &t.nodes, &t.rest, &t.velocities)?;
            td.set_item("volume_error", t.volume_error)?;
            td.set_item("inverted", t.inverted)?;
            tissues.append(td)?;
        }
        d.set_item("tissues", tissues)?;
        let contacts = PyList::empty(py);
        for c in &o.contacts {
            let cd = PyDict::new(py);
            cd.set_item("point", vec3(py, &c.point))?;
            cd.set_item("force", vec3(py, &c.force))?;
            cd.set_item("penetration", c.penetration)?;
            contacts.append(cd)?;
        }
        d.set_item("contacts", contacts)?;
        d.set_item("hand_force", vec3(py, &o.hand_force))?;
        d.set_item("hand_torque", vec3(py, &o.hand_torque))?;
        let e = PyDict::new(py);
        e.set_item("kinetic", o.energy.kinetic)?;
        e.set_item("elastic", o.energy.elastic)?;
        e.set_item("external", o.energy.external)?;
        d.set_item("energy", e)?;
        Ok(d)
    }
}
