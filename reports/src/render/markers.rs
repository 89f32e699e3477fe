//! The error at a scene's measured points (the Truth Cube's beads), per
//! model's best ok run: the RMS error of each layer of points against its
//! height, and a map of each point's error over the central slice. Where an
//! RMS bead error comes from (the loaded face, the bulging sides) is what a
//! reviewer asks of it.

use std::path::Path;

use plotters::style::RGBColor;

use super::{Group, Section, Styles, best_ok_runs, read_run_files, run_label};
use crate::figure::{Axis, Figure, LegendEntry, Line, Look, Marker as Shape, Panel, SeriesSpec};
use crate::format::fmt_sig;
use crate::{Marker, RunInfo, read_markers};

/// Models mapped (one panel each, beside the layer profile): a 2 x 2 grid.
const MAX_MAPS: usize = 3;
/// Room for the profile and three maps in a 2 x 2 grid, legend on the right.
const SIZE: (u32, u32) = (1400, 1150);
/// Millimetres per metre: the points are millimetres apart.
const MM: f64 = 1e3;
/// Error classes of the map, as multiples of the class unit (the accuracy
/// target when it is a length): under half of it, under it, under twice,
/// under four times, beyond.
const CLASS_EDGES: [f64; 4] = [0.5, 1.0, 2.0, 4.0];
/// One colour per class, light to dark (ColorBrewer YlOrRd, 5 classes), so
/// a grey-scale print keeps the order.
const CLASS_COLORS: [RGBColor; 5] = [
    RGBColor(254, 204, 92),
    RGBColor(253, 141, 60),
    RGBColor(240, 59, 32),
    RGBColor(189, 0, 38),
    RGBColor(80, 0, 20),
];

/// Distance between two points (m).
fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The layers of `values` (one coordinate of every point): indices grouped
/// where consecutive sorted values are closer than half the spacing of a
/// cubic lattice of the same number of points over the same extent, in
/// ascending order.
fn layers(values: &[f64]) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..values.len()).filter(|&i| values[i].is_finite()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let (Some(&lo), Some(&hi)) = (order.first(), order.last()) else {
        return Vec::new();
    };
    let per_side = (order.len() as f64).cbrt().round().max(2.0);
    let gap = 0.5 * (values[hi] - values[lo]) / (per_side - 1.0);
    let mut out: Vec<Vec<usize>> = Vec::new();
    for i in order {
        match out.last_mut() {
            Some(layer) if values[i] - values[*layer.last().unwrap_or(&i)] <= gap => layer.push(i),
            _ => out.push(vec![i]),
        }
    }
    out
}

/// The class of an error `e` given the class unit.
fn class(e: f64, unit: f64) -> usize {
    CLASS_EDGES.iter().take_while(|&&edge| e > edge * unit).count()
}

/// The length every point error is classed by: the scenario's accuracy
/// target when its metric is a length in m (`_m`), else the median error
/// of the points drawn. With the reason, for the note.
fn class_unit(g: &Group, info: &RunInfo, runs: &[(&crate::ResultRow, Vec<Marker>)]) -> Option<(f64, String)> {
    let scenario = g.rows.first().map_or("", |r| r.scenario.as_str());
    if let Some(t) = info.targets.get(scenario)
        && t.metric.ends_with("_m")
        && t.value > 0.0
    {
        return Some((
            t.value,
            format!("the accuracy target ({} = {} mm)", t.metric, fmt_sig(t.value * MM, 3)),
        ));
    }
    let mut all: Vec<f64> = runs
        .iter()
        .flat_map(|(_, ms)| ms.iter().map(|m| dist(m.model, m.reference)))
        .filter(|e| e.is_finite())
        .collect();
    all.sort_by(f64::total_cmp);
    let median = *all.get(all.len() / 2)?;
    (median > 0.0).then(|| {
        (
            median,
            format!("the median point error ({} mm)", fmt_sig(median * MM, 3)),
        )
    })
}

/// The RMS of the point errors (or of the measured motion) of each layer
/// of rest heights (z), against the layer's mean rest height, in mm.
fn profile(ms: &[Marker], of: impl Fn(&Marker) -> f64) -> Vec<(f64, f64)> {
    let z: Vec<f64> = ms.iter().map(|m| m.rest[2]).collect();
    layers(&z)
        .iter()
        .map(|layer| {
            let n = layer.len() as f64;
            let rms = (layer.iter().map(|&i| of(&ms[i]).powi(2)).sum::<f64>() / n).sqrt();
            let height = layer.iter().map(|&i| z[i]).sum::<f64>() / n;
            (rms * MM, height * MM)
        })
        .collect()
}

/// The points of the rest layer in y nearest the points' centroid: the
/// central slice the map shows.
fn central_slice(ms: &[Marker]) -> Vec<usize> {
    let y: Vec<f64> = ms.iter().map(|m| m.rest[1]).collect();
    let mid = y.iter().sum::<f64>() / y.len().max(1) as f64;
    let mean = |l: &Vec<usize>| l.iter().map(|&i| y[i]).sum::<f64>() / l.len() as f64;
    layers(&y)
        .into_iter()
        .min_by(|a, b| (mean(a) - mid).abs().total_cmp(&(mean(b) - mid).abs()))
        .unwrap_or_default()
}

/// The look of error class `k` on the map.
fn class_look(k: usize) -> Look {
    Look {
        color: CLASS_COLORS[k],
        marker: Some(Shape::Circle),
        line: Line::None,
    }
}

