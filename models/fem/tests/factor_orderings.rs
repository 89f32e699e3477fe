//! The Cholesky fill orderings and the `f32` stale-factor preconditioner.
//!
//! * [`Pattern::nested_dissection`] returns a permutation of the nodes and,
//!   on the bench block (12,960 tets), gives a sparser factor than AMD and
//!   RCM, with the same solution up to round-off;
//! * the stale-factor PCG with the `f32` copy of the factor
//!   (`DynParams::reuse_f32`) reaches the same tolerance, so it moves the
//!   nodes by no more than that tolerance allows, and it is bit-identical
//!   across reruns and thread counts.

use surgbench_core::Vec3;
use surgbench_fem::assembly::{Pattern, System};
use surgbench_fem::bench_support::bench_block;
use surgbench_fem::core::Solid;
use surgbench_fem::{DynParams, FemModel, Jacobian, Law, LinearSolver, Ordering};

fn assert_permutation(order: &[usize], n: usize, what: &str) {
    let mut seen = vec![false; n];
    assert_eq!(
        order.len(),
        n,
        "{what}: order has {} entries for {n} nodes",
        order.len()
    );
    for &i in order {
        assert!(i < n && !seen[i], "{what}: node {i} out of range or repeated");
        seen[i] = true;
    }
}

#[test]
fn nested_dissection_is_a_permutation() {
    let b = bench_block();
    let pat = Pattern::new(&b.mesh.nodes, &b.mesh.tets);
    assert_permutation(&pat.nested_dissection(), b.mesh.nodes.len(), "bench block");
    // An uneven block (odd cell counts, one cell thick in x) and a single tet.
    let m = surgbench_core::mesh::block(Vec3::new(0.01, 0.03, 0.02), [1, 7, 5]);
    let pat = Pattern::new(&m.nodes, &m.tets);
    assert_permutation(&pat.nested_dissection(), m.nodes.len(), "1 x 7 x 5 block");
    let tet = [Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()];
    let pat = Pattern::new(&tet, &[[0, 1, 2, 3]]);
    assert_permutation(&pat.nested_dissection(), 4, "one tet");
}

/// The bench block's Newmark matrix `c_m M + K` (dt = 1 ms, Rayleigh
/// alpha = 5/s), factorized with `ordering`, and a fixed right-hand side.
fn bench_system(ordering: Ordering, single: bool) -> (Solid, System, f64, Vec<f64>) {
    let b = bench_block();
    let mut solid = Solid::new(&b.mesh, &b.material, Law::Corotational, 1).expect("solid");
    let n = solid.n_nodes();
    let mut free = vec![true; 3 * n];
    for &i in b.fixed_nodes.iter().chain(b.driven_nodes.iter().map(|d| &d.0)) {
        free[3 * i..3 * i + 3].fill(false);
    }
    let rest = solid.rest.clone();
    solid.evaluate(&rest, Some(Jacobian::Warped), 0.0);
    let c_m = 4.0 / (1e-3 * 1e-3) + 5.0 * 2.0 / 1e-3;
    let mut sys = System::new(&solid.pat, free);
    sys.set_single_precision_preconditioner(single);
    sys.set_values(&solid.pat, &solid.kmat, 1.0, &solid.mass, c_m);
    sys.factorize(&solid.pat, ordering).expect("positive definite");
    let b: Vec<f64> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f64 * 1e-3 - 0.5).collect();
    (solid, sys, c_m, b)
}

/// Factor non-zeros and the direct (f64) solution of the fixed right-hand side.
fn factor_and_solve(ordering: Ordering) -> (usize, Vec<f64>) {
    let (_, mut sys, _, mut x) = bench_system(ordering, false);
    sys.solve_cholesky(&mut x);
    (sys.factor_nnz().expect("factorized"), x)
}

#[test]
fn f32_split_solve_preconditions_its_own_matrix_almost_exactly() {
    let (_, mut sys, _, mut x_ref) = bench_system(Ordering::NestedDissection, true);
    let [b0, b1, top] = sys.split_values().expect("faer chose a supernodal factor");
    let nnz = sys.factor_nnz().expect("factorized");
    assert_eq!(b0 + b1 + top, nnz, "the cut covers the factor once");
    assert!(b0 > 0 && b1 > 0, "both bins have work: {b0}, {b1}, top {top}");
    let b = x_ref.clone();
    sys.solve_cholesky(&mut x_ref);
    for threads in [1, 2] {
        let (solid, mut sys, c_m, _) = bench_system(Ordering::NestedDissection, true);
        let mut x = vec![0.0; b.len()];
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let (it, rel) = pool
            .install(|| sys.solve_factor_pcg(&solid.pat, &solid.kmat, 1.0, &solid.mass, c_m, &b, &mut x, 1e-10, 10))
            .expect("factorized");
        // The preconditioner is this matrix's own factor rounded to f32:
        // `M^-1 A = I + E` with `|E|` of order cond(A) * 6e-8, so each CG
        // iteration gains about six digits and 1e-10 takes two; a wrong
        // split solve (a missed update between bins and top) stalls.
        assert!(it <= 2 && rel <= 1e-10, "{threads} threads: {it} iterations to {rel:e}");
        let scale = x_ref.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = x.iter().zip(&x_ref).fold(0.0f64, |m, (a, c)| m.max((a - c).abs()));
        // Residual 1e-10 relative: the solution error is at most
        // cond(A) * 1e-10, far below 1e-8 for this mass-dominated matrix.
        assert!(
            diff <= 1e-8 * scale,
            "{threads} threads: x differs from the f64 solve by {diff:e}"
        );
    }
}

