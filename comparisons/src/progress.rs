//! Progress of a batch: the time left, weighted by what each run took in
//! the previous report written to the same folder, and how it is shown (a
//! bar on a terminal, one line per finished run when stderr is a log file).

use std::collections::HashMap;
use std::io::{IsTerminal, Write};
use std::path::Path;
use std::time::Instant;

use surgbench_reports::ResultRow;

/// What a run of an earlier report cost (s): its build plus its steps at
/// their median wall time. Spawning, references and repeats are left out;
/// [`Eta`] scales every estimate by the ratio observed in this batch, so
/// only the runs' relative costs need to be right. `None` when the row has
/// no timing (a failed or unsupported run).
pub fn run_cost_s(r: &ResultRow) -> Option<f64> {
    let steps = r.outcome.steps.filter(|s| s.is_finite() && *s >= 0.0)?;
    let ms = r.outcome.ms_per_step_median.filter(|m| m.is_finite() && *m >= 0.0)?;
    let build = r.outcome.build_ms.filter(|b| b.is_finite() && *b >= 0.0).unwrap_or(0.0);
    Some((steps * ms + build) / 1e3)
}

/// Each run's cost in the report at `out` (keyed by its `run_dir`), when a
/// readable one is there; empty otherwise (no report yet, or one written
/// by an older surgbench).
pub fn previous_costs(out: &Path) -> HashMap<String, f64> {
    let Ok(rows) = surgbench_reports::read_results_csv(&out.join("results.csv")) else {
        return HashMap::new();
    };
    rows.iter()
        .filter_map(|r| Some((r.run_dir.clone(), run_cost_s(r)?)))
        .collect()
}

/// The time left in a batch. Each run has a prior cost (from the previous
/// report, `None` when unknown); as runs finish, the ratio of their actual
/// to their prior time scales the priors of the runs left, and runs
/// without a prior count as the mean time of the finished runs.
#[derive(Debug, Clone)]
pub struct Eta {
    prior: Vec<Option<f64>>,
    actual: Vec<Option<f64>>,
}

impl Eta {
    /// A batch of `prior.len()` runs with those prior costs (s).
    pub fn new(prior: Vec<Option<f64>>) -> Self {
        let actual = vec![None; prior.len()];
        Eta { prior, actual }
    }

    /// Run `i` took `secs`.
    pub fn finish(&mut self, i: usize, secs: f64) {
        if let Some(a) = self.actual.get_mut(i) {
            *a = Some(secs);
        }
    }

    /// Seconds left; `None` while nothing is known to estimate from (no
    /// run finished and some run without a prior).
    pub fn remaining_s(&self) -> Option<f64> {
        let done: Vec<(Option<f64>, f64)> = self
            .prior
            .iter()
            .zip(&self.actual)
            .filter_map(|(p, a)| a.map(|a| (*p, a)))
            .collect();
        let (sum_prior, sum_actual) = done
            .iter()
            .filter_map(|(p, a)| p.map(|p| (p, *a)))
            .fold((0.0, 0.0), |(sp, sa), (p, a)| (sp + p, sa + a));
        // Observed time per unit of prior cost; 1 until a run with a prior
        // and a measurable cost has finished.
        let scale = if sum_prior > 1e-9 { sum_actual / sum_prior } else { 1.0 };
        let mean_done = if done.is_empty() {
            None
        } else {
            Some(done.iter().map(|(_, a)| a).sum::<f64>() / done.len() as f64)
        };
        let mut left = 0.0;
        for (p, a) in self.prior.iter().zip(&self.actual) {
            if a.is_some() {
                continue;
            }
            left += match p {
                Some(p) => scale * p,
                None => mean_done?,
            };
        }
        Some(left)
    }
}

/// `secs` as a person reads a wait: `0.4 s`, `45 s`, `3 min 05 s`, `1 h 02 min`.
pub fn human_duration(secs: f64) -> String {
    let secs = secs.max(0.0);
    if secs < 9.95 {
        return format!("{secs:.1} s");
    }
    let s = secs.round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min", s / 3600, (s % 3600) / 60),
    }
}

