//! Compressible neo-Hookean block under 20 % homogeneous uniaxial
//! compression against the closed form.
//!
//! Energy (Bonet and Wood 2008, Eq. 6.27, as in `material.rs`):
//! `psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`, so
//! `P = mu (F - F^-T) + lambda ln J F^-T`. For `F = diag(a, a, s)` (axial
//! stretch `s`, lateral stretch `a`, `J = a^2 s`) the lateral faces are
//! traction free iff
//! `P11 = mu (a - 1/a) + lambda ln(a^2 s) / a = 0`, i.e.
//! `g(a) = mu (a^2 - 1) + lambda ln(a^2 s) = 0` (solved by Newton), and the
//! axial nominal stress is `P33 = mu (s - 1/s) + lambda ln(a^2 s) / s` (Pa,
//! force per rest area).
//!
//! Boundary conditions that make this field the exact solution: rollers on
//! the bottom (`u_z = 0`) and top (`u_z = -0.2 L`) faces, lateral faces
//! free, and two pins against rigid motion (the origin fixed; `u_y = 0` at
//! `(L, 0, 0)`), both satisfied by `u = ((a - 1) x, (a - 1) y, (s - 1) z)`.
//! A homogeneous `F` is represented exactly by linear tets and is in
//! equilibrium node by node (constant `P`, closed element boundaries;
//! zero traction on the lateral faces), so the FEM answer differs from the
//! closed form only by the Newton tolerance.

mod common;
use common::tissue;
use nalgebra::{DMatrix, SymmetricEigen};
use surgbench_core::{Vec3, mesh};
use surgbench_fem::core::Solid;
use surgbench_fem::material::lame;
use surgbench_fem::{Constraint, Jacobian, Law, Loads, StaticParams, solve_static};

/// Lateral stretch `a` and axial nominal stress `P33` (Pa) of homogeneous
/// uniaxial stress at axial stretch `s` (closed form above; Newton on `g`).
fn uniaxial(mu: f64, lambda: f64, s: f64) -> (f64, f64) {
    let mut a = 1.0;
    for _ in 0..50 {
        let g = mu * (a * a - 1.0) + lambda * (a * a * s).ln();
        let dg = 2.0 * mu * a + 2.0 * lambda / a;
        let da = g / dg;
        a -= da;
        if da.abs() < 1e-16 {
            break;
        }
    }
    let g = mu * (a * a - 1.0) + lambda * (a * a * s).ln();
    // Quadratic convergence from a = 1 reaches round-off (|g| ~ 1e-16 lambda).
    assert!(
        g.abs() < 1e-12 * lambda,
        "closed form: g(a = {a}) = {g:e} for mu {mu}, lambda {lambda}, s {s}"
    );
    let p33 = mu * (s - 1.0 / s) + lambda * (a * a * s).ln() / s;
    (a, p33)
}

