//! Contact with a vessel: a wire sagging onto a tube wall (force balance with
//! the wall forces, non-penetration), a wire pushed into a dead end until
//! it buckles, and a wire sliding through a bend in two rigidly related
//! frames (frame independence, Coulomb sliding).

use nalgebra::{Translation3, Unit, UnitQuaternion};
use std::sync::Arc;
use surgbench_core::sdf::{CenterlineBuilder, StraightTube};
use surgbench_core::{
    ContactParams, ControlKey, ControlTimeline, DeviceCommand, Fidelity, Iso3, ModelFactory, Observation, RodBody,
    Scene, Sdf, Vec3,
};
use surgbench_der::{DerFactory, DerRod};

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
    // Penalty contact: a node carrying a wall force F sits d(F) past the
    // margin surface, with d = sqrt(2 eps F / k) on the cubic onset
    // (k = 10 EA/|e|, eps = 1e-5 L; see the rod docs). No node carries more
    // than the whole weight, so d(weight) bounds the depth (measured 1.0e-8 m
    // against a bound of 2.0e-8 m), far inside the 0.2 mm margin: the wall
    // itself is never reached.
    let sec = &body.sections[0];
    let k = 10.0 * sec.youngs_modulus * sec.area() / (body.length / 40.0);
    let eps = 1e-5 * body.length;
    let bound = (2.0 * eps * weight / k).sqrt();
    assert!(
        worst <= bound,
        "node past the margin surface by {worst:e} m, penalty bound {bound:e} m"
    );
    // Rod in equilibrium: the rod pushes the hand down with the part of the
    // weight the wall does not carry: hand - wall = -weight. The wall force
    // is the converged penalty + friction force, part of the solve, so the
    // balance holds to the Newton tolerance (1e-9 L on the update; measured
    // 2.6e-12 relative). Tolerance 1e-8 relative.
    assert!(
        balance < 1e-8,
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
/// KNOWN LIMIT (ignored): with the step control and adaptive substepping
/// of the rod (see its module docs), the frictionless push completes the
/// 30 mm but compresses the wire by 3.8e-3 (the ~24 N helical-buckling
/// force of 30% excess length in the lumen, so the 1e-3 stretch bound below
/// is not physical at that push). With friction 0.2/0.15 an edge used to
/// collapse (`Diverged`) after 7-12 mm of push; since the friction-apex
/// step cap the run completes (about 4 minutes) but fails the bounds below:
/// a node 1.2e-6 m past the margin surface (the penalty depth of ~30 N
/// the end carries, against the 1e-9 m bound) and compression 3.3e-3. The
/// tip first touches the end at 4.9 mm. Measured with this test (run it
/// with `--ignored`).
#[test]
#[ignore = "known limit: slow (minutes); the wedged wire exceeds the 1e-9 m depth and 1e-3 stretch bounds, see doc"]
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

/// Capstan-like scene (the harness's `capstan`, coarse): a soft wire fed
/// through a tube that turns by 90 degrees, its tip pulled against the
/// wall by a dead force, friction 0.3.
fn capstan_scene() -> Scene {
    let (r, lumen, rc, theta) = (0.445e-3, 0.7e-3, 15e-3, std::f64::consts::FRAC_PI_2);
    let tube = CenterlineBuilder::new(Vec3::new(-5e-3, 0.0, 0.0), Vec3::x())
        .line(15e-3)
        .arc(rc, theta, Vec3::y())
        .line(40e-3)
        .build_constant(lumen)
        .unwrap();
    let mut rod = RodBody::uniform(5e-3, r, 2e8, 0.3, 6450.0);
    rod.tip_force = Vec3::new(theta.cos(), theta.sin(), 0.0);
    let mut s = Scene::empty("capstan");
    s.duration = 2.0;
    s.bodies.push(rod.into());
    s.environment.vessel = Some(Arc::new(tube));
    s.environment.contact = ContactParams {
        friction_static: 0.3,
        friction_dynamic: 0.3,
        margin: r,
    };
    let key = |t, insertion| ControlKey {
        t,
        insertion,
        rotation: 0.0,
    };
    s.control = ControlTimeline {
        keys: vec![key(0.0, 0.0), key(1.0, 0.02)],
    };
    s
}

/// The harness's `capstan` at its start (comparisons/src/scenarios/vessel.rs,
/// default parameters): the 43.6 mm wire lies straight in the entry of a
/// 0.7 mm tube along +x, a 1 N dead tip force along +y (the exit direction
/// after the 90 degree bend) presses the tip onto the wall, and the clamp
/// feeds at 20 mm/s; friction `mu` (static = dynamic).
fn capstan_start_scene(mu: f64) -> Scene {
    let (r, lumen, rc, theta) = (0.445e-3, 0.7e-3, 15e-3, std::f64::consts::FRAC_PI_2);
    let entry = rc * theta + 15e-3 + 10e-3;
    let tube = CenterlineBuilder::new(Vec3::new(-5e-3, 0.0, 0.0), Vec3::x())
        .line(5e-3 + entry)
        .arc(rc, theta, Vec3::y())
        .line(40e-3)
        .build_constant(lumen)
        .unwrap();
    let mut rod = RodBody::uniform(entry - 5e-3, r, 2e8, 0.3, 6450.0);
    rod.tip_force = Vec3::new(theta.cos(), theta.sin(), 0.0);
    let mut s = Scene::empty("capstan-start");
    s.duration = 2.0;
    s.bodies.push(rod.into());
    s.environment.vessel = Some(Arc::new(tube));
    s.environment.contact = ContactParams {
        friction_static: mu,
        friction_dynamic: mu,
        margin: r,
    };
    let key = |t, insertion| ControlKey {
        t,
        insertion,
        rotation: 0.0,
    };
    s.control = ControlTimeline {
        keys: vec![key(0.0, 0.0), key(1.0, 0.02)],
    };
    s
}

/// Run `steps` steps at 8 segments; every step must converge. Returns the
/// final observation, the largest stretch after each step and the Newton
/// iterations of each step.
fn run_capstan(scene: &Scene, steps: usize) -> (Observation, Vec<f64>, Vec<u32>) {
    let f = DerFactory;
    let fid = Fidelity::parse_pairs(&["segments=8"]).unwrap();
    let mut m = f.build(scene, &fid).unwrap();
    let dt = m.dt();
    let mut stretch = Vec::new();
    let mut iterations = Vec::new();
    for k in 0..steps {
        let cmd = scene.control.command_at((k + 1) as f64 * dt);
        let st = m
            .step(dt, &cmd)
            .unwrap_or_else(|e| panic!("{}: step {k}: {e}", scene.name));
        assert!(st.converged, "{}: step {k} did not converge: {st:?}", scene.name);
        stretch.push(m.observe().rods[0].max_stretch);
        iterations.push(st.iterations);
    }
    (m.observe(), stretch, iterations)
}

/// Rotation (axis (1, 2, 3), 0.7 rad) and translation used by the
/// frame-independence tests (the harness's conformance suite uses the same).
fn rigid_motion() -> Iso3 {
    Iso3::from_parts(
        Translation3::new(0.3, -0.2, 0.5),
        UnitQuaternion::from_axis_angle(&Unit::new_normalize(Vec3::new(1.0, 2.0, 3.0)), 0.7),
    )
}

/// Largest distance (m) between the nodes of `a` moved by `iso` and those of `b`.
fn node_mismatch(a: &Observation, b: &Observation, iso: &Iso3) -> f64 {
    a.rods[0]
        .nodes
        .iter()
        .zip(&b.rods[0].nodes)
        .map(|(x, y)| (iso.transform_point(&(*x).into()).coords - y).norm())
        .fold(0.0, f64::max)
}

/// Regression (harness conformance, `capstan` at 8 segments): DER diverged
/// at t = 0.017 s in one frame and not in a rigidly moved one. Cause: the
/// old post-step friction stopped the wall node every step (the impulse to
/// stop a light node is always inside the cone), so the edge behind it was
/// compressed by the whole feed (20 um, 3%) per step until it collapsed;
/// the exactly planar identity frame failed one way, the rotated frame
/// (rounding breaks the symmetry) buckled out of plane and stopped
/// converging. With friction in the solve, both frames now agree to
/// rounding and the wire slides against Coulomb friction.
#[test]
fn contact_is_frame_independent() {
    let scene = capstan_scene();
    let iso = rigid_motion();
    let moved = scene.transformed(&iso);
    let steps = 40;
    let (a, sa, _) = run_capstan(&scene, steps);
    let (b, sb, _) = run_capstan(&moved, steps);
    let worst = node_mismatch(&a, &b, &iso);
    let fa = iso.rotation * a.hand_force;
    let df = (fa - b.hand_force).norm();
    eprintln!(
        "frame independence: max node difference {worst:.2e} m, hand force difference {df:.2e} N, stretch {:.3e} / {:.3e}",
        sa[steps - 1],
        sb[steps - 1]
    );
    // Both runs take the same Newton iterations; they differ by rounding of
    // 0.5 m coordinates (1e-16 relative) amplified by the solve. The Newton
    // tolerance (1e-9 L = 5e-12 m on the last update, quadratically
    // converging) bounds what a different iteration count could cause:
    // 1e-12 m. Measured 3e-16 m.
    assert!(worst < 1e-12, "rigidly moved scene differs by {worst:e} m");
    // Hand force ~0.3 N from stiffnesses up to EA/|e| = 2e5 N/m times
    // positions agreeing to 1e-12 m: 1e-7 N. Measured 4e-12 N.
    assert!(df < 1e-7, "hand force {fa:?} vs {:?} (diff {df:e} N)", b.hand_force);
    // Steady sliding: every wall contact is on the Coulomb cone,
    // |f_t| = mu |f_n|, and the edges stay nearly inextensible (the old
    // code compressed an edge by 3% per step).
    let tube = scene.environment.vessel.as_ref().unwrap();
    let mut normal_total = 0.0;
    for c in &a.contacts {
        let n = tube.gradient(&c.point).normalize();
        let fnorm = -c.force.dot(&n);
        let ft = (c.force + n * fnorm).norm();
        normal_total += fnorm;
        // Sliding far past the stick band (20 um per step against 1e-9 m):
        // f_1 = 1 exactly; the lagged normal force changes by < 1e-9
        // relative per step once steady (measured).
        assert!(
            (ft - 0.3 * fnorm).abs() <= 1e-6 * fnorm,
            "contact at {:?}: tangential {ft:e} N vs mu * normal {:e} N",
            c.point,
            0.3 * fnorm
        );
    }
    assert!(
        normal_total > 0.5,
        "the tip force presses the wire on the wall (normal {normal_total} N)"
    );
    // Axial compression of a sliding wire: friction mu N over EA (~2.4e-3).
    let ea = 2e8 * std::f64::consts::PI * 0.445e-3f64.powi(2);
    let bound = 0.3 * normal_total / ea;
    for (k, s) in sa.iter().enumerate() {
        // Twice the friction strain: dynamic transients at the start.
        assert!(
            s.abs() <= 2.0 * bound,
            "step {k}: stretch {s:e}, friction strain {bound:e}"
        );
    }
}

/// Regression (harness conformance, `capstan` at 8 segments, 20 steps):
/// DER differed by 4e-5 m between the scene and the same scene rotated,
/// with friction 0 or 0.3. Two causes, both in the Newton solve:
///
/// * the contact Hessian was Gauss-Newton (`k n n^T`): across the tube it
///   lacked the wall-curvature stiffness `P'/rho` (4e3 N/m for the 1 N tip
///   on the wall 0.26 mm from the axis), so Newton overshot that mode and
///   it grew by 1.36 per iteration. With the scene aligned with the axes
///   the mode is exactly zero (the step converged in 3-5 iterations); rotated,
///   rounding seeded it and every step hit the 25-iteration limit (then
///   40-80 with substeps, stopping at the tolerance from a different side);
/// * with friction, a sliding tip whose solution sticks was carried by the
///   Newton step through the apex of its friction cone (slip 1e-8 m to
///   1e-4 m) and back: the steps 2-5 failed in both frames (substepped to
///   the limit, accepted unconverged, so rounding decided the answer).
///
/// Now both frames take the same iterations and agree to rounding.
#[test]
fn capstan_start_is_frame_independent() {
    let iso = rigid_motion();
    for mu in [0.0, 0.3] {
        let scene = capstan_start_scene(mu);
        let steps = 20;
        let (a, _, ia) = run_capstan(&scene, steps);
        let (b, _, ib) = run_capstan(&scene.transformed(&iso), steps);
        let worst = node_mismatch(&a, &b, &iso);
        eprintln!("capstan start, mu {mu}: max node difference {worst:.2e} m; iterations {ia:?} / {ib:?}");
        // Newton converges quadratically here: 3-8 iterations a step
        // (measured, both frames). The defect took 25 on every step of the
        // rotated frame, 40-80 with substeps. 10 leaves room for a harder step.
        for (k, (x, y)) in ia.iter().zip(&ib).enumerate() {
            assert!(
                *x <= 10 && *y <= 10,
                "mu {mu}, step {k}: {x} / {y} Newton iterations (original / rotated frame)"
            );
        }
        // The tolerance (1e-9 L = 4.4e-11 m on the last update, after which
        // the quadratic iteration is far closer) bounds how far two runs can
        // stop apart; only rounding differs. Measured 8e-17 m (mu 0) and
        // 4e-13 m (mu 0.3); the defect gave 4e-5 m.
        let bound = 1e-9 * 43.56e-3;
        assert!(
            worst <= bound,
            "mu {mu}: rigidly moved scene differs by {worst:e} m (bound {bound:e} m)"
        );
    }
}
