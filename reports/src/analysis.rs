//! Numbers derived from the rows: observed convergence order, Pareto fronts,
//! which fidelity knob is swept, the finest and the best ok run of a model.

use std::cmp::Ordering;

use crate::{ResultRow, Status};

/// Observed order of convergence `p` from errors `err[i]` at resolutions `n[i]`
/// (segments, cells per side, steps per second...).
///
/// If `err ~ C h^p` with `h ~ 1/n`, then `ln err = ln C - p ln n`: this returns
/// `p = -slope` of the ordinary least-squares line through `(ln n, ln err)`:
/// the least-squares observed order of grid-refinement studies (e.g. Eca &
/// Hoekstra, J. Comput. Phys. 262 (2014) 104-130, with the exact solution
/// known so the error is measured rather than extrapolated).
/// Points with a non-finite or non-positive `n` or `err` are ignored (they
/// have no logarithm); extra entries of the longer slice are ignored. Returns
/// `None` with fewer than two usable points or when all usable `n` are equal.
///
/// ```
/// let n = [10.0, 20.0, 40.0];
/// let e: Vec<f64> = n.iter().map(|n: &f64| 3.0 * n.powi(-2)).collect();
/// let p = surgbench_reports::fit_order(&n, &e).unwrap();
/// assert!((p - 2.0).abs() < 1e-12);
/// ```
pub fn fit_order(n: &[f64], err: &[f64]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = n
        .iter()
        .zip(err)
        .filter(|(n, e)| n.is_finite() && **n > 0.0 && e.is_finite() && **e > 0.0)
        .map(|(n, e)| (n.ln(), e.ln()))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let k = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / k;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / k;
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    // Centred sums: sxx is exactly 0 only when all ln n are equal.
    if sxx <= 0.0 {
        return None;
    }
    Some(-(sxy / sxx))
}

/// A convergence order fitted with its quality ([`fit_convergence`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrderFit {
    /// Least-squares order `p` ([`fit_order`]).
    pub order: f64,
    /// Half-width of the 95 % confidence interval of `p`: Student's t with
    /// `points - 2` degrees of freedom times the slope's standard error (0 for
    /// an exact power law).
    pub ci95: f64,
    /// Coefficient of determination of the line through `(ln n, ln err)`.
    pub r2: f64,
    /// Points fitted.
    pub points: usize,
}

/// Why no order is reported ([`fit_convergence`]).
#[derive(Debug, Clone, PartialEq)]
pub enum NoOrder {
    /// Fewer than three usable points with distinct `n`: two points always
    /// lie on a line, so they say nothing of whether `err ~ n^-p` holds.
    TooFew(usize),
    /// The errors do not fall strictly as `n` grows (errors in order of
    /// increasing `n`): no single order describes them (a round-off floor,
    /// a pre-asymptotic range, or a model that does not converge).
    NonMonotone(Vec<f64>),
}

/// Two-sided 97.5 % quantile of Student's t with `dof` degrees of freedom
/// (tabulated to 3 decimals for 1..=30, the normal quantile beyond).
fn t975(dof: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
        2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
    ];
    T.get(dof.wrapping_sub(1)).copied().unwrap_or(1.960)
}

