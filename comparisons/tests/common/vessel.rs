//! Helpers shared by the vessel-scenario tests: a kinematic test wire
//! following a prescribed path with a prescribed hand force, its factory,
//! and running a scenario with it through the runner.

use std::sync::Arc;
use surgbench_comparisons::runner::{RunOptions, RunSummary, run_single};
use surgbench_comparisons::scenario::{Params, Scenario};
use surgbench_comparisons::scenarios::vessel::{self, ENTRY_S};
use surgbench_core::{
    BuildError, Capability, DeviceCommand, Family, Fidelity, Mat3, Model, ModelFactory, Observation, RodObs, Scene,
    Settings, SimError, StepStats, Vec3,
};

pub type PathFn = Arc<dyn Fn(f64) -> Vec3 + Send + Sync>;

pub type HandFn = Arc<dyn Fn(f64, &DeviceCommand) -> Vec3 + Send + Sync>;

/// A wire whose free length `L0 + insertion` lies along `path(s)` (s from
/// the clamp), with a prescribed hand force.
pub struct Kinematic {
    pub path: PathFn,
    pub hand: HandFn,
    pub l0: f64,
    pub n: usize,
    pub t: f64,
    pub cmd: DeviceCommand,
}

impl Kinematic {
    /// A wire of free length `l0` (m) in `n` segments along `path`, with no
    /// hand force, at time zero.
    pub fn along(path: impl Fn(f64) -> Vec3 + Send + Sync + 'static, l0: f64, n: usize) -> Self {
        Kinematic {
            path: Arc::new(path),
            hand: Arc::new(|_, _| Vec3::zeros()),
            l0,
            n,
            t: 0.0,
            cmd: DeviceCommand::default(),
        }
    }
}

impl Model for Kinematic {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.t += dt;
        self.cmd = *cmd;
        Ok(StepStats::default())
    }
    fn observe(&self) -> Observation {
        let l = self.l0 + self.cmd.insertion;
        let s: Vec<f64> = (0..=self.n).map(|i| l * i as f64 / self.n as f64).collect();
        let nodes: Vec<Vec3> = s.iter().map(|&s| (self.path)(s)).collect();
        Observation {
            time: self.t,
            rods: vec![rod_obs(s, nodes, Vec3::zeros())],
            hand_force: (self.hand)(self.t, &self.cmd),
            ..Default::default()
        }
    }
    fn dt(&self) -> f64 {
        1e-3
    }
}

/// A rod observation of `nodes` at arclengths `s` (m), at their rest
/// positions, every node moving at `velocity`, frames the identity.
pub fn rod_obs(s: Vec<f64>, nodes: Vec<Vec3>, velocity: Vec3) -> RodObs {
    RodObs {
        arclength: s,
        rest: nodes.clone(),
        velocities: vec![velocity; nodes.len()],
        frames: vec![Mat3::identity(); nodes.len() - 1],
        nodes,
        max_stretch: 0.0,
    }
}

pub type Builder = Box<dyn Fn(&Scene) -> Box<dyn Model> + Send + Sync>;

pub struct TestFactory {
    pub caps: &'static [Capability],
    pub build: Builder,
}

impl ModelFactory for TestFactory {
    fn id(&self) -> &'static str {
        "test-kinematic"
    }
    fn description(&self) -> &'static str {
        "test-only model"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn capabilities(&self) -> &'static [Capability] {
        self.caps
    }
    fn default_fidelity(&self, _scene: &Scene) -> Fidelity {
        let mut f = Fidelity::default();
        f.set("dt", 1e-3).unwrap();
        f
    }
    fn build_resolved(&self, scene: &Scene, _s: &Settings) -> Result<Box<dyn Model>, BuildError> {
        Ok((self.build)(scene))
    }
}

pub const ALL_ROD_CAPS: &[Capability] = &[
    Capability::Rod,
    Capability::Twist,
    Capability::TipForce,
    Capability::LoadRamp,
    Capability::VaryingProperties,
    Capability::RestCurvature,
    Capability::Insertion,
    Capability::VesselContact,
    Capability::Friction,
    Capability::Flow,
    Capability::MovingVessel,
];

pub fn scenario(id: &str) -> &'static dyn Scenario {
    vessel::all().into_iter().find(|s| s.id() == id).unwrap()
}

pub fn run(s: &dyn Scenario, p: &Params, f: &TestFactory) -> RunSummary {
    let r = s.instantiate(p).unwrap();
    run_single(s, p, &r, f, &Fidelity::default(), &RunOptions::default()).unwrap()
}

/// Default initial free length of the `arch-insertion` wire (m).
pub const L0: f64 = 0.2;

/// The aortic arch trunk from the clamp: s -> trunk.point_at(ENTRY_S + s).
pub fn arch_follower(l0: f64, hand: Vec3) -> TestFactory {
    TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(move |_scene| {
            let trunk = surgbench_core::vessel::aortic_arch().trunk;
            Box::new(Kinematic {
                path: Arc::new(move |s| trunk.point_at(ENTRY_S + s)),
                hand: Arc::new(move |_, _| hand),
                l0,
                n: 40,
                t: 0.0,
                cmd: DeviceCommand::default(),
            })
        }),
    }
}
