//! Finite-difference checks of every elastic energy term (stretch, bend with
//! rest curvature and anisotropic stiffness, twist) at random non-trivial
//! configurations with random twist angles.
//!
//! Gradients: central differences of the energy, where the reference frames
//! of the perturbed configuration are parallel-transported from the
//! unperturbed one (exactly as the Newton solver does). Jacobians: central
//! differences of the analytic gradient under the same transport. The
//! symmetric part of the Jacobian (what the solver factorises) is also
//! checked against second differences of the energy.

mod common;
use common::{Rng, RngVec};
use surgbench_core::Vec3;
use surgbench_der::energy::{
    self, Stencil, VERTEX_DOFS, VertexParams, VertexTerms, reference_twist, transport_director,
};

const N: usize = VERTEX_DOFS;

fn random_stencil(rng: &mut Rng, len: f64) -> Stencil {
    let x0 = rng.vec(len);
    let ta = rng.vec(1.0).normalize();
    // A turning angle of order 0.3-1 rad: far from straight, far from folded.
    let tb = (ta + rng.normal_to(&ta) * rng.range(0.3, 1.0)).normalize();
    let x1 = x0 + ta * len * rng.range(0.7, 1.3);
    let x2 = x1 + tb * len * rng.range(0.7, 1.3);
    let d = [rng.normal_to(&ta), rng.normal_to(&tb)];
    let rt = reference_twist(&d[0], &ta, &d[1], &tb, 0.0);
    Stencil {
        x: [x0, x1, x2],
        theta: [rng.range(-3.0, 3.0), rng.range(-3.0, 3.0)],
        ref_d1: d,
        ref_twist: rt,
    }
}

/// The stencil moved by `du` (local DOF order), frames transported from `st`.
fn perturbed(st: &Stencil, du: &[f64; N]) -> Stencil {
    let mut s = *st;
    for (k, off) in [0usize, 4, 8].iter().enumerate() {
        s.x[k] += Vec3::new(du[*off], du[off + 1], du[off + 2]);
    }
    s.theta[0] += du[3];
    s.theta[1] += du[7];
    let t_old = [(st.x[1] - st.x[0]).normalize(), (st.x[2] - st.x[1]).normalize()];
    let t_new = [(s.x[1] - s.x[0]).normalize(), (s.x[2] - s.x[1]).normalize()];
    for j in 0..2 {
        s.ref_d1[j] = transport_director(&st.ref_d1[j], &t_old[j], &t_new[j]);
    }
    s.ref_twist = reference_twist(&s.ref_d1[0], &t_new[0], &s.ref_d1[1], &t_new[1], st.ref_twist);
    s
}

