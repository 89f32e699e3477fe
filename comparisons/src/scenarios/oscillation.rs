//! Free vibration scored against a sine: the analysis every vibration scene
//! shares (`cantilever-vibration`, `block-vibration`). A scene tracks one
//! scalar displacement `z(t)` of the model (the rod tip's transverse
//! component, a tissue block's top-centre sway) against the reference
//! `A sin(omega t)` of a body started in its first mode with the mode's
//! velocity, and reads the period, the numerical damping per period, the
//! phase at the end and the RMS error off the track.

use crate::scenario::Metrics;

/// The scalar displacement over a run against `amplitude sin(omega t)`.
#[derive(Debug, Clone)]
pub struct VibrationTrack {
    /// Reference amplitude (m).
    pub amplitude: f64,
    /// Reference angular frequency (rad/s).
    pub omega: f64,
    /// The samples so far.
    pub track: TipTrack,
    /// Sum over the samples of the squared error against the reference (m^2).
    sum2: f64,
}

impl VibrationTrack {
    /// An empty track against `amplitude` (m) `sin(omega t)` (rad/s).
    pub fn new(amplitude: f64, omega: f64) -> Self {
        Self {
            amplitude,
            omega,
            track: TipTrack::default(),
            sum2: 0.0,
        }
    }

    /// Take in the displacement `z` (m) at time `t` (s).
    pub fn push(&mut self, t: f64, z: f64) {
        self.sum2 += (z - self.reference_at(t)).powi(2);
        self.track.samples.push((t, z));
    }

    /// The reference displacement at `t` (m).
    pub fn reference_at(&self, t: f64) -> f64 {
        self.amplitude * (self.omega * t).sin()
    }

    /// The reference period `2 pi / omega` (s).
    pub fn period(&self) -> f64 {
        2.0 * std::f64::consts::PI / self.omega
    }

    /// `tip_rms_error_rel` (RMS error over the amplitude) and, once the
    /// track has crossed zero twice, `period_s`, `period_error_rel`,
    /// `damping_per_period` (amplitude lost per period), `amplitude_loss_rel`
    /// (at the last half period) and `phase_error_rad` (at the last crossing).
    pub fn metrics(&self, m: &mut Metrics) {
        let n = self.track.samples.len();
        if n > 0 {
            m.insert(
                "tip_rms_error_rel".into(),
                (self.sum2 / n as f64).sqrt() / self.amplitude,
            );
        }
        if let Some(o) = self.track.oscillation(self.amplitude) {
            let t_ref = self.period();
            m.insert("period_s".into(), o.period);
            m.insert("period_error_rel".into(), (o.period - t_ref).abs() / t_ref);
            m.insert("damping_per_period".into(), 1.0 - o.ratio_per_period);
            m.insert("amplitude_loss_rel".into(), 1.0 - o.last_peak);
            let (t_last, k) = o.last_crossing;
            m.insert(
                "phase_error_rad".into(),
                (self.omega * (t_last - k as f64 * t_ref / 2.0)).abs(),
            );
        }
    }
}

/// The transverse tip displacement over a run, as the scorer sees it.
#[derive(Debug, Clone, Default)]
pub struct TipTrack {
    /// `(t, z)`: time (s) and transverse tip displacement (m), one per step.
    pub samples: Vec<(f64, f64)>,
}

/// What the track says about the oscillation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oscillation {
    /// Period from a least-squares line through the zero-crossing times (s).
    pub period: f64,
    /// Amplitude kept per period, `exp(2 slope)` of a least-squares line
    /// through `ln |peak|` against the half-period index (1 = no damping).
    pub ratio_per_period: f64,
    /// The last half-period's peak over the reference amplitude.
    pub last_peak: f64,
    /// Time of the last zero crossing (s) and how many half periods it ends.
    pub last_crossing: (f64, usize),
}

