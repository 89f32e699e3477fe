//! Comparing two reports point by point: what `surgbench diff OLD NEW` prints
//! and what the accuracy gate judges.
//!
//! A point is a row's scenario, model, fidelity and parameters (the n-th row
//! of the same key matches the n-th: a comparison may run a point twice).
//! For each point found in both reports it compares the status, every metric
//! and the median time per step. A change is a **regression** when
//!
//! - the status got worse (ok -> anything else; unsupported -> unstable ->
//!   timeout -> failed in that order), or a point of OLD is missing in NEW;
//! - an error metric grew beyond the tolerance: `|new| > |old| (1 + rel) +
//!   abs`. Error metrics are the row's primary metric and every metric whose
//!   name contains `error`; signed errors (a phase, a period error) count by
//!   their size. An error metric OLD had and NEW lacks is a regression too;
//! - the median ms/step grew beyond the time tolerance (when one is given:
//!   times change from run to run and machine to machine, errors do not).
//!
//! Other metrics (forces, counts, diagnostics) are listed when they change
//! beyond the tolerance, never judged: a larger hand force is not worse.
//! Metrics are compared only where both runs are `ok`: an unstable run's
//! numbers are not trustworthy, and its status change is the finding.

use std::collections::{BTreeMap, BTreeSet};

use crate::{ResultRow, Status};

/// Tolerances of a comparison (all relative ones are fractions: 0.01 = 1 %).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffOptions {
    /// Relative tolerance on metrics.
    pub rel: f64,
    /// Absolute tolerance on metrics (in each metric's own unit).
    pub abs: f64,
    /// Relative tolerance on the median ms/step; `None`: times not judged.
    pub time: Option<f64>,
}

impl Default for DiffOptions {
    /// Round-off: the same binary on the same CPU type reproduces every
    /// error bit for bit, and reordered floating-point sums move the last
    /// few of 16 digits; times judged at 25 %, about what a quiet machine
    /// holds between runs of the same binary.
    fn default() -> Self {
        Self {
            rel: 1e-9,
            abs: 0.0,
            time: Some(0.25),
        }
    }
}

/// How one quantity changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Change {
    /// Within the tolerance.
    Same,
    /// Better beyond the tolerance (an error or time shrank, a status rose).
    Better,
    /// Changed beyond the tolerance, not judged (a non-error metric).
    Changed,
    /// Worse beyond the tolerance: a regression.
    Worse,
}

impl Change {
    /// The word the table prints.
    pub fn word(self) -> &'static str {
        match self {
            Change::Same => "same",
            Change::Better => "better",
            Change::Changed => "changed",
            Change::Worse => "WORSE",
        }
    }
}

/// Which point a row is: scenario, model, fidelity, parameters.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct PointKey {
    /// Scenario id.
    pub scenario: String,
    /// Model id.
    pub model: String,
    /// Fidelity string as the row holds it.
    pub fidelity: String,
    /// Parameter overrides as the row holds them.
    pub params: String,
    /// 0 for the first row of this key in its report, 1 for the second, ...
    pub occurrence: usize,
}

impl std::fmt::Display for PointKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} / {} [{}]", self.scenario, self.model, self.fidelity)?;
        if !self.params.is_empty() {
            write!(f, " ({})", self.params)?;
        }
        if self.occurrence > 0 {
            write!(f, " #{}", self.occurrence + 1)?;
        }
        Ok(())
    }
}

/// One metric of one point in both reports.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricDiff {
    /// Metric name (a column of results.csv).
    pub name: String,
    /// Value in OLD (`None`: absent or not finite).
    pub old: Option<f64>,
    /// Value in NEW.
    pub new: Option<f64>,
    /// Whether it is judged as an error (module docs).
    pub is_error: bool,
    /// Whether it is the row's primary metric.
    pub primary: bool,
    /// The verdict.
    pub change: Change,
}

/// One point found in both reports.
#[derive(Debug, Clone, PartialEq)]
pub struct PointDiff {
    /// Which point.
    pub key: PointKey,
    /// Status in OLD and NEW.
    pub status: (Status, Status),
    /// Verdict on the status.
    pub status_change: Change,
    /// Metrics (union of both rows' names), compared when both runs are ok.
    pub metrics: Vec<MetricDiff>,
    /// Median ms/step in OLD and NEW, where both have one.
    pub ms_per_step: Option<(f64, f64)>,
    /// Verdict on the time (`Same` when times are not judged).
    pub time_change: Change,
}

