//! From rows to plots and pages: [`render`] and [`render_dir`].

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

use crate::analysis::coarse_to_fine;
use crate::doc::{fill_toc, to_html, to_markdown};
use crate::figure::{Line, Look, Marker, PALETTE, save};
use crate::format::{fnv1a, slug};
use crate::{ReportError, ResultRow, RunInfo, staging};

mod centreline;
mod convergence;
mod error_time;
mod force_time;
mod markers;
mod pareto;
mod stability;
mod tables;
mod tip_path;
mod tip_time;
mod verdicts;

use centreline::centreline_figure;
use convergence::convergence_figure;
use error_time::error_time_figure;
use force_time::{force_depth_figure, force_time_figure};
use markers::markers_figure;
use pareto::pareto_figure;
use stability::stability_figure;
use tables::page;
use tip_path::tip_path_figure;
use tip_time::tip_time_figure;

/// Size of single-panel plots (px): 770 px of chart + 330 px of legend.
const PLOT_SIZE: (u32, u32) = (1100, 700);

/// Renders the report for `rows` into `dir` (which normally already holds
/// `results.csv`): `plots/<stem>-{pareto,convergence,error-time,tip-time,tip-path,centreline,force-time,force-depth,points,stability}.{svg,png}` (tip-time where the runs recorded a reference trajectory, tip-path where they wrote the tip's path in its bend plane to `tip_path.csv`, centreline for rod models and the rod of coupled ones, force-time where they recorded a reference force, force-depth where they also recorded the indenter's depth, points where they wrote the scene's measured points to `markers.csv`),
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
            ("pareto", pareto_figure(g, &styles, info, &mut sec)),
            ("convergence", convergence_figure(g, &styles, &mut sec)),
            ("error-time", error_time_figure(dir, g, &styles, &mut sec)),
            ("tip-time", tip_time_figure(dir, g, &styles, &mut sec)),
            ("tip-path", tip_path_figure(dir, g, &mut sec)),
            ("centreline", centreline_figure(dir, g, &styles, &mut sec)),
            ("force-time", force_time_figure(dir, g, &styles, &mut sec)),
            ("force-depth", force_depth_figure(dir, g, &styles, &mut sec)),
            ("points", markers_figure(dir, g, &styles, info, &mut sec)),
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
    blocks.extend(tables::run_section(info));
    fill_toc(&mut blocks);
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
///
/// All or nothing: the new report is rendered into a temporary sibling of
/// `dir` that starts as `dir`'s files (hard-linked, see
/// [`crate::staging::link_tree`]) without its earlier plots and pages, and
/// is moved into place only when every file is written. On any error (a
/// malformed `haptic.csv`, a full disk) the temporary sibling is removed
/// and `dir` keeps every file as it was.
pub fn render_dir(dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    // The real folder, so that `.` or a path ending in `..` has a name
    // and a parent to stage beside.
    let dir = &fs::canonicalize(dir).map_err(|e| ReportError::io(dir, e))?;
    let rows = crate::read_results_csv(&dir.join("results.csv"))?;
    let summary = dir.join("summary.json");
    let info = if summary.exists() {
        crate::read_run_info(&summary)?
    } else {
        RunInfo::default()
    };
    let tmp = staging::temp_sibling(dir).map_err(|e| ReportError::io(dir, e))?;
    let rendered = staging::link_tree(dir, &tmp, &is_rendered)
        .map_err(|e| ReportError::io(dir, e))
        .and_then(|()| render(&tmp, &rows, &info))
        .and_then(|files| {
            staging::replace_dir(&tmp, dir).map_err(|e| ReportError::io(dir, e))?;
            Ok(files
                .iter()
                .map(|f| dir.join(f.strip_prefix(&tmp).unwrap_or(f)))
                .collect())
        });
    if rendered.is_err() {
        let _ = fs::remove_dir_all(&tmp);
    }
    rendered
}

