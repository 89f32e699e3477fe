//! `fit_order`, `pareto_front` and the tick/number formatting, on data whose
//! answer is known in closed form.

mod common;

use surgbench_reports::{NoOrder, fit_convergence, fit_order, fmt_sig, fmt_tick, log_ticks, pareto_front};

#[test]
fn recovers_exact_orders() {
    let n = [8.0, 16.0, 32.0, 64.0, 128.0];
    for (p_true, c) in [(2.0, 0.37), (1.0, 5.0), (0.5, 1e-3), (4.0, 1e3)] {
        let e: Vec<f64> = n.iter().map(|n: &f64| c * n.powf(-p_true)).collect();
        let p = fit_order(&n, &e).expect("five points fit");
        // Exact power law: only rounding of ln/pow remains, ~1e-15 relative.
        assert!((p - p_true).abs() < 1e-12, "p_true={p_true} C={c}: fitted {p}");
    }
    // Non-uniform spacing and unsorted input.
    let n = [40.0, 10.0, 13.0, 100.0];
    let e: Vec<f64> = n.iter().map(|n: &f64| 2.0 / (n * n)).collect();
    let p = fit_order(&n, &e).unwrap();
    assert!((p - 2.0).abs() < 1e-12, "unsorted: fitted {p}");
}

#[test]
fn least_squares_on_noisy_data() {
    // Multiplicative noise of +-5 % around C n^-2 over one decade of n.
    let mut rng = common::SplitMix(7);
    let n: Vec<f64> = (0..12).map(|i| 10.0 * 10f64.powf(i as f64 / 11.0)).collect();
    let e: Vec<f64> = n
        .iter()
        .map(|n| 0.3 * n.powi(-2) * (1.0 + 0.1 * (rng.unit() - 0.5)))
        .collect();
    let p = fit_order(&n, &e).unwrap();
    // Worst case of the least-squares slope under |d ln e| <= -ln(0.95):
    // |dp| <= max|d| * sum|x - mean| / sum (x - mean)^2, with x = ln n.
    let x: Vec<f64> = n.iter().map(|n| n.ln()).collect();
    let mx = x.iter().sum::<f64>() / x.len() as f64;
    let bound = -(0.95f64.ln()) * x.iter().map(|x| (x - mx).abs()).sum::<f64>()
        / x.iter().map(|x| (x - mx).powi(2)).sum::<f64>();
    assert!((p - 2.0).abs() <= bound, "noisy fit {p}, worst-case bound {bound}");
}

#[test]
fn none_without_two_usable_points() {
    assert_eq!(fit_order(&[10.0], &[1e-3]), None);
    assert_eq!(fit_order(&[], &[]), None);
    // Equal resolutions: no slope.
    assert_eq!(fit_order(&[10.0, 10.0], &[1e-3, 2e-3]), None);
    // Non-positive or non-finite points are dropped, leaving one.
    assert_eq!(fit_order(&[10.0, 20.0, 40.0], &[1e-3, 0.0, f64::NAN]), None);
    assert_eq!(fit_order(&[10.0, -20.0], &[1e-3, 1e-4]), None);
    // Dropped points do not disturb the rest.
    let p = fit_order(&[10.0, 20.0, 40.0, 0.0], &[1e-2, 0.0, 1e-2 / 16.0, 1.0]).unwrap();
    assert!((p - 2.0).abs() < 1e-12, "fitted {p}");
}

#[test]
fn pareto_front_keeps_only_non_dominated_points() {
    let pts = [
        (1.0, 0.1),   // 0 front
        (2.0, 0.01),  // 1 front
        (3.0, 0.05),  // 2 dominated by 1
        (0.5, 0.2),   // 3 front (fastest)
        (2.0, 0.02),  // 4 dominated by 1 (same time, worse error)
        (5.0, 0.001), // 5 front (most accurate)
        (1.0, 0.1),   // 6 duplicate of 0: dropped
        (f64::NAN, 1e-9),
    ];
    assert_eq!(pareto_front(&pts), vec![3, 0, 1, 5]);
    // Brute-force check of the definition on seeded random points.
    let mut rng = common::SplitMix(99);
    let pts: Vec<(f64, f64)> = (0..200).map(|_| (rng.unit(), rng.unit())).collect();
    let front = pareto_front(&pts);
    for (i, p) in pts.iter().enumerate() {
        let dominated = pts.iter().any(|q| q.0 <= p.0 && q.1 <= p.1 && (q.0 < p.0 || q.1 < p.1));
        assert_eq!(front.contains(&i), !dominated, "point {i} {p:?}");
    }
    assert!(front.windows(2).all(|w| pts[w[0]].0 < pts[w[1]].0), "not time-ordered");
}

