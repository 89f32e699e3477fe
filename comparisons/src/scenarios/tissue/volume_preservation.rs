//! `volume-preservation`: a block squashed and twisted by prescribed
//! boundary motion; volume change against the exact (isochoric) motion.

use super::*;
use crate::params;
use crate::scenario::{Declared, Inputs, ParamSet, ParamSpec, Pointwise, Range, ScenarioInfo, ScenarioRun, UsageError};
use surgbench_core::{Family, Observation, TetMesh, Vec3};

params! {
    /// Parameters of `volume-preservation`.
    pub struct VolumeParams {
        edge: ParamSpec::new("edge", 0.01, "m", Range::Positive, "cube edge"),
        compression: ParamSpec::new(
            "compression",
            0.2,
            "1",
            Range::Open(0.0, 0.6),
            "top face moved down by this fraction of the edge",
        ),
        twist: ParamSpec::new(
            "twist",
            PI / 4.0,
            "rad",
            Range::Closed(-PI / 2.0, PI / 2.0),
            "rotation of the top face about the vertical axis through its centre",
        ),
        youngs_modulus: ParamSpec::new("youngs_modulus", 5e3, "Pa", Range::Positive, "Young's modulus"),
        poisson_ratio: ParamSpec::new(
            "poisson_ratio",
            0.49,
            "1",
            Range::Open(0.0, 0.5),
            "Poisson ratio (nearly incompressible by default)",
        ),
        density: DENSITY,
        ramp_time: RAMP,
        duration: DURATION,
        settle_tol: SETTLE,
    }
}

struct VolumeRun {
    mesh: TetMesh,
}

impl Pointwise for VolumeRun {
    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        let v = volume_stats(&self.mesh, &t.nodes);
        m.insert("volume_ratio".into(), v.ratio);
        m.insert("max_element_volume_change_rel".into(), v.max_element_change);
        m.insert("min_element_volume_ratio".into(), v.min_element_ratio);
        // Does the model's own volume report agree with its nodes?
        m.insert(
            "reported_volume_mismatch_rel".into(),
            (t.volume_error - (v.ratio - 1.0)).abs(),
        );
        common_metrics(&mut m, &self.mesh, t);
        m
    }
}

/// Displacement of a top-face node `x0` (m) of a cube of edge `edge`:
/// rotation by `twist` about the vertical axis through the face centre,
/// then down by `compression * edge`.
pub fn squash_twist(x0: &Vec3, edge: f64, compression: f64, twist: f64) -> Vec3 {
    let c = Vec3::new(0.5 * edge, 0.5 * edge, x0.z);
    let rot = nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), twist);
    c + rot * (x0 - c) - Vec3::new(0.0, 0.0, compression * edge) - x0
}

/// Block squashed and twisted: nearly incompressible volume preservation.
pub const VOLUME_PRESERVATION: Declared<VolumeParams> = Declared {
    info: ScenarioInfo {
        id: "volume-preservation",
        description: "cube clamped at the base, top face squashed and twisted, nearly incompressible: volume change",
        family: Family::Tissue,
        reference: "exact volume (V = V0 for an incompressible solid); for nu < 0.5 a property metric, ~(1-2nu) x compression expected",
        primary_error: "volume_change_rel",
        target: crate::scenario::Target::new(0.01, "1 % volume change of a nearly incompressible block"),
        params: VolumeParams::SPECS,
        sweep: LEVELS,
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &VolumeParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let level = mesh_level(VOLUME_PRESERVATION.info.id, inputs.fidelity)?;
    let (edge, c, twist) = (p.edge, p.compression, p.twist);
    let solid = material(p.youngs_modulus, p.density, p.poisson_ratio);
    let body = clamped_cube(edge, level, solid, |x| squash_twist(x, edge, c, twist));
    let mesh = body.mesh.clone();
    let e = p.youngs_modulus;
    let scene = static_scene(VOLUME_PRESERVATION.info.id, body, p.ramp_time, p.duration, p.settle_tol)?;
    // Elastic energy scale E V (strain^2 + shear^2), twice over.
    let work = 2.0 * e * edge.powi(3) * (c * c + twist * twist);
    Ok(ScenarioRun::new(scene, VolumeRun { mesh }, work, edge))
}