/// Whether `rel` (relative to a report folder) is one of the files
/// [`render`] writes anew: the pages and the plots.
fn is_rendered(rel: &Path) -> bool {
    let plot = rel.parent() == Some(Path::new("plots")) && rel.extension().is_some_and(|e| e == "svg" || e == "png");
    plot || rel == Path::new("report.md") || rel == Path::new("index.html")
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

/// Colour and marker per model, the same in every plot (models sorted by
/// name), and the machines the timings come from.
struct Styles {
    models: Vec<String>,
    /// Host names the rows name, sorted; more than one means timings are
    /// grouped by machine ([`Styles::by_machine`]).
    hosts: Vec<String>,
}

impl Styles {
    fn new(rows: &[ResultRow]) -> Self {
        let set: BTreeSet<&str> = rows.iter().map(|r| r.model.as_str()).collect();
        let hosts: BTreeSet<&str> = rows.iter().map(|r| r.host.as_str()).filter(|h| !h.is_empty()).collect();
        Styles {
            models: set.into_iter().map(String::from).collect(),
            hosts: hosts.into_iter().map(String::from).collect(),
        }
    }
    /// Whether the timings come from more than one machine: speed figures
    /// are then grouped by machine, never compared across machines.
    fn by_machine(&self) -> bool {
        self.hosts.len() > 1
    }
    /// The machine groups of speed figures: each host, or one group (`""`)
    /// for a report from one machine.
    fn machine_groups(&self) -> Vec<&str> {
        if self.by_machine() {
            self.hosts.iter().map(String::as_str).collect()
        } else {
            vec![""]
        }
    }
    /// Whether `r`'s timings belong to machine group `host` ([`Styles::machine_groups`]).
    fn on_machine(&self, r: &ResultRow, host: &str) -> bool {
        !self.by_machine() || r.host == host
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
    /// Whether the scene scores an outcome (its runs report `success`, 1 or
    /// 0, as `branch-selection` does): a rate and a time, not an error on a
    /// log axis. Its page gives a table ([`tables`]), not error plots.
    fn is_outcome(&self) -> bool {
        self.rows.iter().any(|r| r.metrics.contains_key(OUTCOME_METRIC))
    }
}

/// The metric of an outcome scene: 1 when the run reached its goal, else 0.
const OUTCOME_METRIC: &str = "success";
/// The time an outcome scene's run took to reach its goal (s).
const OUTCOME_TIME: &str = "time_to_target_s";

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

/// A run's settings as pages name them: `default`, or the fidelity with
/// numbers to 4 significant digits ([`crate::short_settings`]).
fn settings_label(r: &ResultRow) -> String {
    if r.fidelity.is_empty() {
        "default".into()
    } else {
        crate::short_settings(&r.fidelity)
    }
}

/// Each of `runs` that wrote the run file `name` with at least one row,
/// read by `read`; a file that does not read is named in a note starting
/// with `what` (paths relative to the report), not a failed render.
fn read_run_files<'a, T>(
    dir: &Path,
    runs: impl IntoIterator<Item = &'a ResultRow>,
    name: &str,
    read: impl Fn(&Path) -> Result<Vec<T>, ReportError>,
    what: &str,
    sec: &mut Section,
) -> Vec<(&'a ResultRow, Vec<T>)> {
    let mut out = Vec::new();
    for r in runs {
        if r.run_dir.trim().is_empty() {
            continue;
        }
        let path = dir.join(&r.run_dir).join(name);
        if !path.is_file() {
            continue;
        }
        match read(&path) {
            Ok(v) if !v.is_empty() => out.push((r, v)),
            Ok(_) => {}
            Err(e) => sec.notes.push(format!(
                "{what}: none for {}: {}.",
                run_label(r),
                e.to_string().replace(&format!("{}/", dir.display()), "")
            )),
        }
    }
    out
}

fn run_label(r: &ResultRow) -> String {
    if r.fidelity.is_empty() {
        r.model.clone()
    } else {
        format!("{} {}", r.model, crate::short_settings(&r.fidelity))
    }
}

/// Each model's best ok run in the group ([`best_ok`]: most accurate, then
/// fastest), in style order: the runs the summary and the over-time plots
/// show.
fn best_ok_runs<'a>(g: &'a Group<'a>) -> Vec<&'a ResultRow> {
    g.models
        .iter()
        .filter_map(|m| crate::analysis::best_ok(&g.model_rows(m), |r| g.err(r)))
        .collect()
}

/// A one-panel plot over simulated time (linear time axis).
fn over_time(
    title: String,
    y: crate::figure::Axis,
    series: Vec<crate::figure::SeriesSpec>,
    legend: Vec<crate::figure::LegendEntry>,
) -> crate::figure::Figure {
    one_panel(
        title,
        crate::figure::Axis::linear("simulated time t [s]"),
        y,
        series,
        legend,
    )
}

/// A one-panel plot with the axes `x` and `y`.
fn one_panel(
    title: String,
    x: crate::figure::Axis,
    y: crate::figure::Axis,
    series: Vec<crate::figure::SeriesSpec>,
    legend: Vec<crate::figure::LegendEntry>,
) -> crate::figure::Figure {
    crate::figure::Figure {
        title,
        panels: vec![crate::figure::Panel {
            title: String::new(),
            x,
            y,
            series,
        }],
        legend,
        size: PLOT_SIZE,
    }
}

fn usable(v: Option<f64>) -> Option<f64> {
    v.filter(|x| x.is_finite() && *x > 0.0)
}

/// A file-name stem for a group, unique among `stems`.
fn group_stem(key: (&str, &str, &str), many_comparisons: bool, stems: &mut BTreeSet<String>) -> String {
    let (comparison, scenario, params) = key;
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
        base = format!("{cut}-{:016x}", fnv1a(base.as_bytes()));
    }
    let mut stem = base.clone();
    let mut i = 2;
    while !stems.insert(stem.clone()) {
        stem = format!("{base}-{i}");
        i += 1;
    }
    stem
}

