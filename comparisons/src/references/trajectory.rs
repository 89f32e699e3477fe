//! Cached reference trajectories: a converged model's tip path over time.

use super::tables::read_csv_columns;
use crate::error::UsageError;
use crate::scenario::Inputs;
use std::path::Path;
use surgbench_core::Vec3;

/// A cached reference trajectory `t,x,y,z` (s, m).
#[derive(Debug, Clone, PartialEq)]
pub struct TipTrajectory {
    /// Samples `(t, tip)` in increasing time.
    pub samples: Vec<(f64, Vec3)>,
}

impl TipTrajectory {
    /// Read a CSV whose header names `t,x,y,z` (s, m; `#` lines are
    /// provenance); the times must increase and there must be a sample.
    /// Errors name the file and line.
    pub fn load(file: &Path) -> Result<Self, UsageError> {
        let rows = read_csv_columns(file, &["t", "x", "y", "z"])?;
        let mut samples: Vec<(f64, Vec3)> = Vec::with_capacity(rows.len());
        for (i, r) in rows.iter().enumerate() {
            if samples.last().is_some_and(|s| !(r[0] > s.0)) {
                return Err(UsageError(format!(
                    "{}: sample {}: time does not increase",
                    file.display(),
                    i + 1
                )));
            }
            samples.push((r[0], Vec3::new(r[1], r[2], r[3])));
        }
        if samples.is_empty() {
            return Err(UsageError(format!("{}: no samples", file.display())));
        }
        Ok(Self { samples })
    }

    /// Tip at time `t` by linear interpolation (nearest sample outside).
    pub fn at(&self, t: f64) -> Vec3 {
        let s = &self.samples;
        if t <= s[0].0 {
            return s[0].1;
        }
        if t >= s[s.len() - 1].0 {
            return s[s.len() - 1].1;
        }
        let i = s.partition_point(|x| x.0 <= t) - 1;
        let w = (t - s[i].0) / (s[i + 1].0 - s[i].0);
        s[i].1 + (s[i + 1].1 - s[i].1) * w
    }
}

/// Load `<datasets>/reference/<scenario>/tip_trajectory.csv` when the
/// parameters are the defaults it was computed for: `None` when they are
/// not or when no file is there (the report shows `reference_available` 0);
/// a file that is there but unreadable or malformed is an error naming it.
pub fn cached_reference(scenario: &str, inputs: &Inputs) -> Result<Option<TipTrajectory>, UsageError> {
    if !inputs.params.overrides_string().is_empty() {
        return Ok(None);
    }
    let path = inputs
        .datasets
        .join("reference")
        .join(scenario)
        .join("tip_trajectory.csv");
    match path.try_exists() {
        Ok(true) => {}
        Ok(false) => return Ok(None),
        Err(e) => return Err(UsageError(format!("cannot read {}: {e}", path.display()))),
    }
    TipTrajectory::load(&path).map(Some)
}