#[test]
fn nested_dissection_reduces_fill_on_the_bench_block() {
    let (nnz_nd, x_nd) = factor_and_solve(Ordering::NestedDissection);
    let (nnz_amd, x_amd) = factor_and_solve(Ordering::Amd);
    let (nnz_rcm, _) = factor_and_solve(Ordering::Rcm);
    // Measured: ND 2.27 M, AMD 2.86 M, RCM 5.54 M; only the order is asserted.
    assert!(
        nnz_nd < nnz_amd && nnz_nd < nnz_rcm,
        "factor nnz: nested dissection {nnz_nd}, AMD {nnz_amd}, RCM {nnz_rcm}"
    );
    // The automatic ordering keeps the smaller of the two analyses.
    let (nnz_auto, x_auto) = factor_and_solve(Ordering::Auto);
    assert_eq!(nnz_auto, nnz_nd.min(nnz_amd));
    assert_eq!(x_auto, x_nd, "auto picked nested dissection, same factor");
    let scale = x_amd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = x_nd.iter().zip(&x_amd).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    // Same matrix, two orderings: the solutions differ by round-off only
    // (measured 2e-15 of the largest entry); 1e-12 leaves a margin of 500
    // for other CPUs' kernels, while a wrong permutation would give O(1).
    assert!(
        diff <= 1e-12 * scale,
        "ND vs AMD solution differ by {diff:e} (scale {scale:e})"
    );
}

/// Ramp the bench block to full stroke over 20 steps and hold 5, with the
/// stale-factor PCG (every element rebuilt) under nested dissection.
fn run(reuse_f32: bool, threads: usize) -> (Vec<Vec3>, (usize, usize)) {
    let p = DynParams {
        solver: LinearSolver::Cholesky(Ordering::NestedDissection),
        reuse_f32,
        rayleigh_mass: 5.0,
        threads,
        ..Default::default()
    };
    let mut m = FemModel::new(&bench_block(), Vec3::zeros(), 1e-3, p).expect("bench model");
    for k in 0..25 {
        m.advance(1e-3, ((k + 1) as f64 / 20.0).min(1.0)).expect("step");
    }
    (m.positions(), m.solver_counts())
}

#[test]
fn f32_preconditioner_reaches_the_same_tolerance() {
    let (x64, c64) = run(false, 2);
    let (x32, c32) = run(true, 2);
    let rest = &bench_block().mesh.nodes;
    let scale = x64.iter().zip(rest).fold(0.0f64, |m, (p, q)| m.max((p - q).norm()));
    let diff = x64.iter().zip(&x32).fold(0.0f64, |m, (p, q)| m.max((p - q).norm()));
    // Both stop at a relative residual of REUSE_TOL = 1e-6 every step, so
    // each solve's error is of that order relative to the step's motion:
    // 1e-6 of the largest displacement bounds 25 steps. Measured 7e-15: the
    // f32 rounding only perturbs the CG's correction to the predictor,
    // which is small (examples/step_speed.rs: both match the refactorized
    // reference to the same 6.8e-7 with the same iteration counts).
    assert!(
        diff <= 1e-6 * scale,
        "f32 vs f64 preconditioner: nodes differ by {diff:e} m (largest displacement {scale:e} m); counts {c64:?} vs {c32:?}"
    );
    // ...but the f32 path was taken: its round-off shows.
    assert!(x32 != x64, "f32 and f64 preconditioner gave bit-identical nodes");
    // Bit-identical for a rerun and for another thread count.
    let (x1, c1) = run(true, 1);
    assert!(x1 == x32 && c1 == c32, "1 vs 2 threads: counts {c1:?} vs {c32:?}");
    let (x2, _) = run(true, 2);
    assert!(x2 == x32, "rerun with 2 threads differs");
}

