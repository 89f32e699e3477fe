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

use super::super::oscillation::VibrationTrack;
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

impl Reference for Vibration {
    fn scorer<'a>(&'a self, _scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(VibrationScorer {
            reference: *self,
            track: VibrationTrack::new(self.amplitude, self.omega),
        })
    }
}

/// Per-run sums of one vibration run.
struct VibrationScorer {
    reference: Vibration,
    track: VibrationTrack,
}

impl Scorer for VibrationScorer {
    fn observe_step(&mut self, obs: &Observation) {
        if let Some(r) = obs.rods.first() {
            let v = &self.reference;
            self.track.push(obs.time, (r.tip() - v.rest_tip).dot(&v.direction));
        }
    }

    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        self.track.metrics(&mut m);
        if let Some(rod) = obs.rods.first() {
            m.insert("max_stretch".into(), rod.max_stretch.abs());
        }
        m
    }

    fn reference_tip_at(&self, t: f64) -> Option<[f64; 3]> {
        let r = &self.reference;
        let x = r.rest_tip + r.direction * self.track.reference_at(t);
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
