//! The tidy results table (`results.csv`), the run header (`summary.json`) and
//! per-run time series (`observables.csv`): types, writers and readers.
//!
//! All numbers are SI (m, kg, s, N, Pa, rad) except the columns whose names say
//! otherwise (`ms_per_step_*` in milliseconds, `peak_rss_mb` in MiB,
//! `build_ms` in milliseconds).
//!
//! Numbers are written in the shortest form that reads back to the same `f64`
//! (Rust's `Display`/`LowerExp` are round-trip exact), so `read(write(rows))`
//! gives bit-identical values and a report re-rendered from `results.csv`
//! alone equals the original.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::ops::{Deref, DerefMut};
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::ReportError;
use crate::summary::{End, FidelityValue, Outcome, RunSummary, Status};

/// One row per scenario x model x fidelity: what the harness measured for one run.
///
/// `None` means "not measured / not applicable" and is written as an empty cell.
/// Times are in the units their names say (`ms`, `s`), everything else SI.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct ResultRow {
    /// Comparison name, e.g. `"standard"`.
    pub comparison: String,
    /// Scenario id, e.g. `"cantilever-gravity"`.
    pub scenario: String,
    /// Model id, e.g. `"der"`.
    pub model: String,
    /// `"rod"` | `"tissue"` | `"coupled"`.
    pub family: String,
    /// Fidelity as given by the harness, e.g. `"segments=20;dt=0.001"` (stable order).
    pub fidelity: String,
    /// Scenario parameter overrides, e.g. `"length=0.3;youngs_modulus=5e10"` (`""` = defaults).
    pub params: String,
    /// Number of rod segments, if the fidelity sets it.
    pub segments: Option<f64>,
    /// Mesh refinement level (cells per side = 2^level), if the fidelity sets it.
    pub mesh_level: Option<f64>,
    /// Time step (s).
    pub dt: Option<f64>,
    /// Solver iterations per step, if the fidelity sets it.
    pub iterations: Option<f64>,
    /// What the run measured (columns `status` through `watchdog_t`); its
    /// fields also read directly on the row (`row.status`).
    #[serde(flatten)]
    pub outcome: Outcome,
    /// Name of the scenario's headline error metric, a key of `metrics`.
    pub primary_error: String,
    /// This run's folder relative to the report folder (`""` if none); holds `observables.csv`.
    pub run_dir: String,
    /// Host name of the machine the run's timings come from (`""` = not
    /// recorded: a report from one machine). Written as the optional
    /// `host` column ([`OPTIONAL_COLUMNS`]) when any row has one.
    #[serde(default)]
    pub host: String,
    /// Error metrics by name, e.g. `"tip_error_rel"`, `"rms_node_error_m"` (units in the name).
    pub metrics: BTreeMap<String, f64>,
}

impl Deref for ResultRow {
    type Target = Outcome;

    fn deref(&self) -> &Outcome {
        &self.outcome
    }
}

impl DerefMut for ResultRow {
    fn deref_mut(&mut self) -> &mut Outcome {
        &mut self.outcome
    }
}

impl ResultRow {
    /// This row with what a run's `summary.json` says: its outcome, metrics,
    /// resolved fidelity (`fidelity` and the knob columns) and `run_dir`.
    pub fn with_summary(mut self, s: RunSummary, run_dir: String) -> Self {
        let knob = |k: &str| s.fidelity.get(k).and_then(FidelityValue::number);
        (self.segments, self.mesh_level, self.dt, self.iterations) =
            (knob("segments"), knob("mesh_level"), knob("dt"), knob("iterations"));
        if !s.fidelity_string.is_empty() {
            self.fidelity = s.fidelity_string;
        }
        self.outcome = s.outcome;
        self.metrics = s.errors;
        self.run_dir = run_dir;
        self
    }
}

