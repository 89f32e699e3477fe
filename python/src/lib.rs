//! # surgbench-py: the Python bindings (`import surgbench`)
//!
//! The extension module `surgbench._surgbench`, wrapped by the Python
//! package in `python/surgbench/`. It runs the harness in process:
//!
//! - [`scenarios`] and [`models`]: what `surgbench list` shows, as dicts;
//! - [`run_one`]: one run through the same resolver, runner, watchdogs and
//!   scorer as `surgbench run-one`, returned as a [`result::RunResult`]
//!   whose numbers equal those `run-one` writes;
//! - [`sim::Simulation`]: step any model by hand (the GIL is released
//!   while it steps) and read its state as numpy arrays;
//! - [`register_model`]: a model written in Python ([`model::PyFactory`])
//!   joins the registry and runs every scenario it supports;
//! - [`cli`]: the whole command line (`python -m surgbench ...`), whose
//!   batches start their children as `python -m surgbench run-one`.
//!
//! Units are SI throughout (m, kg, s, N, Pa), as in the rest of surgbench.

mod convert;
mod model;
mod result;
mod scene;
mod sim;

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::collections::BTreeMap;
use surgbench_comparisons::resolve::ResolvedRun;
use surgbench_comparisons::runner::RunOptions;
use surgbench_comparisons::{UsageError as HarnessUsage, registry};
use surgbench_core::Setting;

create_exception!(
    _surgbench,
    UsageError,
    PyValueError,
    "Bad input: an unknown scenario, model, parameter or setting, or a value out of range (the CLI's exit 2)."
);
create_exception!(
    _surgbench,
    SimulationError,
    PyException,
    "A step failed: the model diverged or its solver failed (`Simulation.step`)."
);
create_exception!(
    _surgbench,
    Unsupported,
    PyException,
    "Raised by a Python model's `build` when it cannot run the scene: the run becomes `unsupported` with this reason."
);
create_exception!(
    _surgbench,
    Diverged,
    PyException,
    "Raised by a Python model's `step` when its state is no longer usable: the run stops as `unstable`, as a Rust model's divergence does."
);

/// A harness usage error as the Python exception [`UsageError`].
pub(crate) fn usage(e: HarnessUsage) -> PyErr {
    UsageError::new_err(e.0)
}

/// Settings (`{"segments": 20, "solver": "cg"}`) as fidelity knobs: a
/// number stays a number, a string is a choice name or a number in text.
fn settings_of(settings: Option<&Bound<'_, PyDict>>) -> PyResult<BTreeMap<String, Setting>> {
    let mut out = BTreeMap::new();
    let Some(d) = settings else { return Ok(out) };
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        let value = if let Ok(text) = v.extract::<String>() {
            Setting::parse(&text).map_err(|e| UsageError::new_err(format!("setting `{key}`: {}", e.0)))?
        } else if let Ok(x) = v.extract::<f64>() {
            Setting::Number(x)
        } else {
            return Err(UsageError::new_err(format!(
                "setting `{key}` must be a number or a name, got {}",
                v.get_type().name()?
            )));
        };
        out.insert(key, value);
    }
    Ok(out)
}

/// Scenario parameter overrides as the resolver takes them.
fn overrides_of(params: Option<BTreeMap<String, f64>>) -> Vec<(String, f64)> {
    params.unwrap_or_default().into_iter().collect()
}

