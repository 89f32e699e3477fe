//! From rows to plots and pages: [`render`] and [`render_dir`].

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

use crate::analysis::{Knob, choose_knob, coarse_to_fine, distinct, fidelity_without, finest};
use crate::doc::{Block, Cell, to_html, to_markdown};
use crate::figure::{
    Axis, BAD_RED, FAIL_GREY, Figure, LegendEntry, Line, Look, Marker, OK_GREEN, PALETTE, Panel, SeriesSpec, save,
};
use crate::format::{fmt_plain, fmt_sig, slug};
use crate::{End, ReportError, ResultRow, RunInfo, Status, fit_order, pareto_front, read_series};

/// Size of single-panel plots (px): 770 px of chart + 330 px of legend.
const PLOT_SIZE: (u32, u32) = (1100, 700);

/// Renders the report for `rows` into `dir` (which normally already holds
/// `results.csv`): `plots/<stem>-{pareto,convergence,error-time,stability}.{svg,png}`,
/// `report.md` and `index.html`. Returns every file written, plots first.
///
/// `plots/` is owned by the renderer: stale `.svg`/`.png` files in it are
/// removed first, so a re-render never shows plots of rows that are gone.
/// Runs that are not `ok` are never dropped silently: they appear in every
/// table with their reason, and each plot lists what it could not show
/// (non-ok runs, missing or non-positive values on log axes, missing time series).
pub fn render(dir: &Path, rows: &[ResultRow], info: &RunInfo) -> Result<Vec<PathBuf>, ReportError> {
    let plots_dir = dir.join("plots");
    fs::create_dir_all(&plots_dir).map_err(|e| ReportError::io(&plots_dir, e))?;
    remove_stale_plots(&plots_dir)?;

    let styles = Styles::new(rows);
    let mut groups = group_rows(rows);
    let mut written = Vec::new();
    let mut sections = Vec::new();
    for g in &mut groups {
        let mut sec = Section::default();
        let figs = [
            ("pareto", pareto_figure(g, &styles, &mut sec)),
            ("convergence", convergence_figure(g, &styles, &mut sec)),
            ("error-time", error_time_figure(dir, g, &styles, &mut sec)),
            ("stability", stability_figure(g, &styles, &mut sec)),
        ];
        for (kind, fig) in figs {
            if let Some((fig, alt)) = fig {
                let stem = format!("{}-{kind}", g.stem);
                written.extend(save(&fig, &plots_dir, &stem)?);
                sec.images.push((stem, alt));
            }
        }
        sections.push(sec);
    }

    let mut blocks = page(info, rows, &groups, &sections, &styles);
    // The haptic-loop table, when the comparison ran one (`haptic.csv`).
    let haptic = dir.join("haptic.csv");
    if haptic.exists() {
        blocks.extend(crate::haptic::section(&crate::read_haptic_csv(&haptic)?));
    }
    let title = format!("surgbench report: {}", or_unknown(&info.comparison));
    let md = dir.join("report.md");
    write_atomic(&md, &to_markdown(&blocks))?;
    let html = dir.join("index.html");
    write_atomic(&html, &to_html(&title, &blocks))?;
    written.push(md);
    written.push(html);
    Ok(written)
}

/// Re-renders a report folder from its files alone: reads `dir/results.csv`
/// and `dir/summary.json` (absent: an empty header, said so on the page) and
/// calls [`render`]. This is what `surgbench report DIR` runs.
pub fn render_dir(dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let rows = crate::read_results_csv(&dir.join("results.csv"))?;
    let summary = dir.join("summary.json");
    let info = if summary.exists() {
        crate::read_run_info(&summary)?
    } else {
        RunInfo::default()
    };
    render(dir, &rows, &info)
}

fn write_atomic(path: &Path, text: &str) -> Result<(), ReportError> {
    let tmp = path.with_extension("tmp");
    fs::write(&tmp, text).map_err(|e| ReportError::io(&tmp, e))?;
    fs::rename(&tmp, path).map_err(|e| ReportError::io(path, e))
}

