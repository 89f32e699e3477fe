//! Cost of one chain-mail step: a 100-link guidewire (1 m, r = 0.5 mm) in a
//! straight 3 mm tube along its axis, lying on the tube wall under gravity,
//! pushed 1 cm in and out (period 2 s) and rotated at 1 rad/s, SDF collision and friction
//! (C_f = 0.3) on every step, default 10 relaxation sweeps, dt = 1 ms.
//! Target (DESIGN.md): <= 0.05 ms/step on one core. Two cases: the default
//! clamp-axis boxes (`frame=clamp`) and the link-frame boxes (`frame=link`).

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use surgbench_chainmail::ChainmailFactory;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{DeviceCommand, Fidelity, ModelFactory, RodBody, Scene, Vec3};

fn scene() -> Scene {
    let mut s = Scene::empty("bench-tube");
    s.bodies.push(RodBody::uniform(1.0, 5e-4, 5e10, 0.3, 6450.0).into());
    s.gravity = Vec3::new(0.0, 0.0, -9.81);
    s.environment.vessel = Some(Arc::new(StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1.5e-3,
    }));
    s.environment.contact.friction_static = 0.3;
    s.environment.contact.margin = 1e-4;
    s
}

fn command(t: f64) -> DeviceCommand {
    // push 1 cm in and back (period 2 s) so the wire keeps ~100 links, and rotate
    DeviceCommand {
        insertion: 0.005 * (1.0 - (std::f64::consts::PI * t).cos()),
        rotation: t,
        load: 0.0,
        base_pose: None,
    }
}

fn bench(c: &mut Criterion) {
    let s = scene();
    let dt = 1e-3;
    // frame=clamp: the default clamp-axis boxes; frame=link: the link-frame boxes
    // (body-frame offsets, wall contact inside the relaxation iterations),
    // the mode a curved vessel needs
    for (frame, name) in [
        ("frame=clamp", "chainmail_step_100_links_tube_push_rotate"),
        ("frame=link", "chainmail_step_100_links_tube_push_rotate_link_frame"),
    ] {
        let f = Fidelity::parse_pairs(&["segments=100", "dt=0.001", frame]).unwrap();
        let mut m = ChainmailFactory.build(&s, &f).unwrap();
        let mut k = 0u64;
        // warm up into contact
        for _ in 0..2000 {
            k += 1;
            let t = k as f64 * dt;
            m.step(dt, &command(t)).unwrap();
        }
        assert!(
            !m.observe().contacts.is_empty(),
            "bench scene has no contacts ({frame})"
        );
        c.bench_function(name, |b| {
            b.iter(|| {
                k += 1;
                let t = k as f64 * dt;
                let cmd = command(t);
                black_box(m.step(dt, &cmd).unwrap());
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
