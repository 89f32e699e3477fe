//! Cost of the Cholesky pieces alone on the bench block's Newmark matrix
//! `c_m M + K` (12,960 tets / 2,704 nodes, bottom fixed, top driven,
//! `dt = 1 ms`, Rayleigh `alpha = 5/s`, warped stiffness at rest): factor
//! non-zeros, and wall time per numeric factorization and per
//! forward/backward solve (faer, `f64`, sequential), and per application
//! of the stale-factor PCG's preconditioner with the `f64` factor and with
//! the `f32` copy solved two-way parallel ([`surgbench_fem::supernodal`];
//! `threads` is the size of the rayon pool it runs in).
//!
//! `cargo run --release -p surgbench-fem --example factor_cost -- [amd|rcm|nd] [threads] [factorizations] [solves] [f64|f32]`
//!
//! For instruction counts run it under
//! `valgrind --tool=callgrind --toggle-collect='*System*factorize*'`
//! (or `'*System*solve_cholesky*'`, `'*CholState*solve_precond*'`) and
//! divide by the repetitions. Also
//! prints a bit pattern hash of the last solution (reruns and thread
//! counts can be compared for bit-identity).

use std::time::Instant;
use surgbench_fem::Ordering;
use surgbench_fem::assembly::System;
use surgbench_fem::bench_support::bench_block;
use surgbench_fem::core::Solid;
use surgbench_fem::{Jacobian, Law};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let ordering = match args.get(1).map(|s| s.as_str()).unwrap_or("amd") {
        "rcm" => Ordering::Rcm,
        "nd" => Ordering::NestedDissection,
        _ => Ordering::Amd,
    };
    let threads: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let nfact: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(3);
    let nsolve: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(20);
    let b = bench_block();
    let mut solid = Solid::new(&b.mesh, &b.material, Law::Corotational, threads).expect("solid");
    let n = solid.n_nodes();
    let mut free = vec![true; 3 * n];
    for &i in b.fixed_nodes.iter().chain(b.driven_nodes.iter().map(|d| &d.0)) {
        free[3 * i..3 * i + 3].fill(false);
    }
    let rest = solid.rest.clone();
    solid.evaluate(&rest, Some(Jacobian::Warped), 0.0);
    let (dt, alpha) = (1e-3, 5.0);
    let c_m = 4.0 / (dt * dt) + alpha * 2.0 / dt;
    let mut sys = System::new(&solid.pat, free);
    sys.set_values(&solid.pat, &solid.kmat, 1.0, &solid.mass, c_m);
    let t0 = Instant::now();
    for _ in 0..nfact {
        solid
            .install(|| sys.factorize(&solid.pat, ordering))
            .expect("factorize");
    }
    let fact_ms = t0.elapsed().as_secs_f64() * 1e3 / nfact.max(1) as f64;
    let rhs: Vec<f64> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f64 * 1e-3 - 0.5).collect();
    let mut x = rhs.clone();
    let t0 = Instant::now();
    for _ in 0..nsolve {
        x.copy_from_slice(&rhs);
        solid.install(|| sys.solve_cholesky(&mut x));
    }
    let solve_ms = t0.elapsed().as_secs_f64() * 1e3 / nsolve.max(1) as f64;
    let hash = x.iter().fold(0u64, |h, v| h.rotate_left(5) ^ v.to_bits());
    // The stale-factor PCG's preconditioner alone (zero iterations: one
    // preconditioner solve and one product with `A`), with the f64 and the
    // f32 factor (fifth argument: `f64` or `f32` for only that one).
    let mut pre_ms = [f64::NAN; 2];
    let which = args.get(5).map(|s| s.as_str());
    for (single, ms) in [false, true].into_iter().zip(&mut pre_ms) {
        if which.is_some_and(|w| w != if single { "f32" } else { "f64" }) {
            continue;
        }
        sys.set_single_precision_preconditioner(single);
        let t0 = Instant::now();
        for _ in 0..nsolve {
            x.fill(0.0);
            solid.install(|| {
                sys.solve_factor_pcg(&solid.pat, &solid.kmat, 1.0, &solid.mass, c_m, &rhs, &mut x, 1e-6, 0)
            });
        }
        *ms = t0.elapsed().as_secs_f64() * 1e3 / nsolve.max(1) as f64;
    }
    println!(
        "{ordering:?} threads {threads}: free DOFs {}, factor nnz {:?} (f32 cut: bins and top {:?}), {fact_ms:.2} ms/factorization, {solve_ms:.3} ms/solve, PCG preconditioner + product f64 {:.3} / f32 {:.3} ms, solution hash {hash:016x}",
        sys.n_free(),
        sys.factor_nnz(),
        sys.split_values(),
        pre_ms[0],
        pre_ms[1]
    );
}
