//! Is the corotational failure on the level-0 truth cube (see
//! `issue_truth_cube_newton.rs`) a real instability of the discrete model?
//!
//! Method: at converged quasi-static states of the scenario's ramp, the
//! exact tangent stiffness `K = d2E/dx2` (the crate's assembled exact
//! Jacobian) restricted to the free DOFs is formed densely and its
//! spectrum computed with `nalgebra`'s `SymmetricEigen` (225 free DOFs at
//! level 0). A negative eigenvalue at an equilibrium means the equilibrium
//! is a saddle of the discrete energy (unstable). The negative curvature is
//! confirmed independently of the assembled matrix by the second difference
//! of the total energy along the eigenvector.
//!
//! Findings (measured; 80 mm cube, 4x4x4 cells, 384 tets, E = 15.3 kPa,
//! nu = 0.499, bonded plates):
//! * corotational: the smallest eigenvalue falls from 30.8 N/m at rest to
//!   2.2 N/m at 9.8 % strain and crosses zero near 10.4 % (-1.9 N/m at
//!   10.95 %); at the last converged state of the 18.25 % ramp (12.70 %)
//!   three eigenvalues are negative, the smallest -16.0 N/m
//!   (-4.8e-5 of the largest, 3.36e5 N/m; -0.52 of the softest mode at
//!   rest). The next step (12.8 %) fails in Newton. The mode is 99 % lateral
//!   and largest on two vertical edges of the cube one cell away from a
//!   plate (`(L, L, L/4)` and `(0, 0, 3L/4)`, the pair related by the
//!   mesh's diagonal), a sway of those edge columns along `(1, -1, 0)`;
//!   neighbouring nodes are only partly correlated (0.43 averaged over
//!   tet edges): a localized, mesh-scale mode, not a global buckling mode.
//! * neo-Hookean at its own equilibrium is *also* a saddle on this mesh:
//!   one negative eigenvalue, -6.1 N/m at 12.7 % and -10.5 N/m at 18.25 %
//!   (-2.6e-5 of the largest), positive (32.6 N/m) at 4.9 %; its mode sits
//!   at the centre layer (`z = L/2`) and is less smooth (correlation 0.1 to
//!   0.56). Newton still converges there: the projected Jacobian is positive
//!   definite and the unstable direction carries almost no residual.
//!   The neo-Hookean Hessian at the *corotational* state is far more
//!   indefinite (11 negative, -1.35e3 N/m) because that state loses volume
//!   the neo-Hookean law punishes; it is not a neo-Hookean equilibrium.
//! * on the 8x8x8 mesh both laws are stable at the same strains
//!   (corotational 12.7 %: smallest eigenvalue +2.7 N/m; neo-Hookean
//!   18.25 %: +5.0 N/m).
//!
//! Diagnosis: a spurious instability of the coarse, volumetrically locking
//! P1 mesh at nu = 0.499 (lambda / mu = 499), not of the continuum (a bonded
//! incompressible neo-Hookean block first wrinkles near 46 % compression,
//! Biot 1965) and not specific to the corotational law: the locked
//! elements carry pressures of many mu, whose geometric stiffness makes
//! mesh-scale modes negative. The corotational law reaches it earlier and
//! with more modes because its rotation term `(lambda tr(S - I) - 2 mu) dR`
//! softens directly with compression. A fix belongs to the discretization
//! (refinement, mixed u-p or F-bar elements), not to the Newton solver.
//!
//! The tests below assert these properties; level 1 uses a dense Cholesky
//! as the positive-definiteness certificate (an eigen-decomposition of its
//! 1701 DOFs would take too long for a unit test).

use nalgebra::{DMatrix, SymmetricEigen};
use surgbench_core::{TissueBody, Vec3};
use surgbench_fem::core::Solid;
use surgbench_fem::{DynParams, FemModel, Integrator, Jacobian, Law};

mod common;
use common::{TRUTH_CUBE_EDGE as EDGE, cosine_ramp, truth_cube_body as body};

/// Free DOFs (not on the plates), in DOF order.
fn free_dofs(b: &TissueBody) -> Vec<usize> {
    let mut free = vec![true; 3 * b.mesh.nodes.len()];
    for &i in b.fixed_nodes.iter().chain(b.driven_nodes.iter().map(|d| &d.0)) {
        free[3 * i..3 * i + 3].fill(false);
    }
    (0..free.len()).filter(|&d| free[d]).collect()
}

/// Dense exact tangent stiffness `d2E/dx2` (N/m) on the free DOFs at `x`.
fn tangent(b: &TissueBody, law: Law, x: &[Vec3]) -> DMatrix<f64> {
    let mut s = Solid::new(&b.mesh, &b.material, law, 1).expect("valid truth cube");
    s.evaluate(x, Some(Jacobian::Exact), 0.0);
    let dofs = free_dofs(b);
    let mut index = vec![usize::MAX; 3 * b.mesh.nodes.len()];
    for (k, &d) in dofs.iter().enumerate() {
        index[d] = k;
    }
    let mut k = DMatrix::zeros(dofs.len(), dofs.len());
    for i in 0..s.pat.n {
        for bi in s.pat.row_ptr[i]..s.pat.row_ptr[i + 1] {
            let j = s.pat.col[bi];
            for a in 0..3 {
                for c in 0..3 {
                    let (r, q) = (index[3 * i + a], index[3 * j + c]);
                    if r != usize::MAX && q != usize::MAX {
                        k[(r, q)] = s.kmat[bi][(a, c)];
                    }
                }
            }
        }
    }
    k
}

