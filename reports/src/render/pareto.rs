//! The speed-against-error plot of one group, with its Pareto front.

use super::{Group, PLOT_SIZE, Section, Styles, run_label, usable};
use crate::figure::{Axis, BAD_RED, FAIL_GREY, Figure, LegendEntry, Line, Look, Panel, SeriesSpec};
use crate::format::fmt_sig;
use crate::{End, ResultRow, RunInfo, Status, pareto_front};

/// The speed axis of a group: a run's cost, its name and the axis label.
pub(super) struct Cost {
    pub(super) of: fn(&ResultRow) -> Option<f64>,
    pub(super) name: &'static str,
    axis: &'static str,
    /// A static scene: the cost is the wall time to the solution.
    pub(super) is_static: bool,
}

impl Cost {
    /// Static scenes (every ok run ends settled or at its time limit):
    /// models take different dt and step counts to the same equilibrium, so
    /// the fair cost is the wall time to the solution, not the time per step.
    /// (Older results.csv files have no solve_wall_s: they keep ms/step.)
    pub(super) fn of_group(g: &Group) -> Self {
        let ok: Vec<&ResultRow> = g.rows.iter().copied().filter(|r| r.status == Status::Ok).collect();
        let is_static = !ok.is_empty()
            && ok
                .iter()
                .all(|r| matches!(r.end, End::Settled | End::TimeLimit) && r.solve_wall_s.is_some());
        if is_static { Cost::TO_SOLUTION } else { Cost::PER_STEP }
    }

    /// A dynamic scene's cost: the median wall time per step.
    pub(super) const PER_STEP: Cost = Cost {
        of: |r| r.ms_per_step_median,
        name: "ms/step",
        axis: "median wall time per step [ms] (log)",
        is_static: false,
    };

    /// A static scene's cost: the wall time to the solution.
    pub(super) const TO_SOLUTION: Cost = Cost {
        of: |r| r.solve_wall_s,
        name: "time to solution (s)",
        axis: "wall time to solution [s] (log)",
        is_static: true,
    };
}

/// Ok runs the plot leaves out, by why.
#[derive(Default)]
struct Omitted {
    missing: Vec<String>,
    nonpos: Vec<String>,
}

/// (cost, error) of `model`'s ok runs that a log-log plot can show; the
/// others go to `omitted`.
fn model_points(
    g: &Group,
    model: &str,
    on_machine: &dyn Fn(&ResultRow) -> bool,
    cost: &Cost,
    omitted: &mut Omitted,
) -> Vec<(f64, f64)> {
    let cost_name = cost.name;
    let mut pts = Vec::new();
    let ok = g.model_rows(model).into_iter().filter(|r| r.status == Status::Ok);
    for r in ok.filter(|r| on_machine(r)) {
        match ((cost.of)(r), g.err(r)) {
            (Some(t), Some(e)) => {
                if usable(Some(t)).is_some() && usable(Some(e)).is_some() {
                    pts.push((t, e));
                } else {
                    omitted.nonpos.push(format!(
                        "{} ({cost_name} = {}, {} = {})",
                        run_label(r),
                        fmt_sig(t, 3),
                        g.metric,
                        fmt_sig(e, 3)
                    ));
                }
            }
            (t, e) => omitted.missing.push(format!(
                "{} (no {})",
                run_label(r),
                if t.is_none() && e.is_none() {
                    format!("{cost_name} and no {}", g.metric)
                } else if t.is_none() {
                    cost_name.to_string()
                } else {
                    g.metric.clone()
                }
            )),
        }
    }
    pts
}

/// The notes that name the ok runs the plot leaves out.
fn omission_notes(omitted: &Omitted, sec: &mut Section) {
    if !omitted.nonpos.is_empty() {
        sec.notes.push(format!(
            "Speed/error plot omits ok runs with a zero, negative or non-finite value (a log axis cannot show them): {}.",
            omitted.nonpos.join("; ")
        ));
    }
    if !omitted.missing.is_empty() {
        sec.notes.push(format!(
            "Speed/error plot omits ok runs without a value: {}.",
            omitted.missing.join("; ")
        ));
    }
}

/// One series (points and Pareto front) and legend entry per model and
/// machine: timings of two machines never share a front.
fn model_series(g: &Group, st: &Styles, cost: &Cost, omitted: &mut Omitted) -> (Vec<SeriesSpec>, Vec<LegendEntry>) {
    let mut series = Vec::new();
    let mut legend = Vec::new();
    for (variant, host) in st.machine_groups().into_iter().enumerate() {
        for model in &g.models {
            let pts = model_points(g, model, &|r| st.on_machine(r, host), cost, omitted);
            if pts.is_empty() {
                continue;
            }
            let mut front: Vec<(f64, f64)> = pareto_front(&pts).into_iter().map(|i| pts[i]).collect();
            front.sort_by(|a, b| a.0.total_cmp(&b.0));
            let look = st.look(model, variant, Line::Solid);
            let on = if host.is_empty() {
                String::new()
            } else {
                format!(" on {host}")
            };
            legend.push(LegendEntry {
                look,
                label: format!("{model}{on} ({} runs, {} on front)", pts.len(), front.len()),
            });
            series.push(SeriesSpec {
                look,
                points: pts,
                line_points: front,
            });
        }
    }
    (series, legend)
}