/// The observed order of [`fit_order`] with what a reader needs to trust
/// it: at least three points of distinct `n`, errors falling strictly with
/// `n`, and the fit's 95 % confidence interval and R^2 (issue 22: two-point
/// "orders" and orders through non-monotone data were printed as if they
/// meant something). Unusable points (non-positive, non-finite) are dropped
/// first, as in [`fit_order`]; points of equal `n` count once for the
/// three-point rule and are not compared with each other.
///
/// ```
/// use surgbench_reports::{fit_convergence, NoOrder};
/// let n = [10.0, 20.0, 40.0];
/// let f = fit_convergence(&n, &[1e-2, 2.5e-3, 6.25e-4]).unwrap();
/// assert!((f.order - 2.0).abs() < 1e-12 && f.ci95 < 1e-9);
/// assert_eq!(fit_convergence(&n[..2], &[1e-2, 2.5e-3]), Err(NoOrder::TooFew(2)));
/// assert!(matches!(fit_convergence(&n, &[5.29, 1.45e-3, 0.862]), Err(NoOrder::NonMonotone(_))));
/// ```
pub fn fit_convergence(n: &[f64], err: &[f64]) -> Result<OrderFit, NoOrder> {
    let mut pts: Vec<(f64, f64)> = n
        .iter()
        .zip(err)
        .filter(|(n, e)| n.is_finite() && **n > 0.0 && e.is_finite() && **e > 0.0)
        .map(|(n, e)| (*n, *e))
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.total_cmp(&a.1)));
    let mut distinct = pts.iter().map(|p| p.0).collect::<Vec<_>>();
    distinct.dedup();
    if distinct.len() < 3 {
        return Err(NoOrder::TooFew(distinct.len()));
    }
    if pts.windows(2).any(|w| w[1].0 > w[0].0 && w[1].1 >= w[0].1) {
        return Err(NoOrder::NonMonotone(pts.iter().map(|p| p.1).collect()));
    }
    let (ns, es): (Vec<f64>, Vec<f64>) = pts.iter().copied().unzip();
    let order = fit_order(&ns, &es).expect("three distinct usable points");
    let k = pts.len() as f64;
    let xy: Vec<(f64, f64)> = pts.iter().map(|(n, e)| (n.ln(), e.ln())).collect();
    let mx = xy.iter().map(|p| p.0).sum::<f64>() / k;
    let my = xy.iter().map(|p| p.1).sum::<f64>() / k;
    let sxx: f64 = xy.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let syy: f64 = xy.iter().map(|p| (p.1 - my).powi(2)).sum();
    // Residuals of the line y = my - order (x - mx).
    let ssr: f64 = xy.iter().map(|p| (p.1 - (my - order * (p.0 - mx))).powi(2)).sum();
    let dof = pts.len() - 2;
    let se = (ssr / dof as f64 / sxx).sqrt();
    Ok(OrderFit {
        order,
        ci95: t975(dof) * se,
        r2: if syy > 0.0 { 1.0 - ssr / syy } else { 1.0 },
        points: pts.len(),
    })
}

/// Indices of the Pareto-optimal points of `(time, error)` pairs (both to be
/// minimised), ordered by increasing time (so by decreasing error).
///
/// A point is kept when no other point is at least as fast and at least as
/// accurate while strictly better in one of the two; of exact duplicates the
/// first is kept. Points with a NaN coordinate are never on the front.
/// This is the front ann-benchmarks draws (`create_pointset`).
///
/// ```
/// let pts = [(1.0, 0.1), (2.0, 0.01), (3.0, 0.05), (0.5, 0.2)];
/// assert_eq!(surgbench_reports::pareto_front(&pts), vec![3, 0, 1]);
/// ```
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| !points[i].0.is_nan() && !points[i].1.is_nan())
        .collect();
    idx.sort_by(|&a, &b| {
        let (pa, pb) = (points[a], points[b]);
        pa.0.total_cmp(&pb.0).then(pa.1.total_cmp(&pb.1)).then(a.cmp(&b))
    });
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

/// The discretization knob a convergence study varies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Knob {
    /// Rod segments: `n = segments`.
    Segments,
    /// Mesh level: `n = 2^level` cells per side.
    MeshLevel,
    /// Time step: `n = 1/dt` steps per simulated second.
    Dt,
}

impl Knob {
    /// The fidelity key of this knob (as in `"segments=20;dt=0.001"`).
    pub(crate) fn key(self) -> &'static str {
        match self {
            Knob::Segments => "segments",
            Knob::MeshLevel => "mesh_level",
            Knob::Dt => "dt",
        }
    }

    /// The resolution `n` of `row` (grows as the run gets finer), if set.
    pub(crate) fn resolution(self, row: &ResultRow) -> Option<f64> {
        match self {
            Knob::Segments => row.segments,
            Knob::MeshLevel => row.mesh_level.map(|l| 2f64.powf(l)),
            Knob::Dt => row.dt.filter(|d| *d > 0.0).map(|d| 1.0 / d),
        }
    }

    /// Axis label for `n`.
    pub(crate) fn axis_label(self) -> &'static str {
        match self {
            Knob::Segments => "segments (log)",
            Knob::MeshLevel => "cells per side, 2^mesh_level (log)",
            Knob::Dt => "steps per simulated second, 1/dt [1/s] (log)",
        }
    }

    /// What `n` is, in words.
    pub(crate) fn n_name(self) -> &'static str {
        match self {
            Knob::Segments => "segments",
            Knob::MeshLevel => "cells per side (2^mesh_level)",
            Knob::Dt => "steps per second (1/dt)",
        }
    }

    /// Whether `n` is a count (labelled as an integer).
    pub(crate) fn is_count(self) -> bool {
        !matches!(self, Knob::Dt)
    }
}

