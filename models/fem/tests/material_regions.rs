//! A body of two materials (`TissueBody::regions`, `Solid::with_materials`):
//! a bar of two layers in series pulled by a uniform traction.
//!
//! Closed form: with Poisson ratio 0 and the traction `t` on the end face,
//! the stress is uniaxial and uniform, `sigma_xx = t`, and the end moves by
//! `u(L) = t (L1 / E1 + L2 / E2)`. The displacement is piecewise linear in
//! x, which linear tets whose planes follow the interface represent
//! exactly, so the only error is the solver's. For the corotational law a
//! pure stretch has `R = I` and, with `lambda = 0`, first Piola stress
//! `P = 2 mu (F - I) = E (F - I)`: the same linear answer against the dead
//! traction.

use surgbench_core::{SolidMaterial, TissueBody, TissueRegion, Vec3, mesh};
use surgbench_fem::{Constraint, Law, Loads, StaticParams, pressure_loads, solve_static_materials};

const L1: f64 = 4e-3;
const L2: f64 = 6e-3;
const W: f64 = 4e-3;
const E1: f64 = 10e3;
const E2: f64 = 40e3;
/// Tension on the end face (Pa): a strain of 1 % in the softer layer.
const T: f64 = 100.0;

fn gel(youngs_modulus: f64, density: f64) -> SolidMaterial {
    SolidMaterial {
        youngs_modulus,
        poisson_ratio: 0.0,
        density,
    }
}

/// The bar as a tissue body: the second layer a region of its own.
fn bar() -> TissueBody {
    let x = [0.0, 0.5 * L1, L1, L1 + L2 / 3.0, L1 + 2.0 * L2 / 3.0, L1 + L2];
    let y = [0.0, 0.5 * W, W];
    let m = mesh::graded_block(&x, &y, &y).unwrap();
    let stiff: Vec<usize> = (0..m.tets.len())
        .filter(|&e| {
            let c = m.tets[e].iter().map(|&i| m.nodes[i]).sum::<Vec3>() / 4.0;
            c.x > L1
        })
        .collect();
    let mut body = TissueBody::new(m, gel(E1, 1000.0));
    body.regions.push(TissueRegion {
        name: "stiff".into(),
        material: gel(E2, 1200.0),
        tets: stiff,
        cutting_force: None,
    });
    body
}

/// End displacement along x (m) at every node of the plane `x = at`
/// (their mean and spread) under the traction, with `law`.
fn stretch(law: Law) -> Vec<(f64, f64, f64)> {
    let b = bar();
    validate(&b);
    let m = &b.mesh;
    let tol = 1e-12;
    // Rollers on x = 0 hold x; two more pins take out the rigid motions
    // across and about the axis.
    let mut cons: Vec<Constraint> = mesh::nodes_on_plane(m, 0, 0.0, tol)
        .into_iter()
        .map(|i| Constraint {
            node: i,
            axes: [true, m.nodes[i].norm() < tol, m.nodes[i].norm() < tol],
            displacement: Vec3::zeros(),
        })
        .collect();
    for c in &mut cons {
        let p = m.nodes[c.node];
        if p.x.abs() < tol && (p.y - W).abs() < tol && p.z.abs() < tol {
            c.axes[2] = true;
        }
    }
    let end = mesh::nodes_on_plane(m, 0, L1 + L2, tol);
    let faces: Vec<[usize; 3]> = mesh::boundary_faces(m)
        .into_iter()
        .filter(|f| f.iter().all(|i| end.contains(i)))
        .collect();
    let loads = Loads {
        body_force: None,
        nodal: pressure_loads(m, &faces, -T),
    };
    let (materials, of) = b.tet_materials();
    let info = solve_static_materials(m, &materials, &of, law, &cons, &loads, &StaticParams::default()).unwrap();
    [L1, L1 + L2]
        .iter()
        .map(|&at| {
            let u: Vec<f64> = mesh::nodes_on_plane(m, 0, at, tol)
                .iter()
                .map(|&i| info.displacements[i].x)
                .collect();
            let mean = u.iter().sum::<f64>() / u.len() as f64;
            let spread = u.iter().map(|v| (v - mean).abs()).fold(0.0, f64::max);
            (at, mean, spread)
        })
        .collect()
}

/// The body alone in a scene validates, and the scene asks for regions.
fn validate(body: &TissueBody) {
    let mut s = surgbench_core::Scene::empty("bar");
    s.bodies.push(surgbench_core::Body::Tissue(body.clone()));
    s.validate().unwrap();
    assert!(
        s.required_capabilities()
            .contains(&surgbench_core::Capability::MaterialRegions)
    );
}

#[test]
fn two_layers_in_series_stretch_by_the_sum_of_their_compliances() {
    for law in [Law::Linear, Law::Corotational] {
        let got = stretch(law);
        let want = [T * L1 / E1, T * (L1 / E1 + L2 / E2)];
        for ((at, u, spread), w) in got.iter().zip(want) {
            // Exact up to the Newton tolerance (1e-10 relative residual by
            // default) and round-off: 1e-8 of the displacement.
            assert!(
                (u - w).abs() < 1e-8 * w,
                "{law:?} x = {at}: u = {u} m, closed form {w} m"
            );
            assert!(
                *spread < 1e-8 * w,
                "{law:?} x = {at}: plane not kept plane, spread {spread} m"
            );
        }
    }
}

#[test]
fn each_tet_carries_its_own_density() {
    let b = bar();
    let (materials, of) = b.tet_materials();
    let solid = surgbench_fem::core::Solid::with_materials(&b.mesh, &materials, &of, Law::Linear, 1).unwrap();
    let mass: f64 = solid.mass.iter().sum();
    let want = (1000.0 * L1 + 1200.0 * L2) * W * W;
    // Sums of tet volumes: round-off only.
    assert!((mass - want).abs() < 1e-12 * want, "mass {mass} kg, want {want} kg");
    // An index past the materials, or one index short, is refused.
    let mut bad = of.clone();
    bad[0] = 2;
    assert!(surgbench_fem::core::Solid::with_materials(&b.mesh, &materials, &bad, Law::Linear, 1).is_err());
    assert!(surgbench_fem::core::Solid::with_materials(&b.mesh, &materials, &of[1..], Law::Linear, 1).is_err());
}
