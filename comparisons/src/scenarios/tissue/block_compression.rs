//! `block-compression`: a cube clamped at its base, a bonded plate on top
//! pushed down; plate force against the scikit-fem reference.

use super::*;
use crate::params;
use crate::references::BlockReference;
use crate::scenario::{Declared, Inputs, ParamSet, ParamSpec, Pointwise, Range, ScenarioInfo, ScenarioRun, UsageError};
use surgbench_core::{Family, Observation, TetMesh, Vec3};

params! {
    /// Parameters of `block-compression`.
    ///
    /// Defaults follow `datasets/reference/block-compression/meta.toml`; the
    /// Poisson ratio is the reference's (0.3) and not a parameter.
    pub struct BlockParams {
        edge: ParamSpec::new("edge", 0.01, "m", Range::Positive, "cube edge"),
        strain: ParamSpec::new(
            "strain",
            0.02,
            "1",
            Range::Open(0.0, 1.0),
            "nominal compressive strain of the plate, <= 0.2 (the reference's range); 0.02 = small strain, 0.2 = large",
        ),
        youngs_modulus: ParamSpec::new("youngs_modulus", 5e3, "Pa", Range::Positive, "Young's modulus"),
        density: DENSITY,
        ramp_time: RAMP,
        duration: DURATION,
        settle_tol: SETTLE,
    }
}

struct BlockRun {
    mesh: TetMesh,
    force_ref: f64,
}

impl Pointwise for BlockRun {
    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        // The body pushes the plate up (+z): compressive force positive.
        let f = obs.hand_force;
        force_metrics(&mut m, f.z, self.force_ref);
        m.insert("lateral_force_rel".into(), f.xy().norm() / self.force_ref);
        common_metrics(&mut m, &self.mesh, t);
        m
    }
}

/// Block between a clamped base and a bonded plate, compressed.
pub const BLOCK_COMPRESSION: Declared<BlockParams> = Declared {
    info: ScenarioInfo {
        id: "block-compression",
        description: "cube clamped at the base, bonded plate on top pushed down to `strain`: plate force",
        family: Family::Tissue,
        reference: "scikit-fem P2, LINEAR elasticity (datasets/reference/block-compression): exact for small strain; at 20% large-strain laws differ by design",
        primary_error: "force_error_rel",
        target: crate::scenario::Target::new(
            0.05,
            "5 % of the reaction force: the project's default for tissue forces",
        ),
        params: BlockParams::SPECS,
        sweep: LEVELS,
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &BlockParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let level = mesh_level(BLOCK_COMPRESSION.info.id, inputs.fidelity)?;
    let reference = BlockReference::load(inputs.datasets)?;
    let (edge, strain, e) = (p.edge, p.strain, p.youngs_modulus);
    let force_ref = reference.force(strain, edge, e).ok_or_else(|| {
        UsageError(format!(
            "block-compression: strain {strain} is outside the reference's 0..{}",
            reference.max_strain()
        ))
    })?;
    let solid = material(p.youngs_modulus, p.density, reference.poisson_ratio);
    let body = clamped_cube(edge, level, solid, |_| Vec3::new(0.0, 0.0, -strain * edge));
    let mesh = body.mesh.clone();
    let scene = static_scene(BLOCK_COMPRESSION.info.id, body, p.ramp_time, p.duration, p.settle_tol)?;
    // Twice the linear work F d / 2: room for stiffer large-strain laws.
    let work = force_ref * strain * edge;
    Ok(ScenarioRun::new(scene, BlockRun { mesh, force_ref }, work, edge))
}
