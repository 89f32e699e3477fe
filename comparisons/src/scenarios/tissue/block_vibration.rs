//! `block-vibration`: a tissue block clamped at its base, started in its
//! first eigenmode with the mode's velocity and left free: the tissue
//! models' dynamics (Newmark conserves, backward Euler damps, XPBD and the
//! meshless integrators have their own dissipation) against scikit-fem.
//!
//! The block is the reference's box, `[0, 0.01] x [0, 0.015] x [0, 0.02]`
//! m (`datasets/reference/block-vibration`): x thinner than y, so the first
//! mode is one sway along x and not a cube's degenerate pair; `nu = 0.3`
//! (the reference's). The initial velocity of node `i` is
//! `A omega_1 phi(x_i)`, `phi` the P2 first mode (scaled to `phi_x = 1` at
//! the top centre), so the top centre's x displacement follows
//! `A sin(omega_1 t)` in the continuum. A P1 mesh's own first mode differs
//! from the P2 one by its discretization error, so the start puts a little
//! energy into higher modes: that is part of what a mesh level costs. At the
//! default amplitude, 0.5 % of the height, large-strain laws differ from the
//! linear reference by O(amplitude^2).
//!
//! Metrics (the cantilever's, [`super::super::oscillation`]): period error
//! (the primary; the reference's own error is ~1.1e-3, Richardson from its
//! three meshes), damping per period, phase at the end, RMS error over the
//! run; and `energy_drift_rel`, the largest change of the model's reported
//! mechanical energy over the run relative to its value after the first step.

use super::*;
use crate::params;
use crate::references::VibrationReference;
use crate::scenario::{Declared, Inputs, ParamSet, Reference, ScenarioInfo, ScenarioRun, Scorer, Target, UsageError};
use crate::scenarios::oscillation::VibrationTrack;
use surgbench_core::{Family, Observation, Scene, TetMesh, Vec3};

params! {
    /// Parameters of `block-vibration`. The geometry and Poisson ratio are
    /// the reference's and not parameters.
    pub struct BlockVibrationParams {
        youngs_modulus: ParamSpec::new("youngs_modulus", 5e3, "Pa", Range::Positive, "Young's modulus"),
        density: ParamSpec::new("density", 1000.0, "kg/m^3", Range::Positive, "density"),
        amplitude: ParamSpec::new(
            "amplitude",
            1e-4,
            "m",
            Range::Positive,
            "sway amplitude of the top centre in the first mode (1e-4 = 0.5 % of the height)"
        ),
        duration: ParamSpec::new(
            "duration",
            1.3,
            "s",
            Range::Positive,
            "simulated time of free vibration (1.3 s = 10.2 periods at the defaults)"
        ),
    }
}

/// Mesh levels of the block: `(2, 3, 4) 2^level` cells along x, y, z.
pub fn vibration_cells(level: usize) -> [usize; 3] {
    [2 << level, 3 << level, 4 << level]
}

/// Free vibration of a clamped block in its first mode.
pub const BLOCK_VIBRATION: Declared<BlockVibrationParams> = Declared {
    info: ScenarioInfo {
        id: "block-vibration",
        description: "block clamped at its base, started in its first eigenmode, free for ten periods",
        family: Family::Tissue,
        reference: "scikit-fem P2 generalised eigenproblem (datasets/reference/block-vibration): omega_1 = 49.49 rad/s (period 0.1270 s) at the defaults, top centre A sin(omega_1 t)",
        primary_error: "period_error_rel",
        target: Target::new(
            0.01,
            "the period within 1 %: ten periods end within 0.1 period of the reference (ten times the reference's own error)",
        ),
        params: BlockVibrationParams::SPECS,
        sweep: LEVELS,
        quick: 2,
        mesh: None,
    },
    datasets: None,
    build,
};

/// The reference a run is scored against.
struct BlockVibration {
    mesh: TetMesh,
    /// The top-centre node of the mesh.
    node: usize,
    /// Its rest position (m).
    rest: Vec3,
    amplitude: f64,
    omega: f64,
}

impl Reference for BlockVibration {
    fn scorer<'a>(&'a self, _scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(BlockScorer {
            reference: self,
            track: VibrationTrack::new(self.amplitude, self.omega),
            energy: None,
        })
    }
}

/// Per-run sums of one block-vibration run.
struct BlockScorer<'a> {
    reference: &'a BlockVibration,
    track: VibrationTrack,
    /// The model's energy after the first step and the largest departure
    /// from it so far (J); `None` before the first step.
    energy: Option<(f64, f64)>,
}

impl BlockScorer<'_> {
    fn node(&self, obs: &Observation) -> Option<Vec3> {
        obs.tissues
            .first()
            .and_then(|t| t.nodes.get(self.reference.node))
            .copied()
    }
}