/// The layer profile and point-error maps of the group's best ok runs that
/// wrote `markers.csv`; `None` for groups without measured points.
pub(super) fn markers_figure(
    dir: &Path,
    g: &Group,
    st: &Styles,
    info: &RunInfo,
    sec: &mut Section,
) -> Option<(Figure, String)> {
    let runs = read_run_files(dir, best_ok_runs(g), "markers.csv", read_markers, "Point errors", sec);
    let (unit, unit_why) = class_unit(g, info, &runs)?;
    // The points' own measured motion, for scale (the same for every run):
    // drawn beside the errors it would squeeze them against the axis.
    let motion = profile(&runs.first()?.1, |m| dist(m.rest, m.reference));
    let mut legend = Vec::new();
    let mut profile_series = Vec::new();
    for (r, ms) in &runs {
        let look = st.look(&r.model, 0, Line::Solid);
        let pts = profile(ms, |m| dist(m.model, m.reference));
        legend.push(LegendEntry {
            look,
            label: run_label(r),
        });
        profile_series.push(SeriesSpec {
            look,
            points: pts.clone(),
            line_points: pts,
        });
    }
    let mut panels = vec![Panel {
        title: "error by layer of rest height".into(),
        x: Axis::linear("RMS point error in the layer [mm]"),
        y: Axis::linear("rest height z [mm]"),
        series: profile_series,
    }];
    let bounds: Vec<String> = CLASS_EDGES.iter().map(|e| fmt_sig(e * unit * MM, 2)).collect();
    for k in 0..CLASS_COLORS.len() {
        let label = match k {
            0 => format!("error ≤ {} mm", bounds[0]),
            k if k == CLASS_EDGES.len() => format!("error > {} mm", bounds[k - 1]),
            k => format!("{} to {} mm", bounds[k - 1], bounds[k]),
        };
        legend.push(LegendEntry {
            look: class_look(k),
            label,
        });
    }
    for (r, ms) in runs.iter().take(MAX_MAPS) {
        let slice = central_slice(ms);
        let mut by_class = vec![Vec::new(); CLASS_COLORS.len()];
        for &i in &slice {
            let m = &ms[i];
            let e = dist(m.model, m.reference);
            if e.is_finite() {
                by_class[class(e, unit)].push((m.rest[0] * MM, m.rest[2] * MM));
            }
        }
        panels.push(Panel {
            title: format!("{}: central slice, {} points", r.model, slice.len()),
            x: Axis::linear("rest x [mm]"),
            y: Axis::linear("rest z [mm]"),
            series: by_class
                .into_iter()
                .enumerate()
                .filter(|(_, p)| !p.is_empty())
                .map(|(k, points)| SeriesSpec {
                    look: class_look(k),
                    points,
                    line_points: Vec::new(),
                })
                .collect(),
        });
    }
    if runs.len() > MAX_MAPS {
        let left: Vec<String> = runs[MAX_MAPS..].iter().map(|(r, _)| r.model.clone()).collect();
        sec.notes.push(format!(
            "Point errors: maps drawn for the first {MAX_MAPS} models; {} in the layer profile only.",
            left.join(", ")
        ));
    }
    sec.notes.push(format!(
        "Point errors: distance between where each model's best ok run carries a measured point at the end \
         (barycentric in its rest cell) and where the reference has it. The map shows the rest layer \
         nearest the centre in y, coloured in classes of {unit_why}; the profile gives each layer's RMS by \
         rest height. For scale, the reference moves the layers by {} mm RMS, bottom to top.",
        motion.iter().map(|p| fmt_sig(p.0, 2)).collect::<Vec<_>>().join(", ")
    ));
    let fig = Figure {
        title: format!("{}: error at the measured points (best ok run)", g.title),
        panels,
        legend,
        size: SIZE,
    };
    let alt = format!(
        "{}: RMS point error per layer against rest height for {} model(s), and a map of each point's error over the central slice",
        g.title,
        runs.len()
    );
    Some((fig, alt))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3 x 3 x 3 lattice, 10 mm apart with 1 mm jitter, splits into three
    /// layers of nine in each coordinate; a single point is one layer.
    #[test]
    fn layers_of_a_jittered_lattice() {
        let mut z = Vec::new();
        for i in 0..27 {
            let jitter = if i % 2 == 0 { 1e-3 } else { -1e-3 };
            z.push((i / 9) as f64 * 0.01 + jitter);
        }
        let l = layers(&z);
        assert_eq!(l.iter().map(Vec::len).collect::<Vec<_>>(), vec![9, 9, 9]);
        assert!(l[0].iter().all(|&i| i < 9) && l[2].iter().all(|&i| i >= 18));
        assert_eq!(layers(&[0.3]).len(), 1);
        assert!(layers(&[]).is_empty());
    }

    /// An error exactly at an edge falls in the class below it (`<= edge`):
    /// exactly the target is in class 1, "0.5 to 1" target.
    #[test]
    fn classes_by_target() {
        let unit = 1e-3;
        assert_eq!(class(0.0, unit), 0);
        assert_eq!(class(0.5e-3, unit), 0);
        assert_eq!(class(1e-3, unit), 1);
        assert_eq!(class(1.5e-3, unit), 2);
        assert_eq!(class(3e-3, unit), 3);
        assert_eq!(class(5e-3, unit), 4);
    }
}