/// Number of distinct finite values.
pub(crate) fn distinct(vals: impl Iterator<Item = f64>) -> usize {
    let mut v: Vec<f64> = vals.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.len()
}

/// The knob a set of runs varies: segments first, then mesh level, then dt;
/// `None` when none takes two or more distinct values.
pub(crate) fn choose_knob(rows: &[&ResultRow]) -> Option<Knob> {
    [Knob::Segments, Knob::MeshLevel, Knob::Dt]
        .into_iter()
        .find(|k| distinct(rows.iter().filter_map(|r| k.resolution(r))) >= 2)
}

/// `fidelity` (`"a=1;b=2"`) with the entry `key` removed, entries trimmed,
/// original order kept: the "other knobs" group of a convergence curve.
pub(crate) fn fidelity_without(fidelity: &str, key: &str) -> String {
    fidelity
        .split(';')
        .map(str::trim)
        .filter(|kv| !kv.is_empty())
        .filter(|kv| kv.split('=').next().map(str::trim) != Some(key))
        .collect::<Vec<_>>()
        .join(";")
}

/// Orders runs from coarse to fine: resolution (segments, else 2^mesh_level)
/// ascending, then dt descending, then iterations ascending.
pub(crate) fn coarse_to_fine(a: &ResultRow, b: &ResultRow) -> Ordering {
    let res = |r: &ResultRow| {
        r.segments
            .or(r.mesh_level.map(|l| 2f64.powf(l)))
            .unwrap_or(f64::NEG_INFINITY)
    };
    res(a)
        .total_cmp(&res(b))
        .then(b.dt.unwrap_or(f64::INFINITY).total_cmp(&a.dt.unwrap_or(f64::INFINITY)))
        .then(
            a.iterations
                .unwrap_or(f64::NEG_INFINITY)
                .total_cmp(&b.iterations.unwrap_or(f64::NEG_INFINITY)),
        )
}

/// The finest run among `rows` (last in [`coarse_to_fine`] order; the first
/// such run in input order on ties).
pub(crate) fn finest<'a>(rows: impl Iterator<Item = &'a ResultRow>) -> Option<&'a ResultRow> {
    let mut best: Option<&ResultRow> = None;
    for r in rows {
        match best {
            Some(b) if coarse_to_fine(r, b) != Ordering::Greater => {}
            _ => best = Some(r),
        }
    }
    best
}

/// The run that stands for a model in the summary and the over-time plots
/// (issue 22: chosen by merit, not by fineness, so a model's face is not an
/// unstable variant): its most accurate `ok` run by `err`, the fastest
/// (median ms/step) of equally accurate ones, then the finest; an `ok` run
/// without an error value only when no `ok` run has one. `None` when no run
/// is `ok`.
pub(crate) fn best_ok<'a>(rows: &[&'a ResultRow], err: impl Fn(&ResultRow) -> Option<f64>) -> Option<&'a ResultRow> {
    let ok: Vec<&ResultRow> = rows.iter().copied().filter(|r| r.status == Status::Ok).collect();
    let usable = |r: &ResultRow| err(r).filter(|e| e.is_finite()).map(f64::abs);
    let time = |r: &ResultRow| r.ms_per_step_median.unwrap_or(f64::INFINITY);
    ok.iter()
        .copied()
        .filter_map(|r| usable(r).map(|e| (e, r)))
        .min_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(time(a.1).total_cmp(&time(b.1)))
                .then(coarse_to_fine(b.1, a.1))
        })
        .map(|(_, r)| r)
        .or_else(|| finest(ok.into_iter()))
}