impl Scorer for BlockScorer<'_> {
    fn observe_step(&mut self, obs: &Observation) {
        if let Some(x) = self.node(obs) {
            self.track.push(obs.time, x.x - self.reference.rest.x);
        }
        let e = obs.energy.kinetic + obs.energy.elastic;
        self.energy = Some(match self.energy {
            None => (e, 0.0),
            Some((e0, d)) => (e0, d.max((e - e0).abs())),
        });
    }

    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        self.track.metrics(&mut m);
        if let Some((e0, d)) = self.energy
            && e0 > 0.0
        {
            m.insert("energy_drift_rel".into(), d / e0);
        }
        if let Some(t) = tissue_of(obs, &self.reference.mesh) {
            common_metrics(&mut m, &self.reference.mesh, t);
        }
        m
    }

    fn reference_tip_at(&self, t: f64) -> Option<[f64; 3]> {
        let r = self.reference;
        Some([r.rest.x + self.track.reference_at(t), r.rest.y, r.rest.z])
    }

    fn tracked_point(&self, obs: &Observation) -> Option<[f64; 3]> {
        self.node(obs).map(|x| [x.x, x.y, x.z])
    }
}

fn build(p: &BlockVibrationParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let id = BLOCK_VIBRATION.info.id;
    let level = mesh_level(id, inputs.fidelity)?;
    let reference = VibrationReference::load(inputs.datasets)?;
    let size = reference.size;
    let omega = reference.omega_at(p.youngs_modulus, p.density);
    let mesh = mesh::block(size, vibration_cells(level));
    let tol = 1e-9 * size.max();
    let solid = material(p.youngs_modulus, p.density, reference.poisson_ratio);
    let mut body = TissueBody::new(mesh, solid);
    body.fixed_nodes = mesh::nodes_on_plane(&body.mesh, 2, 0.0, tol);
    let mode: Vec<Vec3> = body
        .mesh
        .nodes
        .iter()
        .map(|x| {
            reference
                .mode_at(x)
                .ok_or_else(|| UsageError(format!("{id}: node {x:?} is outside the reference's box")))
        })
        .collect::<Result<_, _>>()?;
    body.initial_velocity = mode.iter().map(|phi| phi * (p.amplitude * omega)).collect();
    let top = Vec3::new(size.x / 2.0, size.y / 2.0, size.z);
    let node = (0..body.mesh.nodes.len())
        .min_by(|&a, &b| {
            (body.mesh.nodes[a] - top)
                .norm()
                .total_cmp(&(body.mesh.nodes[b] - top).norm())
        })
        .expect("a block has nodes");
    // The modal energy, 1/2 (A omega)^2 sum m_i |phi_i|^2 with the lumped
    // node masses: the energy watchdog's scale.
    let mut mass = vec![0.0; body.mesh.nodes.len()];
    for t in &body.mesh.tets {
        let [a, b, c, d] = t.map(|i| body.mesh.nodes[i]);
        let m = mesh::tet_volume(&a, &b, &c, &d).abs() * p.density / 4.0;
        for &i in t {
            mass[i] += m;
        }
    }
    let energy = 0.5
        * (p.amplitude * omega).powi(2)
        * mass
            .iter()
            .zip(&mode)
            .map(|(m, phi)| m * phi.norm_squared())
            .sum::<f64>();
    let rest = body.mesh.nodes[node];
    let body_mesh = body.mesh.clone();
    let mut scene = Scene::empty(id);
    scene.duration = p.duration;
    scene.bodies.push(Body::Tissue(body));
    let run = BlockVibration {
        mesh: body_mesh,
        node,
        rest,
        amplitude: p.amplitude,
        omega,
    };
    Ok(ScenarioRun::new(scene, run, energy, size.z).with_reference_tip([rest.x, rest.y, rest.z]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datasets::datasets_dir;

    /// The committed reference: the mode is 1 along x at the top centre,
    /// zero on the clamped base, and interpolation is exact at grid nodes
    /// and linear between them.
    #[test]
    fn the_reference_mode_is_normalised_and_clamped() {
        let r = VibrationReference::load(&datasets_dir()).expect("committed reference");
        let top = r.mode_at(&Vec3::new(0.005, 0.0075, 0.02)).unwrap();
        assert!((top.x - 1.0).abs() < 1e-7, "{top:?}"); // written to 8 digits
        for p in [Vec3::new(0.003, 0.011, 0.0), Vec3::new(0.01, 0.0, 0.0)] {
            assert_eq!(r.mode_at(&p).unwrap(), Vec3::zeros());
        }
        let (a, b) = (Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.000625, 0.0, 0.01));
        let mid = r.mode_at(&((a + b) / 2.0)).unwrap();
        assert!((mid - (r.mode_at(&a).unwrap() + r.mode_at(&b).unwrap()) / 2.0).norm() < 1e-15);
        assert!(r.mode_at(&Vec3::new(0.02, 0.0, 0.0)).is_none());
        // Scaling: omega^2 ~ E / rho.
        assert!((r.omega_at(2.0e4, 1000.0) / r.omega - 2.0).abs() < 1e-15);
    }
}
