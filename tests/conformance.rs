//! The conformance suite every registered model runs automatically (in the
//! spirit of SOFA's ForceField test harness): forces equal minus the energy
//! gradient, rigid motions of the whole scene change nothing, the same
//! inputs give bit-identical results, an unsupported scene is refused with
//! a reason. A crate under `models/` that is not registered fails the suite.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use surgbench_comparisons::registry;
use surgbench_comparisons::scenario::Params;
use surgbench_core::rng::SplitMix64 as Rng;
use surgbench_core::{
    Body, BuildError, Capability, Fidelity, ModelFactory, Observation, RodBody, Scene, SolidMaterial, TetMesh,
    TissueBody, Vec3,
};

/// Steps every conformance run takes: enough to leave the rest state.
const STEPS: usize = 20;

/// Each supported scenario at default parameters, coarse fidelity. Tip
/// loads that a scene ramps up later (capstan: once threaded) are applied in
/// full from the start here, so the few conformance steps run the loaded
/// contact path rather than an unloaded wire.
fn supported(f: &dyn ModelFactory) -> Vec<(String, Scene)> {
    let mut v = Vec::new();
    for sc in registry::scenarios() {
        let p = Params::resolve(sc.id(), sc.params(), &[]).unwrap();
        let run = sc.instantiate(&p).unwrap();
        let mut scene = run.scene().clone();
        for b in &mut scene.bodies {
            if let Body::Rod(r) = b {
                r.tip_load_ramp = None;
            }
        }
        if f.check(&scene).is_ok() {
            v.push((sc.id().to_string(), scene));
        }
    }
    v
}

fn coarse(f: &dyn ModelFactory, scene: &Scene) -> Fidelity {
    let mut fid = f.default_fidelity(scene);
    if fid.segments.is_some() || scene.rods().next().is_some() {
        fid.segments = Some(8);
    }
    fid
}

/// Build at coarse fidelity and take `steps` steps. A step error (the model
/// diverged) is a result the report shows, not a conformance failure: it is
/// returned so determinism can still be checked on it.
fn run(f: &dyn ModelFactory, scene: &Scene, steps: usize) -> Result<Observation, String> {
    let fid = coarse(f, scene);
    let mut m = f
        .build(scene, &fid)
        .unwrap_or_else(|e| panic!("{} on {}: build failed: {e}", f.id(), scene.name));
    let dt = m.dt();
    for k in 0..steps {
        let cmd = scene.control.command_at((k + 1) as f64 * dt);
        m.step(dt, &cmd).map_err(|e| format!("step {k}: {e}"))?;
    }
    Ok(m.observe())
}

/// Force scale of a scene (N): weight of every body, dead tip forces, and
/// each rod's bending force scale `EI / L^2` (so unloaded scenes have one).
fn force_scale(scene: &Scene) -> f64 {
    let g = scene.gravity.norm();
    let rods: f64 = scene
        .rods()
        .map(|r| {
            let s0 = &r.sections[0];
            let bending = s0.youngs_modulus * s0.second_moment() / (r.length * r.length);
            r.sections.iter().map(|s| s.density * s.area()).fold(0.0, f64::max) * r.length * g
                + r.tip_force.norm()
                + bending
        })
        .sum();
    let tissues: f64 = scene
        .tissues()
        .map(|t| {
            let v: f64 = t
                .mesh
                .tets
                .iter()
                .map(|e| {
                    let [a, b, c, d] = e.map(|i| t.mesh.nodes[i]);
                    ((b - a).cross(&(c - a)).dot(&(d - a)) / 6.0).abs()
                })
                .sum();
            v * t.material.density * g
        })
        .sum();
    (rods + tissues).max(1e-12)
}

fn positions(o: &Observation) -> Vec<Vec3> {
    o.rods
        .iter()
        .flat_map(|r| r.nodes.iter().copied())
        .chain(o.tissues.iter().flat_map(|t| t.nodes.iter().copied()))
        .collect()
}

#[test]
fn every_model_crate_is_registered() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let registered: Vec<&str> = registry::models().iter().map(|r| r.krate).collect();
    for e in std::fs::read_dir(&dir).unwrap() {
        let e = e.unwrap();
        if !e.path().join("Cargo.toml").is_file() {
            continue;
        }
        let name = e.file_name().to_string_lossy().replace('-', "_");
        if name == "core" {
            continue;
        }
        let krate = format!("surgbench_{name}");
        assert!(
            registered.contains(&krate.as_str()),
            "models/{name} ({krate}) has no factory in registry::models(): {registered:?}"
        );
    }
}

