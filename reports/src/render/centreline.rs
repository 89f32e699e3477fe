//! The rod's final shape, projected on the x–z and x–y planes, for each
//! model's best ok run, against the scenario's reference centreline when
//! it has one (a cantilever's elastica): the evidence behind a tip error,
//! and the wire's path through a vessel.

use std::path::Path;

use plotters::style::BLACK;

use super::{Group, PLOT_SIZE, Section, Styles, best_ok_runs, run_label};
use crate::figure::{Axis, Figure, LegendEntry, Line, Look, Panel, SeriesSpec};
use crate::{read_centreline, read_final_positions};

/// Two panels side by side need more width than one: 2 x 535 px of chart
/// plus the 330 px legend.
const SIZE: (u32, u32) = (1400, 700);

/// The projection of `p` on the plane of axes `(a, b)` (0 = x, 1 = y, 2 = z).
fn project(p: &[[f64; 3]], (a, b): (usize, usize)) -> Vec<(f64, f64)> {
    p.iter()
        .filter(|q| q[a].is_finite() && q[b].is_finite())
        .map(|q| (q[a], q[b]))
        .collect()
}

/// The final centreline of the first rod of each model's best ok run
/// ([`best_ok_runs`]) in two projections, with the reference centreline
/// (`reference_centreline.csv`, dashed black) when the runs wrote one;
/// `None` for groups without rod models.
pub(super) fn centreline_figure(dir: &Path, g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    let mut reference: Option<Vec<[f64; 3]>> = None;
    let mut curves = Vec::new();
    for r in best_ok_runs(g) {
        // Rod models, and the coupled ones whose first body is a rod (a
        // needle in tissue, a catheter in a compliant vessel): the final
        // needle is the path its tip cut.
        if !matches!(r.family.as_str(), "rod" | "coupled") || r.run_dir.trim().is_empty() {
            continue;
        }
        let run = dir.join(&r.run_dir);
        // Notes name files relative to the report, so that a re-render in
        // another folder (`surgbench report`) writes the same page.
        let relative = |e: crate::ReportError| e.to_string().replace(&format!("{}/", dir.display()), "");
        let state = run.join("final_state.csv");
        match read_final_positions(&state, 0) {
            Ok(p) if p.len() >= 2 => curves.push((r, p)),
            Ok(_) => {}
            Err(_) if !state.exists() => sec.notes.push(format!(
                "Centreline: no shape for {}: its run folder has no final_state.csv.",
                run_label(r)
            )),
            Err(e) => sec
                .notes
                .push(format!("Centreline: no shape for {}: {}.", run_label(r), relative(e))),
        }
        let path = run.join("reference_centreline.csv");
        if reference.is_none() && path.is_file() {
            match read_centreline(&path) {
                Ok(c) => reference = Some(c),
                Err(e) => sec.notes.push(format!("Centreline: no reference: {}.", relative(e))),
            }
        }
    }
    if curves.is_empty() {
        return None;
    }
    let dashed = Look {
        color: BLACK,
        marker: None,
        line: Line::Dashed,
    };
    let mut legend = Vec::new();
    if reference.is_some() {
        legend.push(LegendEntry {
            look: dashed,
            label: "reference".into(),
        });
    }
    for (r, _) in &curves {
        legend.push(LegendEntry {
            look: st.look(&r.model, 0, Line::Solid),
            label: run_label(r),
        });
    }
    let panel = |plane: (usize, usize), name: &str| {
        let mut series = Vec::new();
        if let Some(c) = &reference {
            series.push(SeriesSpec {
                look: dashed,
                points: Vec::new(),
                line_points: project(c, plane),
            });
        }
        for (r, p) in &curves {
            let pts = project(p, plane);
            // About ten markers per curve so models stay apart in grey scale.
            let step = (pts.len() / 10).max(1);
            series.push(SeriesSpec {
                look: st.look(&r.model, 0, Line::Solid),
                points: pts.iter().copied().step_by(step).collect(),
                line_points: pts,
            });
        }
        let axis = ["x", "y", "z"];
        Panel {
            title: name.into(),
            x: Axis::linear(format!("{} [m]", axis[plane.0])),
            y: Axis::linear(format!("{} [m]", axis[plane.1])),
            series,
        }
    };
    // A view across which every shape is flat (a planar cantilever seen
    // from above) shows nothing but a line and degenerate ticks: it is left
    // out, and the title says the shapes are planar.
    let span = |k: usize| {
        let all = curves
            .iter()
            .flat_map(|(_, p)| p.iter())
            .chain(reference.iter().flatten())
            .map(|q| q[k])
            .filter(|v| v.is_finite());
        let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        (hi - lo).max(0.0)
    };
    let (sx, sy, sz) = (span(0), span(1), span(2));
    // Flat: within 10 um per metre of the shapes' largest extent (round-off
    // out of plane, e.g. 3e-8 m in a 0.35 m arch, is not a shape).
    let flat = |s: f64| s <= 1e-5 * sx.max(sy).max(sz);
    let mut views = Vec::new();
    if !flat(sz) || flat(sy) {
        views.push(((0, 2), "side view (x–z)"));
    }
    if !flat(sy) {
        views.push(((0, 1), "top view (x–y)"));
    }
    let planar = if views.len() == 1 {
        "; the shapes are planar"
    } else {
        ""
    };
    let against = if reference.is_some() {
        " against the reference"
    } else {
        ""
    };
    let names: Vec<&str> = views.iter().map(|(_, n)| *n).collect();
    let fig = Figure {
        title: format!("{}: rod centreline at the end (best ok run){against}{planar}", g.title),
        panels: views.iter().map(|(plane, name)| panel(*plane, name)).collect(),
        legend,
        size: if views.len() == 1 { PLOT_SIZE } else { SIZE },
    };
    let alt = format!(
        "{}: each model's final rod centreline in {}{}",
        g.title,
        names.join(" and "),
        if reference.is_some() {
            ", with the reference shape (dashed)"
        } else {
            " (no reference shape; a vessel wall, where the scene has one, is not drawn)"
        }
    );
    Some((fig, alt))
}