fn remove_stale_plots(plots_dir: &Path) -> Result<(), ReportError> {
    let rd = fs::read_dir(plots_dir).map_err(|e| ReportError::io(plots_dir, e))?;
    for ent in rd {
        let p = ent.map_err(|e| ReportError::io(plots_dir, e))?.path();
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
        if p.is_file() && (ext == "svg" || ext == "png") {
            fs::remove_file(&p).map_err(|e| ReportError::io(&p, e))?;
        }
    }
    Ok(())
}

fn or_unknown(s: &str) -> &str {
    if s.trim().is_empty() { "(unknown)" } else { s }
}

/// Colour and marker per model, the same in every plot (models sorted by name).
struct Styles {
    models: Vec<String>,
}

impl Styles {
    fn new(rows: &[ResultRow]) -> Self {
        let set: BTreeSet<&str> = rows.iter().map(|r| r.model.as_str()).collect();
        Styles {
            models: set.into_iter().map(String::from).collect(),
        }
    }
    fn index(&self, model: &str) -> usize {
        self.models.iter().position(|m| m == model).unwrap_or(0)
    }
    /// Look of `model`; `variant` > 0 shifts the marker and dashes the line
    /// (a second fidelity group of the same model).
    fn look(&self, model: &str, variant: usize, line: Line) -> Look {
        let i = self.index(model);
        let n = PALETTE.len();
        let m = Marker::ALL.len();
        Look {
            color: PALETTE[i % n],
            marker: Some(Marker::ALL[(i + i / n + variant) % m]),
            line: if variant > 0 && line == Line::Solid {
                Line::Dashed
            } else {
                line
            },
        }
    }
}

/// The rows of one scenario (with one set of parameter overrides) of one comparison.
struct Group<'a> {
    title: String,
    stem: String,
    metric: String,
    rows: Vec<&'a ResultRow>,
    /// Models present, in style order.
    models: Vec<String>,
    /// Messages about the metric name itself.
    metric_notes: Vec<String>,
}

impl Group<'_> {
    fn model_rows(&self, model: &str) -> Vec<&ResultRow> {
        self.rows.iter().copied().filter(|r| r.model == model).collect()
    }
    fn err(&self, r: &ResultRow) -> Option<f64> {
        r.metrics.get(&self.metric).copied()
    }
    fn metric_label(&self) -> String {
        metric_label(&self.metric)
    }
}

/// What the page says about one group besides its table.
#[derive(Default)]
struct Section {
    /// (plot stem, alt text)
    images: Vec<(String, String)>,
    orders: Vec<String>,
    notes: Vec<String>,
}

/// Axis label of an error metric, with the unit read from its name's suffix.
fn metric_label(name: &str) -> String {
    let unit = [
        ("_rel", "relative, 1"),
        ("_mm", "mm"),
        ("_m", "m"),
        ("_n", "N"),
        ("_nm", "N m"),
        ("_rad", "rad"),
        ("_deg", "deg"),
        ("_pa", "Pa"),
        ("_j", "J"),
        ("_s", "s"),
    ]
    .iter()
    .find(|(s, _)| name.to_ascii_lowercase().ends_with(s))
    .map(|(_, u)| *u);
    match unit {
        Some(u) => format!("{name} [{u}]"),
        None => name.to_string(),
    }
}

fn run_label(r: &ResultRow) -> String {
    if r.fidelity.is_empty() {
        r.model.clone()
    } else {
        format!("{} {}", r.model, r.fidelity)
    }
}

fn usable(v: Option<f64>) -> Option<f64> {
    v.filter(|x| x.is_finite() && *x > 0.0)
}