#[test]
fn ids_are_unique_and_every_model_runs_something() {
    let ms = registry::models();
    for (i, a) in ms.iter().enumerate() {
        for b in &ms[i + 1..] {
            assert_ne!(a.factory.id(), b.factory.id(), "duplicate model id");
        }
    }
    for r in &ms {
        assert!(!r.factory.description().is_empty());
    }
}

#[test]
fn same_inputs_give_bit_identical_results() {
    for r in registry::models() {
        for (sid, scene) in supported(r.factory) {
            let a = run(r.factory, &scene, STEPS);
            let b = run(r.factory, &scene, STEPS);
            assert!(a == b, "{} on {sid}: two identical runs differ", r.factory.id());
            if let Err(e) = a {
                eprintln!(
                    "note: {} on {sid} diverges at coarse fidelity ({e}); determinism checked on the failure",
                    r.factory.id()
                );
            }
        }
    }
}

/// Model x scenario pairs known to break rigid-motion invariance, with what
/// was measured; each is open (noted on its issue) and checked as a strict
/// expected failure, so a fix shows up here.
const KNOWN_FRAME_DEPENDENT: &[(&str, &str, &str)] = &[];

#[test]
fn rigid_motion_of_the_scene_moves_the_answer_rigidly() {
    let iso = Isometry3::from_parts(
        Translation3::new(0.3, -0.2, 0.5),
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)), 0.7),
    );
    // Axis-aligned roller constraints can only follow a rotation that maps
    // axes to axes: scenes with them get this one (x->y, y->z, z->x).
    let permuting = Isometry3::from_parts(
        Translation3::new(-0.1, 0.4, 0.2),
        UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(1.0, 1.0, 1.0)),
            2.0 * std::f64::consts::PI / 3.0,
        ),
    );
    assert!(surgbench_core::frames::axis_permutation(&permuting).is_some());
    for r in registry::models() {
        for (sid, scene) in supported(r.factory) {
            let rollers = scene.tissues().any(|t| !t.partial_fixed.is_empty());
            let iso = if rollers { permuting } else { iso };
            let (a, b) = match (
                run(r.factory, &scene, STEPS),
                run(r.factory, &scene.transformed(&iso), STEPS),
            ) {
                (Ok(a), Ok(b)) => (a, b),
                (Err(e), Err(_)) => {
                    eprintln!(
                        "note: {} on {sid} diverges at coarse fidelity ({e}) in both frames",
                        r.factory.id()
                    );
                    continue;
                }
                (a, b) => panic!(
                    "{} on {sid}: one frame diverges and the other does not: {:?} vs {:?}",
                    r.factory.id(),
                    a.err(),
                    b.err()
                ),
            };
            let (pa, pb) = (positions(&a), positions(&b));
            assert_eq!(pa.len(), pb.len());
            let scale = pa.iter().map(|p| p.norm()).fold(0.0, f64::max).max(1e-3);
            let worst = pa
                .iter()
                .zip(&pb)
                .map(|(x, y)| (iso.transform_point(&(*x).into()).coords - y).norm())
                .fold(0.0, f64::max);
            // Only rounding differs between the two runs; iterative solvers
            // stop at their tolerance (<= 1e-10 relative by default), so the
            // answers agree to well under 1e-8 of the scene size.
            let known = KNOWN_FRAME_DEPENDENT
                .iter()
                .find(|(m, s, _)| *m == r.factory.id() && *s == sid);
            if let Some((_, _, why)) = known {
                // Strict expected failure: when the defect is fixed this
                // fails, and the entry must go.
                assert!(
                    worst > 1e-8 * scale,
                    "{} on {sid} is now frame-independent (max {worst:.3e} m): remove it from KNOWN_FRAME_DEPENDENT",
                    r.factory.id()
                );
                eprintln!(
                    "known defect: {} on {sid} differs by {worst:.3e} m between frames ({why})",
                    r.factory.id()
                );
                continue;
            }
            assert!(
                worst <= 1e-8 * scale,
                "{} on {sid}: rigidly moved scene gives a different answer (max {worst:.3e} m, scale {scale} m)",
                r.factory.id()
            );
            let fa = iso.rotation * a.hand_force;
            let fscale = force_scale(&scene).max(a.hand_force.norm());
            // Same rounding argument as for positions, on the scene's force scale.
            assert!(
                (fa - b.hand_force).norm() <= 1e-6 * fscale,
                "{} on {sid}: hand force does not rotate with the scene: {fa:?} vs {:?}",
                r.factory.id(),
                b.hand_force
            );
        }
    }
}

