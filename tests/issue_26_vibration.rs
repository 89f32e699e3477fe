//! Issue 26: dynamics verified on `cantilever-vibration` (a cantilever
//! started in its first bending mode, free for 100 s; period 12.64 s). The
//! runs go through the harness as `surgbench run dynamics` does, so these
//! numbers are the report's.
//!
//! Closed forms for one linear mode `x'' = -omega^2 x` stepped at `h`
//! (amplification matrices of the two schemes; e.g. Hughes, *The Finite
//! Element Method*, 1987, Sec. 9.3): backward Euler multiplies the amplitude
//! by `(1 + (omega h)^2)^(-1/2)` and advances the phase by `atan(omega h)`
//! per step, so it keeps `(1 + (omega h)^2)^(-pi / atan(omega h))` of the
//! amplitude per period; Newmark (beta = 1/4, gamma = 1/2) keeps all of it
//! and advances the phase by `2 atan(omega h / 2)`, lengthening the period
//! by `(omega h / 2) / atan(omega h / 2)`.

use surgbench_comparisons::registry;
use surgbench_comparisons::runner::{RunOptions, RunSummary, run_single};
use surgbench_comparisons::scenario::Params;
use surgbench_core::beam::{FIRST_CANTILEVER_MODE, SECOND_CANTILEVER_MODE, cantilever_mode};
use surgbench_core::{Fidelity, Setting};

const SCENARIO: &str = "cantilever-vibration";

/// `omega_1` of the default rod (rad/s): 1.8751^2 sqrt(EI / (rho A L^4)).
fn omega() -> f64 {
    let (r, e, rho, l) = (0.02f64, 1e5, 500.0, 1.0f64);
    FIRST_CANTILEVER_MODE.powi(2) * (e * r * r / 4.0 / (rho * l.powi(4))).sqrt()
}

fn fidelity(knobs: &[(&str, f64)], extras: &[(&str, &str)]) -> Fidelity {
    let mut f = Fidelity::default();
    for (k, v) in knobs {
        f.set(k, *v).unwrap();
    }
    for (k, v) in extras {
        f.extras.insert(k.to_string(), Setting::from(*v));
    }
    f
}

fn run(model: &str, fid: &Fidelity) -> RunSummary {
    let sc = registry::scenario(SCENARIO).unwrap();
    let p = Params::resolve(sc.id(), sc.params(), &[]).unwrap();
    let inst = sc.instantiate_at(&p, fid).unwrap();
    let f = registry::model(model).unwrap();
    let s = run_single(sc, &p, &inst, f, fid, &RunOptions::default()).unwrap();
    assert_eq!(s.status, "ok", "{model} {fid}: {}", s.reason);
    assert_eq!(s.end, "duration", "{model} {fid} did not run the 100 s");
    s
}

/// Backward Euler's amplitude kept per period at step `h` (module docs).
fn backward_euler_ratio(h: f64) -> f64 {
    let x = omega() * h;
    (-(std::f64::consts::PI / x.atan()) * (1.0 + x * x).ln()).exp()
}

/// The target: DER at its default fidelity (40 segments, dt = 1 ms,
/// Newmark for a free rod) keeps the period within 0.5 % and the amplitude
/// within 1 % over the 100 s. Measured: 5.3e-4 and -4.4e-4 (the discrete
/// first mode's tip amplitude under the continuous one's start, O(h^2)).
#[test]
fn der_default_keeps_period_and_amplitude() {
    let s = run("der", &Fidelity::default());
    assert!(
        s.fidelity_string.contains("integrator=newmark"),
        "{}",
        s.fidelity_string
    );
    let (period, loss) = (s.errors["period_error_rel"], s.errors["amplitude_loss_rel"]);
    assert!(period < 5e-3, "period error {period:.3e}");
    assert!(loss.abs() < 1e-2, "amplitude loss {loss:.3e}");
    // Newmark conserves: the fitted decay per period is round-off and the
    // mode's slight beating with higher ones (measured 1.8e-7).
    assert!(s.errors["damping_per_period"].abs() < 1e-5);
}

/// `model` with `extra` set damps as backward Euler at `dt / substeps` for
/// each `dt`, to 1 % of the damping: the closed form holds for the discrete
/// first mode, whose frequency is within 5.3e-4 (DER, 40 segments) of
/// omega_1, so 1 % is already loose (measured: within 0.1 %).
fn damps_as_backward_euler(model: &str, extra: (&str, &str), dts: &[f64], substeps: f64) {
    for &dt in dts {
        let s = run(model, &fidelity(&[("dt", dt)], &[extra]));
        let want = 1.0 - backward_euler_ratio(dt / substeps);
        let got = s.errors["damping_per_period"];
        assert!(
            (got - want).abs() < 1e-2 * want,
            "{model} dt {dt}: damping {got:.5} against {want:.5}"
        );
    }
}

