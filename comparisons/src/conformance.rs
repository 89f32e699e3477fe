//! The conformance suite every model runs (in the spirit of SOFA's
//! ForceField test harness): the same inputs give bit-identical results,
//! rigid motions of the whole scene move the answer rigidly, forces equal
//! minus the energy gradient, and a scene the model cannot do is refused
//! with a reason. Each check takes one factory, runs it on every catalogue
//! scenario it accepts (default parameters, coarse fidelity) and returns
//! the notes it made or the first violation; `tests/conformance.rs` runs
//! them on every registered model, and a new model's own test can run them
//! on its factory before it is registered.

use crate::registry;
use crate::scenario::Params;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use surgbench_core::rng::SplitMix64;
use surgbench_core::{
    Body, BuildError, Capability, Fidelity, ModelFactory, Observation, RodBody, Scene, SolidMaterial, TetMesh,
    TissueBody, Vec3,
};

/// Steps every conformance run takes: enough to leave the rest state.
pub const STEPS: usize = 20;

/// A model x scenario pair known to break rigid-motion invariance: model
/// id, scenario id, what was measured. Checked as a strict expected
/// failure, so a fix shows up.
pub type KnownDefect = (&'static str, &'static str, &'static str);

/// Every catalogue scenario at default parameters, instantiated once per
/// process (building meshes and loading references takes seconds; the
/// suite asks for them once per model and check). Tip loads a scene ramps
/// up later (capstan: once threaded) are applied in full from the start, so
/// the few conformance steps run the loaded contact path.
fn catalogue() -> &'static [(String, Scene)] {
    static SCENES: std::sync::OnceLock<Vec<(String, Scene)>> = std::sync::OnceLock::new();
    SCENES.get_or_init(|| {
        let mut v = Vec::new();
        for sc in registry::scenarios() {
            let Ok(p) = Params::resolve(sc.id(), sc.params(), &[]) else {
                continue;
            };
            let Ok(run) = sc.instantiate(&p) else { continue };
            let mut scene = run.scene().clone();
            for b in &mut scene.bodies {
                if let Body::Rod(r) = b {
                    r.tip_load_ramp = None;
                }
            }
            v.push((sc.id().to_string(), scene));
        }
        v
    })
}

/// Each catalogue scenario `f` accepts, at default parameters ([`catalogue`]).
pub fn supported(f: &dyn ModelFactory) -> Vec<(String, Scene)> {
    catalogue()
        .iter()
        .filter(|(_, scene)| f.check(scene).is_ok())
        .cloned()
        .collect()
}

/// The model's default fidelity with 8 rod segments.
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
fn run(f: &dyn ModelFactory, scene: &Scene, steps: usize) -> Result<Result<Observation, String>, String> {
    let fid = coarse(f, scene);
    let mut m = f
        .build(scene, &fid)
        .map_err(|e| format!("{} on {}: build failed: {e}", f.id(), scene.name))?;
    let dt = m.dt();
    for k in 0..steps {
        let cmd = scene.control.command_at((k + 1) as f64 * dt);
        if let Err(e) = m.step(dt, &cmd) {
            return Ok(Err(format!("step {k}: {e}")));
        }
    }
    Ok(Ok(m.observe()))
}

/// Two identical runs on every accepted scene give bit-identical
/// observations (or the same failure).
pub fn deterministic(f: &dyn ModelFactory) -> Result<Vec<String>, String> {
    let mut notes = Vec::new();
    for (sid, scene) in supported(f) {
        let a = run(f, &scene, STEPS)?;
        if a != run(f, &scene, STEPS)? {
            return Err(format!("{} on {sid}: two identical runs differ", f.id()));
        }
        if let Err(e) = a {
            notes.push(format!(
                "{} on {sid} diverges at coarse fidelity ({e}); determinism checked on the failure",
                f.id()
            ));
        }
    }
    Ok(notes)
}