/// A converged state: strain and node positions (m).
type State = (f64, Vec<Vec3>);

/// Converged states `(strain, positions)` of the quasi-static ramp to
/// `strain` at the first steps reaching each of `marks`, and the last
/// converged state (the run stops at the first failing step). `steps`:
/// `None` for the scenario's cosine ramp at dt = 1 ms (255 steps), or
/// `Some(k)` equal increments (the model halves a failing one).
fn ramp_states(law: Law, strain: f64, n: usize, marks: &[f64], steps: Option<usize>) -> (Vec<State>, State) {
    let b = body(strain, n);
    let p = DynParams {
        integrator: Integrator::QuasiStatic,
        iterations: 30,
        law,
        ..Default::default()
    };
    let mut m = FemModel::new(&b, Vec3::zeros(), 1e-3, p).expect("valid truth cube");
    let mut out = Vec::new();
    let mut last = (0.0, m.positions().to_vec());
    let count = steps.unwrap_or(255);
    for k in 0..count {
        let s = match steps {
            None => cosine_ramp((k + 1) as f64 * 1e-3, 0.25),
            Some(c) => (k + 1) as f64 / c as f64,
        };
        if m.advance(1e-3, s).is_err() {
            break;
        }
        let e = s * strain;
        if out.len() < marks.len() && e >= marks[out.len()] {
            out.push((e, m.positions().to_vec()));
        }
        last = (e, m.positions().to_vec());
    }
    (out, last)
}

/// Spectrum summary of the tangent at `x`: sorted eigenvalues and the unit
/// eigenvector of the smallest as a nodal field.
fn spectrum(b: &TissueBody, law: Law, x: &[Vec3]) -> (Vec<f64>, Vec<Vec3>) {
    let eig = SymmetricEigen::new(tangent(b, law, x));
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &c| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[c]));
    let ev = order.iter().map(|&i| eig.eigenvalues[i]).collect();
    let v = eig.eigenvectors.column(order[0]);
    let mut u = vec![Vec3::zeros(); b.mesh.nodes.len()];
    for (k, &d) in free_dofs(b).iter().enumerate() {
        u[d / 3][d % 3] = v[k];
    }
    (ev, u)
}

/// Second difference of the elastic energy (J/m^2) along `u` at `x`
/// (the plates stay put: `u` is zero there).
fn energy_curvature(b: &TissueBody, law: Law, x: &[Vec3], u: &[Vec3], h: f64) -> f64 {
    let mut s = Solid::new(&b.mesh, &b.material, law, 1).expect("valid truth cube");
    let mut e = |c: f64| {
        let y: Vec<Vec3> = x.iter().zip(u).map(|(p, w)| p + w * c).collect();
        s.evaluate(&y, None, 0.0).energy
    };
    (e(h) - 2.0 * e(0.0) + e(-h)) / (h * h)
}

