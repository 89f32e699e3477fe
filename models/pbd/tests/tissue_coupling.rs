//! `pbd-tissue` as the tissue of a coupled run (instrument in a deformable
//! vessel): it reports its contact surface and takes forces on it (its
//! saved state is checked by the conformance suite, `tests/conformance.rs`).

use surgbench_core::mesh::{block, boundary_faces};
use surgbench_core::{Body, DeviceCommand, Fidelity, Model, Scene, Setting, SolidMaterial, TissueBody, Vec3};
use surgbench_pbd::PbdTissue;

/// A free 2 x 2 x 2 cm block (no support, no gravity) whose top faces are
/// the contact surface.
fn free_block() -> Scene {
    let mesh = block(Vec3::new(0.02, 0.02, 0.02), [2, 2, 2]);
    let mut body = TissueBody::new(
        mesh.clone(),
        SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.4,
            density: 1000.0,
        },
    );
    body.contact_surface = boundary_faces(&mesh)
        .into_iter()
        .filter(|f| f.iter().all(|&i| (mesh.nodes[i].z - 0.02).abs() < 1e-12))
        .collect();
    let mut scene = Scene::empty("free-block");
    scene.bodies.push(Body::Tissue(body));
    scene
}

fn model(scene: &Scene) -> PbdTissue {
    let mut f = Fidelity {
        dt: Some(1e-3),
        iterations: Some(10),
        ..Default::default()
    };
    f.extras.insert("substeps".into(), Setting::from(2.0));
    PbdTissue::new(scene, &f).expect("build")
}

/// The surface forces are external forces and nothing else: the block's
/// momentum is their impulse, `sum m v = sum f t`, to round-off (every
/// XPBD edge and volume correction is mass-weighted with gradients summing
/// to zero, so it moves no momentum; Macklin et al. 2016, Sec. 3).
#[test]
fn surface_forces_give_the_block_their_impulse() {
    let scene = free_block();
    let mut m = model(&scene);
    let n = m.surface_positions().expect("a contact surface").len();
    assert_eq!(n, 9, "the top of a 2 x 2 x 2 block has 3 x 3 nodes");
    let f = Vec3::new(1e-4, 0.0, -1e-3);
    m.set_surface_forces(&vec![f; n]).unwrap();
    let steps = 50;
    for _ in 0..steps {
        m.step(1e-3, &DeviceCommand::default()).unwrap();
    }
    let obs = m.observe();
    let p: Vec3 = m
        .masses()
        .iter()
        .zip(&obs.tissues[0].velocities)
        .map(|(mi, v)| *mi * v)
        .sum();
    let want = f * (n as f64) * (steps as f64 * 1e-3);
    assert!(
        (p - want).norm() < 1e-12 * want.norm(),
        "momentum {p:?} against impulse {want:?}"
    );
    // A force vector of the wrong length, or not finite, is an error.
    assert!(m.set_surface_forces(&vec![f; n - 1]).is_err());
    assert!(m.set_surface_forces(&vec![Vec3::new(f64::NAN, 0.0, 0.0); n]).is_err());
}