/// Resolve a run exactly as `run-one` does (scenario, model, parameters,
/// settings checked once): any bad input is a [`UsageError`].
pub(crate) fn resolve(
    scenario: &str,
    model: &str,
    params: Option<BTreeMap<String, f64>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<ResolvedRun> {
    let knobs = settings_of(settings)?;
    ResolvedRun::from_knobs(scenario, model, &overrides_of(params), &knobs).map_err(usage)
}

/// Every scenario: id, family, description, reference, primary error and
/// parameters (name, default, unit, admissible range, doc; SI units).
#[pyfunction]
fn scenarios(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for s in registry::scenarios() {
        let d = PyDict::new(py);
        d.set_item("id", s.id())?;
        d.set_item("family", s.family().name())?;
        d.set_item("description", s.description())?;
        d.set_item("reference", s.reference())?;
        d.set_item("primary_error", s.info().primary_error)?;
        let params = PyList::empty(py);
        for p in s.params() {
            let pd = PyDict::new(py);
            pd.set_item("name", p.name)?;
            pd.set_item("default", p.default)?;
            pd.set_item("unit", p.unit)?;
            pd.set_item("range", p.range.describe())?;
            pd.set_item("doc", p.doc)?;
            params.append(pd)?;
        }
        d.set_item("params", params)?;
        out.append(d)?;
    }
    Ok(out)
}

/// Every registered model: id, family, description, capabilities, where
/// it lives (`krate`: a Rust crate, or `python`) and its settings beyond
/// the common ones (`segments`, `mesh_level`, `dt`, `iterations`).
#[pyfunction]
fn models(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for r in registry::models() {
        let f = r.factory;
        let d = PyDict::new(py);
        d.set_item("id", f.id())?;
        d.set_item("family", f.family().name())?;
        d.set_item("description", f.description())?;
        d.set_item("krate", r.krate)?;
        let caps: Vec<&str> = f.capabilities().iter().map(|c| c.name()).collect();
        d.set_item("capabilities", caps)?;
        let keys = PyList::empty(py);
        for k in f.fidelity_keys() {
            let kd = PyDict::new(py);
            kd.set_item("name", k.name)?;
            kd.set_item("values", k.values())?;
            kd.set_item("doc", k.doc)?;
            keys.append(kd)?;
        }
        d.set_item("settings", keys)?;
        out.append(d)?;
    }
    Ok(out)
}

/// One run, as `surgbench run-one --scenario S --model M --param ..
/// --fidelity .. --repeats N` makes it, without the files: the GIL is
/// released while it runs (a Python model takes it back for its calls).
/// A model that panics or raises is a `failed` result with the message.
#[pyfunction]
#[pyo3(signature = (scenario, model, params=None, settings=None, repeats=1))]
fn run_one(
    py: Python<'_>,
    scenario: &str,
    model: &str,
    params: Option<BTreeMap<String, f64>>,
    settings: Option<&Bound<'_, PyDict>>,
    repeats: usize,
) -> PyResult<result::RunResult> {
    if repeats == 0 {
        return Err(UsageError::new_err("repeats must be >= 1"));
    }
    let resolved = resolve(scenario, model, params, settings)?;
    let opts = RunOptions {
        repeats,
        ..Default::default()
    };
    let summary = py.detach(|| result::run_caught(&resolved, &opts))?;
    Ok(result::RunResult::new(summary))
}

/// Register a model class written in Python under `id` (see the package's
/// `register_model` for the protocol). `defaults` are its settings
/// (`{"dt": 1e-3, "segments": 20}`; `dt` is required).
#[pyfunction]
#[pyo3(signature = (cls, id, description, family, capabilities, defaults))]
fn register_model(
    cls: Bound<'_, PyAny>,
    id: &str,
    description: &str,
    family: &str,
    capabilities: Vec<String>,
    defaults: &Bound<'_, PyDict>,
) -> PyResult<()> {
    let knobs = settings_of(Some(defaults))?;
    let factory = model::PyFactory::new(cls.unbind(), id, description, family, &capabilities, &knobs)?;
    registry::register(Box::leak(Box::new(factory)), registry::PYTHON).map_err(usage)
}

/// The `surgbench` command line run in this process (`argv[0]` is the
/// program name), its batches' children started as `python -m surgbench`
/// with this interpreter; returns the exit code.
#[pyfunction]
fn cli(py: Python<'_>, argv: Vec<String>) -> PyResult<u8> {
    let exe: String = py.import("sys")?.getattr("executable")?.extract()?;
    let launcher = surgbench::cli::Launcher {
        exe: exe.into(),
        args: vec!["-m".into(), "surgbench".into()],
    };
    Ok(py.detach(|| surgbench::cli::main(argv, launcher)))
}

/// The extension module.
#[pymodule]
fn _surgbench(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("UsageError", py.get_type::<UsageError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("Unsupported", py.get_type::<Unsupported>())?;
    m.add("Diverged", py.get_type::<Diverged>())?;
    m.add_function(wrap_pyfunction!(scenarios, m)?)?;
    m.add_function(wrap_pyfunction!(models, m)?)?;
    m.add_function(wrap_pyfunction!(run_one, m)?)?;
    m.add_function(wrap_pyfunction!(register_model, m)?)?;
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    m.add_class::<result::RunResult>()?;
    m.add_class::<sim::Simulation>()?;
    m.add_class::<scene::SceneView>()?;
    Ok(())
}
