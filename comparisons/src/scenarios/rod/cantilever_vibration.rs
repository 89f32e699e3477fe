//! `cantilever-vibration`: the free vibration of a clamped rod started in its
//! first bending mode, the dynamic cantilever case DisMech ships with its
//! Euler-Bernoulli reference (L = 1 m, r = 0.02 m, rho = 500 kg/m^3,
//! E = 1e5 Pa, no gravity). The tip follows `A sin(omega_1 t)` with
//! `omega_1 = (beta_1 L)^2 sqrt(E I / (rho A L^4))` (period 12.64 s at these
//! values); the run is scored on the period, the numerical damping per
//! period, the phase at the end and the RMS tip error, which is what tells
//! the integrators apart (backward Euler damps, Newmark conserves, XPBD and
//! the chain-mail have their own dissipation).
//!
//! The initial velocity is the first clamped-free mode shape
//! ([`surgbench_core::beam::cantilever_mode`], Blevins 1979, Table 8-1)
//! scaled so that the tip's amplitude is `amplitude`:
//! `v(s) = A omega_1 phi(s/L) / phi(1) e_z`, with the section turning at the
//! slope's rate `-A omega_1 phi'(s/L) / (L phi(1)) e_y`. The default
//! amplitude, 1.0055e-2 m, is the one DisMech's reference data file gives
//! for its initial velocity field. At A/L = 1 % the closed form's small
//! deflection assumption holds: the geometric stiffening shifts the
//! frequency by O((A/L)^2) = 1e-4, and the axial shortening of the tip
//! (about 0.6 A^2 / L) is left out of the score, which reads the transverse
//! (mode) component of the tip displacement only.

use super::{POISSON, RodCase, rod_case};
use crate::params;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, Reference, ScenarioInfo, ScenarioRun, Scorer, Sweep,
};
use surgbench_core::beam::{FIRST_CANTILEVER_MODE, cantilever_mode, first_bending_frequency};
use surgbench_core::{Family, Observation, RodVelocity, Scene, Vec3, rod::VelocitySample};

/// Free vibration of a cantilever in its first bending mode.
pub const CANTILEVER_VIBRATION: Declared<VibrationParams> = Declared {
    info: ScenarioInfo {
        id: "cantilever-vibration",
        description: "clamped rod started in its first bending mode, free for 100 s (DisMech's dynamic cantilever)",
        family: Family::Rod,
        reference: "Euler-Bernoulli free vibration: tip A sin(omega_1 t), omega_1 = 1.8751^2 sqrt(EI/(rho A L^4)) (period 12.64 s)",
        primary_error: "tip_rms_error_rel",
        target: crate::scenario::Target::new(0.05, "the tip within 5 % of the mode's amplitude, RMS over the run"),
        params: VibrationParams::SPECS,
        sweep: Sweep::Knob("dt", &[0.4, 0.2, 0.1, 0.05]),
        quick: 2,
        mesh: None,
    },
    datasets: None,
    build,
};

params! {
    /// Parameters of `cantilever-vibration`.
    pub struct VibrationParams {
        length: ParamSpec::new("length", 1.0, "m", Range::Positive, "free length of the rod"),
        radius: ParamSpec::new("radius", 0.02, "m", Range::Positive, "radius of the solid circular section"),
        youngs_modulus: ParamSpec::new("youngs_modulus", 1e5, "Pa", Range::Positive, "Young's modulus"),
        poisson_ratio: POISSON,
        density: ParamSpec::new("density", 500.0, "kg/m^3", Range::Positive, "density"),
        amplitude: ParamSpec::new(
            "amplitude",
            1.0055e-2,
            "m",
            Range::Positive,
            "tip amplitude of the first mode the rod starts in (DisMech's reference data)"
        ),
        duration: ParamSpec::new("duration", 100.0, "s", Range::Positive, "simulated time of free vibration"),
    }
}

/// Samples of the initial velocity field along the rod: linear
/// interpolation between 401 samples misses the mode by `h^2 phi'' / 8`,
/// below 3e-6 of the tip speed.
const FIELD_SAMPLES: usize = 400;

/// The closed form a run is scored against.
#[derive(Debug, Clone, Copy)]
pub struct Vibration {
    /// Tip amplitude (m).
    pub amplitude: f64,
    /// `omega_1` (rad/s).
    pub omega: f64,
    /// Rest position of the tip (m).
    rest_tip: Vec3,
    /// Direction of the mode's transverse motion (unit).
    direction: Vec3,
}

impl Vibration {
    /// Period `2 pi / omega_1` (s).
    pub fn period(&self) -> f64 {
        2.0 * std::f64::consts::PI / self.omega
    }
}