/// A model that saves its state ([`surgbench_core::Model::save_state`], what
/// an iterated coupling retries a step from) restores it exactly: on its
/// first accepted scene, `STEPS` steps, save, `STEPS / 4` more; restore and
/// the same steps again give the same observation bit for bit. `Ok(false)`
/// when the model saves nothing or diverges before the save (nothing to
/// check); `Err` names a restore that does not give the same numbers.
pub fn restores_state(f: &dyn ModelFactory) -> Result<bool, String> {
    let Some((sid, scene)) = supported(f).into_iter().next() else {
        return Ok(false);
    };
    let mut m = f
        .build(&scene, &coarse(f, &scene))
        .map_err(|e| format!("{} on {sid}: build failed: {e}", f.id()))?;
    let dt = m.dt();
    let steps = |m: &mut dyn surgbench_core::Model, from: usize, n: usize| -> Result<(), String> {
        for k in from..from + n {
            m.step(dt, &scene.control.command_at((k + 1) as f64 * dt))
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    };
    if steps(m.as_mut(), 0, STEPS).is_err() {
        return Ok(false);
    }
    let Some(saved) = m.save_state() else {
        return Ok(false);
    };
    let after = steps(m.as_mut(), STEPS, STEPS / 4).map(|_| m.observe());
    m.restore_state(saved.as_ref())
        .map_err(|e| format!("{} on {sid}: its own saved state is refused: {e}", f.id()))?;
    let again = steps(m.as_mut(), STEPS, STEPS / 4).map(|_| m.observe());
    if after != again {
        return Err(format!(
            "{} on {sid}: stepping from a restored state differs from stepping from the saved one",
            f.id()
        ));
    }
    Ok(true)
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
            // Driven boundaries: the force of straining the body by its
            // largest driven displacement, E |u| V^(1/3); a self-balanced
            // drive (the patch test) has a zero net hand force, which is
            // then compared against this scale, not against roundoff.
            let u = t.driven_nodes.iter().map(|(_, u)| u.norm()).fold(0.0, f64::max);
            v * t.material.density * g + t.material.youngs_modulus * u * v.cbrt()
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

/// The rigid motions the check applies: a general one, and for scenes with
/// axis-aligned roller constraints one that maps axes to axes (x->y, y->z,
/// z->x), the only kind rollers can follow.
fn motions() -> (Isometry3<f64>, Isometry3<f64>) {
    let general = Isometry3::from_parts(
        Translation3::new(0.3, -0.2, 0.5),
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)), 0.7),
    );
    let permuting = Isometry3::from_parts(
        Translation3::new(-0.1, 0.4, 0.2),
        UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(1.0, 1.0, 1.0)),
            2.0 * std::f64::consts::PI / 3.0,
        ),
    );
    (general, permuting)
}

/// The largest node distance (m) between run `a` moved by `iso` and run `b`
/// of the moved scene, and the scene's size (m).
fn frame_difference(a: &Observation, b: &Observation, iso: &Isometry3<f64>) -> Result<(f64, f64), String> {
    let (pa, pb) = (positions(a), positions(b));
    if pa.len() != pb.len() {
        return Err(format!("{} nodes in one frame, {} in the other", pa.len(), pb.len()));
    }
    let scale = pa.iter().map(|p| p.norm()).fold(0.0, f64::max).max(1e-3);
    let worst = pa
        .iter()
        .zip(&pb)
        .map(|(x, y)| (iso.transform_point(&(*x).into()).coords - y).norm())
        .fold(0.0, f64::max);
    Ok((worst, scale))
}

/// Every accepted scene moved rigidly gives the same answer moved rigidly:
/// node positions to 1e-8 of the scene size and the hand force rotated to
/// 1e-6 of the scene's force scale (only rounding and iterative-solver
/// tolerances, <= 1e-10 relative by default, differ between the frames).
/// Pairs listed in `known` must still differ (strict expected failures).
pub fn rigid_motion(f: &dyn ModelFactory, known: &[KnownDefect]) -> Result<Vec<String>, String> {
    let (general, permuting) = motions();
    if surgbench_core::frames::axis_permutation(&permuting).is_none() {
        return Err("the roller-scene motion does not map axes to axes".into());
    }
    let mut notes = Vec::new();
    for (sid, scene) in supported(f) {
        let rollers = scene.tissues().any(|t| !t.partial_fixed.is_empty());
        let iso = if rollers { permuting } else { general };
        let (a, b) = match (run(f, &scene, STEPS)?, run(f, &scene.transformed(&iso), STEPS)?) {
            (Ok(a), Ok(b)) => (a, b),
            (Err(e), Err(_)) => {
                notes.push(format!(
                    "{} on {sid} diverges at coarse fidelity ({e}) in both frames",
                    f.id()
                ));
                continue;
            }
            (a, b) => {
                return Err(format!(
                    "{} on {sid}: one frame diverges and the other does not: {:?} vs {:?}",
                    f.id(),
                    a.err(),
                    b.err()
                ));
            }
        };
        let (worst, scale) = frame_difference(&a, &b, &iso).map_err(|e| format!("{} on {sid}: {e}", f.id()))?;
        if let Some((_, _, why)) = known.iter().find(|(m, s, _)| *m == f.id() && *s == sid) {
            if worst <= 1e-8 * scale {
                return Err(format!(
                    "{} on {sid} is now frame-independent (max {worst:.3e} m): remove it from the known defects",
                    f.id()
                ));
            }
            notes.push(format!(
                "known defect: {} on {sid} differs by {worst:.3e} m between frames ({why})",
                f.id()
            ));
            continue;
        }
        if worst > 1e-8 * scale {
            return Err(format!(
                "{} on {sid}: rigidly moved scene gives a different answer (max {worst:.3e} m, scale {scale} m)",
                f.id()
            ));
        }
        let fa = iso.rotation * a.hand_force;
        let fscale = force_scale(&scene).max(a.hand_force.norm());
        if (fa - b.hand_force).norm() > 1e-6 * fscale {
            return Err(format!(
                "{} on {sid}: hand force does not rotate with the scene: {fa:?} vs {:?}",
                f.id(),
                b.hand_force
            ));
        }
    }
    Ok(notes)
}

