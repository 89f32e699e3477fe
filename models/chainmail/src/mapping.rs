//! From SI material parameters to the chain-mail's `alpha_min`, `alpha_max`,
//! `beta`, and the calibration of its one free constant.
//!
//! A chain-mail has no Young's modulus and no force scale, so the mapping
//! brings its own: the wire's weight per length under standard gravity,
//! `w = rho A g_ref` (N/m, `g_ref = 9.80665 m/s^2` whatever the scene's
//! gravity). Per link of rest length `Delta` (m), with `E I` the bending and
//! `E A` the axial stiffness of the section at the link's midpoint:
//!
//! - shear (bending) `beta = C * w Delta^3 / (E I)`: the dimensionless
//!   flexibility of one link under that reference load;
//! - stretch/compression `alpha_max - 1 = 1 - alpha_min = C * w Delta / (E A)`,
//!   the axial analogue with the same `C` (about `1e-6`: nearly inextensible).
//!
//! `C` is fitted once on **one scene**, the gravity cantilever of
//! [`crate::calibration::calibration_scene`] at the factory's default fidelity, so that the
//! settled tip deflection equals Euler–Bernoulli's `q L^4 / (8 E I)`
//! (Timoshenko & Gere, *Mechanics of Materials*, cantilever under uniform
//! load). It is then used unchanged on every scene and fidelity. The
//! calibration case (L = 0.1 m, r = 0.5 mm, E = 50 GPa, rho = 6450 kg/m^3,
//! segments 20) is not a scored scene: `cantilever-gravity` is the same wire
//! at 0.2 m, so its error measures how the fit carries over to another
//! length (and, at a fixed segment count, another link length). Fitted at
//! 0.1 m, `C` comes out as the 0.2 m fit did to 7 digits: where the boxes
//! bind, each link turns by its box limit `~ beta ~ Delta^3`, so at a fixed
//! segment count the sag scales as `n Delta Delta^3 ~ L^4`, Euler–Bernoulli's
//! scaling, and the constant does not depend on the length. It does depend
//! on the segment count and the time step (`g dt^2` per step against the
//! relaxation): sag over Euler–Bernoulli is 0.138 at 40 segments and 0.685
//! at dt = 1 ms on the calibration case (`tests/rules.rs`). The mapping is
//! resolution-bound, and `surgbench list` says so. [`crate::calibration::calibrate_beta_constant`] recomputes it; a test checks it
//! against the committed [`BETA_CONSTANT`].
//!
//! # Two mappings ([`BetaMapping`], fidelity extra `beta_mapping`)
//!
//! A geometric model has no single right mapping: the load scale decides
//! what the boxes mean. Two are offered so that a report can show the
//! trade-off:
//!
//! - `0` ([`BetaMapping::Weight`], default): the weight-calibrated mapping
//!   above. Right sag on the gravity cantilever it was fitted to, but with
//!   the wire's weight as load scale a 50 GPa, r = 0.445 mm body may turn by
//!   about 0.2 deg per 5 mm link (minimum bend radius ~1.3 m): it cannot
//!   follow a vessel.
//! - `1` ([`BetaMapping::Navigation`]): the box admits, per link, the bend of
//!   the largest elastic curvature the section can take,
//!   `kappa_max = eps_y / r` (surface strain `eps_y` at the radius `r` of a
//!   bent solid circle, Euler–Bernoulli `eps = kappa r`), so the per-link
//!   turning limit is `theta = Delta kappa_max` ([`bend_limit`]). The exact
//!   box for it follows from [`crate::rules::valid_box`]: with rest offset
//!   `(Delta, 0, 0)` in the sponsor's box frame the box is
//!   `[alpha_min Delta, alpha_max Delta] x [-beta Delta, beta Delta]^2`. The
//!   wire is axially rigid at navigation loads (`T / (E A)` ~ `6e-5` at 2 N
//!   for the 0.89 mm nitinol wire), so `alpha_min = alpha_max = 1`, and the
//!   link on the box edge `(Delta, beta Delta, 0)` turns by `atan(beta)`:
//!   `beta = tan theta` ([`navigation_link_params`]; a neighbour past that
//!   edge in its bend plane projects onto it, test
//!   `navigation_box_edge_is_the_intended_bend`).
//!   The price is the box's axis-aligned shape: a link turned by `phi` is
//!   `1 / cos phi` times its rest length (1 % at the 8 deg per 5 mm link of
//!   a 35 mm arch; 27 % at the limit `theta` = 39 deg of the 0.89 mm wire's
//!   5 mm links), and the square cross-section lets a link turn by
//!   `atan(sqrt 2 tan theta)` towards a diagonal. `theta` is capped at
//!   [`MAX_BEND_PER_LINK`] = 45 deg (`beta = 1`).
//!   (The other exact box, `beta = sin theta`, `alpha_min = cos theta`, keeps
//!   a link at the edge inextensible but lets every straight link shorten to
//!   `cos theta`: measured on `arch-insertion`, a straight push then
//!   compresses the first links by 5 % before any contact, at 0.18 s.)
//!   `eps_y` is a stated constant, [`NITINOL_RECOVERABLE_STRAIN`] = 6 % by
//!   default (extra `yield_strain` overrides it, e.g. 0.004 for stainless
//!   steel). **Nothing is fitted**: no constant of this mapping is
//!   calibrated on any scenario, so it is scored on all of them.

use crate::rules::LinkParams;
use surgbench_core::RodSection;

/// Reference gravity of the mapping's load scale (m/s^2).
pub const G_REF: f64 = 9.80665;

/// Calibrated `C` (computed in the paper's world-axis frame; the
/// base-clamp frame is identical on the calibration scene, so it shares it).
pub const BETA_CONSTANT: f64 = 1214.297;

