//! The convergence plot of one group: error against resolution, with fitted orders.

use std::collections::BTreeMap;

use super::{Group, PLOT_SIZE, Section, Styles, run_label, usable};
use crate::analysis::{Knob, choose_knob, fidelity_without};
use crate::figure::{Axis, Figure, LegendEntry, Line, Panel, SeriesSpec};
use crate::format::{fmt_plain, fmt_sig};
use crate::{NoOrder, ResultRow, Status, fit_convergence};

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

/// A run's knobs as `(key, value)` pairs.
type Knobs = Vec<(String, String)>;

/// One run's other knobs as `(key, value)` pairs, in their recorded order.
fn other_pairs(r: &ResultRow, knob: Knob) -> Knobs {
    other_knobs(r, knob)
        .split(';')
        .filter(|kv| !kv.trim().is_empty())
        .map(|kv| match kv.split_once('=') {
            Some((k, v)) => (k.trim().to_string(), v.trim().to_string()),
            None => (kv.trim().to_string(), String::new()),
        })
        .collect()
}

/// The other knobs of a model's runs that follow `knob` rather than define a
/// curve: a knob whose value is the same for every run at one resolution and
/// one setting of the remaining knobs (a model's `dt` chosen per mesh level
/// by a Courant rule, say). Grouping by it would split one refinement study
/// into single-point curves without an order.
///
/// Starts from every knob that takes two or more values and releases, one at
/// a time, each that varies among runs agreeing on the resolution and on the
/// knobs already released (named choices first, then by key), so a knob is
/// called a follower only when the data cannot tell it from one.
fn followers(runs: &[Knobs], res: &[f64]) -> Vec<String> {
    let value = |run: &[(String, String)], key: &str| {
        run.iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.clone())
            .unwrap_or_default()
    };
    let mut keys: Vec<String> = runs.iter().flatten().map(|(k, _)| k.clone()).collect();
    keys.sort();
    keys.dedup();
    let mut follow: Vec<String> = keys
        .into_iter()
        .filter(|k| {
            let mut vals: Vec<String> = runs.iter().map(|r| value(r, k)).collect();
            vals.sort();
            vals.dedup();
            vals.len() > 1
        })
        .collect();
    // Named choices (`variant=seed`) are released before numbers.
    follow.sort_by_key(|k| (runs.iter().all(|r| value(r, k).parse::<f64>().is_ok()), k.clone()));
    loop {
        let varies = |k: &String| {
            let mut seen: BTreeMap<(u64, Vec<String>), String> = BTreeMap::new();
            runs.iter().zip(res).any(|(run, n)| {
                let cell: Vec<String> = run
                    .iter()
                    .filter(|(key, _)| !follow.contains(key))
                    .map(|(key, v)| format!("{key}={v}"))
                    .collect();
                let v = value(run, k);
                seen.entry((n.to_bits(), cell)).or_insert_with(|| v.clone()) != &v
            })
        };
        match follow.iter().position(varies) {
            Some(i) => {
                follow.remove(i);
            }
            None => return follow,
        }
    }
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

/// One model's ok runs with a positive error, and the knob it varies.
type Own<'a> = (String, Option<Knob>, Vec<&'a ResultRow>);

/// Each model's own knob and usable ok runs.
fn own_knobs<'g>(g: &'g Group) -> Vec<Own<'g>> {
    let mut own = Vec::new();
    for model in &g.models {
        let ok: Vec<&ResultRow> = g
            .model_rows(model)
            .into_iter()
            .filter(|r| r.status == Status::Ok && usable(g.err(r)).is_some())
            .collect();
        own.push((model.clone(), choose_knob(&ok), ok));
    }
    own
}

/// The note naming ok runs whose error has no logarithm.
fn note_bad_errors(g: &Group, sec: &mut Section) {
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
}

/// The knob most models vary (preference segments > mesh level > dt on ties).
fn plot_knob(own: &[Own]) -> Option<Knob> {
    let mut votes: Vec<(Knob, usize)> = [Knob::Segments, Knob::MeshLevel, Knob::Dt]
        .into_iter()
        .map(|k| (k, own.iter().filter(|o| o.1 == Some(k)).count()))
        .collect();
    // Stable sort keeps the preference order on ties.
    votes.sort_by_key(|v| std::cmp::Reverse(v.1));
    votes.first().filter(|v| v.1 > 0).map(|v| v.0)
}

/// The curves drawn and their legend entries.
#[derive(Default)]
struct Curves {
    series: Vec<SeriesSpec>,
    legend: Vec<LegendEntry>,
}

