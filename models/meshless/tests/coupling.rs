//! The meshless tissue as the tissue of a coupled run: its contact surface
//! is the MLS surface (the meshless seed's), forces on it reach the nodes
//! through the transpose of the map (its saved state is checked by the
//! conformance suite, `tests/conformance.rs`).

use surgbench_core::mesh::{block, boundary_faces};
use surgbench_core::{Body, Fidelity, Model, Scene, SolidMaterial, TissueBody, Vec3};
use surgbench_meshless::MeshlessTissue;

/// A 2 x 2 x 2 cm block held at its base, no gravity; its top faces are
/// the contact surface.
fn block_scene() -> Scene {
    let mesh = block(Vec3::new(0.02, 0.02, 0.02), [3, 3, 3]);
    let mut body = TissueBody::new(
        mesh.clone(),
        SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.4,
            density: 1000.0,
        },
    );
    body.fixed_nodes = (0..mesh.nodes.len())
        .filter(|&i| mesh.nodes[i].z.abs() < 1e-12)
        .collect();
    body.contact_surface = boundary_faces(&mesh)
        .into_iter()
        .filter(|f| f.iter().all(|&i| (mesh.nodes[i].z - 0.02).abs() < 1e-12))
        .collect();
    let mut scene = Scene::empty("held-block");
    scene.bodies.push(Body::Tissue(body));
    scene
}

/// At rest (no internal force, no gravity) the probe's forces are the
/// applied ones: their sum and their moment about the origin are those of
/// the surface forces at the surface points, to round-off. The MLS shape
/// functions sum to one and reproduce linear fields (`sum_j phi_j x_j = p`),
/// so `sum_j f_j = sum_k f_k` and `sum_j x_j x f_j = sum_k p_k x f_k`.
#[test]
fn surface_forces_keep_their_resultant_and_moment() {
    let scene = block_scene();
    let mut m = MeshlessTissue::new(&scene, &Fidelity::default()).unwrap();
    let p = Model::surface_positions(&m).expect("a contact surface");
    let forces: Vec<Vec3> = (0..p.len())
        .map(|k| Vec3::new(1e-3 * (k as f64).sin(), 2e-4 * k as f64, -1e-3))
        .collect();
    m.set_surface_forces(&forces).unwrap();
    let x: Vec<Vec3> = m.positions().to_vec();
    let probe = m.energy_probe().unwrap();
    let f = probe.forces();
    let nodal: Vec<Vec3> = f.chunks(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
    let sum: Vec3 = nodal.iter().sum();
    let moment: Vec3 = x.iter().zip(&nodal).map(|(xi, fi)| xi.cross(fi)).sum();
    let want_sum: Vec3 = forces.iter().sum();
    let want_moment: Vec3 = p.iter().zip(&forces).map(|(pk, fk)| pk.cross(fk)).sum();
    let scale = forces.iter().map(|f| f.norm()).sum::<f64>();
    assert!((sum - want_sum).norm() < 1e-12 * scale, "{sum:?} vs {want_sum:?}");
    assert!(
        (moment - want_moment).norm() < 1e-12 * scale * 0.02,
        "{moment:?} vs {want_moment:?}"
    );
    assert!(
        m.set_surface_forces(&forces[1..]).is_err(),
        "one force per contact vertex"
    );
}