impl PointDiff {
    /// The worst verdict of the point (status, metrics, time).
    pub fn worst(&self) -> Change {
        self.metrics
            .iter()
            .map(|m| m.change)
            .chain([self.status_change, self.time_change])
            .max()
            .unwrap_or(Change::Same)
    }
}

/// Two reports compared.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReportDiff {
    /// Points in both, in NEW's row order.
    pub points: Vec<PointDiff>,
    /// Points only NEW has.
    pub added: Vec<PointKey>,
    /// Points only OLD has: regressions (a point no longer measured).
    pub missing: Vec<PointKey>,
}

impl ReportDiff {
    /// Regressions: points with a worse status, error or time, plus the
    /// missing points.
    pub fn regressions(&self) -> usize {
        self.points.iter().filter(|p| p.worst() == Change::Worse).count() + self.missing.len()
    }

    /// Points whose worst verdict is `better`: something improved, nothing
    /// got worse or changed unjudged.
    pub fn improvements(&self) -> usize {
        self.points.iter().filter(|p| p.worst() == Change::Better).count()
    }
}

/// Whether `name` is judged as an error of `row` (module docs).
pub fn is_error_metric(row: &ResultRow, name: &str) -> bool {
    name == row.primary_error || name.contains("error")
}

/// Rank of a status, best first, for judging a status change.
fn status_rank(s: Status) -> u8 {
    match s {
        Status::Ok => 0,
        Status::Unsupported => 1,
        Status::Unstable => 2,
        Status::Timeout | Status::Stopped => 3,
        Status::Failed => 4,
        Status::Unset => 5,
    }
}

/// Rows keyed by point, each key's rows counted in file order.
fn keyed(rows: &[ResultRow]) -> Vec<(PointKey, &ResultRow)> {
    let mut seen: BTreeMap<PointKey, usize> = BTreeMap::new();
    rows.iter()
        .map(|r| {
            let mut key = PointKey {
                scenario: r.scenario.clone(),
                model: r.model.clone(),
                fidelity: r.fidelity.clone(),
                params: r.params.clone(),
                occurrence: 0,
            };
            let n = seen.entry(key.clone()).or_insert(0);
            key.occurrence = *n;
            *n += 1;
            (key, r)
        })
        .collect()
}

/// A finite value or `None`.
fn finite(v: Option<&f64>) -> Option<f64> {
    v.copied().filter(|v| v.is_finite())
}

/// Verdict on an error metric (smaller magnitude is better).
fn judge_error(old: Option<f64>, new: Option<f64>, o: &DiffOptions) -> Change {
    match (old, new) {
        (Some(a), Some(b)) => {
            let (a, b) = (a.abs(), b.abs());
            if b > a * (1.0 + o.rel) + o.abs {
                Change::Worse
            } else if b < a * (1.0 - o.rel) - o.abs {
                Change::Better
            } else {
                Change::Same
            }
        }
        (Some(_), None) => Change::Worse,
        (None, Some(_)) => Change::Changed,
        (None, None) => Change::Same,
    }
}

/// Verdict on a metric that is not an error: changed or not.
fn judge_other(old: Option<f64>, new: Option<f64>, o: &DiffOptions) -> Change {
    match (old, new) {
        (Some(a), Some(b)) if (b - a).abs() <= o.rel * a.abs().max(b.abs()) + o.abs => Change::Same,
        (None, None) => Change::Same,
        _ => Change::Changed,
    }
}