impl Reference for Vibration {
    fn scorer<'a>(&'a self, _scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(VibrationScorer {
            reference: *self,
            track: TipTrack::default(),
            sum2: 0.0,
        })
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

/// Per-run sums of one vibration run.
struct VibrationScorer {
    reference: Vibration,
    track: TipTrack,
    /// Sum over the observed steps of the squared transverse tip error (m^2).
    sum2: f64,
}

impl Scorer for VibrationScorer {
    fn observe_step(&mut self, obs: &Observation) {
        if let Some(r) = obs.rods.first() {
            let v = &self.reference;
            let z = (r.tip() - v.rest_tip).dot(&v.direction);
            self.sum2 += (z - v.amplitude * (v.omega * obs.time).sin()).powi(2);
            self.track.samples.push((obs.time, z));
        }
    }

    fn score(&self, obs: &Observation) -> Metrics {
        let r = &self.reference;
        let mut m = Metrics::new();
        let n = self.track.samples.len();
        if n > 0 {
            m.insert("tip_rms_error_rel".into(), (self.sum2 / n as f64).sqrt() / r.amplitude);
        }
        if let Some(o) = self.track.oscillation(r.amplitude) {
            let t_ref = r.period();
            m.insert("period_s".into(), o.period);
            m.insert("period_error_rel".into(), (o.period - t_ref).abs() / t_ref);
            m.insert("damping_per_period".into(), 1.0 - o.ratio_per_period);
            m.insert("amplitude_loss_rel".into(), 1.0 - o.last_peak);
            let (t_last, k) = o.last_crossing;
            m.insert(
                "phase_error_rad".into(),
                (r.omega * (t_last - k as f64 * t_ref / 2.0)).abs(),
            );
        }
        if let Some(rod) = obs.rods.first() {
            m.insert("max_stretch".into(), rod.max_stretch.abs());
        }
        m
    }

    fn reference_tip_at(&self, t: f64) -> Option<[f64; 3]> {
        let r = &self.reference;
        let x = r.rest_tip + r.direction * (r.amplitude * (r.omega * t).sin());
        Some([x.x, x.y, x.z])
    }
}

/// The initial velocity field of the first mode with tip amplitude
/// `amplitude` (m) on a rod along +x, bending towards +z.
fn first_mode_field(length: f64, omega: f64, amplitude: f64) -> RodVelocity {
    let b = FIRST_CANTILEVER_MODE;
    let tip = cantilever_mode(b, 1.0).0;
    let samples = (0..=FIELD_SAMPLES)
        .map(|i| {
            let xi = i as f64 / FIELD_SAMPLES as f64;
            let (phi, dphi) = cantilever_mode(b, xi);
            VelocitySample {
                s: xi * length,
                velocity: Vec3::new(0.0, 0.0, amplitude * omega * phi / tip),
                angular_velocity: Vec3::new(0.0, -amplitude * omega * dphi / (length * tip), 0.0),
            }
        })
        .collect();
    RodVelocity { samples }
}

fn build(p: &VibrationParams, _: &Inputs) -> Result<ScenarioRun, crate::scenario::UsageError> {
    let c = rod_case!(p);
    let mut body = c.body();
    let omega = first_bending_frequency(&body.sections[0], p.length);
    body.initial_velocity = Some(first_mode_field(p.length, omega, p.amplitude));
    let mut scene = Scene::empty(CANTILEVER_VIBRATION.info.id);
    scene.duration = p.duration;
    // The modal kinetic energy, 1/2 rho A (A omega)^2 L int phi^2 / phi(1)^2
    // = rho A L (A omega)^2 / 8 (Blevins' normalisation: int phi^2 = 1,
    // phi(1)^2 = 4): the energy watchdog's scale.
    let energy = body.sections[0].density * body.sections[0].area() * p.length * (p.amplitude * omega).powi(2) / 8.0;
    scene.bodies.push(body.into());
    let reference = Vibration {
        amplitude: p.amplitude,
        omega,
        rest_tip: Vec3::new(p.length, 0.0, 0.0),
        direction: Vec3::z(),
    };
    Ok(ScenarioRun::new(scene, reference, energy, p.length).with_reference_tip([p.length, 0.0, 0.0]))
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

    /// The initial field is the mode: zero at the clamp, the tip speed
    /// `A omega`, the section turning at the slope's rate.
    #[test]
    fn first_mode_field_scales_to_the_amplitude() {
        let f = first_mode_field(1.0, 0.5, 0.01);
        assert_eq!(f.at(0.0).0, Vec3::zeros());
        assert!((f.at(1.0).0.z - 0.005).abs() < 1e-15);
        let (_, w) = f.at(1.0);
        let slope_rate = 0.005 * cantilever_mode(FIRST_CANTILEVER_MODE, 1.0).1 / 2.0;
        assert!((w.y + slope_rate).abs() < 1e-15);
    }
}
