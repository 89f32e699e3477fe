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

mod common;
use common::{sagging_wire, wire_body, x_tube};

/// Sagging onto the wall of a 1 mm tube (free sag would be ~4 mm): at rest,
/// hand force + wall forces balance the weight, and no node penetrates.
#[test]
fn wire_resting_on_tube_wall_balances_forces() {
    let body = wire_body();
    let mut rod = sagging_wire(&body, 40);
    let tube = x_tube();
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

/// The contact penalty energy is part of the reported energy and of the
/// energy probe, consistent with the contact force: a 0.2 m wire sagging
/// onto a 1 mm tube's wall under gravity (frictionless) comes to rest; then
/// * for every node in contact (all on the cubic onset of the penalty),
///   minus the central difference of `contact_energy` over its position
///   equals its reported wall force;
/// * the probe's generalised forces (elastic + gravity + wall) vanish on
///   the free coordinates: the wall force is in them, and the wire is at
///   rest;
/// * `energies().elastic` = strain energy + penalty energy;
/// * one node pushed 5 um deeper (the quadratic part of the penalty): the
///   probe's wall force (probe forces with minus without the vessel) is
///   minus the central difference of `contact_energy`.
#[test]
fn contact_energy_is_consistent_with_contact_forces() {
    use surgbench_core::EnergyProbe;
    let body = wire_body();
    let mut rod = sagging_wire(&body, 20);
    let mut free = rod.clone();
    let tube = x_tube();
    let contact = ContactParams {
        friction_static: 0.0,
        friction_dynamic: 0.0,
        margin: 2e-4,
    };
    rod.set_vessel(Some(Arc::new(tube)), contact);
    for k in 0..400 {
        let st = rod.step(1e-3, &DeviceCommand::default()).unwrap();
        assert!(st.converged, "step {k}: {st:?}");
    }
    let contacts = rod.contacts().to_vec();
    assert!(
        contacts.len() >= 3,
        "wire should lie on the wall: {} contacts",
        contacts.len()
    );
    let e0 = rod.contact_energy();
    assert!(e0 > 0.0, "penalty energy {e0:e} J with {} contacts", contacts.len());
    let q0 = rod.coords().to_vec();
    let (mut worst, mut fmax) = (0.0f64, 0.0f64);
    let onset = 1e-5 * body.length;
    for c in &contacts {
        let k = (0..rod.num_nodes())
            .find(|&k| rod.node(k) == c.point)
            .expect("contact at a node");
        let d = tube.distance(&c.point) + contact.margin;
        // Step 1e-3 of the depth: on the cubic onset (d < eps_c) central
        // differences err by h^2 / (3 d^2) = 3.3e-7 relative, past it the
        // quadratic is differenced exactly.
        let h = 1e-3 * d;
        let mut g = Vec3::zeros();
        for a in 0..3 {
            let mut q = q0.clone();
            q[4 * k + a] += h;
            rod.set_coords(&q);
            let ep = rod.contact_energy();
            q[4 * k + a] -= 2.0 * h;
            rod.set_coords(&q);
            let em = rod.contact_energy();
            g[a] = (ep - em) / (2.0 * h);
        }
        rod.set_coords(&q0);
        let err = (c.force + g).norm() / c.force.norm();
        eprintln!(
            "node {k}: depth {d:.3e} m ({}), wall force {:?} N, -dE/dx {:?}, rel err {err:.1e}",
            if d < onset { "onset" } else { "quadratic" },
            c.force,
            -g
        );
        worst = worst.max(err);
        fmax = fmax.max(c.force.norm());
    }
    // Truncation 3.3e-7 (above); rounding of the energy (~1e-9 J, to 1e-25 J)
    // over h >= 1e-11 m is 1e-14 N against forces >= 1e-4 N.
    assert!(worst < 1e-6, "contact force vs -dE/dx: worst rel err {worst:e}");

    let f = rod.forces();
    let residual = rod.free().iter().map(|&i| f[i].abs()).fold(0.0, f64::max);
    eprintln!("probe forces at rest: largest {residual:.2e} N (largest wall force {fmax:.2e} N)");
    // At rest the probe's forces (elastic + gravity + wall) are the Newton
    // residual of the last step (measured 1.8e-11 N); without the wall force
    // in the probe they would be the wall force itself (2.8e-4 N). 1e-3 of
    // the largest wall force tells the two apart by orders of magnitude.
    assert!(
        residual < 1e-3 * fmax,
        "probe forces at rest {residual:e} N, wall force {fmax:e} N"
    );
    let e = rod.energies();
    let split = e.elastic - rod.elastic_energy() - e0;
    assert!(
        split.abs() <= 1e-15 * e.elastic.abs(),
        "elastic {} != strain {} + penalty {e0}",
        e.elastic,
        rod.elastic_energy()
    );

    // Quadratic regime: push the last contact node 5 um into the wall
    // (depth 2.5 eps_c): the penalty is quadratic there, central differences
    // are exact up to rounding.
    let k = (0..rod.num_nodes())
        .find(|&k| rod.node(k) == contacts[contacts.len() - 1].point)
        .unwrap();
    let mut q = q0.clone();
    q[4 * k + 2] -= 5e-6;
    rod.set_coords(&q);
    free.set_coords(&q);
    let d = tube.distance(&rod.node(k)) + contact.margin;
    assert!(d > onset, "depth {d:e} m should be past the onset {onset:e} m");
    let (fw, ff) = (rod.forces(), free.forces());
    let wall = Vec3::new(
        fw[4 * k] - ff[4 * k],
        fw[4 * k + 1] - ff[4 * k + 1],
        fw[4 * k + 2] - ff[4 * k + 2],
    );
    let h = 1e-9;
    let mut g = Vec3::zeros();
    for a in 0..3 {
        let mut qp = q.clone();
        qp[4 * k + a] += h;
        rod.set_coords(&qp);
        let ep = rod.contact_energy();
        qp[4 * k + a] -= 2.0 * h;
        rod.set_coords(&qp);
        let em = rod.contact_energy();
        rod.set_coords(&q);
        g[a] = (ep - em) / (2.0 * h);
    }
    let err = (wall + g).norm() / wall.norm();
    eprintln!(
        "node {k} at depth {d:.3e} m: probe wall force {wall:?} N, -dE/dx {:?}, rel err {err:.1e}",
        -g
    );
    // Quadratic: no truncation; rounding of the energy (~1e-4 J, to 1e-20 J)
    // over h = 1e-9 m is 1e-11 N against ~30 N: 1e-9 leaves room.
    assert!(
        err < 1e-9,
        "probe wall force {wall:?} vs -dE/dx {:?}: rel err {err:e}",
        -g
    );
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

/// What a push into the dead end measured.
#[derive(Debug)]
struct DeadEndRun {
    /// Deepest node past the margin surface at the end (m).
    depth: f64,
    /// Largest normal force on one node from the end wall, at the end (N).
    end_force: f64,
    /// Largest normal force on one node from the tube wall, at the end (N).
    side_force: f64,
    /// Largest distance of a node from the tube axis (m).
    lateral: f64,
    /// Largest ratio over the steps of `|edge strain| EA` to the axial
    /// force the hand and the wall friction can put in the wire,
    /// `push + mu_s * sum(tube-wall normal forces)`.
    strain_ratio: f64,
    /// Push force at the hand at the end (N).
    push: f64,
    /// Sum of the tube-wall normal forces at the end (N).
    side_total: f64,
    /// Axial stiffness EA (N).
    ea: f64,
}

/// Depth past the margin surface (m) at which the rod's C2 penalty carries
/// a normal force `f` (N): `sqrt(2 eps f / k)` on the cubic onset
/// (`f < k eps / 2`), `f / k + eps / 2` past it, with `k = 10 EA / |e|` and
/// `eps = 1e-5 L` (the rod's module docs, "Contact").
fn penalty_depth(f: f64, k: f64, eps: f64) -> f64 {
    if f < 0.5 * k * eps {
        (2.0 * eps * f / k).sqrt()
    } else {
        f / k + 0.5 * eps
    }
}

/// Push a 0.1 m nitinol wire (r = 0.2 mm) `push` m into a 2 mm tube closed
/// at x = 0.105 m (the tip starts 5 mm short of it), with `segments`
/// segments, the clamp ramped over `ramp` steps of 1 ms, then held for
/// `hold` steps; gravity breaks the symmetry (a perfectly straight push
/// never buckles), damping 20 1/s, friction `mu` (static, dynamic).
fn push_into_dead_end(segments: usize, push: f64, ramp: usize, hold: usize, mu: (f64, f64)) -> DeadEndRun {
    let body = RodBody::uniform(0.1, 2e-4, 5e10, 0.3, 6450.0);
    let mut rod = DerRod::from_body(&body, segments).unwrap();
    rod.gravity = Vec3::new(0.0, 0.0, -9.81);
    rod.params.damping = 20.0;
    let vessel = Arc::new(DeadEnd {
        tube: StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 2e-3,
        },
        end: 0.105,
    });
    let contact = ContactParams {
        friction_static: mu.0,
        friction_dynamic: mu.1,
        margin: 2e-4,
    };
    rod.set_vessel(Some(vessel.clone()), contact);
    let sec = &body.sections[0];
    let ea = sec.youngs_modulus * sec.area();
    // Normal forces of the end wall (largest on one node) and of the tube
    // wall (largest, sum).
    let forces = |rod: &DerRod| {
        let (mut end, mut side, mut total): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for c in rod.contacts() {
            let n = vessel.gradient(&c.point);
            let f = -c.force.dot(&n);
            if n == Vec3::x() {
                end = end.max(f);
            } else {
                side = side.max(f);
                total += f;
            }
        }
        (end, side, total)
    };
    let mut strain_ratio: f64 = 0.0;
    for k in 1..=ramp + hold {
        let ins = push * (k as f64 / ramp as f64).min(1.0);
        let cmd = DeviceCommand {
            insertion: ins,
            ..Default::default()
        };
        rod.step(1e-3, &cmd)
            .unwrap_or_else(|e| panic!("{segments} segments, mu {mu:?}: step {k}: {e}"));
        let axial = -rod.hand_wrench().0.x + mu.0 * forces(&rod).2;
        strain_ratio = strain_ratio.max(rod.max_stretch().abs() * ea / axial);
    }
    let n = rod.num_nodes();
    let depth = (2..n)
        .map(|k| vessel.distance(&rod.node(k)) + contact.margin)
        .fold(f64::NEG_INFINITY, f64::max);
    let (end_force, side_force, side_total) = forces(&rod);
    DeadEndRun {
        depth,
        end_force,
        side_force,
        side_total,
        strain_ratio,
        push: -rod.hand_wrench().0.x,
        lateral: (0..n).map(|k| rod.node(k).yz().norm()).fold(0.0, f64::max),
        ea,
    }
}

/// Bounds a push into the dead end must meet, derived from the contact
/// model and the forces measured at the hand and the walls (not a depth of
/// zero). With friction the wire can carry more axial force than the push:
/// when it recoils (the clamp stops, the buckled wire relaxes) static
/// friction on the tube wall holds it against the end, up to `mu_s` times
/// the tube-wall normal forces. So, with `F = push + mu_s sum(N_side)`:
/// * node forces: the end wall carries at most `F`; a tube-wall node of a
///   helically buckled wire carries the contact force per length
///   `w = r_c F^2 / (4 EI)` (Lubinski et al. 1962; Mitchell 1988, "New
///   concepts for helical buckling"; `r_c` = 1.8 mm the radial clearance of
///   the centreline) over at most two edges (a discrete helix touching at
///   every other node at worst): `2 w |e|`;
/// * penetration: a penalty contact sits past the margin surface by the
///   depth that carries its force (`penalty_depth`), so no node may be
///   deeper than the penalty depth of the larger of those two forces;
/// * compression: a straight wire under an axial force `F` is strained by
///   `F / EA`; in the buckled wire the internal force also has a shear
///   part, which the inclined edges partly turn into tension, so the edge
///   strain may exceed `F / EA` by a fraction of the order of the helix
///   angle: measured up to 4% (10 mm push, 20 segments). Bound `1.1 F / EA`
///   at every step;
/// * the wire buckles sideways (lateral > 1 mm in the 1.8 mm margin
///   surface) and the end pushes back on the hand.
fn check_dead_end(r: &DeadEndRun, segments: usize, mu_s: f64, what: &str) {
    let (l, radius, e) = (0.1, 2e-4, 5e10);
    let ei = e * std::f64::consts::PI * radius * radius * radius * radius / 4.0;
    let edge = l / segments as f64;
    let axial = r.push + mu_s * r.side_total;
    let helix = 2.0 * 1.8e-3 * axial * axial / (4.0 * ei) * edge;
    let k = 10.0 * r.ea / edge;
    let depth_bound = penalty_depth(axial.max(helix), k, 1e-5 * l);
    eprintln!(
        "{what}: {r:?}; axial bound {axial:.3e} N, helix node force {helix:.3e} N, depth bound {depth_bound:.3e} m"
    );
    assert!(
        r.end_force <= axial,
        "{what}: end-wall node force {:e} N exceeds push + friction {axial:e} N",
        r.end_force
    );
    assert!(
        r.side_force <= helix,
        "{what}: tube-wall node force {:e} N exceeds the helical-buckling estimate {helix:e} N",
        r.side_force
    );
    assert!(
        r.depth <= depth_bound,
        "{what}: node {:e} m past the margin surface, penalty depth bound {depth_bound:e} m",
        r.depth
    );
    assert!(
        r.strain_ratio <= 1.1,
        "{what}: edge strain reached {:.3} times (push + friction) / EA",
        r.strain_ratio
    );
    assert!(
        r.lateral > 1e-3,
        "{what}: wire should buckle sideways (max lateral {} m)",
        r.lateral
    );
    assert!(r.push > 0.0, "{what}: the wall must push back on the hand");
}

/// Push a wire 8 mm into a dead end at 20 segments (the tip meets the end
/// after 5 mm): it buckles inside the tube, the solve stays stable, and
/// depth and compression stay within what the penalty contact and the
/// push force explain (see `check_dead_end`). The small version of the
/// ignored 30 mm push below. Measured (8 mm over 160 ms, 50 mm/s): depth
/// 7.9e-7 m (bound 8.8e-7 m), end-wall force 3.94 N (push 3.63 N + friction
/// capacity 1.20 N), strain up to 1.046 (push + friction) / EA.
///
/// OPEN: the same push over 120 ms (67 mm/s) breaks the force bounds: end
/// wall 4.82 N against push + mu_s sum N = 4.24 N, strain ratio 1.18, depth
/// 8.76e-7 m against 8.22e-7 m. Not explained yet (candidates: the one-step
/// lag of the friction's normal force, which lets friction exceed
/// `mu_s N` of the current step when the normal force drops; dynamics of
/// the faster recoil).
#[test]
fn pushing_into_dead_end_buckles_within_penalty_depth() {
    let r = push_into_dead_end(20, 0.008, 160, 40, (0.2, 0.15));
    check_dead_end(&r, 20, 0.2, "8 mm push, 20 segments, friction 0.2/0.15");
}

/// Push a wire 3 cm into a dead end at 40 segments with friction: it buckles
/// helically inside the tube, the solve stays stable.
///
/// Slow (about 4 minutes in release on a loaded machine: the wedged wire
/// needs many substeps), hence ignored; the 8 mm push above tests the
/// same bounds in a fraction of a second. History, measured with this test:
/// the old bounds (1e-9 m depth, 1e-3 strain) were not physical. The run
/// completes with nodes up to 1.2e-6 m past the margin surface and a
/// compression of 3.3e-3 at a peak push of 43 N: the penalty
/// (`k = 10 EA / |e|` = 2.5e7 N/m, onset 1e-6 m) puts a node carrying F
/// at F/k + 0.5e-6 m (1.2e-6 m for ~18 N), and a 30 N axial load on the
/// 0.2 mm wire (EA = 6.3e3 N) is a strain of 4.8e-3. Frictionless, it
/// completes at 3.8e-3 compression (the ~24 N helical-buckling force
/// `8 pi^2 EI / p^2` of a 13.6 mm pitch).
#[test]
#[ignore = "slow (minutes); the 8 mm push pushing_into_dead_end_buckles_within_penalty_depth tests the same bounds"]
fn pushing_into_dead_end_buckles_without_penetration() {
    let r = push_into_dead_end(40, 0.03, 400, 200, (0.2, 0.15));
    check_dead_end(&r, 40, 0.2, "30 mm push, 40 segments, friction 0.2/0.15");
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
    let key = |t, insertion| ControlKey::feed(t, insertion, 0.0);
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
    let key = |t, insertion| ControlKey::feed(t, insertion, 0.0);
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
        // stop apart; only rounding differs. Measured 1.2e-16 m (mu 0) and
        // 1.9e-12 m (mu 0.3; 4e-13 m with the former finite-difference wall
        // curvature); the defect gave 4e-5 m.
        let bound = 1e-9 * 43.56e-3;
        assert!(
            worst <= bound,
            "mu {mu}: rigidly moved scene differs by {worst:e} m (bound {bound:e} m)"
        );
    }
}
