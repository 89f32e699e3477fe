//! The chain-mail rules as pure functions: the valid box of a neighbour, its
//! projection, the relaxation target and the paper's friction factor.
//!
//! These follow the generalized 3D chain-mail guidewire paper (after Gibson
//! 1997, "3D ChainMail", and Li & Brodlie 2003, "Soft object modelling with
//! generalised ChainMail"). Lengths are in metres; `alpha_min`, `alpha_max`
//! and `beta` are dimensionless.

use surgbench_core::{Mat3, Vec3};

/// Constraint parameters of one link (dimensionless).
///
/// A neighbour at rest difference `d` from its sponsor may move, along each
/// box axis, between `alpha_min |d_a|` and `alpha_max |d_a|` (compression and
/// stretch), widened by `beta` times the sum of the other two rest
/// differences (shear). `beta = 0` is rigid in shear; larger is softer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkParams {
    /// Compression limit, `0 < alpha_min <= 1`.
    pub alpha_min: f64,
    /// Stretch limit, `alpha_max >= 1`.
    pub alpha_max: f64,
    /// Shear limit, `beta >= 0`.
    pub beta: f64,
}

impl LinkParams {
    /// Rigid link: no compression, stretch or shear.
    pub const RIGID: LinkParams = LinkParams {
        alpha_min: 1.0,
        alpha_max: 1.0,
        beta: 0.0,
    };

    /// Check the ranges; the message names the bad value.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.alpha_min > 0.0 && self.alpha_min <= 1.0) {
            return Err(format!("alpha_min must be in (0, 1], got {}", self.alpha_min));
        }
        if !(self.alpha_max >= 1.0 && self.alpha_max.is_finite()) {
            return Err(format!("alpha_max must be >= 1 and finite, got {}", self.alpha_max));
        }
        if !(self.beta >= 0.0 && self.beta.is_finite()) {
            return Err(format!("beta must be >= 0 and finite, got {}", self.beta));
        }
        Ok(())
    }
}

/// The valid box of a neighbour relative to its (moved) sponsor, as
/// per-axis `(lo, hi)` offsets (m) in the box frame.
///
/// `rest_diff` is the neighbour's rest position minus the sponsor's, in the
/// box frame. For axis x with `dx = |rest_diff.x|`, `s = dy + dz`:
/// - neighbour on the positive side: `[alpha_min dx - beta s, alpha_max dx + beta s]`;
/// - negative side (mirrored): `[-(alpha_max dx + beta s), -(alpha_min dx - beta s)]`;
///
/// and cyclically for y, z (the paper's valid-region equations).
pub fn valid_box(rest_diff: &Vec3, p: &LinkParams) -> [(f64, f64); 3] {
    let a = rest_diff.map(f64::abs);
    let mut out = [(0.0, 0.0); 3];
    for k in 0..3 {
        let d = a[k];
        let s = a[(k + 1) % 3] + a[(k + 2) % 3];
        let lo = p.alpha_min * d - p.beta * s;
        let hi = p.alpha_max * d + p.beta * s;
        out[k] = if rest_diff[k] >= 0.0 { (lo, hi) } else { (-hi, -lo) };
    }
    out
}

/// Move `neighbour` to the nearest point of its valid box around `sponsor`.
///
/// `frame` holds the box axes as columns (identity for the paper's world
/// axes); `rest_diff` is expressed in that frame. Returns the new position
/// and whether it moved. Because the box is axis-aligned in `frame`, the
/// nearest point is the per-axis clamp. A neighbour within rounding
/// (`1e-12 |rest_diff|`) of its box counts as valid and does not move, so
/// that exact boxes (`alpha = 1`, `beta = 0`) do not propagate rounding noise.
pub fn project_into_box(
    sponsor: &Vec3,
    neighbour: &Vec3,
    rest_diff: &Vec3,
    frame: &Mat3,
    p: &LinkParams,
) -> (Vec3, bool) {
    let q = frame.tr_mul(&(neighbour - sponsor));
    let b = valid_box(rest_diff, p);
    let mut c = q;
    for k in 0..3 {
        c[k] = q[k].clamp(b[k].0, b[k].1);
    }
    if (c - q).norm() <= 1e-12 * rest_diff.norm() {
        (*neighbour, false)
    } else {
        (sponsor + frame * c, true)
    }
}