/// Compare one point's two rows.
fn diff_point(key: PointKey, a: &ResultRow, b: &ResultRow, o: &DiffOptions) -> PointDiff {
    let (ra, rb) = (status_rank(a.status), status_rank(b.status));
    let status_change = match rb.cmp(&ra) {
        std::cmp::Ordering::Greater => Change::Worse,
        std::cmp::Ordering::Less => Change::Better,
        std::cmp::Ordering::Equal => Change::Same,
    };
    let mut metrics = Vec::new();
    if a.status == Status::Ok && b.status == Status::Ok {
        let names: BTreeSet<&String> = a.metrics.keys().chain(b.metrics.keys()).collect();
        for name in names {
            let (old, new) = (finite(a.metrics.get(name)), finite(b.metrics.get(name)));
            let is_error = is_error_metric(a, name) || is_error_metric(b, name);
            let change = if is_error {
                judge_error(old, new, o)
            } else {
                judge_other(old, new, o)
            };
            metrics.push(MetricDiff {
                name: name.clone(),
                old,
                new,
                is_error,
                primary: *name == b.primary_error,
                change,
            });
        }
    }
    let ms_per_step = finite(a.ms_per_step_median.as_ref()).zip(finite(b.ms_per_step_median.as_ref()));
    let time_change = match (o.time, ms_per_step) {
        (Some(tol), Some((t0, t1))) if t1 > t0 * (1.0 + tol) => Change::Worse,
        (Some(tol), Some((t0, t1))) if t1 < t0 / (1.0 + tol) => Change::Better,
        _ => Change::Same,
    };
    PointDiff {
        key,
        status: (a.status, b.status),
        status_change,
        metrics,
        ms_per_step,
        time_change,
    }
}