/// FNV-1a 64-bit hash (Fowler, Noll, Vo): a stable short tag for long names.
fn fnv1a(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn group_rows(rows: &[ResultRow]) -> Vec<Group<'_>> {
    let comparisons: BTreeSet<&str> = rows.iter().map(|r| r.comparison.as_str()).collect();
    let many_comparisons = comparisons.len() > 1;
    let styles = Styles::new(rows);
    // Groups in order of first appearance (the comparison file's order).
    let mut order: Vec<(&str, &str, &str)> = Vec::new();
    let mut by_key: BTreeMap<(&str, &str, &str), Vec<&ResultRow>> = BTreeMap::new();
    for r in rows {
        let k = (r.comparison.as_str(), r.scenario.as_str(), r.params.as_str());
        if !by_key.contains_key(&k) {
            order.push(k);
        }
        by_key.entry(k).or_default().push(r);
    }
    let mut stems = BTreeSet::new();
    let mut out = Vec::new();
    for k in order {
        let (comparison, scenario, params) = k;
        let mut g_rows = by_key.remove(&k).unwrap_or_default();
        g_rows.sort_by(|a, b| {
            styles
                .index(&a.model)
                .cmp(&styles.index(&b.model))
                .then(coarse_to_fine(a, b))
        });
        let mut base = slug(scenario);
        if many_comparisons {
            base = format!("{}-{}", slug(comparison), base);
        }
        if !params.is_empty() {
            base = format!("{base}--{}", slug(params));
        }
        if base.len() > 90 {
            // Keep file names short; the hash keeps distinct long names distinct.
            let cut: String = base.chars().take(72).collect();
            base = format!("{cut}-{:016x}", fnv1a(&base));
        }
        let mut stem = base.clone();
        let mut i = 2;
        while !stems.insert(stem.clone()) {
            stem = format!("{base}-{i}");
            i += 1;
        }
        let mut title = or_unknown(scenario).to_string();
        if !params.is_empty() {
            title.push_str(&format!(" [{params}]"));
        }
        if many_comparisons {
            title = format!("{comparison}: {title}");
        }
        // The headline metric: the name most rows give (ties: alphabetical).
        let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
        for r in &g_rows {
            if !r.primary_error.is_empty() {
                *counts.entry(r.primary_error.as_str()).or_default() += 1;
            }
        }
        let metric = counts
            .iter()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
            .map(|(m, _)| m.to_string())
            .unwrap_or_default();
        let mut metric_notes = Vec::new();
        if counts.len() > 1 {
            let list: Vec<String> = counts.iter().map(|(m, c)| format!("{m} ({c} rows)")).collect();
            metric_notes.push(format!(
                "Rows name different primary errors: {}; tables and plots use {metric}.",
                list.join(", ")
            ));
        }
        let models: Vec<String> = {
            let set: BTreeSet<usize> = g_rows.iter().map(|r| styles.index(&r.model)).collect();
            set.into_iter().map(|i| styles.models[i].clone()).collect()
        };
        out.push(Group {
            title,
            stem,
            metric,
            rows: g_rows,
            models,
            metric_notes,
        });
    }
    out
}

