//! Scoring a tissue scene along its load curve: the force at every step
//! against the reference force at that step's load factor, summed over the
//! run into an RMS error relative to the RMS reference force.

use crate::scenario::{Metrics, Scorer};
use surgbench_core::Observation;

/// A scene whose force is scored along the whole load ramp.
pub(super) trait ForceCurve: Sync {
    /// Metrics of `obs` alone; `None` when `obs` holds no state of this
    /// scene (no tissue of its mesh, no indenter).
    fn metrics(&self, obs: &Observation) -> Option<Metrics>;
    /// `(force of obs, reference force at obs.time)` (N), or `None` where
    /// the reference has no value (below its first tabulated depth).
    fn curve_point(&self, obs: &Observation) -> Option<(f64, f64)>;
}

/// One run's sums of `(F - F_ref)^2` and `F_ref^2` over its steps (N^2).
pub(super) struct CurveScorer<'a, S> {
    scene: &'a S,
    err2: f64,
    ref2: f64,
}

impl<'a, S: ForceCurve> CurveScorer<'a, S> {
    /// A fresh scorer for one run of `scene`.
    pub(super) fn boxed(scene: &'a S) -> Box<dyn Scorer + 'a> {
        Box::new(Self {
            scene,
            err2: 0.0,
            ref2: 0.0,
        })
    }
}

impl<S: ForceCurve> Scorer for CurveScorer<'_, S> {
    fn observe_step(&mut self, obs: &Observation) {
        if let Some((got, want)) = self.scene.curve_point(obs) {
            self.err2 += (got - want).powi(2);
            self.ref2 += want * want;
        }
    }
    /// The scene's metrics plus `force_curve_error_rel`, the RMS force error
    /// over the steps seen relative to the RMS reference (once any reference
    /// force was seen).
    fn score(&self, obs: &Observation) -> Metrics {
        let Some(mut m) = self.scene.metrics(obs) else {
            return Metrics::new();
        };
        if self.ref2 > 0.0 {
            m.insert("force_curve_error_rel".into(), (self.err2 / self.ref2).sqrt());
        }
        m
    }
}
