//! surgbench results to a tidy CSV, plots (SVG + PNG) and pages (HTML + markdown).
//!
//! The harness hands over plain [`ResultRow`]s (one per scenario x model x
//! fidelity) and a [`RunInfo`]; this crate does not depend on any model crate.
//!
//! ```no_run
//! use std::path::Path;
//! use surgbench_reports::{ResultRow, RunInfo, render, write_results_csv, read_results_csv};
//! # fn main() -> Result<(), surgbench_reports::ReportError> {
//! let dir = Path::new("reports/out/run-1");
//! let rows: Vec<ResultRow> = vec![/* from the harness */];
//! write_results_csv(&dir.join("results.csv"), &rows)?;
//! // Later, or in another process: everything comes back from the CSV.
//! let rows = read_results_csv(&dir.join("results.csv"))?;
//! let files = render(dir, &rows, &RunInfo::default())?;
//! # let _ = files; Ok(()) }
//! ```
//!
//! Units: SI (m, kg, s, N, Pa, rad) throughout, except wall times, which are
//! in milliseconds where the column name says `ms`, and memory in MiB.
//!
//! Honesty rules the renderer keeps: every run appears in the tables, a run
//! that is not `ok` shows its status and reason where its error would be,
//! and each plot lists what it could not draw (non-ok runs, values a log
//! axis cannot show, missing time series).

mod analysis;
mod data;
pub mod diff;
mod doc;
mod error;
mod figure;
mod format;
mod haptic;
mod render;
pub mod staging;
mod summary;

pub use analysis::{NoOrder, OrderFit, fit_convergence, fit_order, pareto_front};
pub use data::{
    AccuracyTarget, DEFAULT_BUDGETS_MS, FIXED_COLUMNS, OPTIONAL_COLUMNS, ResultRow, RunInfo, SERIES_COLUMNS, Series,
    format_f64, read_centreline, read_final_positions, read_markers, read_plane_path, read_results_csv, read_run_info,
    read_series, row_cells, row_from_cells, write_results_csv, write_run_info,
};
pub use error::ReportError;
pub use format::{fmt_sig, fmt_tick, fnv1a, log_ticks, short_settings};
pub use haptic::{HAPTIC_COLUMNS, HapticRow, read_haptic_csv, write_haptic_csv};
pub use render::{render, render_dir};
pub use summary::{
    End, FidelityValue, MARKER_COLUMNS, Marker, NodeState, Outcome, PlanePoint, RunSummary, Sample, Status, Trip,
};
