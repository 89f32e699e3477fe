//! The capstan (belt friction) law.

/// The capstan (belt friction) law `T_out / T_in = exp(mu theta)` for a
/// weightless, perfectly flexible rope sliding over a rough curve of total
/// turning angle `theta` (Euler 1762, "Remarques sur l'effet du frottement
/// dans l'equilibre", Mem. Acad. Sci. Berlin 18; independent of the curve's
/// radius).
pub fn capstan_ratio(mu: f64, theta: f64) -> f64 {
    (mu * theta).exp()
}