/// Backward Euler's numerical damping is the closed form's at three steps
/// (the issue asks for 10 %).
#[test]
fn der_backward_euler_damps_as_the_closed_form() {
    damps_as_backward_euler("der", ("integrator", "backward-euler"), &[0.4, 0.2, 0.1], 1.0);
}

/// XPBD with the direct solve is implicit Euler in positions at the
/// substep `h = dt / substeps` (Macklin et al. 2016, Eq. 1-4: the update is
/// the backward Euler step of the constraint potential): its damping per
/// period is backward Euler's at `h` (default 4 substeps).
#[test]
fn pbd_rod_direct_damps_as_backward_euler_at_the_substep() {
    damps_as_backward_euler("pbd-rod", ("solver", "direct"), &[0.4, 0.1], 4.0);
}

/// The period error of DER (Newmark, dt = 0.02 s: time error
/// (omega dt)^2 / 12 = 8e-6) falls at second order in the segment count,
/// the order of the discrete bending energy (Bergou et al. 2008). Measured
/// at dt = 0.05 s: 8.5e-3, 2.2e-3, 5.8e-4 at 10, 20, 40 segments.
#[test]
fn der_period_converges_at_second_order_in_segments() {
    let errors: Vec<f64> = [10.0, 20.0, 40.0]
        .iter()
        .map(|&n| {
            let s = run("der", &fidelity(&[("segments", n), ("dt", 0.02)], &[]));
            s.errors["period_error_rel"]
        })
        .collect();
    for w in errors.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!(order > 1.8, "order {order:.2} from {errors:?}");
    }
}

/// Newmark's period lengthening is the closed form's: at 40 segments and
/// dt = 0.4 s the time error (3.3e-3) dominates the space error (5.3e-4 at
/// dt = 1 ms, from the default run), and their sum is what is measured
/// (3.81e-3 against 3.82e-3); 5 % covers the two not adding exactly.
#[test]
fn der_newmark_period_lengthens_as_the_closed_form() {
    let x = omega() * 0.4 / 2.0;
    let time_error = x / x.atan() - 1.0;
    let space = run("der", &fidelity(&[("dt", 0.01)], &[]));
    let coarse = run("der", &fidelity(&[("dt", 0.4)], &[]));
    let want = time_error + space.errors["period_error_rel"];
    let got = coarse.errors["period_error_rel"];
    assert!(
        (got - want).abs() < 5e-2 * want,
        "period error {got:.4e} against {want:.4e}"
    );
}

/// A rod started in the first mode stays in it: the transverse displacement
/// projected on the first two clamped-free modes (trapezoid over the free
/// nodes; the modes are orthonormal) has a second-mode content below 1 % of
/// the first's over two periods (the stated fraction). What excites
/// mode 2 is the difference between the continuous mode the rod is started
/// in and the discrete one, O(h^2): measured 1.2e-3 for DER at 40 segments
/// and 5.2e-4 for pbd-rod (direct) at 50.
#[test]
fn a_rod_started_in_the_first_mode_stays_in_it() {
    use surgbench_core::{DeviceCommand, resolve};
    let sc = registry::scenario(SCENARIO).unwrap();
    let p = Params::resolve(sc.id(), sc.params(), &[("duration".into(), 25.0)]).unwrap();
    let inst = sc.instantiate(&p).unwrap();
    let scene = inst.scene();
    for (model, extras) in [("der", vec![]), ("pbd-rod", vec![("solver", "direct")])] {
        let f = registry::model(model).unwrap();
        let fid = fidelity(&[("dt", 0.01)], &extras);
        let settings = resolve(f, scene, &fid).unwrap();
        let mut m = f.build_resolved(scene, &settings).unwrap();
        let (mut c1_max, mut c2_max) = (0.0f64, 0.0f64);
        let steps = (25.0 / m.dt()).round() as usize;
        for _ in 0..steps {
            m.step(m.dt(), &DeviceCommand::default()).unwrap();
            let obs = m.observe();
            let r = &obs.rods[0];
            let (mut c1, mut c2) = (0.0, 0.0);
            let free: Vec<(f64, f64)> = r
                .arclength
                .iter()
                .zip(&r.nodes)
                .filter(|(s, _)| **s >= 0.0)
                .map(|(s, x)| (*s, x.z))
                .collect();
            for w in free.windows(2) {
                let ds = w[1].0 - w[0].0;
                for (s, z) in [w[0], w[1]] {
                    c1 += 0.5 * ds * z * cantilever_mode(FIRST_CANTILEVER_MODE, s).0;
                    c2 += 0.5 * ds * z * cantilever_mode(SECOND_CANTILEVER_MODE, s).0;
                }
            }
            c1_max = c1_max.max(c1.abs());
            c2_max = c2_max.max(c2.abs());
        }
        let ratio = c2_max / c1_max;
        eprintln!("{model}: second-mode content {ratio:.3e} of the first");
        assert!(ratio < 1e-2, "{model}: second-mode content {ratio:.3e} of the first");
    }
}

