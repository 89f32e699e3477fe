use surgbench_comparisons::params;
use surgbench_comparisons::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Pointwise, Range, ScenarioInfo, ScenarioRun, Sweep, Target,
    UsageError,
};
use surgbench_core::{Family, Observation, RodBody, Scene, Settle, Vec3};

/// `rod-at-rest`: an unloaded straight rod must stay where it is.
pub const ROD_AT_REST: Declared<RestParams> = Declared {
    info: ScenarioInfo {
        id: "rod-at-rest",
        description: "unloaded straight rod clamped at the origin: nothing moves",
        family: Family::Rod,
        reference: "closed form: the tip stays at (L, 0, 0)",
        primary_error: "tip_error_m",
        // The largest primary error its user accepts, and why (the report's verdicts).
        target: Target::new(1e-6, "a rod at rest stays within a micrometre"),
        params: RestParams::SPECS,
        sweep: Sweep::Knob("segments", &[10.0, 20.0, 40.0]),
        quick: 2,   // --quick runs the first two of the sweep
        mesh: None, // or Some(MeshKind::Tets): it takes `run-one --mesh FILE`
    },
    datasets: None, // reference data from datasets/ (this one needs none)
    build,
};

params! {
    /// Parameters of `rod-at-rest` (SI units).
    pub struct RestParams {
        length: ParamSpec::new("length", 0.1, "m", Range::Positive, "free length"),
        radius: ParamSpec::new("radius", 5e-4, "m", Range::Positive, "section radius"),
        youngs_modulus: ParamSpec::new("youngs_modulus", 5e10, "Pa", Range::Positive, "Young's modulus"),
        duration: ParamSpec::new("duration", 0.1, "s", Range::Positive, "longest wait for rest"),
    }
}

/// What a run is scored against: here the rest length.
struct AtRest {
    length: f64,
}

// Metrics of one observation alone: `Pointwise`. A scene with run-wide
// metrics (peak force, time to reach) implements `Reference` instead and
// hands out a `Scorer` that sums in `observe_step(&mut self, obs)`.
impl Pointwise for AtRest {
    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        if let Some(rod) = obs.rods.first() {
            let want = Vec3::new(self.length, 0.0, 0.0);
            m.insert("tip_error_m".into(), (rod.tip() - want).norm());
        }
        m
    }
}

/// Validates the parameters, builds the scene and its reference.
fn build(p: &RestParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    let mut scene = Scene::empty(ROD_AT_REST.info.id);
    scene.duration = p.duration;
    scene.settle = Some(Settle {
        velocity_tol: 1e-9,
        min_time: 0.0,
    });
    let rod = RodBody::uniform(p.length, p.radius, p.youngs_modulus, 0.3, 6450.0);
    scene.bodies.push(rod.into());
    // Watchdogs: energy growth past 10x 1e-6 J, a node 10x the length away.
    let run = ScenarioRun::new(scene, AtRest { length: p.length }, 1e-6, p.length);
    Ok(run.with_reference_tip([p.length, 0.0, 0.0]))
}
