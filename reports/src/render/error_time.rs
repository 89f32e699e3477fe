//! The error-over-time plot of one group, from the runs' `observables.csv`.

use std::path::Path;

use super::pareto::Cost;
use super::{Group, Section, Styles, best_ok_runs, or_unknown, over_time, run_label};
use crate::figure::{Axis, Figure, LegendEntry, Line, SeriesSpec};
use crate::read_series;

/// Error over time from `observables.csv` of each model's best ok run
/// ([`best_ok_runs`]: most accurate, then fastest).
///
/// Not for a static scene ([`Cost::of_group`]): it is scored at equilibrium
/// only, and its error over time would draw the load ramp, not accuracy.
pub(super) fn error_time_figure(dir: &Path, g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    if Cost::of_group(g).is_static {
        sec.notes.push(
            "No error-over-time plot: a static scene is scored at equilibrium only (its error during the load ramp is not an accuracy)."
                .into(),
        );
        return None;
    }
    if g.is_outcome() {
        return None;
    }
    let mut series = Vec::new();
    let mut legend = Vec::new();
    for r in best_ok_runs(g) {
        let model = r.model.as_str();
        if r.run_dir.trim().is_empty() {
            sec.notes.push(format!(
                "Error over time: {} has no run folder, so no time series.",
                run_label(r)
            ));
            continue;
        }
        let path = dir.join(&r.run_dir).join("observables.csv");
        let s = match read_series(&path) {
            Ok(s) => s,
            Err(e) => {
                sec.notes
                    .push(format!("Error over time: no curve for {}: {e}.", run_label(r)));
                continue;
            }
        };
        let pts: Vec<(f64, f64)> =
            s.t.iter()
                .zip(&s.error)
                .filter(|(t, e)| t.is_finite() && e.is_finite() && **e > 0.0)
                .map(|(t, e)| (*t, *e))
                .collect();
        let skipped = s.t.len() - pts.len();
        if pts.is_empty() {
            // Named relative to the report: `dir` may be the staging
            // folder the report is renamed from.
            sec.notes.push(format!(
                "Error over time: {} has no positive error sample in {} ({} samples).",
                run_label(r),
                Path::new(&r.run_dir).join("observables.csv").display(),
                s.t.len()
            ));
            continue;
        }
        if skipped > 0 {
            sec.notes.push(format!(
                "Error over time: {skipped} of {} samples of {} are empty, zero or negative and not drawn (log axis).",
                s.t.len(),
                run_label(r)
            ));
        }
        // About ten markers per curve so models stay apart in grey scale.
        let step = (pts.len() / 10).max(1);
        let marks: Vec<(f64, f64)> = pts.iter().copied().step_by(step).collect();
        let look = st.look(model, 0, Line::Solid);
        legend.push(LegendEntry {
            look,
            label: run_label(r),
        });
        series.push(SeriesSpec {
            look,
            points: marks,
            line_points: pts,
        });
    }
    if series.is_empty() {
        return None;
    }
    let fig = over_time(
        format!("{}: {} over time (best ok run)", g.title, or_unknown(&g.metric)),
        Axis::log(format!("{} (log)", g.metric_label())),
        series,
        legend,
    );
    let alt = format!("{}: error over simulated time for each model's best ok run", g.title);
    Some((fig, alt))
}