// --- block-vibration: a tissue block clamped at its base, started in its
// first eigenmode (scikit-fem P2 reference, period 0.1270 s at the defaults).

/// `model` on `block-vibration` at `fid` for `duration` s, checked ok and
/// run to the end.
fn run_block(model: &str, fid: &Fidelity, duration: f64) -> RunSummary {
    let sc = registry::scenario("block-vibration").unwrap();
    let p = Params::resolve(sc.id(), sc.params(), &[("duration".into(), duration)]).unwrap();
    let inst = sc.instantiate_at(&p, fid).unwrap();
    let f = registry::model(model).unwrap();
    let s = run_single(sc, &p, &inst, f, fid, &RunOptions::default()).unwrap();
    assert_eq!(s.status, "ok", "{model} {fid}: {}", s.reason);
    assert_eq!(s.end, "duration", "{model} {fid} did not run to the end");
    s
}

/// fem (Newmark, its default for a free body) converges on the scikit-fem
/// period with mesh level: linear tets' eigenvalue error is O(h^2) for a
/// smooth mode (Strang & Fix 1973, Ch. 6), lowered here by the clamped base
/// edges' singularity (the P2 reference itself converges at 1.84).
/// Measured over four periods: 0.208, 0.0909, 0.0294 at levels 0, 1, 2
/// (orders 1.19, 1.63; over ten periods level 3, 3.5 min, gives 7.9e-3
/// after 0.0294 at level 2: order 1.90); the
/// P1 mesh is too stiff, so the period is short at every level. The
/// asserted order (> 1.4 from level 1 to 2) is the measured one less the
/// scatter a four-period fit leaves; the coarse pair is pre-asymptotic.
#[test]
fn fem_block_period_converges_with_mesh_level() {
    let errors: Vec<f64> = [0.0, 1.0, 2.0]
        .iter()
        .map(|&level| {
            // Newmark is fem's default integrator.
            run_block("fem", &fidelity(&[("mesh_level", level)], &[]), 0.52).errors["period_error_rel"]
        })
        .collect();
    eprintln!("fem block period errors at levels 0, 1, 2: {errors:?}");
    assert!(errors[0] > errors[1] && errors[1] > errors[2], "{errors:?}");
    let order = (errors[1] / errors[2]).log2();
    assert!(order > 1.4 && order < 2.5, "order {order:.2} from {errors:?}");
}

/// Newmark (beta = 1/4, gamma = 1/2) conserves the energy of a linear
/// system exactly (its amplification matrix is a rotation: Hughes 1987,
/// Sec. 9.3), so with the linear law the block's kinetic + strain energy
/// holds to round-off over ten periods (measured 8.5e-13); the corotational
/// law with one Newton iteration per step drifts by what its linearization
/// leaves (measured 4.5e-5), bounded here by 1e-3 over ten periods: the
/// amplitude, as the square root of the energy, then changes by 5e-4 at
/// most, half of DER's 1 % amplitude target on the cantilever.
#[test]
fn fem_newmark_keeps_the_block_energy_over_ten_periods() {
    let lin = run_block(
        "fem",
        &fidelity(&[("mesh_level", 1.0)], &[("material_law", "linear")]),
        1.3,
    );
    assert!(
        lin.errors["energy_drift_rel"] < 1e-9,
        "linear: {:.3e}",
        lin.errors["energy_drift_rel"]
    );
    let corot = run_block("fem", &fidelity(&[("mesh_level", 1.0)], &[]), 1.3);
    let drift = corot.errors["energy_drift_rel"];
    assert!(drift < 1e-3, "corotational: energy drift {drift:.3e}");
    // No numerical damping: the fitted decay per period is the beating of
    // the higher modes the P1 start excites (measured 4.6e-5).
    assert!(corot.errors["damping_per_period"].abs() < 1e-3);
}

/// fem's backward Euler damps the block as the closed form does for the
/// model's own first mode: `1 - (1 + (omega h)^2)^(-pi / atan(omega h))`
/// with `omega` from the run's measured period (the P1 mode's, 9 % above
/// the reference's at level 1). Measured 0.15717 against 0.15706; 1 % as
/// for the rods.
#[test]
fn fem_backward_euler_damps_the_block_as_the_closed_form() {
    let dt = 1e-3;
    let s = run_block(
        "fem",
        &fidelity(&[("mesh_level", 1.0), ("dt", dt)], &[("integrator", "backward-euler")]),
        1.3,
    );
    let x = 2.0 * std::f64::consts::PI / s.errors["period_s"] * dt;
    let want = 1.0 - (-(std::f64::consts::PI / x.atan()) * (1.0 + x * x).ln()).exp();
    let got = s.errors["damping_per_period"];
    assert!((got - want).abs() < 1e-2 * want, "damping {got:.5} against {want:.5}");
}