/// The sparse forward solves' Gram matrix `b_a^T A^-1 b_b` (the tissue's
/// share of the needle's Delassus matrix) against full solves of the
/// bench system ([`bench_system`]), for
/// right-hand sides spread over single tets across the bench block (near
/// the fixed face, the driven face and the middle), with every ordering:
/// the same numbers up to the solves' round-off.
#[test]
fn sparse_forward_gram_matches_full_solves() {
    let b = bench_block();
    let n = b.mesh.nodes.len();
    // Three tets, two axes each, with barycentric weights; one tet touches
    // the fixed bottom (its constrained DOFs are ignored).
    let tets = [0usize, b.mesh.tets.len() / 2, b.mesh.tets.len() - 1];
    let w = [0.1, 0.2, 0.3, 0.4];
    let rhs: Vec<Vec<(usize, f64)>> = tets
        .iter()
        .flat_map(|&e| {
            let t = b.mesh.tets[e];
            [Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.6, 0.8)]
                .into_iter()
                .map(move |dir| {
                    (0..4)
                        .flat_map(|a| (0..3).map(move |c| (3 * t[a] + c, w[a] * dir[c])))
                        .collect()
                })
        })
        .collect();
    let k = rhs.len();
    for ordering in [Ordering::Amd, Ordering::NestedDissection, Ordering::Rcm] {
        let (_, mut sys, _, _) = bench_system(ordering, false);
        let g = sys.gram(&rhs).expect("the bench block's factor is supernodal");
        let mut x = vec![0.0; 3 * n * k];
        for (col, entries) in rhs.iter().enumerate() {
            for &(d, v) in entries {
                x[col * 3 * n + d] += v;
            }
        }
        let bs = x.clone();
        sys.solve_cholesky_many(&mut x, k);
        let scale = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0);
        for a in 0..k {
            for c in 0..k {
                // b_a^T x_c over the free DOFs (x is zero at the others).
                let full: f64 = (0..3 * n).map(|d| bs[a * 3 * n + d] * x[c * 3 * n + d]).sum();
                // Two backward-stable solves of the same factor, summed in
                // different orders: measured 5.8e-16 of the largest entry
                // at most; 1e-13 leaves a factor of 170 for other CPUs.
                assert!(
                    (g[a * k + c] - full).abs() <= 1e-13 * scale,
                    "{ordering:?} G[{a}][{c}] = {} vs {full}",
                    g[a * k + c]
                );
                assert_eq!(g[a * k + c], g[c * k + a]);
            }
        }
        // The same products from the kept columns (`forward_columns`, the
        // needle's cache across steps), one column solved at a time as a
        // new coupling point is: their dot products agree with the full
        // solves to the same round-off.
        let id = sys.factor_id().expect("factored");
        let cols: Vec<_> = rhs
            .iter()
            .map(|b| {
                let (got, mut y) = sys.forward_columns(std::slice::from_ref(b)).expect("supernodal");
                assert_eq!(got, id, "one factor, one id");
                y.pop().expect("one column")
            })
            .collect();
        for a in 0..k {
            for c in 0..k {
                let (d, e) = (cols[a].dot(&cols[c]), g[a * k + c]);
                // As above: two stable solves of one factor.
                assert!((d - e).abs() <= 1e-13 * scale, "{ordering:?} y_{a}.y_{c} = {d} vs {e}");
                assert_eq!(d, cols[c].dot(&cols[a]), "the dot product is symmetric");
            }
        }
        // A full solve in two halves with a column subtracted between them
        // (the needle's coupled step): forward `u = L^-1 P r`, `b_a^T A^-1 r
        // = y_a . u`, then backward from `u - 0.5 y_0` is `A^-1 (r - 0.5
        // b_0)`: against full solves, to their round-off.
        let r: Vec<f64> = (0..3 * n).map(|d| ((d * 7919) % 101) as f64 / 101.0 - 0.5).collect();
        let (got, mut u) = sys.forward_half(&r).expect("supernodal");
        assert_eq!(got, id);
        let mut full = r.clone();
        sys.solve_cholesky(&mut full);
        let rscale = full.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (a, y) in cols.iter().enumerate() {
            let want: f64 = (0..3 * n).map(|d| bs[a * 3 * n + d] * full[d]).sum();
            let bnorm: f64 = bs[a * 3 * n..(a + 1) * 3 * n].iter().map(|v| v.abs()).sum();
            // Relative to |b|_1 |A^-1 r|_inf: measured 8.5e-17 at most;
            // 1e-13 as above.
            assert!(
                (y.dot_dense(&u) - want).abs() <= 1e-13 * bnorm * rscale,
                "{ordering:?} y_{a}.u"
            );
        }
        cols[0].sub_from(0.5, &mut u);
        let mut z = vec![0.0; 3 * n];
        sys.backward_half(&mut u, &mut z).expect("supernodal");
        let mut want: Vec<f64> = (0..3 * n).map(|d| r[d] - 0.5 * bs[d]).collect();
        sys.solve_cholesky(&mut want);
        for d in 0..3 * n {
            // Two stable solves of one factor, summed in other orders:
            // measured 1.9e-15 of the largest entry; 1e-12 leaves 500x.
            assert!(
                (z[d] - want[d]).abs() <= 1e-12 * rscale,
                "{ordering:?} dof {d}: {} vs {}",
                z[d],
                want[d]
            );
        }
        sys.forget_factorization();
        assert!(sys.gram(&rhs).is_none(), "no valid factor");
        assert!(sys.forward_columns(&rhs).is_none() && sys.factor_id().is_none());
        assert!(sys.forward_half(&r).is_none() && sys.backward_half(&mut u, &mut z).is_none());
    }
}
