use std::collections::BTreeMap;
use surgbench_comparisons::params;
use surgbench_comparisons::scenario::{
    Metrics, ParamSpec, Params, Range, Scenario, ScenarioInfo, ScenarioRun, Scorer, UsageError, sweep_of,
};
use surgbench_core::{Family, Fidelity, Observation, RodBody, Scene, Settle, Vec3};

/// `rod-at-rest`: an unloaded straight rod must stay where it is.
pub struct RodAtRest;

const INFO: ScenarioInfo = ScenarioInfo {
    id: "rod-at-rest",
    description: "unloaded straight rod clamped at the origin: nothing moves",
    family: Family::Rod,
    reference: "closed form: the tip stays at (L, 0, 0)",
    primary_error: "tip_error_m",
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

/// One instance: the scene and what the scorer compares against.
struct RestRun {
    scene: Scene,
    length: f64,
}

impl RestRun {
    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = BTreeMap::new();
        if let Some(rod) = obs.rods.first() {
            let want = Vec3::new(self.length, 0.0, 0.0);
            m.insert("tip_error_m".into(), (rod.tip() - want).norm());
        }
        m
    }
}

impl ScenarioRun for RestRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    // Metrics of one observation alone: a closure is a Scorer. A scene with
    // run-wide metrics (peak force, time to reach) returns its own struct
    // that sums in `observe_step(&mut self, obs)`.
    fn scorer(&self) -> Box<dyn Scorer + '_> {
        Box::new(|obs: &Observation| self.score(obs))
    }
    fn energy_scale(&self) -> f64 {
        1e-6 // J: the watchdog trips on growth past 10x this
    }
    fn length_scale(&self) -> f64 {
        self.length // m: a node 10x this far from the origin trips the watchdog
    }
}

impl Scenario for RodAtRest {
    fn info(&self) -> &'static ScenarioInfo {
        &INFO
    }
    fn params(&self) -> &'static [ParamSpec] {
        RestParams::SPECS
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[10.0, 20.0, 40.0])
    }
    fn instantiate_at(&self, params: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let p = RestParams::of(params); // p.length, p.radius, ...: a typo does not compile
        let mut scene = Scene::empty(INFO.id);
        scene.duration = p.duration;
        scene.settle = Some(Settle {
            velocity_tol: 1e-9,
            min_time: 0.0,
        });
        scene
            .bodies
            .push(RodBody::uniform(p.length, p.radius, p.youngs_modulus, 0.3, 6450.0).into());
        Ok(Box::new(RestRun {
            scene,
            length: p.length,
        }))
    }
}