/// The page header: where, when and how a comparison ran (`summary.json`).
#[derive(Serialize, Deserialize, Default, Debug, Clone, PartialEq)]
#[serde(default)]
pub struct RunInfo {
    /// Comparison name.
    pub comparison: String,
    /// Date and time of the run (as the harness formats it).
    pub date: String,
    /// Git commit of the code that ran.
    pub commit: String,
    /// Machine description (CPU model, OS).
    pub machine: String,
    /// Cores on the machine.
    pub cores: usize,
    /// Threads the harness used.
    pub threads: usize,
    /// `rustc --version`.
    pub rustc: String,
    /// Versions of the crates involved, by name.
    pub crate_versions: BTreeMap<String, String>,
    /// The command line that produced the run.
    pub command: String,
    /// Whether this was a reduced ("quick") sweep.
    pub quick: bool,
    /// Wall time of the whole comparison (s).
    pub wall_s: f64,
    /// Models written in Python (registered through the bindings) by id,
    /// with their description: the page marks them, since their timings
    /// include the interpreter.
    pub python_models: BTreeMap<String, String>,
    /// Models whose settings rest on a fitted constant, by id, with what was
    /// fitted on which case ([`surgbench_core`]'s `ModelFactory::fitted`):
    /// the page says so. Empty in reports written before it existed.
    pub fitted: BTreeMap<String, String>,
    /// Accuracy target of each scenario by id: the largest primary error a
    /// user of that scene would accept (the report's verdict table). Empty
    /// in reports written before targets existed: no verdicts then.
    pub targets: BTreeMap<String, AccuracyTarget>,
    /// Time budgets per step (ms) the verdicts are stated against, smallest
    /// first ([`DEFAULT_BUDGETS_MS`] unless the run names others).
    pub budgets_ms: Vec<f64>,
}

impl RunInfo {
    /// The time budgets per step (ms) the verdicts and plots use: the run's
    /// own, or [`DEFAULT_BUDGETS_MS`] for a report that names none.
    pub fn budgets(&self) -> Vec<f64> {
        if self.budgets_ms.is_empty() {
            DEFAULT_BUDGETS_MS.to_vec()
        } else {
            self.budgets_ms.clone()
        }
    }
}

/// Time budgets per step (ms): a 1 kHz haptic loop, 60 Hz and 30 Hz visual
/// frames (issue 22).
pub const DEFAULT_BUDGETS_MS: [f64; 3] = [1.0, 16.0, 33.0];

/// The largest primary error a scenario's user would accept, and why.
#[derive(Serialize, Deserialize, Default, Debug, Clone, PartialEq)]
pub struct AccuracyTarget {
    /// The metric it bounds (the scenario's primary error).
    pub metric: String,
    /// A run meets the target when `|error| <= value` (the metric's unit).
    pub value: f64,
    /// Where the number comes from, one line.
    pub why: String,
}

/// The fixed columns of `results.csv`, in file order; metric columns follow, sorted.
pub const FIXED_COLUMNS: [&str; 29] = [
    "comparison",
    "scenario",
    "model",
    "family",
    "fidelity",
    "params",
    "segments",
    "mesh_level",
    "dt",
    "iterations",
    "status",
    "reason",
    "end",
    "steps",
    "sim_time_s",
    "ms_per_step_median",
    "ms_per_step_p95",
    "steps_per_s",
    "real_time_factor",
    "solver_iters_mean",
    "solver_iters_max",
    "peak_rss_mb",
    "build_ms",
    "solve_wall_s",
    "stable",
    "watchdog",
    "watchdog_t",
    "primary_error",
    "run_dir",
];

/// Columns of `results.csv` written only when some row fills them and read
/// when present: `host`, the machine each run's timings come from (a
/// report merged from several machines' shards), and `ms_per_step_max`,
/// the slowest step (absent from reports written before it existed).
pub const OPTIONAL_COLUMNS: [&str; 2] = ["host", "ms_per_step_max"];

/// Whether `name` is a fixed or optional column (never a metric).
fn is_column(name: &str) -> bool {
    FIXED_COLUMNS.contains(&name) || OPTIONAL_COLUMNS.contains(&name)
}

/// The text of optional column `i` (index into [`OPTIONAL_COLUMNS`]) of
/// `row`; empty when the row does not fill it.
fn optional_text(row: &ResultRow, i: usize) -> String {
    match i {
        0 => row.host.clone(),
        1 => row.outcome.ms_per_step_max.map(format_f64).unwrap_or_default(),
        _ => unreachable!("OPTIONAL_COLUMNS has 2 entries"),
    }
}

