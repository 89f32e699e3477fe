//! Cached reference trajectories: a converged model's tip path over time.

use crate::scenario::{Inputs, UsageError};
use surgbench_core::Vec3;

/// A cached reference trajectory `t,x,y,z` (s, m).
#[derive(Debug, Clone, PartialEq)]
pub struct TipTrajectory {
    /// Samples `(t, tip)` in increasing time.
    pub samples: Vec<(f64, Vec3)>,
}

impl TipTrajectory {
    /// Parse CSV with a header naming `t,x,y,z`; errors name the line.
    pub fn parse(file: &str, text: &str) -> Result<Self, UsageError> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
        let (_, header) = lines
            .next()
            .ok_or_else(|| UsageError(format!("{file}: empty reference")))?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let col = |n: &str| {
            names
                .iter()
                .position(|x| *x == n)
                .ok_or_else(|| UsageError(format!("{file}: header has no `{n}` column")))
        };
        let cols = [col("t")?, col("x")?, col("y")?, col("z")?];
        let mut samples: Vec<(f64, Vec3)> = Vec::new();
        for (i, l) in lines {
            let cells: Vec<&str> = l.split(',').map(str::trim).collect();
            let mut v = [0.0; 4];
            for (k, &c) in cols.iter().enumerate() {
                v[k] = cells
                    .get(c)
                    .and_then(|s| s.parse::<f64>().ok())
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        UsageError(format!(
                            "{file}: line {}, column `{}`: not a finite number",
                            i + 1,
                            names[c]
                        ))
                    })?;
            }
            if samples.last().is_some_and(|s| !(v[0] > s.0)) {
                return Err(UsageError(format!("{file}: line {}: time does not increase", i + 1)));
            }
            samples.push((v[0], Vec3::new(v[1], v[2], v[3])));
        }
        if samples.is_empty() {
            return Err(UsageError(format!("{file}: no samples")));
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

/// Load `<datasets>/reference/<scenario>/tip_trajectory.csv` when present
/// and the parameters are the defaults it was computed for.
pub fn cached_reference(scenario: &str, inputs: &Inputs) -> Result<Option<TipTrajectory>, UsageError> {
    if !inputs.params.overrides_string().is_empty() {
        return Ok(None);
    }
    let path = inputs
        .datasets
        .join("reference")
        .join(scenario)
        .join("tip_trajectory.csv");
    match std::fs::read_to_string(&path) {
        Ok(text) => TipTrajectory::parse(&path.display().to_string(), &text).map(Some),
        Err(_) => Ok(None),
    }
}