/// Compare the rows of two reports (module docs); `old` and `new` as read
/// from their `results.csv`.
///
/// ```
/// use surgbench_reports::{ResultRow, Status, diff::{DiffOptions, Change, diff_reports}};
/// let mut a = ResultRow::default();
/// a.scenario = "s".into();
/// a.model = "m".into();
/// a.status = Status::Ok;
/// a.primary_error = "tip_error_rel".into();
/// a.metrics.insert("tip_error_rel".into(), 1e-3);
/// let mut b = a.clone();
/// b.metrics.insert("tip_error_rel".into(), 2e-3);
/// let d = diff_reports(&[a], &[b], &DiffOptions::default());
/// assert_eq!(d.points[0].worst(), Change::Worse);
/// assert_eq!(d.regressions(), 1);
/// ```
pub fn diff_reports(old: &[ResultRow], new: &[ResultRow], o: &DiffOptions) -> ReportDiff {
    let old_k = keyed(old);
    let new_k = keyed(new);
    let old_map: BTreeMap<&PointKey, &ResultRow> = old_k.iter().map(|(k, r)| (k, *r)).collect();
    let new_keys: BTreeSet<&PointKey> = new_k.iter().map(|(k, _)| k).collect();
    let mut out = ReportDiff::default();
    for (k, b) in &new_k {
        match old_map.get(k) {
            Some(a) => out.points.push(diff_point(k.clone(), a, b, o)),
            None => out.added.push(k.clone()),
        }
    }
    out.missing = old_k
        .iter()
        .filter(|(k, _)| !new_keys.contains(k))
        .map(|(k, _)| k.clone())
        .collect();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(model: &str, fid: &str, status: Status, metrics: &[(&str, f64)]) -> ResultRow {
        let mut r = ResultRow {
            scenario: "cantilever-gravity".into(),
            model: model.into(),
            fidelity: fid.into(),
            primary_error: "tip_error_rel".into(),
            metrics: metrics.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            ..Default::default()
        };
        r.status = status;
        r.ms_per_step_median = Some(1.0);
        r
    }

    const OPTS: DiffOptions = DiffOptions {
        rel: 1e-9,
        abs: 0.0,
        time: Some(0.25),
    };

    /// Identical reports: every point the same, nothing to flag.
    #[test]
    fn identical_reports_have_no_change() {
        let rows = vec![
            row(
                "der",
                "segments=20",
                Status::Ok,
                &[("tip_error_rel", 1e-3), ("hand_force_n", 2.0)],
            ),
            row("pbd-rod", "segments=20", Status::Unstable, &[]),
        ];
        let d = diff_reports(&rows, &rows, &OPTS);
        assert_eq!(d.points.len(), 2);
        assert!(d.points.iter().all(|p| p.worst() == Change::Same));
        assert_eq!((d.regressions(), d.improvements()), (0, 0));
        assert!(d.added.is_empty() && d.missing.is_empty());
    }

    /// Errors judged by magnitude against the relative tolerance; other
    /// metrics only listed; a round-off move stays `same`.
    #[test]
    fn metrics_are_judged_by_kind() {
        let old = [row(
            "der",
            "s",
            Status::Ok,
            &[
                ("tip_error_rel", 1e-3),
                ("phase_error_rad", -0.02),
                ("hand_force_n", 2.0),
                ("curve_error_rel", 5e-3),
            ],
        )];
        let new = [row(
            "der",
            "s",
            Status::Ok,
            &[
                // 5e-16 relative: round-off, within 1e-9.
                ("tip_error_rel", 1e-3 * (1.0 + 5e-16)),
                // Signed error: -0.03 is larger in size than -0.02.
                ("phase_error_rad", -0.03),
                ("hand_force_n", 3.0),
                ("curve_error_rel", 4e-3),
            ],
        )];
        let d = diff_reports(&old, &new, &OPTS);
        let by: BTreeMap<&str, Change> = d.points[0]
            .metrics
            .iter()
            .map(|m| (m.name.as_str(), m.change))
            .collect();
        assert_eq!(by["tip_error_rel"], Change::Same);
        assert_eq!(by["phase_error_rad"], Change::Worse);
        assert_eq!(by["hand_force_n"], Change::Changed);
        assert_eq!(by["curve_error_rel"], Change::Better);
        assert_eq!(d.regressions(), 1);
        assert!(
            d.points[0]
                .metrics
                .iter()
                .any(|m| m.primary && m.name == "tip_error_rel")
        );
    }

    /// A lost error metric and a lost point are regressions; a new point is not.
    #[test]
    fn lost_metrics_and_points_are_regressions() {
        let old = [
            row("der", "a", Status::Ok, &[("tip_error_rel", 1e-3)]),
            row("der", "b", Status::Ok, &[("tip_error_rel", 1e-3)]),
        ];
        let new = [
            row("der", "a", Status::Ok, &[]),
            row("der", "c", Status::Ok, &[("tip_error_rel", 1e-3)]),
        ];
        let d = diff_reports(&old, &new, &OPTS);
        assert_eq!(d.points.len(), 1);
        assert_eq!(d.points[0].worst(), Change::Worse);
        assert_eq!(d.missing.len(), 1);
        assert_eq!(d.missing[0].fidelity, "b");
        assert_eq!(d.added[0].fidelity, "c");
        assert_eq!(d.regressions(), 2);
    }

    /// Status order: ok is best, failed worst; metrics of a non-ok run are
    /// not compared.
    #[test]
    fn status_changes_are_ranked() {
        let ok = row("der", "a", Status::Ok, &[("tip_error_rel", 1e-3)]);
        let unstable = row("der", "a", Status::Unstable, &[("tip_error_rel", 9.0)]);
        let failed = row("der", "a", Status::Failed, &[]);
        let d = diff_reports(std::slice::from_ref(&ok), std::slice::from_ref(&unstable), &OPTS);
        assert_eq!(d.points[0].status_change, Change::Worse);
        assert!(d.points[0].metrics.is_empty());
        let d = diff_reports(std::slice::from_ref(&unstable), std::slice::from_ref(&ok), &OPTS);
        assert_eq!(d.points[0].worst(), Change::Better);
        assert_eq!(d.improvements(), 1);
        let d = diff_reports(&[unstable], &[failed], &OPTS);
        assert_eq!(d.points[0].status_change, Change::Worse);
    }

    /// Times judged only when a time tolerance is given.
    #[test]
    fn times_are_judged_when_asked() {
        let old = [row("der", "a", Status::Ok, &[])];
        let mut slow = old[0].clone();
        slow.ms_per_step_median = Some(1.3);
        let d = diff_reports(&old, std::slice::from_ref(&slow), &OPTS);
        assert_eq!(d.points[0].time_change, Change::Worse);
        let errors_only = DiffOptions { time: None, ..OPTS };
        let d = diff_reports(&old, &[slow], &errors_only);
        assert_eq!(d.points[0].time_change, Change::Same);
        assert_eq!(d.regressions(), 0);
    }

    /// The n-th row of a repeated key matches the n-th.
    #[test]
    fn repeated_points_match_in_order() {
        let a = row("der", "a", Status::Ok, &[("tip_error_rel", 1e-3)]);
        let b = row("der", "a", Status::Ok, &[("tip_error_rel", 2e-3)]);
        let d = diff_reports(&[a.clone(), b.clone()], &[a, b], &OPTS);
        assert_eq!(d.points.len(), 2);
        assert_eq!(d.points[1].key.occurrence, 1);
        assert_eq!(d.regressions(), 0);
    }
}
