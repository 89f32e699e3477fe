//! The tip-over-time plot of a group whose scenario gives a reference tip
//! trajectory (the `ref_tip_*` columns of `observables.csv`): each model's
//! most accurate ok run against the reference, in the coordinate the
//! reference moves along most.

use std::path::Path;

use plotters::style::BLACK;

use super::{Group, Section, Styles, over_time, run_label, usable};
use crate::figure::{Axis, Figure, LegendEntry, Line, Look, SeriesSpec};
use crate::{Series, Status, read_series};

/// Each model's ok run with the smallest primary error (the first on ties,
/// rows being coarse to fine), with its series.
fn most_accurate<'g>(dir: &Path, g: &'g Group<'g>, sec: &mut Section) -> Vec<(&'g crate::ResultRow, Series)> {
    let mut out = Vec::new();
    for model in &g.models {
        let best = g
            .model_rows(model)
            .into_iter()
            .filter(|r| r.status == Status::Ok && !r.run_dir.trim().is_empty())
            .filter_map(|r| usable(g.err(r)).map(|e| (r, e)))
            .fold(None, |b: Option<(&crate::ResultRow, f64)>, (r, e)| match b {
                Some((_, be)) if be <= e => b,
                _ => Some((r, e)),
            });
        let Some((r, _)) = best else { continue };
        let path = dir.join(&r.run_dir).join("observables.csv");
        match read_series(&path) {
            Ok(s) => out.push((r, s)),
            Err(e) => sec
                .notes
                .push(format!("Tip over time: no curve for {}: {e}.", run_label(r))),
        }
    }
    out
}

/// The coordinate (0 = x, 1 = y, 2 = z) the reference tip moves along most.
fn moving_axis(s: &Series) -> Option<usize> {
    let range = |v: &[f64]| {
        let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = f.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if f.is_empty() { None } else { Some(hi - lo) }
    };
    let ranges = [range(&s.ref_tip_x)?, range(&s.ref_tip_y)?, range(&s.ref_tip_z)?];
    (0..3).max_by(|&a, &b| ranges[a].total_cmp(&ranges[b]))
}

fn component(s: &Series, axis: usize, reference: bool) -> &[f64] {
    match (axis, reference) {
        (0, false) => &s.tip_x,
        (1, false) => &s.tip_y,
        (_, false) => &s.tip_z,
        (0, true) => &s.ref_tip_x,
        (1, true) => &s.ref_tip_y,
        (_, true) => &s.ref_tip_z,
    }
}

fn points(t: &[f64], v: &[f64]) -> Vec<(f64, f64)> {
    t.iter()
        .zip(v)
        .filter(|(t, v)| t.is_finite() && v.is_finite())
        .map(|(t, v)| (*t, *v))
        .collect()
}

/// Tip coordinate over time against the reference trajectory, when the
/// group's runs recorded one; `None` otherwise (most scenarios).
pub(super) fn tip_time_figure(dir: &Path, g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    let runs = most_accurate(dir, g, sec);
    let (_, with_ref) = runs.iter().find(|(_, s)| moving_axis(s).is_some())?;
    let axis = moving_axis(with_ref)?;
    let name = ["x", "y", "z"][axis];
    let mut series = Vec::new();
    let mut legend = Vec::new();
    let reference = Look {
        color: BLACK,
        marker: None,
        line: Line::Dashed,
    };
    let ref_pts = points(&with_ref.t, component(with_ref, axis, true));
    series.push(SeriesSpec {
        look: reference,
        points: Vec::new(),
        line_points: ref_pts,
    });
    legend.push(LegendEntry {
        look: reference,
        label: "reference".into(),
    });
    for (r, s) in &runs {
        let pts = points(&s.t, component(s, axis, false));
        if pts.is_empty() {
            continue;
        }
        // About ten markers per curve so models stay apart in grey scale.
        let step = (pts.len() / 10).max(1);
        let look = st.look(&r.model, 0, Line::Solid);
        legend.push(LegendEntry {
            look,
            label: run_label(r),
        });
        series.push(SeriesSpec {
            look,
            points: pts.iter().copied().step_by(step).collect(),
            line_points: pts,
        });
    }
    let fig = over_time(
        format!("{}: tip {name} over time (most accurate ok run)", g.title),
        Axis::linear(format!("tip {name} [m]")),
        series,
        legend,
    );
    let alt = format!(
        "{}: tip {name} over simulated time for each model's most accurate ok run, with the reference (dashed)",
        g.title
    );
    Some((fig, alt))
}
