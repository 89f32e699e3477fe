//! Scoring a tissue scene along its load curve: the force at every step
//! against the reference force at that step's load factor, summed over the
//! run into an RMS error relative to the RMS reference force.

use crate::scenario::{Metrics, Reference, Scorer};
use surgbench_core::{Observation, Scene};

/// A scene whose force is scored along the whole load ramp.
pub(super) trait ForceCurve: Send + Sync + 'static {
    /// Metrics of `obs` alone; `None` when `obs` holds no state of this
    /// scene (no tissue of its mesh, no indenter).
    fn metrics(&self, scene: &Scene, obs: &Observation) -> Option<Metrics>;
    /// `(force of obs, reference force at obs.time)` (N), or `None` where
    /// the reference has no value (below its first tabulated depth).
    fn curve_point(&self, scene: &Scene, obs: &Observation) -> Option<(f64, f64)>;
    /// The indenter's depth at the end of the ramp (m); at a step it is
    /// that times the step's load factor.
    fn full_depth(&self) -> f64;
}

/// A [`ForceCurve`] as a scenario's [`Reference`].
pub(super) struct Curve<S>(pub(super) S);

/// One run's sums of `(F - F_ref)^2` and `F_ref^2` over its steps (N^2).
struct CurveScorer<'a, S> {
    run: &'a S,
    scene: &'a Scene,
    err2: f64,
    ref2: f64,
}

impl<S: ForceCurve> Reference for Curve<S> {
    fn scorer<'a>(&'a self, scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(CurveScorer {
            run: &self.0,
            scene,
            err2: 0.0,
            ref2: 0.0,
        })
    }
}

impl<S: ForceCurve> Scorer for CurveScorer<'_, S> {
    fn observe_step(&mut self, obs: &Observation) {
        if let Some((got, want)) = self.run.curve_point(self.scene, obs) {
            self.err2 += (got - want).powi(2);
            self.ref2 += want * want;
        }
    }
    /// The scene's metrics plus `force_curve_error_rel`, the RMS force error
    /// over the steps seen relative to the RMS reference (once any reference
    /// force was seen).
    fn score(&self, obs: &Observation) -> Metrics {
        let Some(mut m) = self.run.metrics(self.scene, obs) else {
            return Metrics::new();
        };
        if self.ref2 > 0.0 {
            m.insert("force_curve_error_rel".into(), (self.err2 / self.ref2).sqrt());
        }
        m
    }
    fn force_point(&self, obs: &Observation) -> Option<(f64, f64)> {
        self.run.curve_point(self.scene, obs)
    }
    fn force_depth(&self, obs: &Observation) -> Option<f64> {
        Some(self.scene.control.command_at(obs.time).load * self.run.full_depth())
    }
}
