//! What a model written in Python is given to build itself: a read-only
//! view of the scene (bodies, materials, loads, gravity, the operator's
//! timeline, the vessel's signed distance) and its resolved settings.
//! SI units throughout; rods lie along the local +x of their base pose.

use crate::convert::{points, to_points, vec3};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use surgbench_core::{Iso3, Scene, Setting, Settings};

/// A scene as a Python model sees it (`build(scene)`).
#[pyclass(frozen, module = "surgbench")]
pub struct SceneView {
    scene: Scene,
    settings: Vec<(String, Setting)>,
}

impl SceneView {
    /// The view of `scene` with the model's resolved `settings`.
    pub(crate) fn new(scene: &Scene, settings: &Settings) -> Self {
        Self {
            scene: scene.clone(),
            settings: settings.fidelity().pairs(),
        }
    }
}

/// A pose as a 4 x 4 homogeneous matrix.
fn pose<'py>(py: Python<'py>, p: &Iso3) -> Bound<'py, PyArray2<f64>> {
    let m = p.to_homogeneous();
    let flat: Vec<f64> = (0..4).flat_map(|i| (0..4).map(move |j| m[(i, j)])).collect();
    PyArray1::from_vec(py, flat)
        .reshape([4, 4])
        .expect("16 values reshape to (4, 4)")
}

/// Signed distances `(n,)` and their gradients `(n, 3)`.
type DistanceAndGradient<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

#[pymethods]
impl SceneView {
    /// Scenario id that built the scene.
    #[getter]
    fn name(&self) -> &str {
        &self.scene.name
    }

    /// Gravity (m/s^2, world frame), shape (3,).
    #[getter]
    fn gravity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec3(py, &self.scene.gravity)
    }

    /// Largest simulated time (s).
    #[getter]
    fn duration(&self) -> f64 {
        self.scene.duration
    }

    /// Static scenes: `{"velocity_tol": m/s, "min_time": s}` (the run ends
    /// when every node is slower than the tolerance), else `None`.
    #[getter]
    fn settle<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(s) = &self.scene.settle else { return Ok(None) };
        let d = PyDict::new(py);
        d.set_item("velocity_tol", s.velocity_tol)?;
        d.set_item("min_time", s.min_time)?;
        Ok(Some(d))
    }

    /// The model's resolved settings (`segments`, `dt`, ...), numbers or names.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.settings {
            match v {
                Setting::Number(x) => d.set_item(k, *x)?,
                Setting::Choice(c) => d.set_item(k, c)?,
            }
        }
        Ok(d)
    }

    /// The rods, in scene order: `length` (m), `base` (4 x 4 pose; the rod
    /// leaves the clamp along the base's local +x), `tip_force` (N),
    /// `tip_torque` (N m) and `sections` (each up to arclength `until`:
    /// `radius`, `youngs_modulus`, `poisson_ratio`, `density`,
    /// `shear_modulus`, `area`, `second_moment`, `polar_moment`,
    /// `rest_curvature` (1/m)).
    #[getter]
    fn rods<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for r in self.scene.rods() {
            let d = PyDict::new(py);
            d.set_item("length", r.length)?;
            d.set_item("base", pose(py, &r.base))?;
            d.set_item("tip_force", vec3(py, &r.tip_force))?;
            d.set_item("tip_torque", vec3(py, &r.tip_torque))?;
            let sections = PyList::empty(py);
            for s in &r.sections {
                let sd = PyDict::new(py);
                sd.set_item("until", s.until)?;
                sd.set_item("radius", s.radius)?;
                sd.set_item("youngs_modulus", s.youngs_modulus)?;
                sd.set_item("poisson_ratio", s.poisson_ratio)?;
                sd.set_item("density", s.density)?;
                sd.set_item("shear_modulus", s.shear_modulus())?;
                sd.set_item("area", s.area())?;
                sd.set_item("second_moment", s.second_moment())?;
                sd.set_item("polar_moment", s.polar_moment())?;
                sd.set_item("rest_curvature", s.rest_curvature.to_vec())?;
                sections.append(sd)?;
            }
            d.set_item("sections", sections)?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// The tissues, in scene order: `nodes` (n, 3) m, `tets` (m, 4) node
    /// indices, `fixed_nodes`, `youngs_modulus` (Pa), `poisson_ratio`,
    /// `density` (kg/m^3).
    #[getter]
    fn tissues<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for t in self.scene.tissues() {
            let d = PyDict::new(py);
            d.set_item("nodes", points(py, &t.mesh.nodes))?;
            let flat: Vec<i64> = t.mesh.tets.iter().flat_map(|e| e.map(|i| i as i64)).collect();
            d.set_item("tets", PyArray1::from_vec(py, flat).reshape([t.mesh.tets.len(), 4])?)?;
            d.set_item("fixed_nodes", t.fixed_nodes.clone())?;
            d.set_item("youngs_modulus", t.material.youngs_modulus)?;
            d.set_item("poisson_ratio", t.material.poisson_ratio)?;
            d.set_item("density", t.material.density)?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Whether the scene has a vessel wall.
    #[getter]
    fn has_vessel(&self) -> bool {
        self.scene.environment.vessel.is_some()
    }

    /// The operator's command at time `t` (s): `insertion` (m fed along the
    /// base tangent since the start), `rotation` (rad about it), `load`
    /// (tissue load factor, 0 to 1).
    fn command_at<'py>(&self, py: Python<'py>, t: f64) -> PyResult<Bound<'py, PyDict>> {
        command_dict(py, &self.scene.control.command_at(t))
    }

    /// The vessel's signed distance (m) and its gradient at `points` (n, 3)
    /// at time `t` (s), as `(distance (n,), gradient (n, 3))`, with the
    /// sign convention of the core's `Sdf`; `None` without a vessel.
    #[pyo3(signature = (points, t=0.0))]
    fn vessel_distance<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        t: f64,
    ) -> PyResult<Option<DistanceAndGradient<'py>>> {
        let Some(sdf) = self.scene.environment.vessel_at(t) else {
            return Ok(None);
        };
        let pts = to_points(points, "points")?;
        let d: Vec<f64> = pts.iter().map(|p| sdf.distance(p)).collect();
        let g: Vec<_> = pts.iter().map(|p| sdf.gradient(p)).collect();
        Ok(Some((PyArray1::from_vec(py, d), crate::convert::points(py, &g))))
    }
}

/// A device command as `{"insertion", "rotation", "load"}` (m, rad, 1).
pub(crate) fn command_dict<'py>(py: Python<'py>, c: &surgbench_core::DeviceCommand) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("insertion", c.insertion)?;
    d.set_item("rotation", c.rotation)?;
    d.set_item("load", c.load)?;
    if let Some(p) = &c.base_pose {
        d.set_item("base_pose", pose(py, p))?;
    }
    Ok(d)
}