/// A group's title: scenario, parameters, and the comparison when there are several.
fn group_title(key: (&str, &str, &str), many_comparisons: bool) -> String {
    let (comparison, scenario, params) = key;
    let mut title = or_unknown(scenario).to_string();
    if !params.is_empty() {
        title.push_str(&format!(" [{params}]"));
    }
    if many_comparisons {
        title = format!("{comparison}: {title}");
    }
    title
}

/// The headline metric: the name most rows give (ties: alphabetical), and
/// a note when rows disagree.
fn group_metric(rows: &[&ResultRow]) -> (String, Vec<String>) {
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for r in rows {
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
    (metric, metric_notes)
}

/// The rows grouped by comparison, scenario and parameters, in order of
/// first appearance (the comparison file's order).
fn group_rows(rows: &[ResultRow]) -> Vec<Group<'_>> {
    let comparisons: BTreeSet<&str> = rows.iter().map(|r| r.comparison.as_str()).collect();
    let many_comparisons = comparisons.len() > 1;
    let styles = Styles::new(rows);
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
        let mut g_rows = by_key.remove(&k).unwrap_or_default();
        g_rows.sort_by(|a, b| {
            styles
                .index(&a.model)
                .cmp(&styles.index(&b.model))
                .then(coarse_to_fine(a, b))
        });
        let stem = group_stem(k, many_comparisons, &mut stems);
        let (metric, metric_notes) = group_metric(&g_rows);
        let models: Vec<String> = {
            let set: BTreeSet<usize> = g_rows.iter().map(|r| styles.index(&r.model)).collect();
            set.into_iter().map(|i| styles.models[i].clone()).collect()
        };
        out.push(Group {
            title: group_title(k, many_comparisons),
            stem,
            metric,
            rows: g_rows,
            models,
            metric_notes,
        });
    }
    out
}