/// How far `neighbour` lies outside its box around `sponsor` (m, 0 inside):
/// the Euclidean distance to the box, used as the constraint residual.
pub fn box_violation(sponsor: &Vec3, neighbour: &Vec3, rest_diff: &Vec3, frame: &Mat3, p: &LinkParams) -> f64 {
    let q = frame.tr_mul(&(neighbour - sponsor));
    let b = valid_box(rest_diff, p);
    let mut s = 0.0;
    for k in 0..3 {
        let e = (b[k].0 - q[k]).max(q[k] - b[k].1).max(0.0);
        s += e * e;
    }
    s.sqrt()
}

/// The shape-preserving position of an element from its neighbours'
/// predictions `Q_i = P_i* + delta_i`: `P* = mean(Q_i)`, the minimizer of
/// `sum ||P* - Q_i||^2` (the paper's physical-optimization step).
pub fn relaxation_target(predictions: &[Vec3]) -> Vec3 {
    let mut s = Vec3::zeros();
    for q in predictions {
        s += q;
    }
    s / predictions.len().max(1) as f64
}

/// The paper's Coulomb friction factor
/// `beta_f = -max((|dp_t| - C_f |dp_n|) / |dp_t|, 0)`, in `[-1, 0]`.
///
/// `dp_t` is the tangential motion of a contact element, `dp_n` its normal
/// collision correction (both m), `0 <= C_f <= 1`. A contact keeps the
/// tangential motion `-beta_f dp_t`: `C_f = 0` keeps it all (frictionless,
/// `beta_f = -1`), `C_f |dp_n| >= |dp_t|` keeps none (sticks, `beta_f = 0`).
/// Zero tangential motion gives `0` (nothing to resist).
pub fn friction_factor(dp_t: f64, dp_n: f64, c_f: f64) -> f64 {
    if dp_t <= 0.0 {
        return 0.0;
    }
    -((dp_t - c_f * dp_n) / dp_t).max(0.0)
}

/// The friction displacement added to a contact element:
/// `-(1 + beta_f) dp_t` (m), so that its tangential motion becomes
/// `-beta_f dp_t`.
///
/// The paper writes `F_friction = (beta_f - 1) dp_t`; taken literally that
/// is `-2 dp_t` at `C_f = 0` (a frictionless contact would reverse the
/// motion), so we read it as the correction that leaves `-beta_f dp_t`, the
/// only reading consistent with the stated limits (`C_f = 0` frictionless,
/// large `C_f` sticks).
pub fn friction_correction(dp_t: &Vec3, dp_n: f64, c_f: f64) -> Vec3 {
    let bf = friction_factor(dp_t.norm(), dp_n, c_f);
    -(1.0 + bf) * dp_t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_positive_side_matches_paper_formula() {
        // sponsor at origin, neighbour at rest (+0.3, -0.1, 0.2)
        let p = LinkParams {
            alpha_min: 0.8,
            alpha_max: 1.3,
            beta: 0.25,
        };
        let d = Vec3::new(0.3, -0.1, 0.2);
        let b = valid_box(&d, &p);
        // x: positive side, dx=0.3, dy+dz=0.3
        assert!((b[0].0 - (0.8 * 0.3 - 0.25 * 0.3)).abs() < 1e-15, "{b:?}");
        assert!((b[0].1 - (1.3 * 0.3 + 0.25 * 0.3)).abs() < 1e-15, "{b:?}");
        // y: negative side, dy=0.1, dz+dx=0.5: mirrored bounds
        assert!((b[1].0 + (1.3 * 0.1 + 0.25 * 0.5)).abs() < 1e-15, "{b:?}");
        assert!((b[1].1 + (0.8 * 0.1 - 0.25 * 0.5)).abs() < 1e-15, "{b:?}");
        // z: positive side, dz=0.2, dx+dy=0.4
        assert!((b[2].0 - (0.8 * 0.2 - 0.25 * 0.4)).abs() < 1e-15, "{b:?}");
    }
}
