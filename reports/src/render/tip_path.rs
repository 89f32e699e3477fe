//! The tip path in its bend plane (`x` along the insertion, `s` the lateral
//! offset) of every ok run of a scene scored on a path's shape (the steered
//! needles), each with the best-fit arc the scene scores it by: the
//! kinematic bicycle model's constant curvature (Webster et al. 2006) fitted
//! to that run, dashed. Mesh level and coupling change the path; this is
//! where a reader sees by how much.

use std::path::Path;

use plotters::style::BLACK;

use super::{Group, PLOT_SIZE, Section, read_run_files, run_label};
use crate::figure::{Axis, Figure, LegendEntry, Line, Look, Marker, PALETTE, Panel, SeriesSpec};
use crate::{Status, read_plane_path};

/// Runs drawn at most (one colour each).
const MAX_RUNS: usize = PALETTE.len() - 1;
/// Millimetres per metre: the paths are millimetres long.
const MM: f64 = 1e3;

/// The path and fitted-arc plot of the group's ok runs that wrote
/// `tip_path.csv`; `None` for other scenes.
pub(super) fn tip_path_figure(dir: &Path, g: &Group, sec: &mut Section) -> Option<(Figure, String)> {
    let ok = g.rows.iter().copied().filter(|r| r.status == Status::Ok);
    let runs = read_run_files(dir, ok, "tip_path.csv", read_plane_path, "Tip path", sec);
    if runs.is_empty() {
        return None;
    }
    if runs.len() > MAX_RUNS {
        sec.notes.push(format!(
            "Tip path: the first {MAX_RUNS} of {} ok runs are drawn.",
            runs.len()
        ));
    }
    let mut series = Vec::new();
    let mut legend = Vec::new();
    for (i, (r, p)) in runs.iter().take(MAX_RUNS).enumerate() {
        let color = PALETTE[i];
        let path: Vec<(f64, f64)> = p
            .iter()
            .filter(|q| q.x.is_finite() && q.s.is_finite())
            .map(|q| (q.x * MM, q.s * MM))
            .collect();
        let look = Look {
            color,
            marker: Some(Marker::ALL[i % Marker::ALL.len()]),
            line: Line::Solid,
        };
        legend.push(LegendEntry {
            look,
            label: run_label(r),
        });
        // About ten markers per curve so runs stay apart in grey scale.
        let step = (path.len() / 10).max(1);
        series.push(SeriesSpec {
            look,
            points: path.iter().copied().step_by(step).collect(),
            line_points: path,
        });
        // One line per arc: a gap in x (the turn between the double bend's
        // arcs) splits it.
        let mut arcs: Vec<Vec<(f64, f64)>> = Vec::new();
        let mut last_index = None;
        for (k, q) in p.iter().enumerate() {
            if !(q.x.is_finite() && q.fit.is_finite()) {
                continue;
            }
            if last_index != Some(k.wrapping_sub(1)) {
                arcs.push(Vec::new());
            }
            if let Some(a) = arcs.last_mut() {
                a.push((q.x * MM, q.fit * MM));
            }
            last_index = Some(k);
        }
        for a in arcs {
            series.push(SeriesSpec {
                look: Look {
                    color,
                    marker: None,
                    line: Line::Dashed,
                },
                points: Vec::new(),
                line_points: a,
            });
        }
    }
    legend.push(LegendEntry {
        look: Look {
            color: BLACK,
            marker: None,
            line: Line::Dashed,
        },
        label: "best-fit arc of each run (bicycle model)".into(),
    });
    sec.notes.push(
        "Tip path: x along the insertion, s the lateral offset in the plane the tip bent in; dashed, each run's \
         best-fit arc over the window the scene scores (Kasa's least-squares circle): the kinematic bicycle \
         model's constant curvature, fitted to that run, not an independent reference."
            .into(),
    );
    let fig = Figure {
        title: format!("{}: tip path in its bend plane (ok runs)", g.title),
        panels: vec![Panel {
            title: String::new(),
            x: Axis::linear("x along the insertion [mm]"),
            y: Axis::linear("s, lateral offset [mm]"),
            series,
        }],
        legend,
        size: PLOT_SIZE,
    };
    let alt = format!(
        "{}: tip path of {} ok run(s) in the bend plane, each with its best-fit arc (dashed)",
        g.title,
        runs.len().min(MAX_RUNS)
    );
    Some((fig, alt))
}