#[test]
fn level0_corotational_equilibrium_turns_unstable_near_10_percent() {
    let b = body(0.1825, 4);
    let (marks, (e_last, x_last)) = ramp_states(Law::Corotational, 0.1825, 4, &[0.098], None);
    // Measured: the ramp to 18.25 % fails at 12.8 % (last converged 12.70 %).
    assert!(
        marks.len() == 1 && e_last > 0.12 && e_last < 0.1825,
        "corotational level 0: last converged strain {e_last:.4} (expected the known failure past 12 %)"
    );
    // Round-off of the dense eigen-solver is ~1e-15 of the largest
    // eigenvalue; 1e-6 of it separates "stable"/"unstable" far above
    // round-off (measured: +6.6e-6 at 9.8 %, -4.8e-5 at 12.70 %).
    let (ev0, _) = spectrum(&b, Law::Corotational, &marks[0].1);
    let lmax0 = ev0[ev0.len() - 1];
    eprintln!(
        "corotational at {:.4}: smallest eigenvalues {:.4e} {:.4e}, largest {lmax0:.4e} N/m",
        marks[0].0, ev0[0], ev0[1]
    );
    assert!(
        ev0[0] > 1e-6 * lmax0,
        "corotational at strain {:.4}: expected a stable equilibrium, smallest eigenvalue {:.4e} N/m (largest {lmax0:.4e})",
        marks[0].0,
        ev0[0]
    );
    let (ev, u) = spectrum(&b, Law::Corotational, &x_last);
    let lmax = ev[ev.len() - 1];
    let negative = ev.iter().filter(|&&l| l < -1e-6 * lmax).count();
    eprintln!(
        "corotational at {e_last:.4}: {negative} negative eigenvalues, smallest {:.4e} {:.4e} {:.4e}, largest {lmax:.4e} N/m, ratio {:.3e}",
        ev[0],
        ev[1],
        ev[2],
        ev[0] / lmax
    );
    assert!(
        ev[0] < -1e-6 * lmax && negative >= 1,
        "corotational at strain {e_last:.4}: smallest eigenvalue {:.4e} N/m (largest {lmax:.4e}): expected a saddle",
        ev[0]
    );
    // Independent check of the negative curvature: the energy's second
    // difference along the (unit) mode. Truncation O(h^2 E'''') and
    // round-off ~1e-16 E / h^2 (E ~ 0.1 J) are both < 1e-3 N/m at h = 1e-5 m,
    // so 1 % of |lambda| (~0.16 N/m) is a loose bound.
    let d2e = energy_curvature(&b, Law::Corotational, &x_last, &u, 1e-5);
    assert!(
        (d2e - ev[0]).abs() < 1e-2 * ev[0].abs(),
        "energy second difference along the mode {d2e:.6e} vs eigenvalue {:.6e} N/m",
        ev[0]
    );
    // Mode character: lateral, largest on a vertical edge of the cube
    // one cell from a plate (measured 0.992 of |u|^2 lateral).
    let lateral: f64 = u.iter().map(|w| w.x * w.x + w.y * w.y).sum();
    let (imax, _) = u
        .iter()
        .enumerate()
        .max_by(|a, c| a.1.norm().total_cmp(&c.1.norm()))
        .expect("nodes");
    let p = b.mesh.nodes[imax];
    let on = |v: f64, w: f64| (v - w).abs() < 1e-9;
    eprintln!("mode: lateral fraction {lateral:.3}, largest at rest position {p:?}");
    assert!(
        lateral > 0.9
            && (on(p.x, 0.0) || on(p.x, EDGE))
            && (on(p.y, 0.0) || on(p.y, EDGE))
            && (on(p.z, 0.25 * EDGE) || on(p.z, 0.75 * EDGE)),
        "mode: lateral fraction {lateral:.3}, largest amplitude at {p:?}"
    );
}

#[test]
fn level0_neo_hookean_equilibrium_is_a_saddle_too() {
    let b = body(0.1825, 4);
    let (marks, (e_last, x_last)) = ramp_states(Law::NeoHookean, 0.1825, 4, &[0.049], None);
    assert!(
        marks.len() == 1 && (e_last - 0.1825).abs() < 1e-12,
        "neo-Hookean level 0 reached only {e_last:.4}"
    );
    // Same round-off argument as above (measured: +9.5e-5 of the largest
    // at 4.9 %, -2.6e-5 at 18.25 %).
    let (ev0, _) = spectrum(&b, Law::NeoHookean, &marks[0].1);
    let (ev, u) = spectrum(&b, Law::NeoHookean, &x_last);
    let (lmax0, lmax) = (ev0[ev0.len() - 1], ev[ev.len() - 1]);
    let negative = ev.iter().filter(|&&l| l < -1e-6 * lmax).count();
    eprintln!(
        "neo-Hookean: smallest eigenvalue {:.4e} at {:.4}, {:.4e} ({negative} negative) at 18.25 %, largest {lmax:.4e} N/m",
        ev0[0], marks[0].0, ev[0]
    );
    assert!(
        ev0[0] > 1e-6 * lmax0 && ev[0] < -1e-6 * lmax && negative >= 1,
        "neo-Hookean: smallest eigenvalue {:.4e} at {:.4} (largest {lmax0:.4e}), {:.4e} at 18.25 % (largest {lmax:.4e})",
        ev0[0],
        marks[0].0,
        ev[0]
    );
    // Energy second difference (see the corotational test for the bound).
    let d2e = energy_curvature(&b, Law::NeoHookean, &x_last, &u, 1e-5);
    assert!(
        (d2e - ev[0]).abs() < 1e-2 * ev[0].abs(),
        "energy second difference {d2e:.6e} vs eigenvalue {:.6e} N/m",
        ev[0]
    );
}

#[test]
fn level1_corotational_is_stable_where_level0_is_not() {
    // 8x8x8 cells at 12.70 %, the strain where the level-0 tangent already
    // has three negative eigenvalues; 8 equal load steps instead of the
    // 255-step ramp keep the test fast (the equilibrium is stable, so the
    // path does not matter).
    let strain = 0.1270;
    let b = body(strain, 8);
    let (_, (e_last, x)) = ramp_states(Law::Corotational, strain, 8, &[], Some(8));
    assert!(
        (e_last - strain).abs() < 1e-12,
        "level 1 corotational reached only {e_last:.4}"
    );
    // Cholesky succeeds iff the matrix is positive definite (measured
    // smallest eigenvalue +2.7 N/m, largest 1.9e5: condition 7e4, far
    // from where round-off could flip a pivot's sign).
    let k = tangent(&b, Law::Corotational, &x);
    let n = k.nrows();
    assert!(
        k.cholesky().is_some(),
        "level 1 corotational tangent at {strain} is not positive definite ({n} free DOFs)"
    );
}
