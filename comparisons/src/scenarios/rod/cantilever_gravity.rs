//! `cantilever-gravity`: a clamped rod sagging under its own weight (small
//! deflection), scored against the elastica it tends to and the
//! Euler-Bernoulli closed form.

use super::{DENSITY, DURATION, LENGTH, POISSON, RADIUS, RodCase, SEGMENTS, SETTLE, YOUNG, rod_case, score_elastica};
use crate::params;
use crate::references::elastica::{self, Elastica};
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Pointwise, Range, ScenarioInfo, ScenarioRun, UsageError,
};
use surgbench_core::{Family, Observation, Scene, Vec3};

/// Clamped rod under its own weight, small deflection.
pub const CANTILEVER_GRAVITY: Declared<GravityParams> = Declared {
    info: ScenarioInfo {
        id: "cantilever-gravity",
        description: "clamped rod sagging under its own weight (small deflection)",
        family: Family::Rod,
        reference: "Euler-Bernoulli w(L) = q L^4/(8EI), scored against the geometrically exact elastica (shooting, 1e-10) it tends to",
        primary_error: "tip_error_rel",
        target: crate::scenario::Target::new(
            0.02,
            "2 % of the Euler-Bernoulli closed form: a static closed form a rod model should reproduce",
        ),
        params: GravityParams::SPECS,
        sweep: SEGMENTS,
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
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
    pub(super) reference: Elastica,
    /// Euler-Bernoulli tip deflection (m, downwards).
    pub(super) eb_tip: f64,
    /// Total transverse load (N).
    pub(super) load: f64,
}

impl Pointwise for CantileverRun {
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

impl CantileverRun {
    /// The instance: energy scale the load's work over the length, the
    /// elastica's tip as the reference tip and its shape, at 201 points, as
    /// the reference centreline the report draws the models against.
    pub(super) fn into_run(self, scene: Scene) -> ScenarioRun {
        let (length, (x, z)) = (self.reference.length, self.reference.tip());
        let energy = self.load * length;
        let shape = (0..=200)
            .map(|k| {
                let (x, z) = self.reference.at(length * k as f64 / 200.0);
                [x, 0.0, z]
            })
            .collect();
        ScenarioRun::new(scene, self, energy, length)
            .with_reference_tip([x, 0.0, z])
            .with_reference_centreline(shape)
    }
}

fn build(p: &GravityParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    let c = rod_case!(p);
    let q = c.weight_per_length(p.gravity);
    let reference = elastica::solve(c.length, c.ei(), q, 0.0, 4000).map_err(|e| UsageError(e.to_string()))?;
    let mut scene = c.scene(CANTILEVER_GRAVITY.info.id, p.duration, p.settle_tol);
    scene.gravity = Vec3::new(0.0, 0.0, -p.gravity);
    scene.bodies.push(c.body().into());
    Ok(CantileverRun {
        eb_tip: elastica::eb_uniform_tip(q, c.length, c.ei()),
        reference,
        load: q * c.length,
    }
    .into_run(scene))
}
