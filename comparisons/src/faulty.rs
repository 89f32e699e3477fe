//! Deliberately broken models that exercise the harness's isolation and
//! watchdogs: one panics, one aborts, one hangs, one goes non-finite.
//! Registered only when the environment variable `SURGBENCH_FAULTY_MODELS`
//! is `1` (the CLI tests set it); never part of a normal comparison.

use surgbench_core::{
    BuildError, Capability, DeviceCommand, Family, Fidelity, Model, ModelFactory, Observation, RodObs, Scene, Settings,
    SimError, StepStats, Vec3,
};

/// How the model misbehaves.
#[derive(Debug, Clone, Copy)]
pub enum Fault {
    /// Panics in the third step.
    Panic,
    /// Aborts the process in the third step.
    Abort,
    /// Sleeps forever in the third step.
    Hang,
    /// Returns NaN positions from the third step on.
    NonFinite,
}

/// Factory of a faulty model.
pub struct FaultyFactory(pub Fault);

/// The panicking model.
pub static PANIC: FaultyFactory = FaultyFactory(Fault::Panic);
/// The aborting model.
pub static ABORT: FaultyFactory = FaultyFactory(Fault::Abort);
/// The hanging model.
pub static HANG: FaultyFactory = FaultyFactory(Fault::Hang);
/// The non-finite model.
pub static NONFINITE: FaultyFactory = FaultyFactory(Fault::NonFinite);

struct Faulty {
    fault: Fault,
    steps: usize,
    t: f64,
    dt: f64,
    length: f64,
}

impl Model for Faulty {
    fn step(&mut self, dt: f64, _cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.steps += 1;
        self.t += dt;
        if self.steps == 3 {
            match self.fault {
                Fault::Panic => panic!("faulty model panicked on purpose at step 3"),
                Fault::Abort => std::process::abort(),
                Fault::Hang => loop {
                    std::thread::sleep(std::time::Duration::from_secs(3600));
                },
                Fault::NonFinite => {}
            }
        }
        Ok(StepStats {
            iterations: 1,
            residual: 0.0,
            converged: true,
        })
    }

    fn observe(&self) -> Observation {
        let bad = matches!(self.fault, Fault::NonFinite) && self.steps >= 3;
        let x = if bad { f64::NAN } else { self.length };
        Observation {
            time: self.t,
            rods: vec![RodObs {
                arclength: vec![0.0, self.length],
                rest: vec![Vec3::zeros(), Vec3::new(self.length, 0.0, 0.0)],
                nodes: vec![Vec3::zeros(), Vec3::new(x, 0.0, 0.0)],
                velocities: vec![Vec3::zeros(); 2],
                frames: vec![surgbench_core::Mat3::identity()],
                max_stretch: 0.0,
            }],
            ..Default::default()
        }
    }

    fn dt(&self) -> f64 {
        self.dt
    }
}

const CAPS: &[Capability] = &[Capability::Rod, Capability::Twist, Capability::TipForce];

impl ModelFactory for FaultyFactory {
    fn id(&self) -> &'static str {
        match self.0 {
            Fault::Panic => "faulty-panic",
            Fault::Abort => "faulty-abort",
            Fault::Hang => "faulty-hang",
            Fault::NonFinite => "faulty-nonfinite",
        }
    }
    fn description(&self) -> &'static str {
        "test double that misbehaves on purpose (harness isolation tests)"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn capabilities(&self) -> &'static [Capability] {
        CAPS
    }
    fn default_fidelity(&self, _scene: &Scene) -> Fidelity {
        Fidelity {
            dt: Some(1e-3),
            ..Default::default()
        }
    }
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let length = scene.rods().next().map(|r| r.length).unwrap_or(1.0);
        Ok(Box::new(Faulty {
            fault: self.0,
            steps: 0,
            t: 0.0,
            dt: settings.fidelity().dt.unwrap_or(1e-3),
            length,
        }))
    }
}