#[test]
fn neo_hookean_uniaxial_compression_matches_closed_form() {
    let (l, strain, nu) = (0.02, 0.2, 0.45);
    let mat = tissue(nu);
    let (mu, lambda) = lame(mat.youngs_modulus, mat.poisson_ratio);
    let s = 1.0 - strain;
    let (a, p33) = uniaxial(mu, lambda, s);

    // 3x3x3 cells (162 tets): odd counts keep the mesh free of mirror
    // symmetries that could hide an error in one direction.
    let m = mesh::block(Vec3::new(l, l, l), [3, 3, 3]);
    let tol = 1e-9 * l;
    let bottom = mesh::nodes_on_plane(&m, 2, 0.0, tol);
    let top = mesh::nodes_on_plane(&m, 2, l, tol);
    let mut cons: Vec<Constraint> = bottom.iter().map(|&i| Constraint::axis(i, 2, 0.0)).collect();
    cons.extend(top.iter().map(|&i| Constraint::axis(i, 2, -strain * l)));
    let near = |p: &Vec3, q: Vec3| (p - q).norm() < tol;
    let origin = m.nodes.iter().position(|p| near(p, Vec3::zeros())).expect("corner");
    let x_corner = m
        .nodes
        .iter()
        .position(|p| near(p, Vec3::new(l, 0.0, 0.0)))
        .expect("corner");
    cons.push(Constraint::fixed(origin));
    cons.push(Constraint::axis(x_corner, 1, 0.0));

    let params = StaticParams {
        load_steps: 4,
        tol: 1e-12,
        ..Default::default()
    };
    let info = solve_static(&m, &mat, Law::NeoHookean, &cons, &Loads::default(), &params)
        .unwrap_or_else(|e| panic!("neo-Hookean uniaxial {strain}: {e}"));
    // The solver may also stop at a rounding-floor stall (<= 1e-5): make
    // sure the tolerance itself was reached.
    assert!(info.residual <= 1e-12, "relative residual {:.3e}", info.residual);

    // Error bound: a relative residual r gives a relative displacement
    // error of at most cond(K) r (K the free-DOF tangent at the solution);
    // factor 10 for the reaction's extra product with K.
    let cond = {
        let mut solid = Solid::new(&m, &mat, Law::NeoHookean, 1).expect("valid mesh");
        let x: Vec<Vec3> = m.nodes.iter().zip(&info.displacements).map(|(p, u)| p + u).collect();
        solid.evaluate(&x, Some(Jacobian::Exact), 0.0);
        let mut free = vec![true; 3 * m.nodes.len()];
        for c in &cons {
            for k in 0..3 {
                if c.axes[k] {
                    free[3 * c.node + k] = false;
                }
            }
        }
        let dofs: Vec<usize> = (0..free.len()).filter(|&d| free[d]).collect();
        let mut index = vec![usize::MAX; free.len()];
        for (k, &d) in dofs.iter().enumerate() {
            index[d] = k;
        }
        let mut kd = DMatrix::zeros(dofs.len(), dofs.len());
        for i in 0..solid.pat.n {
            for bi in solid.pat.row_ptr[i]..solid.pat.row_ptr[i + 1] {
                let j = solid.pat.col[bi];
                for p in 0..3 {
                    for q in 0..3 {
                        let (r, c) = (index[3 * i + p], index[3 * j + q]);
                        if r != usize::MAX && c != usize::MAX {
                            kd[(r, c)] = solid.kmat[bi][(p, q)];
                        }
                    }
                }
            }
        }
        let ev = SymmetricEigen::new(kd).eigenvalues;
        let (lo, hi) = (ev.min(), ev.max());
        assert!(
            lo > 0.0,
            "tangent at the homogeneous state is not positive definite: {lo:e}"
        );
        hi / lo
    };
    let bound = 10.0 * cond * params.tol;

    // Displacement field against the exact homogeneous one.
    let exact = |p: &Vec3| Vec3::new((a - 1.0) * p.x, (a - 1.0) * p.y, (s - 1.0) * p.z);
    let err = m
        .nodes
        .iter()
        .zip(&info.displacements)
        .map(|(p, u)| (u - exact(p)).norm())
        .fold(0.0, f64::max);
    let u_max = m.nodes.iter().map(|p| exact(p).norm()).fold(0.0, f64::max);
    // Lateral stretch read off the far corner (L, L, L/3).
    let corner = m
        .nodes
        .iter()
        .position(|p| near(p, Vec3::new(l, l, l / 3.0)))
        .expect("node");
    let a_fem = 1.0 + info.displacements[corner].x / l;
    // Plate force (N): the rollers' reactions on the top face.
    let force: f64 = top.iter().map(|&i| info.reactions[i].z).sum();
    let force_exact = p33 * l * l;
    eprintln!(
        "nu {nu}, strain {strain}: a = {a:.12} (FEM {a_fem:.12}; small strain 1 + nu eps = {:.3}), \
         P33 {p33:.6} Pa, force {force:.9e} vs {force_exact:.9e} N (rel {:.2e}); \
         max nodal error / max u {:.2e}; cond(K) {cond:.3e}, bound {bound:.1e}; Newton {:?}, Jacobian fallbacks {}",
        1.0 + nu * strain,
        force / force_exact - 1.0,
        err / u_max,
        info.newton_iterations,
        info.jacobian_fallbacks
    );
    assert!(
        err <= bound * u_max,
        "max nodal error {err:e} m vs bound {bound:e} x {u_max:e} m (a = {a}, s = {s}, mu {mu}, lambda {lambda})"
    );
    assert!(
        (a_fem - a).abs() <= bound * a,
        "lateral stretch FEM {a_fem} vs closed form {a} (bound {bound:e})"
    );
    assert!(
        (force - force_exact).abs() <= bound * force_exact.abs(),
        "plate force {force} N vs closed form {force_exact} N (P33 {p33} Pa, bound {bound:e})"
    );
}
