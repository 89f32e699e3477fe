//! Helpers shared by the chain-mail guidewire tests: scenes, wire
//! configurations, and a busy run to compare reruns.
#![allow(dead_code)]

use std::sync::Arc;
use surgbench_chainmail::mapping::{self, BETA_CONSTANT};
use surgbench_chainmail::{BoxFrame, ChainmailFactory, ChainmailWire, WireConfig};
use surgbench_core::flow::FlowField;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{DeviceCommand, Fidelity, ModelFactory, RodBody, Scene, Vec3};

pub fn cantilever(g: f64) -> Scene {
    let mut s = Scene::empty("cantilever");
    s.bodies.push(RodBody::uniform(0.2, 5e-4, 5e10, 0.3, 6450.0).into());
    s.gravity = Vec3::new(0.0, 0.0, -g);
    s
}

pub fn cfg(dt: f64, beta: Option<f64>, frame: BoxFrame) -> WireConfig {
    WireConfig {
        segments: 20,
        iterations: 10,
        dt,
        frame,
        beta_constant: BETA_CONSTANT,
        beta_mapping: mapping::BetaMapping::Weight,
        beta_override: beta,
        haptic_k: None,
    }
}

pub fn wire(scene: &Scene, c: &WireConfig) -> ChainmailWire {
    ChainmailWire::new(scene.rods().next().unwrap(), scene.gravity, &scene.environment, c).unwrap()
}

pub fn settle(w: &mut ChainmailWire, dt: f64, steps: usize) {
    for _ in 0..steps {
        w.advance(dt, &DeviceCommand::default()).unwrap();
    }
}

#[derive(Debug)]
pub struct Swirl;

impl FlowField for Swirl {
    fn velocity(&self, p: &Vec3) -> Vec3 {
        Vec3::new(0.01, -p.z, p.y) * 0.5
    }
}

pub fn busy_scene(c_f: f64) -> Scene {
    let mut s = cantilever(9.81);
    s.environment.vessel = Some(Arc::new(StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1.5e-3,
    }));
    s.environment.flow = Some(Arc::new(Swirl));
    s.environment.contact.friction_static = c_f;
    s.environment.contact.margin = 1e-4;
    s
}

/// `steps` steps of 10 ms of the default chain-mail in `s`, pushing and
/// turning the wire a little every step; every observation.
pub fn push_and_turn(s: &Scene, steps: usize) -> Vec<surgbench_core::Observation> {
    let mut m = ChainmailFactory.build(s, &Fidelity::default()).unwrap();
    let mut obs = Vec::new();
    for k in 0..steps {
        let cmd = DeviceCommand {
            insertion: 2e-4 * k as f64,
            rotation: 0.01 * k as f64,
            load: 0.0,
            base_pose: None,
        };
        m.step(0.01, &cmd).unwrap();
        obs.push(m.observe());
    }
    obs
}