#[test]
fn forces_are_minus_the_energy_gradient() {
    let mut checked = 0;
    for r in registry::models() {
        for (sid, scene) in supported(r.factory) {
            let fid = coarse(r.factory, &scene);
            let mut m = r.factory.build(&scene, &fid).unwrap();
            let dt = m.dt();
            for k in 0..STEPS {
                if m.step(dt, &scene.control.command_at((k + 1) as f64 * dt)).is_err() {
                    break;
                }
            }
            let Some(probe) = m.energy_probe() else { continue };
            // Leave equilibrium (where forces vanish and only rounding is
            // left): a seeded perturbation of 1e-3 of the largest coordinate.
            let mut rng = Rng(0xc0ff_ee00 + checked as u64);
            let mut q0 = probe.coords();
            let amp = 1e-3 * q0.iter().map(|x| x.abs()).fold(0.0, f64::max).max(1e-6);
            for &i in &probe.free() {
                q0[i] += amp * (rng.unit() - 0.5);
            }
            probe.set_coords(&q0);
            let q0 = probe.coords();
            let forces = probe.forces();
            let free = probe.free();
            let scale = forces.iter().map(|f| f.abs()).fold(0.0, f64::max).max(1e-300);
            // Up to 24 free coordinates picked with a seeded generator.
            let picks: Vec<usize> = (0..24.min(free.len()))
                .map(|_| free[(rng.unit() * free.len() as f64) as usize])
                .collect();
            for &i in &picks {
                let h = 1e-6 * q0[i].abs().max(1e-3);
                let mut q = q0.clone();
                q[i] = q0[i] + h;
                probe.set_coords(&q);
                let ep = probe.potential();
                q[i] = q0[i] - h;
                probe.set_coords(&q);
                let em = probe.potential();
                probe.set_coords(&q0);
                let fd = -(ep - em) / (2.0 * h);
                // Central differences: O(h^2) truncation plus O(eps E / h)
                // rounding; 1e-5 of the largest force bounds both here.
                assert!(
                    (fd - forces[i]).abs() <= 1e-5 * scale,
                    "{} on {sid}: coordinate {i}: force {} but -dE/dq = {fd} (scale {scale})",
                    r.factory.id(),
                    forces[i]
                );
            }
            checked += 1;
        }
    }
    eprintln!("energy-gradient conformance checked on {checked} model/scenario pairs");
    // DER has an energy: the check must have run at least on it.
    assert!(checked >= 1, "no model exposed an energy probe");
}

/// A scene each model lacks a capability for: a rod model gets a tissue
/// scene, a tissue model a rod scene, a model doing both a scene with flow
/// or whatever it lacks.
fn unsupported_scene(f: &dyn ModelFactory) -> Option<(Capability, Scene)> {
    let caps = f.capabilities();
    let mut s = Scene::empty("unsupported");
    if !caps.contains(&Capability::Tissue) {
        let nodes = vec![Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()];
        s.bodies.push(Body::Tissue(TissueBody {
            mesh: TetMesh {
                nodes,
                tets: vec![[0, 1, 2, 3]],
            },
            material: SolidMaterial {
                youngs_modulus: 1e4,
                poisson_ratio: 0.3,
                density: 1000.0,
            },
            fixed_nodes: vec![0],
            driven_nodes: vec![],
            partial_fixed: vec![],
            pressure_faces: vec![],
            indenter: None,
        }));
        return Some((Capability::Tissue, s));
    }
    if !caps.contains(&Capability::Rod) {
        s.bodies.push(RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0).into());
        return Some((Capability::Rod, s));
    }
    None
}

#[test]
fn unsupported_scenes_are_refused_with_a_reason() {
    for r in registry::models() {
        let Some((cap, scene)) = unsupported_scene(r.factory) else {
            continue;
        };
        let e = r.factory.check(&scene).expect_err("check must refuse");
        assert!(!e.reason.is_empty(), "{}: empty reason", r.factory.id());
        match r.factory.build(&scene, &Fidelity::default()) {
            Err(BuildError::Unsupported(u)) => assert!(!u.reason.is_empty()),
            Err(other) => panic!(
                "{}: build of a {} scene gave {other} instead of Unsupported",
                r.factory.id(),
                cap.name()
            ),
            Ok(_) => panic!("{}: built a model for a scene needing {}", r.factory.id(), cap.name()),
        }
    }
}