/// How a batch shows its progress: an indicatif bar on a terminal, a line
/// per finished run when stderr is not one (a log file, CI), or nothing
/// (`--quiet`).
pub struct Progress {
    bar: indicatif::ProgressBar,
    lines: bool,
    eta: Eta,
    started: Instant,
    total: usize,
    done: usize,
}

impl Progress {
    /// Progress over runs with these prior costs ([`Eta::new`]).
    pub fn new(prior: Vec<Option<f64>>, quiet: bool) -> Self {
        let total = prior.len();
        let terminal = std::io::stderr().is_terminal();
        let bar = if quiet || !terminal {
            indicatif::ProgressBar::hidden()
        } else {
            let b = indicatif::ProgressBar::new(total as u64);
            b.set_style(
                indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed} {msg}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            b
        };
        Progress {
            bar,
            lines: !quiet && !terminal,
            eta: Eta::new(prior),
            started: Instant::now(),
            total,
            done: 0,
        }
    }

    fn eta_text(&self) -> String {
        self.eta
            .remaining_s()
            .map_or("ETA unknown".into(), |s| format!("ETA {}", human_duration(s)))
    }

    /// Run `i` (`what`) starts.
    pub fn start(&self, what: &str) {
        self.bar.set_message(format!("{} · {what}", self.eta_text()));
    }

    /// Run `i` (`what`) ended with `status` after `secs`.
    pub fn finish(&mut self, i: usize, what: &str, status: &str, secs: f64) {
        self.eta.finish(i, secs);
        self.done += 1;
        self.bar.inc(1);
        if self.lines {
            let line = format!(
                "[{}/{}] {what}: {status} in {} ({} elapsed, {})\n",
                self.done,
                self.total,
                human_duration(secs),
                human_duration(self.started.elapsed().as_secs_f64()),
                self.eta_text()
            );
            // A closed stderr is no reason to stop the batch.
            let _ = std::io::stderr().write_all(line.as_bytes());
        }
    }

    /// Removes the bar.
    pub fn clear(&self) {
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With priors, the time left is the priors left scaled by the observed
    /// ratio: runs of prior 1, 2, 3 s; the first took 2 s (twice its
    /// prior), so the 5 s of prior left become 10 s.
    #[test]
    fn scales_priors_by_the_observed_ratio() {
        let mut e = Eta::new(vec![Some(1.0), Some(2.0), Some(3.0)]);
        assert_eq!(e.remaining_s(), Some(6.0));
        e.finish(0, 2.0);
        assert_eq!(e.remaining_s(), Some(10.0));
        e.finish(1, 2.0);
        // 4 s for 3 s of prior: the last 3 s of prior take 4 s.
        assert_eq!(e.remaining_s(), Some(4.0));
        e.finish(2, 1.0);
        assert_eq!(e.remaining_s(), Some(0.0));
    }

    /// Runs without a prior count as the mean finished run; before any run
    /// has finished their time is unknown.
    #[test]
    fn unknown_runs_take_the_mean() {
        let mut e = Eta::new(vec![None, Some(0.0), None, None]);
        assert_eq!(e.remaining_s(), None);
        e.finish(0, 4.0);
        // Two unknown runs left at 4 s; the zero-cost run (unsupported) 0 s.
        assert_eq!(e.remaining_s(), Some(8.0));
        e.finish(1, 0.0);
        // Mean of finished runs is now 2 s.
        assert_eq!(e.remaining_s(), Some(4.0));
    }

    #[test]
    fn durations_read_as_people_read_them() {
        assert_eq!(human_duration(44.6), "45 s");
        assert_eq!(human_duration(185.0), "3 min 05 s");
        assert_eq!(human_duration(3720.0), "1 h 02 min");
        assert_eq!(human_duration(0.04), "0.0 s");
        assert_eq!(human_duration(9.96), "10 s");
        assert_eq!(human_duration(-1.0), "0.0 s");
    }

    #[test]
    fn a_runs_cost_is_its_steps_and_build() {
        let mut r = ResultRow::default();
        assert_eq!(run_cost_s(&r), None);
        r.outcome.steps = Some(1000.0);
        r.outcome.ms_per_step_median = Some(0.5);
        r.outcome.build_ms = Some(250.0);
        assert_eq!(run_cost_s(&r), Some(0.75));
    }
}
