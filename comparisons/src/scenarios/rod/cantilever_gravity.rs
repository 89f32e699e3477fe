//! `cantilever-gravity`: a clamped rod sagging under its own weight (small
//! deflection), scored against the elastica it tends to and the
//! Euler-Bernoulli closed form.

use super::{DENSITY, DURATION, LENGTH, POISSON, RADIUS, RodCase, SETTLE, YOUNG, rod_case, score_elastica};
use crate::params;
use crate::references::elastica::{self, Elastica};
use crate::scenario::{
    Metrics, ParamSpec, Params, Range, Scenario, ScenarioInfo, ScenarioRun, Scorer, UsageError, sweep_of,
};
use surgbench_core::{Family, Fidelity, Observation, Scene, Vec3};

/// Clamped rod under its own weight, small deflection.
pub struct CantileverGravity;

const INFO: ScenarioInfo = ScenarioInfo {
    id: "cantilever-gravity",
    description: "clamped rod sagging under its own weight (small deflection)",
    family: Family::Rod,
    reference: "Euler-Bernoulli w(L) = q L^4/(8EI), scored against the geometrically exact elastica (shooting, 1e-10) it tends to",
    primary_error: "tip_error_rel",
};

params! {
    /// Parameters of `cantilever-gravity`.
    pub struct GravityParams {
        length: LENGTH,
        radius: RADIUS,
        youngs_modulus: YOUNG,
        poisson_ratio: POISSON,
        density: DENSITY,
        gravity: ParamSpec::new("gravity", 9.81, "m/s^2", Range::Positive, "gravity along -z"),
        settle_tol: SETTLE,
        duration: DURATION,
    }
}

/// A planar cantilever against its elastica (shared with `cantilever-tip-load`).
pub(super) struct CantileverRun {
    pub(super) scene: Scene,
    pub(super) reference: Elastica,
    /// Euler-Bernoulli tip deflection (m, downwards).
    pub(super) eb_tip: f64,
    /// Total transverse load (N).
    pub(super) load: f64,
}

impl CantileverRun {
    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = score_elastica(obs, &self.reference, self.load);
        if let Some(r) = obs.rods.first() {
            m.insert(
                "tip_error_vs_euler_bernoulli_rel".into(),
                ((-r.tip().z) - self.eb_tip).abs() / self.eb_tip,
            );
        }
        m
    }
}

impl ScenarioRun for CantileverRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn scorer(&self) -> Box<dyn Scorer + '_> {
        Box::new(|obs: &Observation| self.score(obs))
    }
    fn energy_scale(&self) -> f64 {
        self.load * self.reference.length
    }
    fn length_scale(&self) -> f64 {
        self.reference.length
    }
    fn reference_tip(&self) -> Option<[f64; 3]> {
        let (x, z) = self.reference.tip();
        Some([x, 0.0, z])
    }
}

impl Scenario for CantileverGravity {
    fn info(&self) -> &'static ScenarioInfo {
        &INFO
    }
    fn params(&self) -> &'static [ParamSpec] {
        GravityParams::SPECS
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[10.0, 20.0, 40.0, 80.0])
    }
    fn instantiate_at(&self, params: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let p = GravityParams::of(params);
        let c = rod_case!(p);
        let q = c.weight_per_length(p.gravity);
        let reference = elastica::solve(c.length, c.ei(), q, 0.0, 4000).map_err(|e| UsageError(e.to_string()))?;
        let mut scene = c.scene(INFO.id, p.duration, p.settle_tol);
        scene.gravity = Vec3::new(0.0, 0.0, -p.gravity);
        scene.bodies.push(c.body().into());
        Ok(Box::new(CantileverRun {
            scene,
            eb_tip: elastica::eb_uniform_tip(q, c.length, c.ei()),
            reference,
            load: q * c.length,
        }))
    }
}
