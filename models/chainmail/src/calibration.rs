//! The one fit of the weight mapping ([`crate::mapping`]): the constant `C`
//! of `beta = C w Delta^3 / (E I)` chosen so that the gravity cantilever of
//! [`calibration_scene`] settles to Euler–Bernoulli's tip deflection
//! `q L^4 / (8 E I)` (Timoshenko & Gere, *Mechanics of Materials*,
//! cantilever under uniform load) at the factory's default fidelity.

use crate::mapping::BetaMapping;
use crate::wire::{BoxFrame, ChainmailWire, WireConfig};
use surgbench_core::{DeviceCommand, RodBody, Scene, Vec3};

/// Length of the calibration cantilever (m): not a length any scored scene
/// uses by default.
pub const CALIBRATION_LENGTH: f64 = 0.1;

/// The calibration scene: a 0.1 m cantilever of a steel-like guidewire core
/// (r = 0.5 mm, E = 50 GPa, nu = 0.3, rho = 6450 kg/m^3) clamped at the
/// origin along +x, gravity 9.81 m/s^2 along -z. It is half as long as the
/// scored `cantilever-gravity` (0.2 m) and no comparison runs it: the
/// constant is fitted on a case nothing scores, and `cantilever-gravity`
/// then measures how the fit carries over to another length.
pub fn calibration_scene() -> Scene {
    let mut s = Scene::empty("chainmail-calibration-gravity-cantilever");
    s.bodies
        .push(RodBody::uniform(CALIBRATION_LENGTH, 5e-4, 5e10, 0.3, 6450.0).into());
    s.gravity = Vec3::new(0.0, 0.0, -9.81);
    s
}

/// Euler–Bernoulli tip deflection `q L^4 / (8 E I)` of the calibration
/// scene (m).
pub fn calibration_target() -> f64 {
    let s = calibration_scene();
    let r = s.rods().next().expect("calibration scene has a rod");
    let sec = &r.sections[0];
    let q = sec.density * sec.area() * s.gravity.norm();
    q * r.length.powi(4) / (8.0 * sec.youngs_modulus * sec.second_moment())
}

/// Settled downward tip deflection (m) of the calibration scene at the
/// default fidelity with constant `c`: stepped until no node moves more than
/// `1e-13 m` in a step (at most `max_steps`).
pub fn settled_tip_deflection(c: f64, max_steps: usize) -> Result<f64, String> {
    let s = calibration_scene();
    let cfg = WireConfig {
        segments: crate::DEFAULT_SEGMENTS,
        iterations: crate::DEFAULT_ITERATIONS,
        dt: crate::DEFAULT_DT,
        frame: BoxFrame::World,
        beta_constant: c,
        beta_mapping: BetaMapping::Weight,
        beta_override: None,
        haptic_k: None,
    };
    let rod = s.rods().next().expect("calibration scene has a rod");
    let mut w = ChainmailWire::new(rod, s.gravity, &s.environment, &cfg)?;
    let cmd = DeviceCommand::default();
    for _ in 0..max_steps {
        w.advance(cfg.dt, &cmd).map_err(|e| e.to_string())?;
        if w.max_speed() * cfg.dt < 1e-13 {
            let tip = w.nodes().last().expect("wire has nodes");
            return Ok(-tip.z);
        }
    }
    Err(format!(
        "calibration scene did not settle in {max_steps} steps (C = {c})"
    ))
}

/// Result of [`calibrate_beta_constant`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// The fitted constant `C`.
    pub constant: f64,
    /// Settled tip deflection with it (m).
    pub tip_deflection: f64,
    /// Euler–Bernoulli target (m).
    pub target: f64,
    /// Simulations run.
    pub evaluations: usize,
}

/// Recompute `C`: bisection on `log C` (the settled deflection
/// grows monotonically with `C`) until the bracket is within a relative
/// `1e-6`. Errors if the target is out of reach (the relaxation alone then
/// limits the sag below it whatever the boxes allow).
pub fn calibrate_beta_constant() -> Result<Calibration, String> {
    let target = calibration_target();
    let max_steps = 400_000;
    let (mut lo, mut hi) = (1e-3_f64, 1e9_f64);
    let mut evals = 0;
    let f_hi = settled_tip_deflection(hi, max_steps)?;
    evals += 1;
    if f_hi < target {
        return Err(format!(
            "target {target:.4e} m unreachable: largest settled deflection {f_hi:.4e} m"
        ));
    }
    while hi / lo > 1.0 + 1e-6 {
        let mid = (lo * hi).sqrt();
        let f = settled_tip_deflection(mid, max_steps)?;
        evals += 1;
        if f < target { lo = mid } else { hi = mid }
    }
    let c = (lo * hi).sqrt();
    let d = settled_tip_deflection(c, max_steps)?;
    Ok(Calibration {
        constant: c,
        tip_deflection: d,
        target,
        evaluations: evals + 1,
    })
}