/// The load parameter `w Delta^3 / (E I)` of one link (dimensionless).
pub fn load_parameter(sec: &RodSection, delta: f64) -> f64 {
    sec.density * sec.area() * G_REF * delta.powi(3) / (sec.youngs_modulus * sec.second_moment())
}

/// Link parameters for a section and link length with constant `c`.
/// `alpha_min` is floored at 0.01 so that a link never collapses.
pub fn link_params(sec: &RodSection, delta: f64, c: f64) -> LinkParams {
    let w = sec.density * sec.area() * G_REF;
    let eps = c * w * delta / (sec.youngs_modulus * sec.area());
    LinkParams {
        alpha_min: (1.0 - eps).max(0.01),
        alpha_max: 1.0 + eps,
        beta: c * load_parameter(sec, delta),
    }
}

/// Recoverable (elastic + superelastic) strain of the default guidewire core
/// material, used by [`BetaMapping::Navigation`]: 6 %.
///
/// Superelastic nitinol recovers strains of 6-8 % on unloading, against
/// well under 1 % for stainless steel (Duerig, Pelton & Stöckel 1999,
/// "An overview of nitinol medical applications", *Materials Science and
/// Engineering A* 273-275, 149-160); the lower end is taken because the
/// navigation scenarios' wires are nitinol-like (50 GPa body) and the
/// plateau ends near 6 %. For a stainless core (~0.2-0.5 %) pass
/// `yield_strain`.
pub const NITINOL_RECOVERABLE_STRAIN: f64 = 0.06;

/// Largest per-link turning the navigation mapping admits (rad): 45 deg,
/// `beta = 1`. Past it a link on its box edge is more than 41 % longer than
/// at rest and the chain no longer resolves a curve.
pub const MAX_BEND_PER_LINK: f64 = std::f64::consts::FRAC_PI_4;

/// How the material parameters become `alpha_min`, `alpha_max`, `beta`
/// (fidelity extra `beta_mapping`: `weight` or `navigation`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BetaMapping {
    /// `weight`: load scale = the wire's weight, one constant `C` calibrated on
    /// the gravity cantilever ([`link_params`]).
    Weight,
    /// `navigation`: bend limit per link from the largest elastic curvature
    /// `eps_y / r` of the section ([`navigation_link_params`]); nothing
    /// fitted.
    Navigation {
        /// Recoverable strain `eps_y` of the core (dimensionless, > 0).
        yield_strain: f64,
    },
}

impl BetaMapping {
    /// The navigation mapping (fidelity `beta_mapping = "navigation"`) for
    /// the core's recoverable strain `yield_strain` (fidelity extra of the
    /// same name); an error names a value outside (0, 1).
    pub fn navigation(yield_strain: f64) -> Result<BetaMapping, String> {
        if !(yield_strain > 0.0 && yield_strain < 1.0) {
            return Err(format!("yield_strain must be in (0, 1), got {yield_strain}"));
        }
        Ok(BetaMapping::Navigation { yield_strain })
    }

    /// Link parameters of a section and link length `delta` (m) under this
    /// mapping; `c` is the weight mapping's constant (unused by the navigation mapping).
    pub fn link_params(&self, sec: &RodSection, delta: f64, c: f64) -> LinkParams {
        match *self {
            BetaMapping::Weight => link_params(sec, delta, c),
            BetaMapping::Navigation { yield_strain } => navigation_link_params(sec, delta, yield_strain),
        }
    }
}

/// Per-link turning limit of the navigation mapping (rad):
/// `theta = Delta eps_y / r`, the turning of a link of length `Delta` (m) at
/// the largest elastic curvature `kappa_max = eps_y / r` of a solid circle of
/// radius `r` (bending strain `kappa r` at the surface), capped at
/// [`MAX_BEND_PER_LINK`].
pub fn bend_limit(sec: &RodSection, delta: f64, yield_strain: f64) -> f64 {
    (delta * yield_strain / sec.radius).min(MAX_BEND_PER_LINK)
}

/// The navigation mapping's box: `beta = tan theta`,
/// `alpha_min = alpha_max = 1`, with `theta` from [`bend_limit`]. The box
/// edge `(Delta, Delta tan theta, 0)` is then a link turned by exactly
/// `theta` (of length `Delta / cos theta`).
pub fn navigation_link_params(sec: &RodSection, delta: f64, yield_strain: f64) -> LinkParams {
    LinkParams {
        alpha_min: 1.0,
        alpha_max: 1.0,
        beta: bend_limit(sec, delta, yield_strain).tan(),
    }
}

/// Largest turning (rad) of a link of length `len` (m) whose rest offset is
/// `(delta, 0, 0)` in its box frame, turning within one box plane: the box
/// limits the lateral offset to `beta delta` and the axial one to
/// `[alpha_min delta, alpha_max delta]`, so the angle is
/// `atan2(min(beta delta, len), sqrt(len^2 - lateral^2))` when that axial
/// length fits in the box, and `acos(alpha_min delta / len)` when the
/// compression limit binds first. `None` if no point of the box has length
/// `len`. The closed form against which the mappings are tested.
pub fn max_bend_in_box(p: &LinkParams, delta: f64, len: f64) -> Option<f64> {
    let lat = (p.beta * delta).min(len);
    let ax = (len * len - lat * lat).sqrt();
    let (lo, hi) = (p.alpha_min * delta, p.alpha_max * delta);
    if ax > hi * (1.0 + 1e-12) {
        // even the widest lateral offset leaves the link too long
        return None;
    }
    if ax >= lo {
        Some(lat.atan2(ax))
    } else if len >= lo {
        Some((lo / len).min(1.0).acos())
    } else {
        None
    }
}
