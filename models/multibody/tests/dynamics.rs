//! Dynamics of the rigid chain (multibody joints): an undamped chain loses
//! energy exactly as rapier's backward-Euler joint springs predict and never
//! gains any, and reruns are bit for bit the same.

use surgbench_core::beam::{FIRST_CANTILEVER_MODE, cantilever_mode, first_bending_frequency};
use surgbench_core::rod::VelocitySample;
use surgbench_core::{DeviceCommand, RodBody, RodVelocity, Vec3};
use surgbench_multibody::{ChainParams, RigidChain};

/// The default rod scenes' wire (0.1 m, radius 0.5 mm, E = 50 GPa)
/// started in its first bending mode with tip speed `amplitude * omega_1`.
fn vibrating_wire(amplitude: f64) -> (RodBody, f64) {
    let mut body = RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0);
    let omega = first_bending_frequency(&body.sections[0], body.length);
    let b = FIRST_CANTILEVER_MODE;
    let tip = cantilever_mode(b, 1.0).0;
    let samples = (0..=200)
        .map(|i| {
            let xi = i as f64 / 200.0;
            let (phi, dphi) = cantilever_mode(b, xi);
            VelocitySample {
                s: xi * body.length,
                velocity: Vec3::new(0.0, 0.0, amplitude * omega * phi / tip),
                angular_velocity: Vec3::new(0.0, -amplitude * omega * dphi / (body.length * tip), 0.0),
            }
        })
        .collect();
    body.initial_velocity = Some(RodVelocity { samples });
    (body, omega)
}

/// Undamped, no gravity, dt = 0.1 ms, 4 substeps (omega_1 h = 0.0061 per
/// substep h): rapier's joint springs are backward Euler per substep, so
/// after each period the energy is what backward Euler leaves of a linear
/// oscillator at omega_1, `(1 + omega^2 h^2)^(-T/h)` = 0.9622 per period.
/// Within a period the energy swings by up to 0.2 % above its value at the
/// period's start (measured: the configuration-dependent mass matrix and
/// Coriolis terms rapier treats semi-implicitly); it never grows from one
/// period to the next.
#[test]
fn undamped_energy_decays_as_backward_euler() {
    let (body, omega) = vibrating_wire(1e-4);
    let dt = 1e-4;
    let p = ChainParams {
        links: 20,
        substeps: 4,
        ..Default::default()
    };
    let h = dt / p.substeps as f64;
    let mut c = RigidChain::new(&body, Vec3::zeros(), &p, 0.0).unwrap();
    let period = 2.0 * std::f64::consts::PI / omega;
    let steps = (period / dt).round() as usize;
    let per_period = (1.0 + (omega * h).powi(2)).powf(-(steps as f64 * dt / h));
    let mut start = c.energies().total();
    let mut ratios = Vec::new();
    let mut swing: f64 = 0.0;
    for _ in 0..5 {
        for _ in 0..steps {
            c.step(dt, &DeviceCommand::default()).unwrap();
            swing = swing.max(c.energies().total() / start - 1.0);
        }
        let e = c.energies().total();
        ratios.push(e / start);
        start = e;
    }
    println!("energy per period {ratios:?}, backward Euler {per_period:.5}, largest swing {swing:.2e}");
    for r in &ratios {
        // The chain's first frequency is the beam's to O(h^2) (0.1 % at 20
        // links: 4e-5 on the ratio) and the sampled field puts a little
        // energy into faster decaying higher modes; measured 7e-5.
        assert!(
            (r - per_period).abs() < 5e-4,
            "per-period energy ratio {r}, backward Euler {per_period}"
        );
    }
    // Measured 2.0e-3 (see above); the bound catches any secular growth.
    assert!(swing < 3e-3, "energy rose {swing:e} above a period's start");
}

/// Two runs of the same chain, gravity and a ramped tip force on: every
/// number observed is bit for bit the same (rapier single-threaded, same binary).
#[test]
fn reruns_are_bit_identical() {
    let (mut body, _) = vibrating_wire(1e-3);
    body.tip_force = Vec3::new(0.0, 1e-3, -2e-3);
    body.tip_load_ramp = Some(surgbench_core::LoadRamp::linear(0.0, 0.05));
    let run = || {
        let p = ChainParams {
            links: 16,
            damping_ratio: 0.3,
            ..Default::default()
        };
        let mut c = RigidChain::new(&body, Vec3::new(0.0, 0.0, -9.81), &p, 0.3).unwrap();
        let cmd = DeviceCommand {
            rotation: 0.3,
            ..Default::default()
        };
        for _ in 0..100 {
            c.step(1e-3, &cmd).unwrap();
        }
        (c.rod_obs(), c.energies(), c.hand_wrench())
    };
    let (a, b) = (run(), run());
    assert!(a.0.nodes.iter().all(|x| x.iter().all(|v| v.is_finite())));
    assert_eq!(a, b);
}
