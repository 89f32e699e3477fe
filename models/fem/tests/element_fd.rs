//! Conformance of the discrete solid (SOFA ForceField test idea): forces are
//! minus the energy gradient and the exact Jacobian is minus the force
//! gradient, both by central finite differences on a perturbed mesh; rigid
//! motions give zero force.

mod common;
use common::{SplitMix, tissue};
use surgbench_core::{Vec3, mesh};
use surgbench_fem::core::Solid;
use surgbench_fem::{Jacobian, Law};

const LAWS: [Law; 3] = [Law::Linear, Law::Corotational, Law::NeoHookean];

fn deformed(seed: u64, amp: f64) -> (surgbench_core::TetMesh, Vec<Vec3>) {
    let m = mesh::block(Vec3::new(0.01, 0.012, 0.014), [2, 2, 2]);
    let mut rng = SplitMix(seed);
    // Random homogeneous stretch plus nodal noise (amp relative to 1 cm).
    let f =
        surgbench_fem::material::M3::identity() * 1.1 + surgbench_fem::material::M3::from_fn(|_, _| 0.1 * rng.signed());
    let x = m
        .nodes
        .iter()
        .map(|p| f * p + rng.signed_vec() * (amp * 0.01))
        .collect();
    (m, x)
}

#[test]
fn forces_are_minus_energy_gradient() {
    for law in LAWS {
        let (m, x) = deformed(1, 0.05);
        let mut s = Solid::new(&m, &tissue(0.35), law, 2).unwrap();
        s.evaluate(&x, None, 0.0);
        let f = s.forces.clone();
        let h = 1e-8; // m; node spacing 5 mm, so relative step 2e-6
        let mut worst: f64 = 0.0;
        let fmax = f.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for i in 0..x.len() {
            for a in 0..3 {
                let mut xp = x.clone();
                xp[i][a] += h;
                let mut xm = x.clone();
                xm[i][a] -= h;
                let ep = s.evaluate(&xp, None, 0.0).energy;
                let em = s.evaluate(&xm, None, 0.0).energy;
                let fd = -(ep - em) / (2.0 * h);
                worst = worst.max((fd - f[i][a]).abs());
            }
        }
        // Central differences: truncation O(h^2) negligible; round-off
        // eps * E / h ~ 1e-16 * 1e-3 / 1e-8. Measured worst ~1e-7 of fmax.
        eprintln!("{law:?}: force FD error {:.3e} (relative)", worst / fmax);
        assert!(
            worst <= 1e-5 * fmax,
            "{law:?}: |f - (-dE/dx)| = {worst:.3e}, max |f| = {fmax:.3e}"
        );
    }
}

#[test]
fn exact_jacobian_is_minus_force_gradient() {
    for law in LAWS {
        let (m, x) = deformed(2, 0.05);
        let mut s = Solid::new(&m, &tissue(0.35), law, 2).unwrap();
        s.evaluate(&x, Some(Jacobian::Exact), 0.0);
        let k = s.kmat.clone();
        let n = x.len();
        let h = 1e-9;
        let mut worst: f64 = 0.0;
        let kmax = k.iter().map(|b| b.amax()).fold(0.0, f64::max);
        for j in 0..n {
            for b in 0..3 {
                let mut xp = x.clone();
                xp[j][b] += h;
                let mut xm = x.clone();
                xm[j][b] -= h;
                s.evaluate(&xp, None, 0.0);
                let fp = s.forces.clone();
                s.evaluate(&xm, None, 0.0);
                let fm = s.forces.clone();
                for i in 0..n {
                    // K[i][j] column b = -(f_i(x + h e_jb) - f_i(x - h e_jb)) / 2h.
                    let col = -(fp[i] - fm[i]) / (2.0 * h);
                    let kij = s
                        .pat
                        .col
                        .get(s.pat.row_ptr[i]..s.pat.row_ptr[i + 1])
                        .and_then(|c| c.binary_search(&j).ok())
                        .map(|off| k[s.pat.row_ptr[i] + off].column(b).into_owned())
                        .unwrap_or_else(Vec3::zeros);
                    worst = worst.max((col - kij).amax());
                }
            }
        }
        // Round-off of the FD: eps * |f| / h ~ 1e-16 * 1 / 1e-9; measured ~1e-6 of kmax.
        eprintln!("{law:?}: stiffness FD error {:.3e} (relative)", worst / kmax);
        assert!(
            worst <= 1e-5 * kmax,
            "{law:?}: |K - (-df/dx)| = {worst:.3e}, max |K| = {kmax:.3e}"
        );
    }
}

#[test]
fn rigid_motions_give_zero_force() {
    let m = mesh::block(Vec3::new(0.01, 0.01, 0.01), [2, 2, 2]);
    let rot = nalgebra::Rotation3::from_scaled_axis(Vec3::new(0.4, -0.9, 1.3));
    let shift = Vec3::new(0.3, -0.2, 0.1);
    for law in LAWS {
        let mut s = Solid::new(&m, &tissue(0.45), law, 2).unwrap();
        // Translation for all laws; rotation only for the nonlinear ones.
        let moves: Vec<Vec<Vec3>> = if law == Law::Linear {
            vec![m.nodes.iter().map(|p| p + shift).collect()]
        } else {
            vec![
                m.nodes.iter().map(|p| p + shift).collect(),
                m.nodes.iter().map(|p| rot * p + shift).collect(),
            ]
        };
        for x in moves {
            let st = s.evaluate(&x, None, 0.0);
            let fmax = s.forces.iter().map(|f| f.amax()).fold(0.0, f64::max);
            // Scale: a 1% strain on this mesh gives forces ~ E * 1e-2 * h^2 ~ 5e-3 N;
            // a rigid motion must give round-off only (1e-10 of that).
            assert!(
                fmax < 1e-12 && st.energy.abs() < 1e-15,
                "{law:?}: max |f| {fmax:.3e} N, E {:.3e} J",
                st.energy
            );
        }
    }
}

/// The rotated-gradient form of the warped stiffness equals the product
/// `R K0 R^T` of the rest stiffness, for random rotations of random tets.
#[test]
fn warped_stiffness_equals_rotated_rest_stiffness() {
    use surgbench_fem::element::{Elements, warp};
    use surgbench_fem::material::M3;
    let (m, _) = deformed(7, 0.0);
    let el = Elements::new(&m).unwrap();
    let (mu, lambda) = (1.7e3, 1.1e4);
    let mut rng = SplitMix(11);
    let mut worst: f64 = 0.0;
    for e in 0..el.len() {
        let axis = rng.signed_vec().normalize();
        let ang = 3.0 * rng.signed();
        let r = *nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), ang).matrix();
        let a = warp(&el.rest_stiffness(mu, lambda, e), &r);
        let b = el.warped_stiffness(mu, lambda, e, &r);
        let scale = a.iter().map(|k: &M3| k.amax()).fold(0.0, f64::max);
        for ab in 0..16 {
            worst = worst.max((a[ab] - b[ab]).amax() / scale);
            // Exact symmetry of the assembled form: K_ba = K_ab^T bit for bit.
            assert_eq!(b[ab], b[4 * (ab % 4) + ab / 4].transpose(), "element {e}, block {ab}");
        }
    }
    // Same quantity, two orders of summation: round-off (a few 1e-16).
    assert!(worst < 1e-13, "max relative block difference {worst:.3e}");
}
