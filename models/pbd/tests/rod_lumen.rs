//! `pbd-rod` as the rod of a coupled run: the harness replaces its lumen
//! before every step (`Model::set_lumen`); its saved state is checked by
//! the conformance suite (`tests/conformance.rs`).

use std::sync::Arc;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{DeviceCommand, Fidelity, ModelFactory, RodBody, Scene, Vec3};
use surgbench_pbd::PbdRodFactory;

/// A straight wire (r = 0.5 mm, 0.1 m) on the axis of a 2 mm tube, no
/// gravity: it rests, touching nothing.
fn scene() -> Scene {
    let mut scene = Scene::empty("wire-in-tube");
    scene.bodies.push(RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0).into());
    scene.duration = 1.0;
    scene.environment.vessel = Some(Arc::new(StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 2e-3,
    }));
    scene.environment.contact.margin = 5e-4;
    scene
}

/// A lumen moved onto the resting wire is seen at once: the wire's
/// particles, far inside the old lumen and not moving, would be skipped by
/// the SDF cache of the old lumen; after `set_lumen` the next step finds
/// them against the new wall and pushes them out of it.
#[test]
fn a_replaced_lumen_is_seen_at_the_next_step() {
    let s = scene();
    let mut m = PbdRodFactory.build(&s, &Fidelity::default()).unwrap();
    let dt = m.dt();
    for _ in 0..20 {
        m.step(dt, &DeviceCommand::default()).unwrap();
    }
    assert!(
        m.observe().contacts.is_empty(),
        "the wire rests on the axis of a 2 mm tube"
    );
    // The new lumen's wall passes 0.2 mm from the axis, inside the wire.
    m.set_lumen(Arc::new(StraightTube {
        origin: Vec3::new(0.0, 0.0, 2.2e-3),
        axis: Vec3::x(),
        radius: 2e-3,
    }))
    .unwrap();
    m.step(dt, &DeviceCommand::default()).unwrap();
    let obs = m.observe();
    assert!(!obs.contacts.is_empty(), "no contact with the new wall");
    let pushed = obs.rods[0]
        .nodes
        .iter()
        .skip(1)
        .map(|x| x.z)
        .fold(f64::INFINITY, f64::min);
    assert!(
        pushed > 0.0,
        "the free particles are pushed up, towards the new axis (lowest z {pushed:e})"
    );
}