/// The scene's accuracy target as a horizontal dashed red line, and (per-step
/// costs only) the time budgets inside the plotted speed range as vertical
/// dashed grey lines, each with its legend entry; a target far
/// off the data (more than a decade) is named in a note instead of
/// stretching the axis.
fn guide_lines(
    g: &Group,
    info: &RunInfo,
    cost: &Cost,
    series: &mut Vec<SeriesSpec>,
    legend: &mut Vec<LegendEntry>,
    sec: &mut Section,
) {
    let pts: Vec<(f64, f64)> = series.iter().flat_map(|s| s.points.iter().copied()).collect();
    let (x0, x1) = pts
        .iter()
        .fold((f64::INFINITY, 0.0f64), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (y0, y1) = pts
        .iter()
        .fold((f64::INFINITY, 0.0f64), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    let scenario = g.rows.first().map_or("", |r| r.scenario.as_str());
    if let Some(t) = info.targets.get(scenario).filter(|t| t.metric == g.metric) {
        if t.value > 0.0 && t.value >= y0 / 10.0 && t.value <= y1 * 10.0 {
            let look = Look {
                color: BAD_RED,
                marker: None,
                line: Line::Dashed,
            };
            series.push(SeriesSpec {
                look,
                points: Vec::new(),
                line_points: vec![(x0, t.value), (x1, t.value)],
            });
            legend.push(LegendEntry {
                look,
                label: format!(
                    "target: {} ≤ {} (below the line meets it)",
                    t.metric,
                    fmt_sig(t.value, 3)
                ),
            });
        } else {
            sec.notes.push(format!(
                "Speed/error plot: the target {} ≤ {} lies more than a decade off the plotted errors ({} to {}) and is not drawn.",
                t.metric,
                fmt_sig(t.value, 3),
                fmt_sig(y0, 3),
                fmt_sig(y1, 3)
            ));
        }
    }
    if cost.is_static {
        return;
    }
    let budgets: Vec<f64> = info.budgets().into_iter().filter(|b| *b >= x0 && *b <= x1).collect();
    if budgets.is_empty() {
        return;
    }
    let look = Look {
        color: FAIL_GREY,
        marker: None,
        line: Line::Dashed,
    };
    for b in &budgets {
        series.push(SeriesSpec {
            look,
            points: Vec::new(),
            line_points: vec![(*b, y0), (*b, y1)],
        });
    }
    let words: Vec<String> = budgets.iter().map(|b| format!("{} ms", fmt_sig(*b, 3))).collect();
    legend.push(LegendEntry {
        look,
        label: format!("time budget per step: {} (left of the line fits it)", words.join(", ")),
    });
}

/// Speed vs error: every ok run a point, each model's Pareto front a line,
/// the scene's accuracy target and the time budgets as dashed lines.
pub(super) fn pareto_figure(g: &Group, st: &Styles, info: &RunInfo, sec: &mut Section) -> Option<(Figure, String)> {
    if g.metric.is_empty() {
        sec.notes
            .push("No speed/error plot: no row names a primary error metric.".into());
        return None;
    }
    if g.is_outcome() {
        sec.notes.push(
            "No speed/error plot: the scene scores an outcome (reached or not), read from its outcome table, not an error on a log axis."
                .into(),
        );
        return None;
    }
    let cost = Cost::of_group(g);
    let mut omitted = Omitted::default();
    let (mut series, mut legend) = model_series(g, st, &cost, &mut omitted);
    omission_notes(&omitted, sec);
    if series.is_empty() {
        sec.notes.push(format!(
            "No speed/error plot: no ok run has both a positive {} and a positive {}.",
            cost.name, g.metric
        ));
        return None;
    }
    legend.push(LegendEntry {
        look: Look {
            color: FAIL_GREY,
            marker: None,
            line: Line::Solid,
        },
        label: "line: the model's Pareto front (no run is both faster and more accurate)".into(),
    });
    guide_lines(g, info, &cost, &mut series, &mut legend, sec);
    let fig = Figure {
        title: format!("{}: speed vs {}", g.title, g.metric),
        panels: vec![Panel {
            title: String::new(),
            x: Axis::log(cost.axis),
            y: Axis::log(format!("{} (log)", g.metric_label())),
            series,
        }],
        legend,
        size: PLOT_SIZE,
    };
    let alt = format!(
        "{}: speed ({}) vs {}, one point per ok run",
        g.title, cost.name, g.metric
    );
    if st.by_machine() {
        sec.notes.push(format!(
            "Timings come from {} machines: the speed/error plot draws each model once per machine (marker and dashes \
             tell the machines apart), with a Pareto front per machine; compare speeds only within one machine.",
            st.hosts.len()
        ));
    }
    if cost.is_static {
        sec.notes.push(
            "Static scene: the speed axis is the wall time to the solution (all steps to settling), since models reach the same equilibrium with different step sizes and counts."
                .into(),
        );
    }
    Some((fig, alt))
}
