//! The force-over-time plot of a group whose scenario is scored along a
//! force history (the `force` and `ref_force` columns of
//! `observables.csv`: a needle's push against `f_cut + f_perlen d`, an
//! indenter's load against Hertz or the scikit-fem curve): each model's
//! best ok run against its reference.

use std::path::Path;

use super::{Group, Section, Styles, best_ok_runs, one_panel, over_time, run_label};
use crate::figure::{Axis, Figure, LegendEntry, Line, Look, SeriesSpec};
use crate::{fmt_sig, read_series};

/// A model whose force exceeds this many times the largest reference force
/// is noted instead of drawn.
const OFF_SCALE: f64 = 10.0;

/// The runs of consecutive finite samples of `v` over `t`: the reference
/// holds in phases (a needle's insertion and its steady retraction, not
/// the hold between), and a line must not bridge the phases.
fn stretches(t: &[f64], v: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for (t, v) in t.iter().zip(v) {
        if t.is_finite() && v.is_finite() {
            if !open {
                out.push(Vec::new());
                open = true;
            }
            if let Some(last) = out.last_mut() {
                last.push((*t, *v));
            }
        } else {
            open = false;
        }
    }
    out
}

/// The abscissa a force plot draws the scored force against.
#[derive(Clone, Copy, PartialEq)]
enum Abscissa {
    /// Simulated time (s), every scene scored along a force history.
    Time,
    /// The indentation depth (m, the `depth` column), the scenes scored
    /// along a load curve.
    Depth,
}

/// The scored force of each model's best ok run ([`best_ok_runs`]) over time,
/// solid, with the reference's value at the same steps, dashed in the same
/// colour (a reference that depends on the run's own state, such as the
/// needle's inserted length, differs from model to model). `None` when no
/// run recorded a reference force. Unreadable series are noted by the
/// error-over-time plot, which reads the same runs.
pub(super) fn force_time_figure(dir: &Path, g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    force_figure(dir, g, st, sec, Abscissa::Time)
}

/// The same force against the indenter's depth, for the scenes scored along
/// a load curve (sphere and wall indentation against Hertz and the
/// scikit-fem contact reference, the wall punch): the force-depth curve a
/// reviewer compares with the reference's. A model solved as a static
/// problem has one point per load increment it took (one for a single
/// increment), drawn as markers. `None` when no run recorded a depth.
pub(super) fn force_depth_figure(dir: &Path, g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    force_figure(dir, g, st, sec, Abscissa::Depth)
}

fn force_figure(dir: &Path, g: &Group, st: &Styles, sec: &mut Section, along: Abscissa) -> Option<(Figure, String)> {
    let mut series = Vec::new();
    let mut legend = Vec::new();
    let mut runs = Vec::new();
    for r in best_ok_runs(g) {
        if r.run_dir.trim().is_empty() {
            continue;
        }
        let Ok(s) = read_series(&dir.join(&r.run_dir).join("observables.csv")) else {
            continue;
        };
        let x = match along {
            Abscissa::Time => &s.t,
            Abscissa::Depth => &s.depth,
        };
        let (got, want) = (stretches(x, &s.force), stretches(x, &s.ref_force));
        if !want.is_empty() {
            runs.push((r, got, want));
        }
    }
    // A force far off every reference would flatten the others to a line
    // at zero: such a model is left off the plot and named in a note (once,
    // by the plot over time).
    let largest = |parts: &[Vec<(f64, f64)>]| parts.iter().flatten().map(|p| p.1.abs()).fold(0.0, f64::max);
    let scale = runs.iter().map(|(_, _, want)| largest(want)).fold(0.0, f64::max);
    for (r, got, want) in runs {
        let model = r.model.as_str();
        let peak = largest(&got);
        if scale > 0.0 && peak > OFF_SCALE * scale {
            if along == Abscissa::Time {
                sec.notes.push(format!(
                    "Force over time: {} is left off the plot: its force reaches {} N, {}x the largest reference force ({} N).",
                    run_label(r),
                    fmt_sig(peak, 3),
                    fmt_sig(peak / scale, 3),
                    fmt_sig(scale, 3)
                ));
            }
            continue;
        }
        let look = st.look(model, 0, Line::Solid);
        let dashed = Look {
            marker: None,
            line: Line::Dashed,
            ..look
        };
        // About ten markers per curve so models stay apart in grey scale.
        let step = (got.iter().map(Vec::len).sum::<usize>() / 10).max(1);
        legend.push(LegendEntry {
            look,
            label: run_label(r),
        });
        legend.push(LegendEntry {
            look: dashed,
            label: format!("{model}: reference at its steps"),
        });
        for part in got {
            series.push(SeriesSpec {
                look,
                points: part.iter().copied().step_by(step).collect(),
                line_points: part,
            });
        }
        for part in want {
            series.push(SeriesSpec {
                look: dashed,
                points: Vec::new(),
                line_points: part,
            });
        }
    }
    if series.is_empty() {
        return None;
    }
    let (fig, alt) = match along {
        Abscissa::Time => (
            over_time(
                format!(
                    "{}: scored force over time against the reference (best ok run)",
                    g.title
                ),
                Axis::linear("force [N]"),
                series,
                legend,
            ),
            format!(
                "{}: the force each model's best ok run is scored on, over simulated time, with the reference's value at the same steps (dashed; gaps where the reference does not hold)",
                g.title
            ),
        ),
        Abscissa::Depth => (
            one_panel(
                format!(
                    "{}: force against indentation depth, with the reference (best ok run)",
                    g.title
                ),
                Axis::linear("indentation depth [m]"),
                Axis::linear("force [N]"),
                series,
                legend,
            ),
            format!(
                "{}: the force each model's best ok run is scored on against the indenter's depth, with the reference's force at the same depths (dashed)",
                g.title
            ),
        ),
    };
    Some((fig, alt))
}

#[cfg(test)]
mod tests {
    use super::stretches;

    #[test]
    fn lines_break_where_the_reference_does_not_hold() {
        let nan = f64::NAN;
        let t = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let v = [nan, 1.0, 2.0, nan, nan, 5.0];
        assert_eq!(stretches(&t, &v), vec![vec![(1.0, 1.0), (2.0, 2.0)], vec![(5.0, 5.0)]]);
        assert!(stretches(&t, &[nan; 6]).is_empty());
    }
}