/// Forces equal minus the energy gradient (central differences at 24
/// seeded free coordinates, off equilibrium) on every accepted scene whose
/// model exposes an [`surgbench_core::EnergyProbe`]; returns how many
/// scenes were checked. Central differences err by `O(h^2)` truncation plus
/// `O(eps E / h)` rounding; 1e-5 of the largest force bounds both here.
pub fn energy_gradient(f: &dyn ModelFactory) -> Result<usize, String> {
    let mut checked = 0;
    for (sid, scene) in supported(f) {
        let fid = coarse(f, &scene);
        let mut m = f.build(&scene, &fid).map_err(|e| format!("{} on {sid}: {e}", f.id()))?;
        let dt = m.dt();
        for k in 0..STEPS {
            if m.step(dt, &scene.control.command_at((k + 1) as f64 * dt)).is_err() {
                break;
            }
        }
        let Some(probe) = m.energy_probe() else { continue };
        // Leave equilibrium (where forces vanish and only rounding is left):
        // a seeded perturbation of 1e-3 of the largest coordinate.
        let mut rng = SplitMix64(0xc0ff_ee00 + checked as u64);
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
            if (fd - forces[i]).abs() > 1e-5 * scale {
                return Err(format!(
                    "{} on {sid}: coordinate {i}: force {} but -dE/dq = {fd} (scale {scale})",
                    f.id(),
                    forces[i]
                ));
            }
        }
        checked += 1;
    }
    Ok(checked)
}

/// A scene `f` lacks a capability for: a rod model gets a tissue scene, a
/// tissue model a rod scene; `None` for a model that does both.
fn unsupported_scene(f: &dyn ModelFactory) -> Option<(Capability, Scene)> {
    let caps = f.capabilities();
    let mut s = Scene::empty("unsupported");
    if !caps.contains(&Capability::Tissue) {
        let nodes = vec![Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()];
        let material = SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.3,
            density: 1000.0,
        };
        let mut t = TissueBody::new(
            TetMesh {
                nodes,
                tets: vec![[0, 1, 2, 3]],
            },
            material,
        );
        t.fixed_nodes = vec![0];
        s.bodies.push(Body::Tissue(t));
        return Some((Capability::Tissue, s));
    }
    if !caps.contains(&Capability::Rod) {
        s.bodies.push(RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0).into());
        return Some((Capability::Rod, s));
    }
    None
}

/// A scene needing a capability the model does not list is refused by
/// `check` with a reason, and by `build` with [`BuildError::Unsupported`].
pub fn refuses_unsupported(f: &dyn ModelFactory) -> Result<(), String> {
    let Some((cap, scene)) = unsupported_scene(f) else {
        return Ok(());
    };
    match f.check(&scene) {
        Ok(()) => return Err(format!("{}: check accepted a scene needing {}", f.id(), cap.name())),
        Err(e) if e.reason.is_empty() => return Err(format!("{}: empty reason", f.id())),
        Err(_) => {}
    }
    match f.build(&scene, &Fidelity::default()) {
        Err(BuildError::Unsupported(u)) if !u.reason.is_empty() => Ok(()),
        Err(BuildError::Unsupported(_)) => Err(format!("{}: build refused with an empty reason", f.id())),
        Err(other) => Err(format!(
            "{}: build of a {} scene gave {other} instead of Unsupported",
            f.id(),
            cap.name()
        )),
        Ok(_) => Err(format!("{}: built a model for a scene needing {}", f.id(), cap.name())),
    }
}
