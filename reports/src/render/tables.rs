//! The report's tables and the page that ties them to the plots.

use std::collections::{BTreeMap, BTreeSet};

use super::{Group, Section, Styles, or_unknown, settings_label, usable};
use crate::RunInfo;
use crate::analysis::{best_ok, finest};
use crate::doc::{Block, Cell};
use crate::format::{fmt_sig, short_settings};
use crate::{End, ResultRow, Status};

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

/// The stable / watchdog cell. `reason_shown`: the row's reason is already
/// in its error cell, so a watchdog message that the reason repeats is not
/// printed a second time.
fn stable_text(r: &ResultRow, reason_shown: bool) -> String {
    let wd = r.watchdog.trim();
    let wd = if reason_shown && !wd.is_empty() && r.reason.contains(wd) {
        ""
    } else {
        wd
    };
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

/// The fastest median ms/step among `ok` runs on `r`'s machine (all runs
/// when the report comes from one machine).
fn best_time_on_machine(ok: &[&ResultRow], r: &ResultRow, st: &Styles) -> f64 {
    ok.iter()
        .filter(|o| st.on_machine(o, &r.host))
        .filter_map(|o| usable(o.ms_per_step_median))
        .fold(f64::INFINITY, f64::min)
}

fn scenario_table(g: &Group, st: &Styles) -> Block {
    let ok: Vec<&ResultRow> = g.rows.iter().copied().filter(|r| r.status == Status::Ok).collect();
    let best_err = ok.iter().filter_map(|r| usable(g.err(r))).fold(f64::INFINITY, f64::min);
    let mut header = vec!["model".into(), "fidelity".into()];
    if st.by_machine() {
        header.push("machine".into());
    }
    header.extend([
        "status".into(),
        if g.metric.is_empty() {
            "primary error".into()
        } else {
            g.metric_label()
        },
        "ms/step median".into(),
        "ms/step p95 / max".into(),
        "real-time factor".into(),
        "solver iters mean / max".into(),
        "peak RSS [MiB]".into(),
        "stable / watchdog".into(),
        "end".into(),
    ]);
    let mut rows = Vec::new();
    for r in &g.rows {
        let best_t = best_time_on_machine(&ok, r, st);
        let is_ok = r.status == Status::Ok;
        let err_cell = if is_ok {
            match g.err(r) {
                Some(e) => Cell {
                    text: fmt_sig(e, 3),
                    bold: e == best_err,
                    ..Cell::default()
                },
                None => Cell::plain("— (not reported)"),
            }
        } else {
            // The status column says what happened; here goes why.
            Cell {
                text: reason_only(r),
                warn: true,
                ..Cell::default()
            }
        };
        let t_cell = Cell {
            text: num(r.ms_per_step_median),
            bold: is_ok && r.ms_per_step_median == Some(best_t),
            ..Cell::default()
        };
        let iters = match (r.solver_iters_mean, r.solver_iters_max) {
            (None, None) => "—".into(),
            (a, b) => format!("{} / {}", num(a), num(b)),
        };
        // The model links to the run's folder (its summary.json, observables.csv, ...).
        let model = if r.run_dir.is_empty() {
            Cell::plain(&r.model)
        } else {
            Cell::plain(&r.model).linked(format!("{}/", r.run_dir))
        };
        let mut row = vec![
            model,
            Cell::plain(if r.fidelity.is_empty() {
                "(default)".into()
            } else {
                short_settings(&r.fidelity)
            }),
        ];
        if st.by_machine() {
            row.push(Cell::plain(or_unknown(&r.host)));
        }
        row.extend([
            Cell {
                text: or_unknown(r.status.as_str()).to_string(),
                warn: !is_ok,
                ..Cell::default()
            },
            err_cell,
            t_cell,
            Cell::plain(match (r.ms_per_step_p95, r.ms_per_step_max) {
                (p95, None) => num(p95),
                (p95, max) => format!("{} / {}", num(p95), num(max)),
            }),
            Cell::plain(num(r.real_time_factor)),
            Cell::plain(iters),
            Cell::plain(num(r.peak_rss_mb)),
            Cell::plain(stable_text(r, !is_ok)),
            Cell::plain(if r.end == End::Unset { "—" } else { r.end.as_str() }),
        ]);
        rows.push(row);
    }
    Block::Table { header, rows }
}

/// How many of `rows` are not ok, by status (`"2 unstable, 1 failed"`).
fn not_ok_counts(rows: &[&ResultRow]) -> String {
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.status != Status::Ok) {
        *counts.entry(or_unknown(r.status.as_str())).or_default() += 1;
    }
    counts
        .iter()
        .map(|(s, n)| format!("{n} {s}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A model's summary, in two forms from one choice of run: the cell of the
/// summary matrix, short enough for six models side by side at 1400 px
/// (the best ok run's error and ms/step, and how many runs were not ok),
/// and its line in the scene's section, which adds the run's settings, or
/// without an ok run the finest run's reason. The best ok run is
/// [`best_ok`]'s: most accurate, then fastest.
fn summary(g: &Group, st: &Styles, mr: &[&ResultRow]) -> (Cell, String) {
    if mr.is_empty() {
        return (Cell::plain("—"), "not run".into());
    }
    let others = not_ok_counts(mr);
    let warn = |text: String| Cell {
        text,
        warn: true,
        ..Cell::default()
    };
    match best_ok(mr, |r| g.err(r)) {
        Some(r) => {
            let e = g.err(r).map_or("no error value".into(), |e| fmt_sig(e, 3));
            let ms = num(r.ms_per_step_median);
            let on = if st.by_machine() {
                format!(" on {}", or_unknown(&r.host))
            } else {
                String::new()
            };
            let (short_also, long_also) = if others.is_empty() {
                (String::new(), String::new())
            } else {
                (format!(" (+{others})"), format!("; also {others}"))
            };
            (
                Cell::plain(format!("{e} at {ms} ms{on}{short_also}")),
                format!("best ok run {e} at {ms} ms/step{on} ({}{long_also})", settings_label(r)),
            )
        }
        // A model that refuses the scene says why, once.
        None if mr.iter().all(|r| r.status == Status::Unsupported) => {
            let r = finest(mr.iter().copied()).expect("non-empty");
            (warn("unsupported".into()), reason_text(r))
        }
        None => {
            let r = finest(mr.iter().copied()).expect("non-empty");
            (
                warn(format!("no ok run ({others})")),
                format!(
                    "no ok run ({others}); finest: {} ({})",
                    reason_text(r),
                    settings_label(r)
                ),
            )
        }
    }
}

/// The anchor of a group's section on the page.
pub(super) fn section_id(g: &Group) -> String {
    format!("scenario-{}", g.stem)
}

fn summary_table(groups: &[Group], st: &Styles) -> Block {
    let mut header = vec!["scenario".to_string(), "primary error".to_string()];
    header.extend(st.models.iter().cloned());
    let mut rows = Vec::new();
    for g in groups {
        let mut row = vec![
            Cell::plain(&g.title).linked(format!("#{}", section_id(g))),
            Cell::plain(or_unknown(&g.metric)),
        ];
        for model in &st.models {
            row.push(summary(g, st, &g.model_rows(model)).0);
        }
        rows.push(row);
    }
    Block::Table { header, rows }
}

/// Per model of the group: its best ok run with settings and, when the
/// report has a target for the scene, its verdict in full.
fn model_lines(g: &Group, st: &Styles, info: &RunInfo) -> Vec<String> {
    g.models
        .iter()
        .map(|m| {
            let mr = g.model_rows(m);
            let best = summary(g, st, &mr).1;
            // An unsupported model's line already says so, with the reason.
            match super::verdicts::verdict_text(g, &mr, info) {
                Some(v) if v != "unsupported" => format!("{m}: {best}; verdict: {v}"),
                _ => format!("{m}: {best}"),
            }
        })
        .collect()
}

/// The page's last section: where, when and how the comparison ran.
pub(super) fn run_section(info: &RunInfo) -> Vec<Block> {
    vec![Block::Anchored(2, "Run".into(), "run".into()), run_table(info)]
}

/// Where, when and how the comparison ran.
fn run_table(info: &RunInfo) -> Block {
    let versions: Vec<String> = info.crate_versions.iter().map(|(k, v)| format!("{k} {v}")).collect();
    let kv = |k: &str, v: String| vec![Cell::plain(k), Cell::plain(v)];
    let mut rows = vec![
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
    ];
    // Per-model notes: `id: text; id: text (what they mean)`.
    let notes = [
        (
            &info.fitted,
            "fitted, not derived",
            "each constant fitted once on the case named, which no comparison scores",
        ),
        (
            &info.python_models,
            "models written in Python",
            "run through the Python bindings: their step times include the interpreter",
        ),
    ];
    for (by_model, key, meaning) in notes {
        if !by_model.is_empty() {
            let listed: Vec<String> = by_model.iter().map(|(id, d)| format!("{id}: {d}")).collect();
            rows.push(kv(key, format!("{} ({meaning})", listed.join("; "))));
        }
    }
    Block::Table {
        header: vec!["run".into(), "".into()],
        rows,
    }
}

/// One scenario's section: counts, table, other metrics, orders, plots, notes.
/// The metrics of a free-vibration run, as the dynamics scenarios name
/// them, with their column headers: the closed forms of a scheme's period
/// and damping are read against these (README, `run dynamics`).
const VIBRATION_METRICS: [(&str, &str); 4] = [
    ("period_error_rel", "period error [1]"),
    ("damping_per_period", "damping per period [1]"),
    ("phase_error_rad", "phase error at the end [rad]"),
    ("amplitude_loss_rel", "amplitude loss [1]"),
];

/// The friction-state LCP's work per needle run (the needle seed's Table 3,
/// Chentanez et al. 2009: trials per step min/mean/max, and the CG
/// iterations of its solver), from the model's diagnostics.
const LCP_METRICS: [(&str, &str); 7] = [
    ("diag_lcp_trials_min", "LCP trials min"),
    ("diag_lcp_trials_mean", "LCP trials mean"),
    ("diag_lcp_trials_max", "LCP trials max"),
    ("diag_lcp_unresolved_steps", "steps unresolved"),
    ("diag_cg_iterations_mean", "CG iterations per step, mean"),
    ("diag_cg_iterations_max", "CG iterations per step, max"),
    ("diag_cg_iterations_per_solve", "CG iterations per solve, mean"),
];

/// The seed's own numbers for [`LCP_METRICS`], to read the table against.
const LCP_SEED_NOTE: &str = "The needle seed (Chentanez et al. 2009, Tables 2-3) reports 1.41 LCP trials per frame on average and 10 at most, 205-413 CG iterations per solve (ours: each step solves once unconstrained and once per trial), and a 130.9 ms frame on 1 thread (38.5 ms on 7) at 13,375 tets; its LCP took 75-83 % of the frame. A dash in the CG columns: the run solved its trials through the Schur complement (lcp_solver=schur), without CG.";

/// Mean wall time per step of each phase of a needle run (the needle
/// seed's Table 2 columns: frame, LCP, tissue, needle, remesh), from the
/// model's diagnostics of its first repeat.
const PHASE_METRICS: [(&str, &str); 5] = [
    ("diag_frame_ms_mean", "frame [ms]"),
    ("diag_lcp_ms_mean", "LCP [ms]"),
    ("diag_tissue_ms_mean", "tissue [ms]"),
    ("diag_needle_ms_mean", "needle [ms]"),
    ("diag_remesh_ms_mean", "remesh [ms]"),
];

/// The seed's own numbers for [`PHASE_METRICS`] and what each phase holds.
const PHASE_SEED_NOTE: &str = "Mean wall time per step over the first repeat's steps, warm-up included (the ms/step column: the median over all repeats). LCP: the coupling's geometry, the Delassus operator (one tissue solve per point and axis) or the seed's CG solves, the trials and the points' update; tissue: assembly, factorization and update of the tissue's linear step; needle: the same for the rod; remesh: the tip remeshing's operations and the tissue's rebuild on the new mesh (coupling=remesh only). The needle seed (Chentanez et al. 2009, Table 2) reports a 130.9 ms frame on 1 thread and 38.5 ms on 7 for its ProsFB scene at 13,375 tets, the LCP 108.8 and 28.3 ms of it, and its tip remeshing 0.5-0.9 ms per frame. Timings compare within one report only.";

/// The tissue mesh a remeshing model leaves after insertion-retraction
/// cycles (`needle-cycles`): its dihedral range after the first twenty
/// steps, the full withdrawals and those that did not give back the mesh
/// as built, and the most compressed tet over the run.
const CYCLE_METRICS: [(&str, &str); 5] = [
    ("dihedral_min_deg", "dihedral min [deg]"),
    ("dihedral_max_deg", "dihedral max [deg]"),
    ("withdrawals", "withdrawals"),
    ("unrestored_withdrawals", "mesh not restored"),
    ("diag_tissue_volume_ratio_min", "V/V0 min"),
];

/// Period, damping and phase of every ok run, when the group's runs report
/// them (free-vibration scenes); `None` for the others.
fn vibration_table(g: &Group) -> Option<Block> {
    metrics_table(g, &VIBRATION_METRICS)
}

/// One row per ok run that reports any of `metrics`: model, fidelity, the
/// median ms/step, and the metrics (blank where a run lacks one); `None`
/// when no run reports them.
fn metrics_table(g: &Group, metrics: &[(&str, &str)]) -> Option<Block> {
    let ok: Vec<&ResultRow> = g
        .rows
        .iter()
        .copied()
        .filter(|r| r.status == Status::Ok && metrics.iter().any(|(m, _)| r.metrics.contains_key(*m)))
        .collect();
    if ok.is_empty() {
        return None;
    }
    let mut header = vec!["model".to_string(), "fidelity".to_string(), "ms/step".to_string()];
    header.extend(metrics.iter().map(|(_, h)| h.to_string()));
    let rows = ok
        .iter()
        .map(|r| {
            let mut row = vec![
                Cell::plain(&r.model),
                Cell::plain(short_settings(&r.fidelity)),
                Cell::plain(num(r.ms_per_step_median)),
            ];
            row.extend(
                metrics
                    .iter()
                    .map(|(m, _)| Cell::plain(num(r.metrics.get(*m).copied()))),
            );
            row
        })
        .collect();
    Some(Block::Table { header, rows })
}

/// An outcome scene's table ([`Group::is_outcome`]): per model, how many of
/// its ok runs reached the goal and how long they took (median and range
/// over those that did), with the median ms/step.
fn outcome_table(g: &Group) -> Option<Block> {
    if !g.is_outcome() {
        return None;
    }
    let header = [
        "model",
        "ok runs reaching the goal",
        "time to the goal [s]: median (min – max)",
        "ms/step median (median over runs)",
    ]
    .map(String::from)
    .to_vec();
    let median = |mut v: Vec<f64>| -> Option<f64> {
        v.retain(|x| x.is_finite());
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        Some(if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        })
    };
    let mut rows = Vec::new();
    for m in &g.models {
        let ok: Vec<&ResultRow> = g.model_rows(m).into_iter().filter(|r| r.status == Status::Ok).collect();
        if ok.is_empty() {
            continue;
        }
        let reached: Vec<&ResultRow> = ok
            .iter()
            .copied()
            .filter(|r| r.metrics.get(super::OUTCOME_METRIC) == Some(&1.0))
            .collect();
        let times: Vec<f64> = reached
            .iter()
            .filter_map(|r| r.metrics.get(super::OUTCOME_TIME).copied())
            .collect();
        let time = match median(times.clone()) {
            Some(t) => {
                let lo = times.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = times.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                format!("{} ({} – {})", fmt_sig(t, 3), fmt_sig(lo, 3), fmt_sig(hi, 3))
            }
            None => "—".into(),
        };
        rows.push(vec![
            Cell::plain(m),
            Cell {
                text: format!(
                    "{} of {} ({:.0} %)",
                    reached.len(),
                    ok.len(),
                    100.0 * reached.len() as f64 / ok.len() as f64
                ),
                bold: reached.len() == ok.len(),
                warn: reached.len() < ok.len(),
                ..Cell::default()
            },
            Cell::plain(time),
            Cell::plain(num(median(ok.iter().filter_map(|r| r.ms_per_step_median).collect()))),
        ]);
    }
    Some(Block::Table { header, rows })
}

fn scenario_section(g: &Group, sec: &Section, st: &Styles, info: &RunInfo) -> Vec<Block> {
    let mut b = Vec::new();
    b.push(Block::Anchored(2, format!("Scenario: {}", g.title), section_id(g)));
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
    b.push(Block::List(model_lines(g, st, info)));
    if let Some(t) = outcome_table(g) {
        b.push(Block::Heading(3, "Outcome per model (ok runs)".into()));
        b.push(t);
    }
    b.push(scenario_table(g, st));
    if let Some(t) = vibration_table(g) {
        b.push(Block::Heading(3, "Period and damping (ok runs)".into()));
        b.push(t);
    }
    if g.rows.iter().any(|r| r.metrics.contains_key("withdrawals"))
        && let Some(t) = metrics_table(g, &CYCLE_METRICS)
    {
        b.push(Block::Heading(
            3,
            "Tissue mesh over the cycles (the needle seed: 10.3-160 deg)".into(),
        ));
        b.push(t);
    }
    if let Some(t) = metrics_table(g, &LCP_METRICS) {
        b.push(Block::Heading(
            3,
            "Friction-state LCP per run (the needle seed's Table 3)".into(),
        ));
        b.push(Block::Para(LCP_SEED_NOTE.into()));
        b.push(t);
    }
    if let Some(t) = metrics_table(g, &PHASE_METRICS) {
        b.push(Block::Heading(
            3,
            "Frame time by phase (the needle seed's Table 2)".into(),
        ));
        b.push(Block::Para(PHASE_SEED_NOTE.into()));
        b.push(t);
    }
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
    b
}

/// The whole page: header, summary table, one section per scenario.
pub(super) fn page(
    info: &RunInfo,
    rows: &[ResultRow],
    groups: &[Group],
    sections: &[Section],
    st: &Styles,
) -> Vec<Block> {
    let mut b = vec![Block::Heading(
        1,
        format!("surgbench report: {}", or_unknown(&info.comparison)),
    )];
    if info.quick {
        b.push(Block::Warning(
            "quick run: reduced sweeps and durations. Use it to check the pipeline, not to publish numbers.".into(),
        ));
    }
    if st.by_machine() {
        b.push(Block::Warning(format!(
            "Timings come from {} machines ({}): speed figures are grouped by machine. Each scenario table names \
             the machine of every run and marks the fastest run of each machine; the speed/error plots draw each \
             machine apart. Compare timings only within one machine; errors do not depend on the machine.",
            st.hosts.len(),
            st.hosts.join(", ")
        )));
    }
    b.push(Block::Para(format!(
        "{} comparison, {}, commit {}, on {} ({} cores, {} threads), {} s wall time. {}. \
         Units are SI (m, kg, s, N, Pa, rad) unless a column says otherwise; times per step are in ms. \
         How it ran, in full: the Run section at the end.",
        or_unknown(&info.comparison),
        or_unknown(&info.date),
        or_unknown(&info.commit),
        or_unknown(&info.machine),
        info.cores,
        info.threads,
        fmt_sig(info.wall_s, 3),
        status_counts(rows.iter())
    )));
    b.push(Block::Toc(Vec::new()));
    b.extend(super::verdicts::verdict_blocks(groups, st, info));
    b.push(Block::Anchored(
        2,
        "Summary: each model's best ok run".into(),
        "summary".into(),
    ));
    b.push(Block::Para(
        "Each cell: the primary error and ms/step of the model's most accurate ok run in the scenario (the fastest of equally accurate ones) \
         and, after +, how many of the model's runs were not ok; — where the model did not run the scene. Each scenario's section names \
         the settings of that run, the verdict in full and the reason of every run that is not ok."
            .into(),
    ));
    b.push(summary_table(groups, st));

    b.push(Block::Para(
        "In each scenario's table, the lowest error and the fastest ms/step among ok runs are bold; runs that are not ok show their \
         reason in place of the error; peak RSS is the run's whole process (scene, reference and model, VmHWM); each model links to its run's folder (runs/...: summary.json, observables.csv, \
         final_state.csv). Tables round to 3 significant digits and settings to 4; results.csv holds every value at full \
         precision, and the command surgbench report DIR re-renders this page from results.csv (and summary.json)."
            .into(),
    ));
    for (g, sec) in groups.iter().zip(sections) {
        b.extend(scenario_section(g, sec, st, info));
    }
    b
}
