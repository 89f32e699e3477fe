//! Kernel weights (dimensionless shapes; the normalisation cancels wherever
//! they are used through a moment matrix).
//!
//! * [`poly6`]: the weight of the elastic moment matrix, the polynomial kernel
//!   Müller et al. (2004, "Point based animation of elastic, plastic and
//!   melting objects", SCA) take from Müller, Charypar & Gross (2003, SCA,
//!   "Particle-based fluid simulation", eq. 20):
//!   `W(r, h) = 315 / (64 pi h^9) (h^2 - r^2)^3` for `r < h`, else 0.
//! * [`cubic_spline`]: the weight of the MLS surface mapping, the cubic spline
//!   of the element-free Galerkin method (Belytschko et al. 1996, "Meshless
//!   methods: an overview and recent developments", CMAME 139, Sec. 2):
//!   with `s = r / R`, `2/3 - 4 s^2 + 4 s^3` for `s <= 1/2`,
//!   `4/3 - 4 s + 4 s^2 - 4/3 s^3` for `1/2 < s <= 1`, 0 beyond.
//!
//! Distances in metres.

/// Poly6 kernel `315 / (64 pi h^9) (h^2 - r^2)^3` for `r < h`, else 0
/// (1/m^3); `r`, `h` in metres.
pub fn poly6(r: f64, h: f64) -> f64 {
    if r >= h {
        return 0.0;
    }
    let q = h * h - r * r;
    315.0 / (64.0 * std::f64::consts::PI * h.powi(9)) * q * q * q
}

/// EFG cubic spline weight of `s = r / radius` (dimensionless, 2/3 at 0,
/// C2, zero from `s = 1` on).
pub fn cubic_spline(r: f64, radius: f64) -> f64 {
    let s = r / radius;
    if s <= 0.5 {
        2.0 / 3.0 - 4.0 * s * s + 4.0 * s * s * s
    } else if s < 1.0 {
        4.0 / 3.0 - 4.0 * s + 4.0 * s * s - 4.0 / 3.0 * s * s * s
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_spline_is_continuous_at_the_knot_and_vanishes_at_the_support() {
        let a = cubic_spline(0.5 - 1e-12, 1.0);
        let b = cubic_spline(0.5 + 1e-12, 1.0);
        // Both branches give 1/6 at s = 1/2; 1e-10 covers the 1e-12 offset times a slope of 2.
        assert!((a - b).abs() < 1e-10 && (a - 1.0 / 6.0).abs() < 1e-10, "a={a} b={b}");
        assert_eq!(cubic_spline(1.0, 1.0), 0.0);
        // The cubic branch at s = 1 - 1e-4 is 4/3 (1e-4)^3 up to rounding.
        assert!(cubic_spline(1.0 - 1e-4, 1.0) < 2e-12);
    }

    #[test]
    fn poly6_integrates_to_one() {
        // Midpoint rule on the radial integral 4 pi int r^2 W dr with 10^4 cells:
        // the error is O(dr^2) ~ 1e-8 relative; 1e-6 leaves margin.
        let h = 0.3;
        let n = 10_000;
        let dr = h / n as f64;
        let s: f64 = (0..n)
            .map(|k| {
                let r = (k as f64 + 0.5) * dr;
                4.0 * std::f64::consts::PI * r * r * poly6(r, h) * dr
            })
            .sum();
        assert!((s - 1.0).abs() < 1e-6, "int W = {s}");
    }
}