/// One model's runs over `knob`, grouped by their other knobs: the fitted
/// order of each group goes to `sec.orders`, and the curves to `curves` when
/// `knob` is the plotted one.
fn model_curves(g: &Group, st: &Styles, own: &Own, knob: Knob, plotted: bool, sec: &mut Section, curves: &mut Curves) {
    let (model, _, ok) = own;
    let pts: Vec<(f64, f64, Knobs)> = ok
        .iter()
        .filter_map(|r| Some((usable(knob.resolution(r))?, usable(g.err(r))?, other_pairs(r, knob))))
        .collect();
    let res: Vec<f64> = pts.iter().map(|p| p.0).collect();
    let runs: Vec<Knobs> = pts.iter().map(|p| p.2.clone()).collect();
    let follow = followers(&runs, &res);
    let mut groups: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for (n, e, run) in pts {
        let key: Vec<String> = run
            .iter()
            .filter(|(k, _)| !follow.contains(k))
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        groups.entry(key.join(";")).or_default().push((n, e));
    }
    if !follow.is_empty() {
        sec.notes.push(format!(
            "{model}: {} takes one value per {} among runs otherwise alike (it follows the refinement), so runs differing only in {} share one convergence curve.",
            follow.join(", "),
            knob.key(),
            if follow.len() == 1 { "it" } else { "these" }
        ));
    }
    let n_groups = groups.len();
    for (variant, (other, mut pts)) in groups.into_iter().enumerate() {
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let ns: Vec<f64> = pts.iter().map(|p| p.0).collect();
        let es: Vec<f64> = pts.iter().map(|p| p.1).collect();
        let fit = fit_convergence(&ns, &es);
        let with = if other.is_empty() {
            String::new()
        } else {
            format!(", {other}")
        };
        sec.orders.push(match &fit {
            Ok(f) => format!(
                "{model}: p = {:.2} ± {:.2} (95 %), R² = {:.4} vs {} ({} ok runs, {}{with}).",
                f.order,
                f.ci95,
                f.r2,
                knob.n_name(),
                f.points,
                knob_range(knob, &ns)
            ),
            Err(why) => {
                let at = if other.is_empty() {
                    String::new()
                } else {
                    format!(" at {}", crate::short_settings(&other))
                };
                format!("{model}: no order vs {}{at}: {}.", knob.n_name(), no_order_reason(why))
            }
        });
        if !plotted {
            continue;
        }
        let tag = if n_groups > 1 && !other.is_empty() {
            format!("{model} {}", crate::short_settings(&other))
        } else {
            model.clone()
        };
        let fit = match fit {
            Ok(f) => format!("p = {:.2} ± {:.2}", f.order, f.ci95),
            Err(NoOrder::TooFew(k)) => format!("no order: {k} point(s)"),
            Err(NoOrder::NonMonotone(_)) => "no order: non-monotone".into(),
        };
        let look = st.look(model, variant, Line::Solid);
        curves.legend.push(LegendEntry {
            look,
            label: format!("{tag} ({fit})"),
        });
        curves.series.push(SeriesSpec {
            look,
            points: pts.clone(),
            line_points: pts,
        });
    }
}

/// Why a fit gives no order, in words with the data.
fn no_order_reason(why: &NoOrder) -> String {
    match why {
        NoOrder::TooFew(k) => format!("{k} distinct value(s) with an ok, positive error; a fit needs 3"),
        NoOrder::NonMonotone(e) => format!(
            "the error does not fall steadily with refinement ({})",
            e.iter().map(|e| fmt_sig(*e, 3)).collect::<Vec<_>>().join(" → ")
        ),
    }
}

/// The order line of a model without a knob to fit against.
fn no_order(g: &Group, model: &str, ok: &[&ResultRow]) -> String {
    if ok.is_empty() {
        format!("{model}: no order (no ok run with a positive {}).", g.metric)
    } else {
        format!(
            "{model}: no order ({} ok run(s) with a positive {}, but no discretization knob takes two values).",
            ok.len(),
            g.metric
        )
    }
}

/// Error vs discretization, log-log, one curve per model and other-knob group,
/// with the fitted order in the legend.
pub(super) fn convergence_figure(g: &Group, st: &Styles, sec: &mut Section) -> Option<(Figure, String)> {
    if g.metric.is_empty() {
        return None;
    }
    let own = own_knobs(g);
    note_bad_errors(g, sec);
    let plot_knob = plot_knob(&own);
    let mut curves = Curves::default();
    for o in &own {
        let (model, knob, ok) = o;
        let Some(knob) = *knob else {
            sec.orders.push(no_order(g, model, ok));
            continue;
        };
        model_curves(g, st, o, knob, Some(knob) == plot_knob, sec, &mut curves);
        if Some(knob) != plot_knob {
            sec.notes.push(format!(
                "{model} varies {} rather than {}: its order is listed but not drawn in the convergence plot.",
                knob.key(),
                plot_knob.map(|k| k.key()).unwrap_or("-")
            ));
        }
    }
    let knob = plot_knob?;
    if curves.series.is_empty() {
        return None;
    }
    Some(figure(g, knob, curves, sec))
}

/// The convergence figure of `curves` over `knob`, with its note and alt text.
fn figure(g: &Group, knob: Knob, curves: Curves, sec: &mut Section) -> (Figure, String) {
    let ticks: Vec<f64> = {
        let mut v: Vec<f64> = curves
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .collect();
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
            series: curves.series,
        }],
        legend: curves.legend,
        size: PLOT_SIZE,
    };
    let alt = format!(
        "{}: {} against {}, log-log, with fitted orders",
        g.title,
        g.metric,
        knob.key()
    );
    (fig, alt)
}