fn unit(k: usize, h: f64) -> [f64; N] {
    let mut u = [0.0; N];
    u[k] = h;
    u
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Step for DOF k: positions scale with the edge length, angles are O(1).
fn step(k: usize, len: f64) -> f64 {
    if k == 3 || k == 7 { 1e-5 } else { 1e-5 * len }
}

/// Check one vertex term; returns (gradient error, Jacobian error, symmetric-Hessian error).
fn check_term(f: &dyn Fn(&Stencil) -> VertexTerms, st: &Stencil, len: f64) -> (f64, f64, f64) {
    let base = f(st);
    // Gradient vs central differences of the energy.
    let mut gfd = [0.0; N];
    for k in 0..N {
        let h = step(k, len);
        let ep = f(&perturbed(st, &unit(k, h))).energy;
        let em = f(&perturbed(st, &unit(k, -h))).energy;
        gfd[k] = (ep - em) / (2.0 * h);
    }
    let gerr: Vec<f64> = (0..N).map(|k| (gfd[k] - base.grad[k]) * step(k, len)).collect();
    let gscale: Vec<f64> = (0..N).map(|k| base.grad[k] * step(k, len)).collect();
    let grad_err = norm(&gerr) / norm(&gscale);
    // Jacobian vs central differences of the analytic gradient.
    let mut jerr = 0.0;
    let mut jnorm = 0.0;
    for c in 0..N {
        let h = step(c, len);
        let gp = f(&perturbed(st, &unit(c, h))).grad;
        let gm = f(&perturbed(st, &unit(c, -h))).grad;
        for r in 0..N {
            // Scale to a dimensionless matrix: J_rc h_r h_c.
            let s = step(r, len) * step(c, len);
            let fd = (gp[r] - gm[r]) / (2.0 * h);
            jerr += ((fd - base.jac[r][c]) * s).powi(2);
            jnorm += (base.jac[r][c] * s).powi(2);
        }
    }
    // Symmetric part vs second differences of the energy (frames transported
    // from the unperturbed configuration along each straight perturbation).
    let mut herr = 0.0;
    let mut hnorm = 0.0;
    for r in 0..N {
        for c in 0..N {
            let (hr, hc) = (step(r, len) * 20.0, step(c, len) * 20.0);
            let mut e = 0.0;
            for (sr, sc, w) in [(1.0, 1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0)] {
                let mut du = [0.0; N];
                du[r] += sr * hr;
                du[c] += sc * hc;
                e += w * f(&perturbed(st, &du)).energy;
            }
            let fd = e / (4.0 * hr * hc);
            let sym = 0.5 * (base.jac[r][c] + base.jac[c][r]);
            let s = step(r, len) * step(c, len);
            herr += ((fd - sym) * s).powi(2);
            hnorm += (sym * s).powi(2);
        }
    }
    (grad_err, (jerr / jnorm).sqrt(), (herr / hnorm).sqrt())
}

fn params(rng: &mut Rng, anisotropic: bool, rest: bool, len: f64) -> VertexParams {
    let b1 = rng.range(0.5, 2.0);
    VertexParams {
        bend: [b1, if anisotropic { b1 * rng.range(2.0, 5.0) } else { b1 }],
        kappa_bar: if rest {
            [rng.range(-0.5, 0.5), rng.range(-0.5, 0.5)]
        } else {
            [0.0, 0.0]
        },
        twist: rng.range(0.5, 2.0),
        twist_bar: 0.0,
        voronoi: len,
    }
}

// Tolerance 1e-6 (from the brief); measured errors are ~1e-9..1e-10 for
// the gradient and Jacobian (central differences, h = 1e-5: O(h^2) truncation
// plus O(eps/h) rounding), and ~1e-7 for second differences of the energy
// (h = 2e-4: rounding O(eps/h^2) dominates).
const TOL: f64 = 1e-6;

#[test]
fn bend_derivatives_match_finite_differences() {
    let mut rng = Rng(0x5EED_0001);
    let mut worst = [0.0f64; 3];
    for trial in 0..20 {
        let len = [1.0, 5e-3][trial % 2];
        let st = random_stencil(&mut rng, len);
        let p = params(&mut rng, trial % 4 >= 2, trial % 3 != 0, len);
        let (g, j, h) = check_term(&|s| energy::bend(s, &p), &st, len);
        worst = [worst[0].max(g), worst[1].max(j), worst[2].max(h)];
        assert!(
            g < TOL && j < TOL && h < TOL,
            "bend trial {trial} (len {len}, {p:?}): grad err {g:.2e}, jac err {j:.2e}, sym hessian err {h:.2e}"
        );
    }
    eprintln!(
        "bend: worst grad err {:.2e}, jac err {:.2e}, sym hessian err {:.2e}",
        worst[0], worst[1], worst[2]
    );
}

#[test]
fn twist_derivatives_match_finite_differences() {
    let mut rng = Rng(0x5EED_0002);
    let mut worst = [0.0f64; 3];
    for trial in 0..20 {
        let len = [1.0, 5e-3][trial % 2];
        let st = random_stencil(&mut rng, len);
        let mut p = params(&mut rng, false, false, len);
        p.twist_bar = rng.range(-0.3, 0.3);
        let (g, j, h) = check_term(&|s| energy::twist(s, &p), &st, len);
        worst = [worst[0].max(g), worst[1].max(j), worst[2].max(h)];
        assert!(
            g < TOL && j < TOL && h < TOL,
            "twist trial {trial} (len {len}): grad err {g:.2e}, jac err {j:.2e}, sym hessian err {h:.2e}"
        );
    }
    eprintln!(
        "twist: worst grad err {:.2e}, jac err {:.2e}, sym hessian err {:.2e}",
        worst[0], worst[1], worst[2]
    );
}

#[test]
fn combined_vertex_term_is_bend_plus_twist() {
    let mut rng = Rng(0x5EED_0003);
    let st = random_stencil(&mut rng, 1.0);
    let p = params(&mut rng, true, true, 1.0);
    let (b, t) = (energy::bend(&st, &p), energy::twist(&st, &p));
    let mut c = VertexTerms::default();
    energy::bend_twist(&st, &p, &mut c);
    let scale = b.energy + t.energy;
    assert!(
        (c.energy - scale).abs() <= 1e-14 * scale,
        "energy {} vs {}",
        c.energy,
        scale
    );
    assert!((energy::bend_twist_energy(&st, &p) - scale).abs() <= 1e-14 * scale);
    for r in 0..N {
        assert!(
            (c.grad[r] - b.grad[r] - t.grad[r]).abs() <= 1e-12 * norm(&c.grad),
            "grad {r}"
        );
    }
}

#[test]
fn stretch_derivatives_match_finite_differences() {
    let mut rng = Rng(0x5EED_0004);
    for trial in 0..20 {
        let x0 = rng.vec(1.0);
        let x1 = x0 + rng.vec(1.0);
        let rest = (x1 - x0).norm() * rng.range(0.8, 1.2);
        let ea = rng.range(1.0, 10.0);
        let (_, g, h) = energy::stretch(&x0, &x1, ea, rest);
        let eps = 1e-6 * rest;
        let mut gfd = Vec3::zeros();
        let mut hfd = surgbench_core::Mat3::zeros();
        for k in 0..3 {
            let mut d = Vec3::zeros();
            d[k] = eps;
            let (ep, gp, _) = energy::stretch(&x0, &(x1 + d), ea, rest);
            let (em, gm, _) = energy::stretch(&x0, &(x1 - d), ea, rest);
            gfd[k] = (ep - em) / (2.0 * eps);
            hfd.set_column(k, &((gp - gm) / (2.0 * eps)));
        }
        let ge = (gfd - g).norm() / g.norm();
        let he = (hfd - h).norm() / h.norm();
        assert!(
            ge < TOL && he < TOL,
            "stretch trial {trial}: grad err {ge:.2e}, hess err {he:.2e}"
        );
    }
}
