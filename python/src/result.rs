//! A run's result in Python: the fields of `run-one`'s `summary.json` as
//! attributes, the time series of `observables.csv` as numpy arrays and the
//! final state of `final_state.csv` as an `(nodes, 3)` array.

use crate::convert::rows3;
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::PyAttributeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use surgbench_comparisons::resolve::ResolvedRun;
use surgbench_comparisons::runner::{RunOptions, RunSummary};
use surgbench_reports::{SERIES_COLUMNS, Status};

/// Run `resolved` as `run-one` does, a panic of the model (or an exception
/// of a Python model) caught as a `failed` summary with its message, as
/// the batch runner records a crashed child.
pub(crate) fn run_caught(resolved: &ResolvedRun, opts: &RunOptions) -> PyResult<RunSummary> {
    match catch_unwind(AssertUnwindSafe(|| resolved.run(opts))) {
        Ok(Ok(s)) => Ok(s),
        Ok(Err(e)) => Err(crate::usage(e)),
        Err(payload) => {
            let msg = payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "panicked".into());
            let mut s = RunSummary {
                scenario: resolved.scenario.id().into(),
                model: resolved.factory.id().into(),
                fidelity_string: resolved.fidelity.to_string(),
                ..Default::default()
            };
            s.status = Status::Failed;
            s.reason = format!("panicked: {msg}");
            Ok(s)
        }
    }
}

/// One run's result (`surgbench.run_one`).
#[pyclass(frozen, module = "surgbench")]
pub struct RunResult {
    summary: RunSummary,
    /// `summary.json`'s object, for the attributes.
    json: serde_json::Map<String, serde_json::Value>,
}

impl RunResult {
    /// The result of a run that produced `summary`.
    pub(crate) fn new(summary: RunSummary) -> Self {
        let json = match serde_json::to_value(&summary) {
            Ok(serde_json::Value::Object(m)) => m,
            _ => serde_json::Map::new(),
        };
        Self { summary, json }
    }
}

/// A JSON value as the Python object `json.loads` would give.
fn to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    let json = py.import("json")?;
    json.call_method1("loads", (v.to_string(),))
}

#[pymethods]
impl RunResult {
    /// Any field of `summary.json` (`status`, `reason`, `end`, `steps`,
    /// `ms_per_step_median`, `primary_error`, `fidelity`, `params`, ...):
    /// `None` where the CLI writes `null`.
    fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        match self.json.get(name) {
            Some(v) => to_py(py, v),
            None => Err(PyAttributeError::new_err(format!("a run result has no `{name}`"))),
        }
    }

    /// The error metrics against the reference, by name (as `summary.json`).
    #[getter]
    fn errors<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.summary.errors {
            d.set_item(k, *v)?;
        }
        Ok(d)
    }

    /// The headline error's value, or `None` when the run has none.
    #[getter]
    fn primary(&self) -> Option<f64> {
        self.summary.errors.get(&self.summary.primary_error).copied()
    }

    /// The sampled time series, one `(samples,)` float64 array per column
    /// of `observables.csv` (`t` s, `tip_x` m: the first rod's tip, or the
    /// point a scene without a rod follows; `hand_fx` N, `hand_tx` N m,
    /// `energy` J, `error`: the primary error, NaN where not scored;
    /// `ref_tip_x` m: the reference tip trajectory, NaN where the scenario's
    /// reference is not one; `force` and `ref_force` N: the force the scene
    /// scores and the reference's value, NaN where it scores none; `depth`
    /// m: the indentation depth a load-curve scene plots that force
    /// against, NaN elsewhere).
    #[getter]
    fn observables<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        // One row per sample, in the column order of `observables.csv`
        // (the CSV writer prints the same fields in the same order).
        let rows: Vec<[f64; SERIES_COLUMNS.len()]> = self
            .summary
            .series
            .iter()
            .map(|x| {
                let ([tx, ty, tz], [fx, fy, fz], [mx, my, mz]) = (x.tip, x.hand_force, x.hand_torque);
                let ([rx, ry, rz], [sf, rf]) = (x.reference_tip, x.force);
                [
                    x.t, tx, ty, tz, fx, fy, fz, mx, my, mz, x.energy, x.error, rx, ry, rz, sf, rf, x.depth,
                ]
            })
            .collect();
        let d = PyDict::new(py);
        for (j, name) in SERIES_COLUMNS.iter().enumerate() {
            d.set_item(name, PyArray1::from_vec(py, rows.iter().map(|r| r[j]).collect()))?;
        }
        Ok(d)
    }

    /// Final node positions (m), shape (nodes, 3): rods first, then tissues.
    #[getter]
    fn final_state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let x: Vec<[f64; 3]> = self.summary.final_state.iter().map(|n| n.x).collect();
        rows3(py, &x)
    }

    /// Rest positions (m) of the same nodes, shape (nodes, 3).
    #[getter]
    fn final_rest<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let x: Vec<[f64; 3]> = self.summary.final_state.iter().map(|n| n.rest).collect();
        rows3(py, &x)
    }

    /// Which body each row of `final_state` belongs to (rods first), shape (nodes,).
    #[getter]
    fn final_body<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        PyArray1::from_vec(py, self.summary.final_state.iter().map(|n| n.body as i64).collect())
    }

    /// The fields of `summary.json` as a dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, &serde_json::Value::Object(self.json.clone()))
    }

    /// Write the files `run-one` writes (`summary.json`, `observables.csv`,
    /// `final_state.csv`) into the existing folder `dir`.
    fn write(&self, dir: PathBuf) -> PyResult<()> {
        self.summary
            .write_files(&dir)
            .map_err(|e| pyo3::exceptions::PyOSError::new_err(format!("cannot write into {}: {e}", dir.display())))
    }

    fn __repr__(&self) -> String {
        let s = &self.summary;
        let primary = s
            .errors
            .get(&s.primary_error)
            .map_or(String::new(), |v| format!(", {} = {v:.4e}", s.primary_error));
        format!(
            "<RunResult {} / {} [{}]: {}{primary}>",
            s.scenario, s.model, s.fidelity_string, s.status
        )
    }
}
