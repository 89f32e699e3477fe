//! The report's first table (issue 22): for each scene and model, the
//! cheapest tested settings that meet the scene's accuracy target and their
//! time per step against the budgets, or what the best run reached.

use super::pareto::Cost;
use super::{Group, Styles, or_unknown, settings_label};
use crate::analysis::best_ok;
use crate::doc::{Block, Cell};
use crate::format::fmt_sig;
use crate::{AccuracyTarget, ResultRow, RunInfo, Status};

/// Where `ms` falls among the budgets: `"within 1 ms"` for the smallest
/// budget it meets, `"over 33 ms"` past the largest, `"time not measured"`.
pub(crate) fn budget_class(ms: Option<f64>, budgets: &[f64]) -> String {
    let Some(ms) = ms.filter(|m| m.is_finite()) else {
        return "time not measured".into();
    };
    match budgets.iter().find(|b| ms <= **b) {
        Some(b) => format!("within {} ms", fmt_sig(*b, 3)),
        None => format!("over {} ms", budgets.last().map_or("—".into(), |b| fmt_sig(*b, 3))),
    }
}

/// The ok runs of `rows` that meet `target`, cheapest by `cost` first
/// (median ms/step, or time to solution in a static scene); ties keep input
/// order.
pub(crate) fn meeting<'a>(rows: &[&'a ResultRow], target: &AccuracyTarget, cost: &Cost) -> Vec<&'a ResultRow> {
    let mut ok: Vec<&ResultRow> = rows
        .iter()
        .copied()
        .filter(|r| r.status == Status::Ok)
        .filter(|r| {
            r.metrics
                .get(&target.metric)
                .is_some_and(|e| e.is_finite() && e.abs() <= target.value)
        })
        .collect();
    ok.sort_by(|a, b| {
        let t = |r: &ResultRow| (cost.of)(r).unwrap_or(f64::INFINITY);
        t(a).total_cmp(&t(b))
    });
    ok
}

/// How a run's cost reads in a verdict: ms/step and the budget it fits, or
/// (a static scene, `budgets` not applicable) the wall time to the solution.
fn cost_text(r: &ResultRow, cost: &Cost, budgets: &[f64]) -> String {
    if cost.is_static {
        format!(
            "{} s to the solution",
            r.solve_wall_s.map_or("—".into(), |t| fmt_sig(t, 3))
        )
    } else {
        format!(
            "{} ms/step, {}",
            r.ms_per_step_median.map_or("—".into(), |m| fmt_sig(m, 3)),
            budget_class(r.ms_per_step_median, budgets)
        )
    }
}

/// One model's verdict on one scene, its runs' cost read as `cost` says
/// ([`Cost::of_group`]: time per step, or time to the solution): the short
/// cell of the verdict matrix (no settings) and the full text with the
/// settings, which the scene's section prints.
fn verdict_cell(rows: &[&ResultRow], target: &AccuracyTarget, budgets: &[f64], cost: &Cost) -> (Cell, String) {
    if rows.is_empty() {
        return (Cell::plain("—"), "not run".into());
    }
    if rows.iter().all(|r| r.status == Status::Unsupported) {
        return (Cell::plain("unsupported"), "unsupported".into());
    }
    if let Some(r) = meeting(rows, target, cost).first() {
        let cell = Cell {
            text: format!("✓ {}", cost_text(r, cost, budgets)),
            bold: true,
            ..Cell::default()
        };
        return (
            cell,
            format!("meets it: {} ({})", cost_text(r, cost, budgets), settings_label(r)),
        );
    }
    let (short, full) = match best_ok(rows, |r| r.metrics.get(&target.metric).copied()) {
        Some(r) => match r.metrics.get(&target.metric) {
            Some(e) => (
                format!("✗ best {}", fmt_sig(*e, 3)),
                format!(
                    "misses it at every tested setting (best: {} at {}, {})",
                    fmt_sig(*e, 3),
                    cost_text(r, cost, budgets),
                    settings_label(r)
                ),
            ),
            None => ("no error value".to_string(), "no error value".to_string()),
        },
        None => ("no ok run".to_string(), "no ok run".to_string()),
    };
    let cell = Cell {
        text: short,
        warn: true,
        ..Cell::default()
    };
    (cell, full)
}

/// The full verdict of the runs `rows` (one model) on `g`'s scene, with
/// settings; `None` when the report has no target for the scene.
pub(super) fn verdict_text(g: &Group, rows: &[&ResultRow], info: &RunInfo) -> Option<String> {
    let scenario = g.rows.first().map(|r| r.scenario.as_str())?;
    let t = info.targets.get(scenario)?;
    Some(verdict_cell(rows, t, &info.budgets(), &Cost::of_group(g)).1)
}

