//! The stability map of one group: run status over resolution and time step.

use std::collections::BTreeSet;

use super::{Group, Section, Styles, run_label, usable};
use crate::analysis::{Knob, distinct};
use crate::figure::{Axis, BAD_RED, FAIL_GREY, Figure, LegendEntry, Line, Look, Marker, OK_GREEN, Panel, SeriesSpec};
use crate::{ResultRow, Status};

/// Marker per status drawn on the map, worst last (drawn on top).
const KINDS: [(Status, RGBLook); 4] = [
    (Status::Ok, (OK_GREEN, Marker::Circle)),
    (Status::Timeout, (FAIL_GREY, Marker::TriangleUp)),
    (Status::Failed, (FAIL_GREY, Marker::Square)),
    (Status::Unstable, (BAD_RED, Marker::Cross)),
];

/// Statuses drawn so far, and runs whose status the map does not draw.
#[derive(Default)]
struct Seen {
    present: BTreeSet<Status>,
    other_status: Vec<String>,
}

/// `model`'s panel: a marker per (resolution, dt) cell of its runs, or
/// `None` (with a note) when it does not vary both.
fn model_panel(model: &str, runs: &[&ResultRow], knob: Knob, sec: &mut Section, seen: &mut Seen) -> Option<Panel> {
    let Seen { present, other_status } = seen;
    let mr: Vec<&ResultRow> = runs.iter().copied().filter(|r| r.model == model).collect();
    let cells: Vec<(f64, f64, &ResultRow)> = mr
        .iter()
        .filter_map(|r| match (usable(knob.resolution(r)), usable(r.dt)) {
            (Some(n), Some(dt)) => Some((n, dt, *r)),
            _ => None,
        })
        .collect();
    let xs = distinct(cells.iter().map(|c| c.0));
    let ys = distinct(cells.iter().map(|c| c.1));
    if xs < 2 || ys < 2 {
        if !mr.is_empty() {
            sec.notes.push(format!(
                "Stability map: {model} does not vary both {} and dt, so it has no panel.",
                knob.key()
            ));
        }
        return None;
    }
    let mut keys: Vec<(u64, u64)> = cells.iter().map(|c| (c.0.to_bits(), c.1.to_bits())).collect();
    let total = keys.len();
    keys.sort_unstable();
    keys.dedup();
    if keys.len() < total {
        sec.notes.push(format!(
            "Stability map: {model} has several runs in one ({}, dt) cell (another knob varies); the worst status is drawn on top.",
            knob.key()
        ));
    }
    let mut series = Vec::new();
    for (status, (color, m)) in KINDS {
        let pts: Vec<(f64, f64)> = cells
            .iter()
            .filter(|c| c.2.status == status)
            .map(|c| (c.0, c.1))
            .collect();
        if !pts.is_empty() {
            present.insert(status);
            series.push(SeriesSpec {
                look: Look {
                    color,
                    marker: Some(m),
                    line: Line::None,
                },
                points: pts,
                line_points: vec![],
            });
        }
    }
    for c in &cells {
        if !KINDS.iter().any(|k| k.0 == c.2.status) {
            other_status.push(format!("{} (status {:?})", run_label(c.2), c.2.status.as_str()));
        }
    }
    let mut xt: Vec<f64> = cells.iter().map(|c| c.0).collect();
    xt.sort_by(f64::total_cmp);
    xt.dedup();
    let mut yt: Vec<f64> = cells.iter().map(|c| c.1).collect();
    yt.sort_by(f64::total_cmp);
    yt.dedup();
    let mut x = Axis::log(knob.axis_label());
    x.plain = true;
    if xt.len() <= 8 {
        x.ticks = Some(xt);
    }
    let mut y = Axis::log("time step dt [s] (log)");
    if yt.len() <= 8 {
        y.ticks = Some(yt);
    }
    Some(Panel {
        title: model.to_string(),
        x,
        y,
        series,
    })
}

/// Stability map: per model, a marker per (resolution, dt) coloured by status.
pub(super) fn stability_figure(g: &Group, _st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    let runs: Vec<&ResultRow> = g
        .rows
        .iter()
        .copied()
        .filter(|r| r.status != Status::Unsupported)
        .collect();
    let knob = [Knob::Segments, Knob::MeshLevel]
        .into_iter()
        .find(|k| distinct(runs.iter().filter_map(|r| k.resolution(r))) >= 2)?;
    if distinct(runs.iter().filter_map(|r| r.dt)) < 2 {
        return None;
    }
    let mut panels = Vec::new();
    let mut seen = Seen::default();
    for model in &g.models {
        if let Some(p) = model_panel(model, &runs, knob, sec, &mut seen) {
            panels.push(p);
        }
    }
    let Seen { present, other_status } = seen;
    if !other_status.is_empty() {
        sec.notes.push(format!(
            "Stability map: runs with an unknown status are not drawn: {}.",
            other_status.join("; ")
        ));
    }
    if panels.is_empty() {
        return None;
    }
    if g.rows.iter().any(|r| r.status == Status::Unsupported) {
        sec.notes
            .push("Stability map: unsupported runs are not drawn (see the table).".into());
    }
    let legend = KINDS
        .iter()
        .filter(|k| present.contains(&k.0))
        .map(|(status, (color, m))| LegendEntry {
            look: Look {
                color: *color,
                marker: Some(*m),
                line: Line::None,
            },
            label: status.to_string(),
        })
        .collect();
    let n = panels.len();
    let cols = if n == 1 { 1 } else { 2 };
    let rows = n.div_ceil(cols) as u32;
    let size = (770 * cols as u32 + 330, 90 + 560 * rows);
    let fig = Figure {
        title: format!("{}: stability over {} and dt", g.title, knob.key()),
        panels,
        legend,
        size,
    };
    let alt = format!("{}: run status over {} and dt, per model", g.title, knob.key());
    Some((fig, alt))
}

type RGBLook = (plotters::style::RGBColor, Marker);