/// Speed vs error: every ok run a point, each model's Pareto front a line.
fn pareto_figure(g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    if g.metric.is_empty() {
        sec.notes
            .push("No speed/error plot: no row names a primary error metric.".into());
        return None;
    }
    // Static scenes (every ok run ends settled or at its time limit): models
    // take different dt and step counts to the same equilibrium, so the fair
    // cost is the wall time to the solution, not the time per step.
    let ok: Vec<&ResultRow> = g.rows.iter().copied().filter(|r| r.status == Status::Ok).collect();
    // (Older results.csv files have no solve_wall_s: they keep ms/step.)
    let is_static = !ok.is_empty()
        && ok
            .iter()
            .all(|r| matches!(r.end, End::Settled | End::TimeLimit) && r.solve_wall_s.is_some());
    let (cost, cost_name, cost_axis) = if is_static {
        (
            (|r: &ResultRow| r.solve_wall_s) as fn(&ResultRow) -> Option<f64>,
            "time to solution (s)",
            "wall time to solution [s] (log)",
        )
    } else {
        (
            (|r: &ResultRow| r.ms_per_step_median) as fn(&ResultRow) -> Option<f64>,
            "ms/step",
            "median wall time per step [ms] (log)",
        )
    };
    let mut series = Vec::new();
    let mut legend = Vec::new();
    let mut missing = Vec::new();
    let mut nonpos = Vec::new();
    for model in &g.models {
        let mut pts = Vec::new();
        for r in g.model_rows(model).into_iter().filter(|r| r.status == Status::Ok) {
            match (cost(r), g.err(r)) {
                (Some(t), Some(e)) => {
                    if usable(Some(t)).is_some() && usable(Some(e)).is_some() {
                        pts.push((t, e));
                    } else {
                        nonpos.push(format!(
                            "{} ({cost_name} = {}, {} = {})",
                            run_label(r),
                            fmt_sig(t, 3),
                            g.metric,
                            fmt_sig(e, 3)
                        ));
                    }
                }
                (t, e) => missing.push(format!(
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
        if pts.is_empty() {
            continue;
        }
        let mut front: Vec<(f64, f64)> = pareto_front(&pts).into_iter().map(|i| pts[i]).collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        let look = st.look(model, 0, Line::Solid);
        legend.push(LegendEntry {
            look,
            label: format!("{model} ({} runs, {} on front)", pts.len(), front.len()),
        });
        series.push(SeriesSpec {
            look,
            points: pts,
            line_points: front,
        });
    }
    if !nonpos.is_empty() {
        sec.notes.push(format!(
            "Speed/error plot omits ok runs with a zero, negative or non-finite value (a log axis cannot show them): {}.",
            nonpos.join("; ")
        ));
    }
    if !missing.is_empty() {
        sec.notes.push(format!(
            "Speed/error plot omits ok runs without a value: {}.",
            missing.join("; ")
        ));
    }
    if series.is_empty() {
        sec.notes.push(format!(
            "No speed/error plot: no ok run has both a positive {cost_name} and a positive {}.",
            g.metric
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
    let fig = Figure {
        title: format!("{}: speed vs {}", g.title, g.metric),
        panels: vec![Panel {
            title: String::new(),
            x: Axis::log(cost_axis),
            y: Axis::log(format!("{} (log)", g.metric_label())),
            series,
        }],
        legend,
        size: PLOT_SIZE,
    };
    let alt = format!("{}: speed ({cost_name}) vs {}, one point per ok run", g.title, g.metric);
    if is_static {
        sec.notes.push(
            "Static scene: the speed axis is the wall time to the solution (all steps to settling), since models reach the same equilibrium with different step sizes and counts."
                .into(),
        );
    }
    Some((fig, alt))
}

/// The group key of a run in a convergence study over `knob`: its other knobs.
fn other_knobs(r: &ResultRow, knob: Knob) -> String {
    let key = format!("{}=", knob.key());
    if r.fidelity.split(';').any(|kv| kv.trim().starts_with(&key)) {
        return fidelity_without(&r.fidelity, knob.key());
    }
    // The fidelity string does not name the knob: rebuild the others from the columns.
    let mut parts = Vec::new();
    for (k, v) in [
        (Knob::Segments, ("segments", r.segments)),
        (Knob::MeshLevel, ("mesh_level", r.mesh_level)),
        (Knob::Dt, ("dt", r.dt)),
    ] {
        if let (true, Some(x)) = (k != knob, v.1) {
            parts.push(format!("{}={}", v.0, crate::format_f64(x)));
        }
    }
    if let Some(it) = r.iterations {
        parts.push(format!("iterations={}", crate::format_f64(it)));
    }
    parts.join(";")
}

fn knob_range(knob: Knob, ns: &[f64]) -> String {
    let lo = ns.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = ns.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    match knob {
        Knob::Segments => format!("segments {} to {}", fmt_plain(lo), fmt_plain(hi)),
        Knob::MeshLevel => format!(
            "cells per side {} to {}, mesh_level {} to {}",
            fmt_plain(lo),
            fmt_plain(hi),
            fmt_plain(lo.log2()),
            fmt_plain(hi.log2())
        ),
        Knob::Dt => format!("dt {} s down to {} s", fmt_sig(1.0 / lo, 3), fmt_sig(1.0 / hi, 3)),
    }
}

/// Error vs discretization, log-log, one curve per model and other-knob group,
/// with the fitted order in the legend.
fn convergence_figure(g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    if g.metric.is_empty() {
        return None;
    }
    // Each model's own knob; the plot uses the knob most models vary.
    let mut own: Vec<(String, Option<Knob>, Vec<&ResultRow>)> = Vec::new();
    for model in &g.models {
        let ok: Vec<&ResultRow> = g
            .model_rows(model)
            .into_iter()
            .filter(|r| r.status == Status::Ok && usable(g.err(r)).is_some())
            .collect();
        own.push((model.clone(), choose_knob(&ok), ok));
    }
    let bad: Vec<String> = g
        .rows
        .iter()
        .filter(|r| r.status == Status::Ok)
        .filter_map(|r| match g.err(r) {
            Some(e) if !(e.is_finite() && e > 0.0) => {
                Some(format!("{} ({} = {})", run_label(r), g.metric, fmt_sig(e, 3)))
            }
            _ => None,
        })
        .collect();
    if !bad.is_empty() {
        sec.notes.push(format!(
            "Convergence plot and orders omit ok runs whose {} is zero, negative or not finite (no logarithm): {}.",
            g.metric,
            bad.join("; ")
        ));
    }
    let mut votes: Vec<(Knob, usize)> = [Knob::Segments, Knob::MeshLevel, Knob::Dt]
        .into_iter()
        .map(|k| (k, own.iter().filter(|o| o.1 == Some(k)).count()))
        .collect();
    // Stable sort keeps the preference order segments > mesh level > dt on ties.
    votes.sort_by_key(|v| std::cmp::Reverse(v.1));
    let plot_knob = votes.first().filter(|v| v.1 > 0).map(|v| v.0);

    let mut series = Vec::new();
    let mut legend = Vec::new();
    for (model, knob, ok) in &own {
        let Some(knob) = *knob else {
            sec.orders.push(if ok.is_empty() {
                format!("{model}: no order (no ok run with a positive {}).", g.metric)
            } else {
                format!(
                    "{model}: no order ({} ok run(s) with a positive {}, but no discretization knob takes two values).",
                    ok.len(),
                    g.metric
                )
            });
            continue;
        };
        let mut groups: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
        for r in ok {
            if let (Some(n), Some(e)) = (usable(knob.resolution(r)), usable(g.err(r))) {
                groups.entry(other_knobs(r, knob)).or_default().push((n, e));
            }
        }
        let n_groups = groups.len();
        for (variant, (other, mut pts)) in groups.into_iter().enumerate() {
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let ns: Vec<f64> = pts.iter().map(|p| p.0).collect();
            let es: Vec<f64> = pts.iter().map(|p| p.1).collect();
            let p = fit_order(&ns, &es);
            let tag = if n_groups > 1 && !other.is_empty() {
                format!("{model} {other}")
            } else {
                model.clone()
            };
            let fit = match p {
                Some(p) => format!("p = {p:.2}"),
                None => format!("no fit: {} point(s)", distinct(ns.iter().copied())),
            };
            let with = if other.is_empty() {
                String::new()
            } else {
                format!(", {other}")
            };
            sec.orders.push(match p {
                Some(p) => format!(
                    "{model}: p = {p:.2} vs {} ({} ok runs, {}{with}).",
                    knob.n_name(),
                    pts.len(),
                    knob_range(knob, &ns)
                ),
                None => format!(
                    "{model}: no order vs {} (fewer than two distinct values{with}).",
                    knob.n_name()
                ),
            });
            if Some(knob) != plot_knob {
                continue;
            }
            let look = st.look(model, variant, Line::Solid);
            legend.push(LegendEntry {
                look,
                label: format!("{tag} ({fit})"),
            });
            series.push(SeriesSpec {
                look,
                points: pts.clone(),
                line_points: pts,
            });
        }
        if Some(knob) != plot_knob {
            sec.notes.push(format!(
                "{model} varies {} rather than {}: its order is listed but not drawn in the convergence plot.",
                knob.key(),
                plot_knob.map(|k| k.key()).unwrap_or("-")
            ));
        }
    }
    let knob = plot_knob?;
    if series.is_empty() {
        return None;
    }
    let ticks: Vec<f64> = {
        let mut v: Vec<f64> = series.iter().flat_map(|s| s.points.iter().map(|p| p.0)).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let mut x = Axis::log(knob.axis_label());
    x.plain = knob.is_count();
    if ticks.len() <= 8 {
        x.ticks = Some(ticks);
    }
    sec.notes.push(format!(
        "Convergence order p: least-squares slope of ln({}) against ln(n), negated, over all ok runs of a curve (h ~ 1/n); \
         a saturating curve (error floor from another knob or the reference) lowers p.",
        g.metric
    ));
    let fig = Figure {
        title: format!("{}: {} vs {}", g.title, g.metric, knob.key()),
        panels: vec![Panel {
            title: String::new(),
            x,
            y: Axis::log(format!("{} (log)", g.metric_label())),
            series,
        }],
        legend,
        size: PLOT_SIZE,
    };
    let alt = format!(
        "{}: {} against {}, log-log, with fitted orders",
        g.title,
        g.metric,
        knob.key()
    );
    Some((fig, alt))
}

/// Error over time from `observables.csv` of each model's finest ok run.
fn error_time_figure(dir: &Path, g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    let mut series = Vec::new();
    let mut legend = Vec::new();
    for model in &g.models {
        let rows = g.model_rows(model);
        let Some(r) = finest(rows.iter().copied().filter(|r| r.status == Status::Ok)) else {
            continue;
        };
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
            sec.notes.push(format!(
                "Error over time: {} has no positive error sample in {} ({} samples).",
                run_label(r),
                path.display(),
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
    let fig = Figure {
        title: format!("{}: {} over time (finest ok run)", g.title, or_unknown(&g.metric)),
        panels: vec![Panel {
            title: String::new(),
            x: Axis::linear("simulated time t [s]"),
            y: Axis::log(format!("{} (log)", g.metric_label())),
            series,
        }],
        legend,
        size: PLOT_SIZE,
    };
    let alt = format!("{}: error over simulated time for each model's finest ok run", g.title);
    Some((fig, alt))
}

/// Stability map: per model, a marker per (resolution, dt) coloured by status.
fn stability_figure(g: &Group, _st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
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
    let kinds: [(Status, RGBLook); 4] = [
        (Status::Ok, (OK_GREEN, Marker::Circle)),
        (Status::Timeout, (FAIL_GREY, Marker::TriangleUp)),
        (Status::Failed, (FAIL_GREY, Marker::Square)),
        (Status::Unstable, (BAD_RED, Marker::Cross)),
    ];
    let mut panels = Vec::new();
    let mut present = BTreeSet::new();
    let mut other_status = Vec::new();
    for model in &g.models {
        let mr: Vec<&ResultRow> = runs.iter().copied().filter(|r| &r.model == model).collect();
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
            continue;
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
        for (status, (color, m)) in kinds {
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
            if !kinds.iter().any(|k| k.0 == c.2.status) {
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
        panels.push(Panel {
            title: model.clone(),
            x,
            y,
            series,
        });
    }
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
    let legend = kinds
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

fn num(v: Option<f64>) -> String {
    v.map(|x| fmt_sig(x, 3)).unwrap_or_else(|| "—".into())
}

fn status_counts<'a>(rows: impl Iterator<Item = &'a ResultRow>) -> String {
    let mut c: BTreeMap<&str, usize> = BTreeMap::new();
    let mut n = 0;
    for r in rows {
        *c.entry(if r.status == Status::Unset {
            "(no status)"
        } else {
            r.status.as_str()
        })
        .or_default() += 1;
        n += 1;
    }
    let mut parts: Vec<String> = ["ok", "unstable", "failed", "timeout", "unsupported"]
        .iter()
        .filter_map(|s| c.remove(s).map(|k| format!("{k} {s}")))
        .collect();
    parts.extend(c.iter().map(|(s, k)| format!("{k} {s}")));
    format!("{n} runs: {}", parts.join(", "))
}

fn reason_text(r: &ResultRow) -> String {
    let reason = r.reason.trim();
    let reason = if reason.is_empty() { "(no reason given)" } else { reason };
    format!("{}: {}", or_unknown(r.status.as_str()), reason)
}

fn reason_only(r: &ResultRow) -> String {
    let reason = r.reason.trim();
    if reason.is_empty() {
        "(no reason given)".into()
    } else {
        reason.to_string()
    }
}

fn stable_text(r: &ResultRow) -> String {
    let wd = r.watchdog.trim();
    let at = r
        .watchdog_t
        .map(|t| format!(" at t = {} s", fmt_sig(t, 3)))
        .unwrap_or_default();
    match r.stable {
        Some(true) if wd.is_empty() => "yes".into(),
        Some(true) => format!("yes ({wd}{at})"),
        Some(false) if wd.is_empty() => format!("no{at}"),
        Some(false) => format!("no: {wd}{at}"),
        None if wd.is_empty() => "—".into(),
        None => format!("{wd}{at}"),
    }
}

fn scenario_table(g: &Group) -> Block {
    let ok: Vec<&ResultRow> = g.rows.iter().copied().filter(|r| r.status == Status::Ok).collect();
    let best_err = ok.iter().filter_map(|r| usable(g.err(r))).fold(f64::INFINITY, f64::min);
    let best_t = ok
        .iter()
        .filter_map(|r| usable(r.ms_per_step_median))
        .fold(f64::INFINITY, f64::min);
    let header = vec![
        "model".into(),
        "fidelity".into(),
        "status".into(),
        if g.metric.is_empty() {
            "primary error".into()
        } else {
            g.metric_label()
        },
        "ms/step median".into(),
        "ms/step p95".into(),
        "real-time factor".into(),
        "solver iters mean / max".into(),
        "stable / watchdog".into(),
        "end".into(),
    ];
    let mut rows = Vec::new();
    for r in &g.rows {
        let is_ok = r.status == Status::Ok;
        let err_cell = if is_ok {
            match g.err(r) {
                Some(e) => Cell {
                    text: fmt_sig(e, 3),
                    bold: e == best_err,
                    warn: false,
                },
                None => Cell::plain("— (not reported)"),
            }
        } else {
            // The status column says what happened; here goes why.
            Cell {
                text: reason_only(r),
                bold: false,
                warn: true,
            }
        };
        let t_cell = Cell {
            text: num(r.ms_per_step_median),
            bold: is_ok && r.ms_per_step_median == Some(best_t),
            warn: false,
        };
        let iters = match (r.solver_iters_mean, r.solver_iters_max) {
            (None, None) => "—".into(),
            (a, b) => format!("{} / {}", num(a), num(b)),
        };
        rows.push(vec![
            Cell::plain(&r.model),
            Cell::plain(if r.fidelity.is_empty() {
                "(default)"
            } else {
                r.fidelity.as_str()
            }),
            Cell {
                text: or_unknown(r.status.as_str()).to_string(),
                bold: false,
                warn: !is_ok,
            },
            err_cell,
            t_cell,
            Cell::plain(num(r.ms_per_step_p95)),
            Cell::plain(num(r.real_time_factor)),
            Cell::plain(iters),
            Cell::plain(stable_text(r)),
            Cell::plain(if r.end == End::Unset { "—" } else { r.end.as_str() }),
        ]);
    }
    Block::Table { header, rows }
}

fn summary_table(groups: &[Group], st: &Styles) -> Block {
    let mut header = vec!["scenario".to_string(), "primary error".to_string()];
    header.extend(st.models.iter().cloned());
    let mut rows = Vec::new();
    for g in groups {
        let mut row = vec![Cell::plain(&g.title), Cell::plain(or_unknown(&g.metric))];
        for model in &st.models {
            let mr = g.model_rows(model);
            let cell = match finest(mr.iter().copied()) {
                None => Cell::plain("not run"),
                Some(r) if r.status == Status::Ok => {
                    let e = g
                        .err(r)
                        .map(|e| fmt_sig(e, 3))
                        .unwrap_or_else(|| "no error value".into());
                    Cell::plain(format!(
                        "{e} at {} ms/step ({})",
                        num(r.ms_per_step_median),
                        if r.fidelity.is_empty() {
                            "default"
                        } else {
                            r.fidelity.as_str()
                        }
                    ))
                }
                Some(r) => Cell {
                    text: format!(
                        "{} ({})",
                        reason_text(r),
                        if r.fidelity.is_empty() {
                            "default"
                        } else {
                            r.fidelity.as_str()
                        }
                    ),
                    bold: false,
                    warn: true,
                },
            };
            row.push(cell);
        }
        rows.push(row);
    }
    Block::Table { header, rows }
}

fn page(info: &RunInfo, rows: &[ResultRow], groups: &[Group], sections: &[Section], st: &Styles) -> Vec<Block> {
    let mut b = vec![Block::Heading(
        1,
        format!("surgbench report: {}", or_unknown(&info.comparison)),
    )];
    if info.quick {
        b.push(Block::Warning(
            "quick run: reduced sweeps and durations. Use it to check the pipeline, not to publish numbers.".into(),
        ));
    }
    let versions: Vec<String> = info.crate_versions.iter().map(|(k, v)| format!("{k} {v}")).collect();
    let kv = |k: &str, v: String| vec![Cell::plain(k), Cell::plain(v)];
    b.push(Block::Table {
        header: vec!["run".into(), "".into()],
        rows: vec![
            kv("comparison", or_unknown(&info.comparison).into()),
            kv("date", or_unknown(&info.date).into()),
            kv("commit", or_unknown(&info.commit).into()),
            kv("machine", or_unknown(&info.machine).into()),
            kv("cores / threads", format!("{} / {}", info.cores, info.threads)),
            kv("rustc", or_unknown(&info.rustc).into()),
            kv("command", or_unknown(&info.command).into()),
            kv("quick", if info.quick { "yes" } else { "no" }.into()),
            kv("wall time [s]", fmt_sig(info.wall_s, 3)),
            kv(
                "crate versions",
                if versions.is_empty() {
                    "(unknown)".into()
                } else {
                    versions.join(", ")
                },
            ),
        ],
    });
    b.push(Block::Para(format!(
        "{}. Units are SI (m, kg, s, N, Pa, rad) unless a column says otherwise; wall times are in ms per step. \
         Tables round to 3 significant digits, results.csv holds every value at full precision, and the command surgbench report DIR \
         re-renders this page from results.csv (and summary.json). In each scenario table the lowest error and the fastest \
         ms/step among ok runs are bold; runs that are not ok show their reason in place of the error.",
        status_counts(rows.iter())
    )));

    b.push(Block::Heading(2, "Summary: finest fidelity of each model".into()));
    b.push(Block::Para(
        "Each cell: the primary error and ms/step of the model's finest run in the scenario, or its status and reason when that run is not ok."
            .into(),
    ));
    b.push(summary_table(groups, st));

    for (g, sec) in groups.iter().zip(sections) {
        b.push(Block::Heading(2, format!("Scenario: {}", g.title)));
        b.push(Block::Para(format!(
            "{}. Primary error: {}.",
            status_counts(g.rows.iter().copied()),
            if g.metric.is_empty() {
                "(none named)".to_string()
            } else {
                g.metric_label()
            }
        )));
        if !g.metric_notes.is_empty() {
            b.push(Block::List(g.metric_notes.clone()));
        }
        b.push(scenario_table(g));
        let others: BTreeSet<&str> = g
            .rows
            .iter()
            .flat_map(|r| r.metrics.keys().map(String::as_str))
            .filter(|m| *m != g.metric)
            .collect();
        if !others.is_empty() {
            b.push(Block::Para(format!(
                "Other metrics of this scenario (in results.csv): {}.",
                others.into_iter().collect::<Vec<_>>().join(", ")
            )));
        }
        if !sec.orders.is_empty() {
            b.push(Block::Heading(3, "Observed convergence order".into()));
            b.push(Block::List(sec.orders.clone()));
        }
        if !sec.images.is_empty() {
            b.push(Block::Heading(3, "Plots".into()));
            for (stem, alt) in &sec.images {
                b.push(Block::Image {
                    svg: format!("plots/{stem}.svg"),
                    png: format!("plots/{stem}.png"),
                    alt: alt.clone(),
                });
            }
        }
        if !sec.notes.is_empty() {
            b.push(Block::Heading(3, "Notes".into()));
            b.push(Block::List(sec.notes.clone()));
        }
    }
    b
}