/// The verdict table and the list of targets with their reasons; nothing
/// when the report records no targets (written before they existed).
pub(super) fn verdict_blocks(groups: &[Group], st: &Styles, info: &RunInfo) -> Vec<Block> {
    if info.targets.is_empty() {
        return Vec::new();
    }
    let budgets = info.budgets();
    let mut header = vec!["scenario".to_string(), "target".to_string()];
    header.extend(st.models.iter().cloned());
    let mut rows = Vec::new();
    let mut reasons = Vec::new();
    for g in groups {
        let scenario = g.rows.first().map_or("", |r| r.scenario.as_str());
        let Some(t) = info.targets.get(scenario) else {
            continue;
        };
        let mut row = vec![
            Cell::plain(&g.title).linked(format!("#{}", super::tables::section_id(g))),
            Cell::plain(format!("{} ≤ {}", or_unknown(&t.metric), fmt_sig(t.value, 3))),
        ];
        let cost = Cost::of_group(g);
        for model in &st.models {
            row.push(verdict_cell(&g.model_rows(model), t, &budgets, &cost).0);
        }
        rows.push(row);
        let line = format!("{scenario}: {} ≤ {}: {}", t.metric, fmt_sig(t.value, 3), t.why);
        if !reasons.contains(&line) {
            reasons.push(line);
        }
    }
    if rows.is_empty() {
        return Vec::new();
    }
    let budget_words: Vec<String> = budgets.iter().map(|b| format!("{} ms", fmt_sig(*b, 3))).collect();
    vec![
        Block::Anchored(2, "Verdicts: accurate enough, and how fast".into(), "verdicts".into()),
        Block::Para(format!(
            "Each cell: ✓ and the cost of the cheapest tested settings (median ms/step) at which the model meets the scene's accuracy target \
             (its primary error at most the target), with the time budget that run fits (per step: {}; 1 ms is a 1 kHz \
             haptic loop, 16 and 33 ms a 60 and 30 Hz frame; in a static scene, the wall time to the solution instead), or ✗ and the \
             best error the model reached when no tested setting meets it; — where the model did not run the scene. \
             Each scenario's section names the settings of every verdict. \
             A verdict holds for the settings tested here only: a finer sweep may meet a target this one misses.",
            budget_words.join(", ")
        )),
        Block::Table { header, rows },
        Block::Heading(3, "Targets".into()),
        Block::List(reasons),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DEFAULT_BUDGETS_MS;

    fn run(fid: &str, err: f64, ms: f64) -> ResultRow {
        let mut r = ResultRow {
            fidelity: fid.into(),
            ..Default::default()
        };
        r.status = Status::Ok;
        r.ms_per_step_median = Some(ms);
        r.metrics.insert("tip_error_rel".into(), err);
        r
    }

    /// A model that meets the target only at its second setting is reported
    /// at that setting; the cheapest of several that meet it wins.
    #[test]
    fn cheapest_run_that_meets_the_target() {
        let t = AccuracyTarget {
            metric: "tip_error_rel".into(),
            value: 0.02,
            why: String::new(),
        };
        let rows = [
            run("segments=10", 0.05, 0.1),
            run("segments=20", 0.015, 0.3),
            run("segments=40", 0.004, 0.9),
        ];
        let refs: Vec<&ResultRow> = rows.iter().collect();
        assert_eq!(meeting(&refs, &t, &Cost::PER_STEP)[0].fidelity, "segments=20");
        let (c, full) = verdict_cell(&refs, &t, &DEFAULT_BUDGETS_MS, &Cost::PER_STEP);
        assert_eq!(full, "meets it: 0.3 ms/step, within 1 ms (segments=20)");
        assert_eq!(c.text, "✓ 0.3 ms/step, within 1 ms");
        let strict = AccuracyTarget { value: 1e-3, ..t };
        let (c, full) = verdict_cell(&refs, &strict, &DEFAULT_BUDGETS_MS, &Cost::PER_STEP);
        assert_eq!(
            full,
            "misses it at every tested setting (best: 0.004 at 0.9 ms/step, within 1 ms, segments=40)"
        );
        assert_eq!(c.text, "✗ best 0.004");
        assert!(c.warn);
        // A static scene: the cheapest by time to the solution, no budget.
        let mut rows = rows;
        for (r, s) in rows.iter_mut().zip([0.5, 2.0, 1.0]) {
            r.solve_wall_s = Some(s);
        }
        let refs: Vec<&ResultRow> = rows.iter().collect();
        let loose = AccuracyTarget { value: 0.02, ..strict };
        let (_, full) = verdict_cell(&refs, &loose, &DEFAULT_BUDGETS_MS, &Cost::TO_SOLUTION);
        assert_eq!(full, "meets it: 1 s to the solution (segments=40)");
    }

    #[test]
    fn budget_classes() {
        let b = DEFAULT_BUDGETS_MS;
        assert_eq!(budget_class(Some(0.5), &b), "within 1 ms");
        assert_eq!(budget_class(Some(1.0), &b), "within 1 ms");
        assert_eq!(budget_class(Some(20.0), &b), "within 33 ms");
        assert_eq!(budget_class(Some(40.0), &b), "over 33 ms");
        assert_eq!(budget_class(None, &b), "time not measured");
    }
}
