//! numpy arrays to and from the core's vectors: points are `(n, 3)`
//! float64 arrays (m, or the unit the caller names), one row a point.

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use surgbench_core::Vec3;

/// Points as an `(n, 3)` float64 array.
pub(crate) fn points<'py>(py: Python<'py>, pts: &[Vec3]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = pts.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    let n = pts.len();
    PyArray1::from_vec(py, flat)
        .reshape([n, 3])
        .expect("n x 3 values reshape to (n, 3)")
}

/// Rows of three as an `(n, 3)` float64 array.
pub(crate) fn rows3<'py>(py: Python<'py>, rows: &[[f64; 3]]) -> Bound<'py, PyArray2<f64>> {
    let pts: Vec<Vec3> = rows.iter().map(|r| Vec3::new(r[0], r[1], r[2])).collect();
    points(py, &pts)
}

/// A vector as a `(3,)` float64 array.
pub(crate) fn vec3<'py>(py: Python<'py>, v: &Vec3) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v.as_slice())
}

/// An `(n, 3)` array-like (a numpy array or nested sequences) as points;
/// `what` names it in the error.
pub(crate) fn to_points(v: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Vec3>> {
    let arr = as_float_array(v)?;
    let a: PyReadonlyArray2<f64> = arr
        .extract()
        .map_err(|_| PyValueError::new_err(format!("{what} must be an (n, 3) float array")))?;
    let shape = a.shape();
    if shape[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (n, 3), got ({}, {})",
            shape[0], shape[1]
        )));
    }
    let view = a.as_array();
    Ok(view.rows().into_iter().map(|r| Vec3::new(r[0], r[1], r[2])).collect())
}

/// A 3-vector from any length-3 sequence of numbers.
pub(crate) fn to_vec3(v: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec3> {
    let x: Vec<f64> = v
        .extract()
        .map_err(|_| PyValueError::new_err(format!("{what} must be three numbers")))?;
    match x.as_slice() {
        [a, b, c] => Ok(Vec3::new(*a, *b, *c)),
        _ => Err(PyValueError::new_err(format!(
            "{what} must be three numbers, got {}",
            x.len()
        ))),
    }
}

/// A float vector from any sequence of numbers.
pub(crate) fn to_floats(v: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<f64>> {
    let arr = as_float_array(v)?;
    arr.call_method0("ravel")?
        .extract::<Vec<f64>>()
        .map_err(|_| PyValueError::new_err(format!("{what} must be numbers")))
}

/// `numpy.asarray(v, dtype=float64)`, C-contiguous.
fn as_float_array<'py>(v: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let np = v.py().import("numpy")?;
    np.call_method1("ascontiguousarray", (v, "float64"))
}