#[test]
fn tick_and_table_formatting() {
    assert_eq!(fmt_tick(1e-3), "1e-3");
    assert_eq!(fmt_tick(2.0 * 10f64.powi(-3)), "2e-3");
    assert_eq!(fmt_tick(2.5e-7), "2.5e-7");
    assert_eq!(fmt_tick(1e2), "1e2");
    assert_eq!(fmt_tick(1.0), "1");
    assert_eq!(fmt_sig(4.6875e-5, 3), "4.69e-5");
    assert_eq!(fmt_sig(0.0123456, 3), "0.0123");
    assert_eq!(fmt_sig(204.8, 3), "205");
    assert_eq!(fmt_sig(0.003, 3), "0.003");
    assert_eq!(fmt_sig(1.5e7, 3), "1.5e7");
    // Decades over a wide range; 1-2-5 within a narrow one; every tick inside.
    let (bold, light) = log_ticks(3e-6, 2e-2);
    assert_eq!(
        bold.iter().map(|v| fmt_tick(*v)).collect::<Vec<_>>(),
        ["1e-5", "1e-4", "1e-3", "1e-2"]
    );
    assert!(light.iter().all(|v| *v >= 3e-6 && *v <= 2e-2), "{light:?}");
    let (bold, _) = log_ticks(1.5e-3, 4e-2);
    assert_eq!(
        bold.iter().map(|v| fmt_tick(*v)).collect::<Vec<_>>(),
        ["2e-3", "5e-3", "1e-2", "2e-2"]
    );
    let (bold, _) = log_ticks(2.1, 4.5);
    assert_eq!(bold.iter().map(|v| fmt_tick(*v)).collect::<Vec<_>>(), ["3", "4"]);
}

/// Issue 22, item 4: the fit's quality by hand. ln n = 0, 1, 2 with ln err
/// = 0, -1.5, -2: slope -1 (order 1), residuals 1/6, -1/3, 1/6, so SSR =
/// 1/6, standard error sqrt(SSR / 1 / sxx) = sqrt(1/12), 95 % half-width
/// 12.706 sqrt(1/12) (Student's t, 1 degree of freedom), R^2 = 1 - (1/6) /
/// (78/36).
#[test]
fn convergence_fit_quality_by_hand() {
    let e1 = std::f64::consts::E;
    let n = [1.0, e1, e1 * e1];
    let err = [1.0, (-1.5f64).exp(), (-2.0f64).exp()];
    let f = fit_convergence(&n, &err).unwrap();
    assert!((f.order - 1.0).abs() < 1e-12, "{f:?}");
    assert!((f.ci95 - 12.706 * (1.0f64 / 12.0).sqrt()).abs() < 1e-9, "{f:?}");
    assert!((f.r2 - (1.0 - 6.0 / 78.0)).abs() < 1e-12, "{f:?}");
    assert_eq!(f.points, 3);
    // An exact power law: no spread, R^2 = 1.
    let n = [10.0, 20.0, 40.0, 80.0];
    let e: Vec<f64> = n.iter().map(|n: &f64| 0.3 * n.powi(-2)).collect();
    let f = fit_convergence(&n, &e).unwrap();
    assert!(
        (f.order - 2.0).abs() < 1e-12 && f.ci95 < 1e-9 && (f.r2 - 1.0).abs() < 1e-12,
        "{f:?}"
    );
}

/// Fewer than three distinct resolutions, or errors that do not fall
/// strictly, give no order (the cases issue 22 found printed as orders).
#[test]
fn convergence_fit_refuses_what_has_no_order() {
    assert_eq!(fit_convergence(&[10.0, 20.0], &[1e-2, 2.5e-3]), Err(NoOrder::TooFew(2)));
    // A repeated resolution counts once.
    assert_eq!(
        fit_convergence(&[10.0, 20.0, 20.0], &[1e-2, 2.5e-3, 2.5e-3]),
        Err(NoOrder::TooFew(2))
    );
    // Unusable points are dropped before counting.
    assert_eq!(
        fit_convergence(&[10.0, 20.0, 40.0], &[1e-2, 0.0, f64::NAN]),
        Err(NoOrder::TooFew(1))
    );
    // The chain-mail's 5.29 -> 0.00145 -> 0.862, in any input order.
    assert_eq!(
        fit_convergence(&[40.0, 10.0, 20.0], &[0.862, 5.29, 0.00145]),
        Err(NoOrder::NonMonotone(vec![5.29, 0.00145, 0.862]))
    );
    // Growing errors (negative "orders") and a round-off plateau.
    assert!(matches!(
        fit_convergence(&[10.0, 20.0, 40.0], &[1e-3, 2e-3, 4e-3]),
        Err(NoOrder::NonMonotone(_))
    ));
    assert!(matches!(
        fit_convergence(&[10.0, 20.0, 40.0], &[1e-3, 1e-15, 1e-15]),
        Err(NoOrder::NonMonotone(_))
    ));
}