/// Sets optional column `i` of `row` from its `results.csv` text.
fn set_optional(row: &mut ResultRow, i: usize, text: &str) -> Result<(), String> {
    match i {
        0 => {
            row.host = text.to_string();
            Ok(())
        }
        1 => parse_f64(text).map(|x| row.outcome.ms_per_step_max = x),
        _ => unreachable!("OPTIONAL_COLUMNS has 2 entries"),
    }
}

/// A field of [`ResultRow`] seen as a CSV cell.
enum Cell<'a> {
    Text(&'a mut String),
    Num(&'a mut Option<f64>),
    Bool(&'a mut Option<bool>),
    Status(&'a mut Status),
    End(&'a mut End),
}

/// The cell of fixed column `i` (index into [`FIXED_COLUMNS`]).
fn cell(row: &mut ResultRow, i: usize) -> Cell<'_> {
    use Cell::*;
    match i {
        0 => Text(&mut row.comparison),
        1 => Text(&mut row.scenario),
        2 => Text(&mut row.model),
        3 => Text(&mut row.family),
        4 => Text(&mut row.fidelity),
        5 => Text(&mut row.params),
        6 => Num(&mut row.segments),
        7 => Num(&mut row.mesh_level),
        8 => Num(&mut row.dt),
        9 => Num(&mut row.iterations),
        10 => Cell::Status(&mut row.outcome.status),
        11 => Text(&mut row.outcome.reason),
        12 => Cell::End(&mut row.outcome.end),
        13 => Num(&mut row.outcome.steps),
        14 => Num(&mut row.outcome.sim_time_s),
        15 => Num(&mut row.outcome.ms_per_step_median),
        16 => Num(&mut row.outcome.ms_per_step_p95),
        17 => Num(&mut row.outcome.steps_per_s),
        18 => Num(&mut row.outcome.real_time_factor),
        19 => Num(&mut row.outcome.solver_iters_mean),
        20 => Num(&mut row.outcome.solver_iters_max),
        21 => Num(&mut row.outcome.peak_rss_mb),
        22 => Num(&mut row.outcome.build_ms),
        23 => Num(&mut row.outcome.solve_wall_s),
        24 => Bool(&mut row.outcome.stable),
        25 => Text(&mut row.outcome.watchdog),
        26 => Num(&mut row.outcome.watchdog_t),
        27 => Text(&mut row.primary_error),
        28 => Text(&mut row.run_dir),
        _ => unreachable!("FIXED_COLUMNS has 29 entries"),
    }
}

/// Formats `v` in the shortest text that parses back to the same `f64`.
///
/// Plain decimals in `[1e-4, 1e15)`, exponent form (`1.5e-7`) outside it.
pub fn format_f64(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-4..1e15).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

fn parse_f64(s: &str) -> Result<Option<f64>, String> {
    let t = s.trim();
    if t.is_empty() {
        return Ok(None);
    }
    t.parse::<f64>()
        .map(Some)
        .map_err(|_| format!("expected a number or an empty cell, found {s:?}"))
}

fn parse_bool(s: &str) -> Result<Option<bool>, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "" => Ok(None),
        "true" => Ok(Some(true)),
        "false" => Ok(Some(false)),
        _ => Err(format!("expected `true`, `false` or an empty cell, found {s:?}")),
    }
}

/// Writes `rows` to `path` as the tidy `results.csv`.
///
/// Header: the [`FIXED_COLUMNS`] in order, then each of the
/// [`OPTIONAL_COLUMNS`] some row fills, then one column per metric name (union over
/// all rows, sorted). `None` and absent metrics are empty cells.
/// A metric named like a fixed column, or with an empty name, is refused
/// ([`ReportError::Invalid`]) because it could not be read back unambiguously.
pub fn write_results_csv(path: &Path, rows: &[ResultRow]) -> Result<(), ReportError> {
    let metric_names: BTreeSet<&str> = rows.iter().flat_map(|r| r.metrics.keys().map(String::as_str)).collect();
    for m in &metric_names {
        if m.trim().is_empty() || is_column(m) {
            return Err(ReportError::Invalid {
                path: path.to_path_buf(),
                message: format!("metric name {m:?} is empty or clashes with a fixed column"),
            });
        }
    }
    let mut w = csv::Writer::from_path(path).map_err(|e| ReportError::csv(path, e))?;
    // The optional columns some row fills.
    let optional: Vec<usize> = (0..OPTIONAL_COLUMNS.len())
        .filter(|&i| rows.iter().any(|r| !optional_text(r, i).is_empty()))
        .collect();
    let header: Vec<&str> = FIXED_COLUMNS
        .iter()
        .copied()
        .chain(optional.iter().map(|&i| OPTIONAL_COLUMNS[i]))
        .chain(metric_names.iter().copied())
        .collect();
    w.write_record(&header).map_err(|e| ReportError::csv(path, e))?;
    for row in rows {
        let mut row = row.clone();
        let mut rec: Vec<String> = (0..FIXED_COLUMNS.len()).map(|i| fixed_text(&mut row, i)).collect();
        rec.extend(optional.iter().map(|&i| optional_text(&row, i)));
        for m in &metric_names {
            rec.push(row.metrics.get(*m).copied().map(format_f64).unwrap_or_default());
        }
        w.write_record(&rec).map_err(|e| ReportError::csv(path, e))?;
    }
    w.flush().map_err(|e| ReportError::io(path, e))
}

/// The text of fixed column `i` (index into [`FIXED_COLUMNS`]) as
/// `results.csv` writes it.
fn fixed_text(row: &mut ResultRow, i: usize) -> String {
    match cell(row, i) {
        Cell::Text(s) => s.clone(),
        Cell::Num(v) => v.map(format_f64).unwrap_or_default(),
        Cell::Bool(b) => b.map(|b| b.to_string()).unwrap_or_default(),
        Cell::Status(v) => v.to_string(),
        Cell::End(v) => v.to_string(),
    }
}

/// Sets fixed column `i` of `row` from its `results.csv` text.
fn set_fixed(row: &mut ResultRow, i: usize, text: &str) -> Result<(), String> {
    match cell(row, i) {
        Cell::Text(s) => {
            *s = text.to_string();
            Ok(())
        }
        Cell::Num(v) => parse_f64(text).map(|x| *v = x),
        Cell::Bool(b) => parse_bool(text).map(|x| *b = x),
        Cell::Status(v) => text.trim().parse().map(|x| *v = x),
        Cell::End(v) => text.trim().parse().map(|x| *v = x),
    }
}

/// One row as the cells `results.csv` would hold, by column name: every
/// fixed column, each optional column the row fills, and each metric. Numbers are in the
/// round-trip form of [`format_f64`], so [`row_from_cells`] gives back the
/// same row bit for bit (a sharded run's point files store rows this way).
pub fn row_cells(row: &ResultRow) -> BTreeMap<String, String> {
    let mut row = row.clone();
    let mut out: BTreeMap<String, String> = (0..FIXED_COLUMNS.len())
        .map(|i| (FIXED_COLUMNS[i].to_string(), fixed_text(&mut row, i)))
        .collect();
    for (i, name) in OPTIONAL_COLUMNS.iter().enumerate() {
        let text = optional_text(&row, i);
        if !text.is_empty() {
            out.insert((*name).into(), text);
        }
    }
    for (k, v) in &row.metrics {
        out.insert(k.clone(), format_f64(*v));
    }
    out
}

/// The row [`row_cells`] describes. Every fixed column must be present; any
/// cell that is not a fixed or optional column is a metric (empty: absent).
/// Errors name the column and the value.
pub fn row_from_cells(cells: &BTreeMap<String, String>) -> Result<ResultRow, String> {
    let mut row = ResultRow::default();
    for (i, name) in FIXED_COLUMNS.iter().enumerate() {
        let text = cells.get(*name).ok_or_else(|| format!("missing column `{name}`"))?;
        set_fixed(&mut row, i, text).map_err(|m| format!("column `{name}`: {m}"))?;
    }
    for (i, name) in OPTIONAL_COLUMNS.iter().enumerate() {
        if let Some(text) = cells.get(*name) {
            set_optional(&mut row, i, text).map_err(|m| format!("column `{name}`: {m}"))?;
        }
    }
    for (name, text) in cells.iter().filter(|(k, _)| !is_column(k)) {
        if let Some(v) = parse_f64(text).map_err(|m| format!("column `{name}`: {m}"))? {
            row.metrics.insert(name.clone(), v);
        }
    }
    Ok(row)
}

/// A flexible CSV reader on `path` and its header names, trimmed.
fn open_csv(path: &Path) -> Result<(csv::Reader<std::fs::File>, Vec<String>), ReportError> {
    let mut rd = csv::ReaderBuilder::new()
        .flexible(true)
        .from_path(path)
        .map_err(|e| ReportError::csv(path, e))?;
    let header: Vec<String> = rd
        .headers()
        .map_err(|e| ReportError::csv(path, e))?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    Ok((rd, header))
}

/// Reads a `results.csv` written by [`write_results_csv`] (or by hand).
///
/// Columns are found by name, so their order does not matter; every fixed
/// column must be present, and any other column is a metric (an empty cell
/// means the metric is absent for that row). A malformed file (missing fixed
/// column, duplicate column, non-numeric value in a numeric column, ragged
/// row) gives a [`ReportError::Parse`] naming file, line and column.
pub fn read_results_csv(path: &Path) -> Result<Vec<ResultRow>, ReportError> {
    let (mut rd, header) = open_csv(path)?;
    let mut seen = BTreeSet::new();
    for h in &header {
        if !seen.insert(h.as_str()) {
            return Err(ReportError::parse(path, 1, h, "duplicate column"));
        }
    }
    // fixed[i] = position of FIXED_COLUMNS[i] in the header.
    let mut fixed = [0usize; FIXED_COLUMNS.len()];
    for (i, name) in FIXED_COLUMNS.iter().enumerate() {
        fixed[i] = header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| ReportError::parse(path, 1, name, "missing required column"))?;
    }
    // (index into OPTIONAL_COLUMNS, position in the header) of those present.
    let optional: Vec<(usize, usize)> = OPTIONAL_COLUMNS
        .iter()
        .enumerate()
        .filter_map(|(i, name)| Some((i, header.iter().position(|h| h == name)?)))
        .collect();
    let metric_cols: Vec<(usize, &str)> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| !is_column(h))
        .map(|(j, h)| (j, h.as_str()))
        .collect();

    let mut rows = Vec::new();
    for rec in rd.records() {
        let rec = rec.map_err(|e| ReportError::csv(path, e))?;
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        if rec.len() != header.len() {
            let col = header
                .get(rec.len().min(header.len().saturating_sub(1)))
                .map(String::as_str)
                .unwrap_or("(row)");
            return Err(ReportError::parse(
                path,
                line,
                col,
                format!("ragged row: {} fields, the header has {}", rec.len(), header.len()),
            ));
        }
        let mut row = ResultRow::default();
        for (i, &j) in fixed.iter().enumerate() {
            set_fixed(&mut row, i, &rec[j]).map_err(|m| ReportError::parse(path, line, FIXED_COLUMNS[i], m))?;
        }
        for &(i, j) in &optional {
            set_optional(&mut row, i, &rec[j]).map_err(|m| ReportError::parse(path, line, OPTIONAL_COLUMNS[i], m))?;
        }
        for &(j, name) in &metric_cols {
            if let Some(v) = parse_f64(&rec[j]).map_err(|m| ReportError::parse(path, line, name, m))? {
                row.metrics.insert(name.to_string(), v);
            }
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Writes `info` as pretty JSON (`summary.json`).
pub fn write_run_info(path: &Path, info: &RunInfo) -> Result<(), ReportError> {
    let text = serde_json::to_string_pretty(info).map_err(|e| ReportError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    fs::write(path, text + "\n").map_err(|e| ReportError::io(path, e))
}

/// Reads `summary.json` as a [`RunInfo`]; fields it lacks take their defaults
/// and fields it has beyond [`RunInfo`]'s are ignored (the harness's summary
/// may carry more).
pub fn read_run_info(path: &Path) -> Result<RunInfo, ReportError> {
    let text = fs::read_to_string(path).map_err(|e| ReportError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| ReportError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// The columns of a per-run `observables.csv`, in file order.
pub const SERIES_COLUMNS: [&str; 18] = [
    "t",
    "tip_x",
    "tip_y",
    "tip_z",
    "hand_fx",
    "hand_fy",
    "hand_fz",
    "hand_tx",
    "hand_ty",
    "hand_tz",
    "energy",
    "error",
    "ref_tip_x",
    "ref_tip_y",
    "ref_tip_z",
    "force",
    "ref_force",
    "depth",
];

/// One run's time series (`<run_dir>/observables.csv`), SI units.
///
/// All vectors have the length of `t`. An empty cell, or a column the file
/// lacks (only `t` is required), reads as `NaN`: "not recorded", which plots skip.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Simulated time (s).
    pub t: Vec<f64>,
    /// Tip position (m): the first rod's, or the point a scene without a
    /// rod follows (a tissue's probe node).
    pub tip_x: Vec<f64>,
    /// Tip position (m).
    pub tip_y: Vec<f64>,
    /// Tip position (m).
    pub tip_z: Vec<f64>,
    /// Reaction force at the operator's hand (N).
    pub hand_fx: Vec<f64>,
    /// Reaction force at the operator's hand (N).
    pub hand_fy: Vec<f64>,
    /// Reaction force at the operator's hand (N).
    pub hand_fz: Vec<f64>,
    /// Reaction torque at the operator's hand (N m).
    pub hand_tx: Vec<f64>,
    /// Reaction torque at the operator's hand (N m).
    pub hand_ty: Vec<f64>,
    /// Reaction torque at the operator's hand (N m).
    pub hand_tz: Vec<f64>,
    /// Total energy (J).
    pub energy: Vec<f64>,
    /// The scenario's primary error at that time (unit of the metric).
    pub error: Vec<f64>,
    /// The reference's tip position (m), where the scenario's reference is
    /// a trajectory (empty cells, NaN, elsewhere).
    pub ref_tip_x: Vec<f64>,
    /// The reference's tip position (m).
    pub ref_tip_y: Vec<f64>,
    /// The reference's tip position (m).
    pub ref_tip_z: Vec<f64>,
    /// The force the scene scores (N, as the scene defines it: the push on
    /// a needle, the load on a whole indenter), where the scene is scored
    /// along a force history (NaN elsewhere).
    pub force: Vec<f64>,
    /// The reference's value of that force at this step (N).
    pub ref_force: Vec<f64>,
    /// The indentation depth the force is plotted against (m), where the
    /// scene is scored along a load curve (NaN elsewhere).
    pub depth: Vec<f64>,
}

impl Series {
    fn column_mut(&mut self, i: usize) -> &mut Vec<f64> {
        match i {
            0 => &mut self.t,
            1 => &mut self.tip_x,
            2 => &mut self.tip_y,
            3 => &mut self.tip_z,
            4 => &mut self.hand_fx,
            5 => &mut self.hand_fy,
            6 => &mut self.hand_fz,
            7 => &mut self.hand_tx,
            8 => &mut self.hand_ty,
            9 => &mut self.hand_tz,
            10 => &mut self.energy,
            11 => &mut self.error,
            12 => &mut self.ref_tip_x,
            13 => &mut self.ref_tip_y,
            14 => &mut self.ref_tip_z,
            15 => &mut self.force,
            16 => &mut self.ref_force,
            _ => &mut self.depth,
        }
    }
}

/// Reads a per-run `observables.csv` into a [`Series`].
///
/// Columns are found by name; `t` is required and must be numeric in every
/// row, other known columns may be absent or empty (read as `NaN`), unknown
/// columns are ignored. Errors name file, line and column.
pub fn read_series(path: &Path) -> Result<Series, ReportError> {
    let (mut rd, header) = open_csv(path)?;
    let pos: Vec<Option<usize>> = SERIES_COLUMNS
        .iter()
        .map(|c| header.iter().position(|h| h == c))
        .collect();
    if pos[0].is_none() {
        return Err(ReportError::parse(path, 1, "t", "missing required column"));
    }
    let mut s = Series::default();
    for rec in rd.records() {
        let rec = rec.map_err(|e| ReportError::csv(path, e))?;
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        if rec.len() != header.len() {
            return Err(ReportError::parse(
                path,
                line,
                "(row)",
                format!("ragged row: {} fields, the header has {}", rec.len(), header.len()),
            ));
        }
        for (i, p) in pos.iter().enumerate() {
            let v = match p {
                Some(j) => parse_f64(&rec[*j]).map_err(|m| ReportError::parse(path, line, SERIES_COLUMNS[i], m))?,
                None => None,
            };
            if i == 0 && v.is_none() {
                return Err(ReportError::parse(path, line, "t", "empty time"));
            }
            s.column_mut(i).push(v.unwrap_or(f64::NAN));
        }
    }
    Ok(s)
}

/// Reads the numeric columns `names` of every row of a small CSV file (a
/// run's `final_state.csv` or `reference_centreline.csv`), found by name;
/// every named column must be present and numeric in every row.
fn read_columns<const N: usize>(path: &Path, names: [&str; N]) -> Result<Vec<[f64; N]>, ReportError> {
    let (mut rd, header) = open_csv(path)?;
    let mut pos = [0usize; N];
    for (k, name) in names.iter().enumerate() {
        pos[k] = header
            .iter()
            .position(|h| h == *name)
            .ok_or_else(|| ReportError::parse(path, 1, name, "missing required column"))?;
    }
    let mut out = Vec::new();
    for rec in rd.records() {
        let rec = rec.map_err(|e| ReportError::csv(path, e))?;
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        let mut row = [0.0; N];
        for (k, name) in names.iter().enumerate() {
            let cell = rec.get(pos[k]).unwrap_or("");
            row[k] = parse_f64(cell)
                .map_err(|m| ReportError::parse(path, line, name, m))?
                .ok_or_else(|| ReportError::parse(path, line, name, "empty value"))?;
        }
        out.push(row);
    }
    Ok(out)
}

/// The final positions (m) of body `body`'s nodes in a run's
/// `final_state.csv`, in node order.
pub fn read_final_positions(path: &Path, body: usize) -> Result<Vec<[f64; 3]>, ReportError> {
    let rows = read_columns(path, ["body", "node", "x", "y", "z"])?;
    let mut nodes: Vec<(f64, [f64; 3])> = rows
        .into_iter()
        .filter(|r| r[0] == body as f64)
        .map(|r| (r[1], [r[2], r[3], r[4]]))
        .collect();
    nodes.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(nodes.into_iter().map(|(_, x)| x).collect())
}

/// A run's `markers.csv` ([`crate::MARKER_COLUMNS`], m): the scenario's
/// measured points at rest, in the model and in the reference.
pub fn read_markers(path: &Path) -> Result<Vec<crate::Marker>, ReportError> {
    Ok(read_columns(path, crate::MARKER_COLUMNS)?
        .into_iter()
        .map(|r| crate::Marker {
            rest: [r[0], r[1], r[2]],
            model: [r[3], r[4], r[5]],
            reference: [r[6], r[7], r[8]],
        })
        .collect())
}

/// A run's `tip_path.csv` (`x,s,arc_s`, m): the tip path in its bend plane
/// and the best-fit arc's offset (an empty `arc_s` outside the arc's
/// window is NaN).
pub fn read_plane_path(path: &Path) -> Result<Vec<crate::PlanePoint>, ReportError> {
    let (mut rd, header) = open_csv(path)?;
    let col = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| ReportError::parse(path, 1, name, "missing required column"))
    };
    let pos = [col("x")?, col("s")?, col("arc_s")?];
    let mut out = Vec::new();
    for rec in rd.records() {
        let rec = rec.map_err(|e| ReportError::csv(path, e))?;
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        let mut v = [f64::NAN; 3];
        for (k, name) in ["x", "s", "arc_s"].iter().enumerate() {
            let cell = parse_f64(rec.get(pos[k]).unwrap_or("")).map_err(|m| ReportError::parse(path, line, name, m))?;
            match (cell, k) {
                (Some(x), _) => v[k] = x,
                (None, 2) => {}
                (None, _) => return Err(ReportError::parse(path, line, name, "empty value")),
            }
        }
        out.push(crate::PlanePoint {
            x: v[0],
            s: v[1],
            fit: v[2],
        });
    }
    Ok(out)
}

/// A run's `reference_centreline.csv` (`x,y,z` in m, base to tip): the
/// reference shape of the rod at the end of the run.
pub fn read_centreline(path: &Path) -> Result<Vec<[f64; 3]>, ReportError> {
    read_columns(path, ["x", "y", "z"])
}