impl TipTrack {
    /// Zero crossings (linear interpolation between samples) and the peak
    /// between each pair (a parabola through the largest sample and its
    /// neighbours); `None` with fewer than two crossings.
    pub fn oscillation(&self, amplitude: f64) -> Option<Oscillation> {
        let s = &self.samples;
        let mut crossings = Vec::new();
        for (i, w) in s.windows(2).enumerate() {
            let ((t0, z0), (t1, z1)) = (w[0], w[1]);
            if (z0 > 0.0) != (z1 > 0.0) && z1 != z0 {
                crossings.push((t0 + (t1 - t0) * z0 / (z0 - z1), i + 1));
            }
        }
        if crossings.len() < 2 {
            return None;
        }
        let times: Vec<f64> = crossings.iter().map(|c| c.0).collect();
        let half = line_slope(&times);
        let peaks: Vec<f64> = crossings.windows(2).map(|w| peak_between(s, w[0].1, w[1].1)).collect();
        let logs: Vec<f64> = peaks.iter().map(|p| p.max(1e-300).ln()).collect();
        let ratio = if logs.len() >= 2 {
            (2.0 * line_slope(&logs)).exp()
        } else {
            1.0
        };
        Some(Oscillation {
            period: 2.0 * half,
            ratio_per_period: ratio,
            last_peak: peaks.last().copied().unwrap_or(f64::NAN) / amplitude,
            last_crossing: (*times.last().expect("two crossings"), times.len()),
        })
    }
}

/// Slope of the least-squares line through `(k, y_k)`, `k = 0, 1, ...`.
fn line_slope(y: &[f64]) -> f64 {
    let n = y.len() as f64;
    let km = (n - 1.0) / 2.0;
    let ym = y.iter().sum::<f64>() / n;
    let (num, den) = y.iter().enumerate().fold((0.0, 0.0), |(a, b), (k, v)| {
        let dk = k as f64 - km;
        (a + dk * (v - ym), b + dk * dk)
    });
    num / den
}

/// Largest `|z|` of the samples `from..to`, refined by the parabola through
/// the largest sample and its neighbours (error O(dt^3) against O(dt^2)).
fn peak_between(s: &[(f64, f64)], from: usize, to: usize) -> f64 {
    let Some(i) = (from..to.min(s.len())).max_by(|&a, &b| s[a].1.abs().total_cmp(&s[b].1.abs())) else {
        return f64::NAN;
    };
    let zi = s[i].1.abs();
    if i == 0 || i + 1 >= s.len() {
        return zi;
    }
    let (a, b) = (s[i - 1].1.abs(), s[i + 1].1.abs());
    let curv = a - 2.0 * zi + b;
    if curv >= 0.0 {
        return zi;
    }
    zi - (b - a).powi(2) / (8.0 * curv)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The track's analysis recovers a known damped sine exactly enough:
    /// `z = A r^(t/T) sin(2 pi t / T)` sampled at T/50 for 8 periods gives
    /// the period to 1e-6 (crossings interpolated linearly: O(dt^3) per
    /// crossing, the sine being straight there to second order) and the
    /// ratio per period to 1e-4 (parabolic peaks: O(dt^3)).
    #[test]
    fn oscillation_of_a_damped_sine() {
        let (a, period, ratio) = (0.01, 12.0, 0.97f64);
        let dt = period / 50.0; // 410 samples: 8.2 periods, the 16th crossing inside
        let track = TipTrack {
            samples: (1..=410)
                .map(|k| {
                    let t = k as f64 * dt;
                    (
                        t,
                        a * ratio.powf(t / period) * (2.0 * std::f64::consts::PI * t / period).sin(),
                    )
                })
                .collect(),
        };
        let o = track.oscillation(a).expect("sixteen crossings");
        assert!((o.period - period).abs() < 1e-6 * period, "period {}", o.period);
        assert!(
            (o.ratio_per_period - ratio).abs() < 1e-4,
            "ratio {}",
            o.ratio_per_period
        );
        assert_eq!(o.last_crossing.1, 16);
        assert!((o.last_crossing.0 - 8.0 * period).abs() < 1e-6 * period);
    }
}
