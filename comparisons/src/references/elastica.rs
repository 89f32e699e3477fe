//! Reference solutions for clamped cantilevers: Euler–Bernoulli closed forms
//! and the planar Kirchhoff elastica solved by shooting.
//!
//! The elastica: an inextensible, unshearable rod clamped at `s = 0` along
//! +x, loaded by a uniform weight `q` (N/m) and a dead tip force `P` (N),
//! both along -z. With the tangent angle `phi(s)` measured from +x towards
//! +z, `x' = cos phi`, `z' = sin phi`, and the bending moment about +y
//! `mu = EI phi'`, the balance of moments of the part beyond `s`
//! (Antman, *Nonlinear Problems of Elasticity*, ch. 4, eq. 4.1.5 in the
//! planar case) gives
//!
//! ```text
//! mu'(s) = (q (L - s) + P) cos phi(s),   phi(0) = 0,   mu(L) = 0.
//! ```
//!
//! The unknown base moment `mu(0)` is found by a secant/bisection shooting
//! on `mu(L) = 0`, integrating with classical RK4 on a fine grid. With
//! `q = 0` this reproduces the tables of Bisshopp & Drucker (1945), "Large
//! deflection of cantilever beams", Quart. Appl. Math. 3:272-275 (checked in
//! the tests).

/// Euler–Bernoulli tip deflection of a cantilever under uniform load `q`
/// (N/m): `w(L) = q L^4 / (8 E I)` (m, positive along the load).
pub fn eb_uniform_tip(q: f64, l: f64, ei: f64) -> f64 {
    q * l.powi(4) / (8.0 * ei)
}

/// Euler–Bernoulli deflection at `x` of a cantilever under uniform load `q`:
/// `w(x) = q x^2 (6 L^2 - 4 L x + x^2) / (24 E I)` (m).
pub fn eb_uniform(q: f64, l: f64, ei: f64, x: f64) -> f64 {
    q * x * x * (6.0 * l * l - 4.0 * l * x + x * x) / (24.0 * ei)
}

/// Euler–Bernoulli deflection at `x` under a tip force `P`:
/// `w(x) = P x^2 (3 L - x) / (6 E I)` (m).
pub fn eb_tip_force(p: f64, l: f64, ei: f64, x: f64) -> f64 {
    p * x * x * (3.0 * l - x) / (6.0 * ei)
}

/// The solved elastica: samples of the deformed centerline.
#[derive(Debug, Clone)]
pub struct Elastica {
    /// Length (m).
    pub length: f64,
    /// Arclength samples (m), uniform, `s[0] = 0`, `s[last] = L`.
    pub s: Vec<f64>,
    /// x coordinate at each sample (m).
    pub x: Vec<f64>,
    /// z coordinate at each sample (m), negative when sagging.
    pub z: Vec<f64>,
    /// Tangent angle (rad), negative when sagging.
    pub phi: Vec<f64>,
    /// Bending moment `EI phi'` at the base (N m).
    pub base_moment: f64,
    /// Residual `|mu(L)|` at the solution (N m).
    pub residual: f64,
}

impl Elastica {
    /// Position `(x, z)` at arclength `s` by cubic Hermite interpolation
    /// between samples (tangent `(cos phi, sin phi)`), accurate to O(h^4).
    pub fn at(&self, s: f64) -> (f64, f64) {
        let n = self.s.len() - 1;
        let h = self.length / n as f64;
        let s = s.clamp(0.0, self.length);
        let i = ((s / h).floor() as usize).min(n - 1);
        let t = (s - self.s[i]) / h;
        let (h00, h10, h01, h11) = (
            2.0 * t * t * t - 3.0 * t * t + 1.0,
            t * t * t - 2.0 * t * t + t,
            -2.0 * t * t * t + 3.0 * t * t,
            t * t * t - t * t,
        );
        let x = h00 * self.x[i] + h10 * h * self.phi[i].cos() + h01 * self.x[i + 1] + h11 * h * self.phi[i + 1].cos();
        let z = h00 * self.z[i] + h10 * h * self.phi[i].sin() + h01 * self.z[i + 1] + h11 * h * self.phi[i + 1].sin();
        (x, z)
    }

    /// Tip position `(x, z)` (m).
    pub fn tip(&self) -> (f64, f64) {
        (*self.x.last().unwrap(), *self.z.last().unwrap())
    }

    /// Tip angle (rad).
    pub fn tip_angle(&self) -> f64 {
        *self.phi.last().unwrap()
    }
}

/// Shooting failed (loads beyond what the bracket search handles).
#[derive(Debug, Clone, PartialEq)]
pub struct ShootingError(pub String);

impl std::fmt::Display for ShootingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "elastica shooting failed: {}", self.0)
    }
}

impl std::error::Error for ShootingError {}

/// Integrate from the clamp with base moment `mu0`; returns `mu(L)` and,
/// if `keep`, the samples.
fn integrate(l: f64, ei: f64, q: f64, p: f64, mu0: f64, n: usize, keep: bool) -> (f64, Option<Elastica>) {
    // State y = (u, z, phi, mu) with the foreshortening u = s - x:
    // y' = (1 - cos phi, sin phi, mu/EI, (q (L-s) + P) cos phi), and
    // 1 - cos phi = 2 sin^2(phi/2) without cancellation. Integrating x
    // itself summed n rounding errors of order eps L into x, which at tiny
    // deflections (E = 1e20: w = 1.3e-13 m) were 5 % of the deflection.
    let f = |s: f64, y: [f64; 4]| -> [f64; 4] {
        let c = y[2].cos();
        let half = (0.5 * y[2]).sin();
        [2.0 * half * half, y[2].sin(), y[3] / ei, (q * (l - s) + p) * c]
    };
    let h = l / n as f64;
    let mut y = [0.0, 0.0, 0.0, mu0];
    let mut out = keep.then(|| Elastica {
        length: l,
        s: Vec::with_capacity(n + 1),
        x: Vec::with_capacity(n + 1),
        z: Vec::with_capacity(n + 1),
        phi: Vec::with_capacity(n + 1),
        base_moment: mu0,
        residual: 0.0,
    });
    let push = |o: &mut Option<Elastica>, s: f64, y: &[f64; 4]| {
        if let Some(e) = o {
            e.s.push(s);
            e.x.push(s - y[0]);
            e.z.push(y[1]);
            e.phi.push(y[2]);
        }
    };
    push(&mut out, 0.0, &y);
    for i in 0..n {
        let s = i as f64 * h;
        let k1 = f(s, y);
        let k2 = f(s + h / 2.0, std::array::from_fn(|j| y[j] + h / 2.0 * k1[j]));
        let k3 = f(s + h / 2.0, std::array::from_fn(|j| y[j] + h / 2.0 * k2[j]));
        let k4 = f(s + h, std::array::from_fn(|j| y[j] + h * k3[j]));
        for j in 0..4 {
            y[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
        }
        push(&mut out, (i + 1) as f64 * h, &y);
    }
    if let Some(e) = &mut out {
        e.residual = y[3].abs();
    }
    (y[3], out)
}

/// Solve the clamped elastica under uniform load `q` (N/m) and tip force `p`
/// (N), both along -z, for a rod of length `l` (m) and bending stiffness
/// `ei` (N m^2). `n` RK4 steps (4000 gives ~1e-13 relative accuracy on
/// smooth loads; the tests check it against n = 8000).
pub fn solve(l: f64, ei: f64, q: f64, p: f64, n: usize) -> Result<Elastica, ShootingError> {
    if !(l > 0.0 && ei > 0.0 && q >= 0.0 && p >= 0.0 && n >= 2) {
        return Err(ShootingError(format!("bad input l={l} ei={ei} q={q} p={p} n={n}")));
    }
    // mu0 in [-(qL^2/2 + PL), 0]: the base moment of the sagging rod is
    // negative (phi decreases) and bounded by the small-deflection moment,
    // which the foreshortened moment arm can only reduce.
    let m_max = q * l * l / 2.0 + p * l;
    if m_max == 0.0 {
        return Ok(integrate(l, ei, q, p, 0.0, n, true).1.expect("kept"));
    }
    let g = |mu0: f64| integrate(l, ei, q, p, mu0, n, false).0;
    let (mut a, mut b) = (-m_max * (1.0 + 1e-9), 0.0);
    let (mut ga, mut gb) = (g(a), g(b));
    if ga * gb > 0.0 {
        return Err(ShootingError(format!(
            "no sign change of mu(L) on [{a}, {b}]: {ga}, {gb}"
        )));
    }
    // Illinois-modified regula falsi: bracketing, superlinear.
    let tol = 1e-14 * m_max;
    let mut side = 0i8;
    for _ in 0..200 {
        let c = (a * gb - b * ga) / (gb - ga);
        let gc = g(c);
        if gc.abs() <= tol || (b - a).abs() <= 1e-15 * m_max {
            let mut e = integrate(l, ei, q, p, c, n, true).1.expect("kept");
            e.base_moment = c;
            return Ok(e);
        }
        if gc * gb > 0.0 {
            b = c;
            gb = gc;
            if side == -1 {
                ga /= 2.0;
            }
            side = -1;
        } else {
            a = c;
            ga = gc;
            if side == 1 {
                gb /= 2.0;
            }
            side = 1;
        }
    }
    Err(ShootingError("no convergence in 200 iterations".into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At a tiny deflection (a 0.5 mm radius wire at E = 1e20: EI = 4.9e6 N m^2)
    /// the tip is Euler-Bernoulli's to 1e-6 (the nonlinear correction is
    /// (w/L)^2 ~ 1e-24) and x is L to a few rounding errors of L: the
    /// foreshortening is integrated, not x itself.
    #[test]
    fn tiny_deflections_are_exact_to_rounding() {
        let (l, ei, q) = (0.1, 1e20 * 4.9e-14, 0.05);
        let e = solve(l, ei, q, 0.0, 4000).unwrap();
        let (x, z) = e.tip();
        let eb = eb_uniform_tip(q, l, ei);
        assert!(((-z - eb) / eb).abs() < 1e-6, "z {z} vs {eb}");
        assert!((x - l).abs() <= 4.0 * f64::EPSILON * l, "x {x}");
    }

    /// Bisshopp & Drucker (1945): alpha = P L^2 / (E I) and the vertical
    /// tip deflection delta/L, to four digits (the same values are
    /// reproduced in Mattiasson 1981, Int. J. Numer. Meth. Eng. 17:145-153).
    const DEFLECTION: [(f64, f64); 6] = [
        (1.0, 0.3017),
        (2.0, 0.4935),
        (3.0, 0.6033),
        (4.0, 0.6700),
        (5.0, 0.7138),
        (10.0, 0.8106),
    ];
    /// The same tables: horizontal tip position x/L (four digits).
    const HORIZONTAL: [(f64, f64); 3] = [(1.0, 0.9436), (2.0, 0.8394), (10.0, 0.4450)];

    #[test]
    fn tip_load_matches_bisshopp_drucker_table() {
        // The tables carry four digits: half a unit of the last digit, plus
        // 1e-5 for the rounding of the tabulated alpha-series itself.
        let tol = 0.6e-4;
        for &(alpha, dv) in &DEFLECTION {
            let e = solve(1.0, 1.0, 0.0, alpha, 4000).unwrap();
            let z = e.tip().1;
            assert!((-z - dv).abs() <= tol, "alpha={alpha}: delta/L={} vs table {dv}", -z);
        }
        for &(alpha, xh) in &HORIZONTAL {
            let e = solve(1.0, 1.0, 0.0, alpha, 4000).unwrap();
            let x = e.tip().0;
            assert!((x - xh).abs() <= tol, "alpha={alpha}: x/L={x} vs table {xh}");
        }
    }

    #[test]
    fn solution_is_converged_to_1e_10() {
        // RK4 is 4th order: halving h changes the tip by ~1/16 of the error.
        for (q, p) in [(3.0, 0.0), (0.0, 3.0), (2.0, 1.0)] {
            let a = solve(1.0, 1.0, q, p, 4000).unwrap();
            let b = solve(1.0, 1.0, q, p, 8000).unwrap();
            let (xa, za) = a.tip();
            let (xb, zb) = b.tip();
            let d = ((xa - xb).powi(2) + (za - zb).powi(2)).sqrt();
            assert!(d < 1e-10, "q={q} p={p}: tip moved {d} between n=4000 and 8000");
            assert!(a.residual < 1e-12, "residual {}", a.residual);
        }
    }

    #[test]
    fn small_load_reduces_to_euler_bernoulli() {
        // Geometric nonlinearity enters at second order in the load:
        // relative difference ~ (w/L)^2, here w/L ~ 1e-4.
        let (l, ei): (f64, f64) = (0.5, 2.0);
        let q = 8.0 * ei * 1e-4 / l.powi(3);
        let e = solve(l, ei, q, 0.0, 2000).unwrap();
        let w = -e.tip().1;
        let eb = eb_uniform_tip(q, l, ei);
        assert!(((w - eb) / eb).abs() < 1e-6, "w={w} eb={eb}");
        for k in 1..=4 {
            let s = l * k as f64 / 4.0;
            let (_, z) = e.at(s);
            let r = eb_uniform(q, l, ei, s);
            assert!((-z - r).abs() < 1e-6 * eb, "s={s}: {} vs {r}", -z);
        }
        let p = 3.0 * ei * 1e-4 / (l * l);
        let e = solve(l, ei, 0.0, p, 2000).unwrap();
        let wp = eb_tip_force(p, l, ei, l);
        assert!(((-e.tip().1 - wp) / wp).abs() < 1e-6);
    }

    #[test]
    fn hermite_interpolation_is_accurate_between_samples() {
        let coarse = solve(1.0, 1.0, 2.0, 1.0, 400).unwrap();
        let fine = solve(1.0, 1.0, 2.0, 1.0, 4000).unwrap();
        for k in 0..37 {
            let s = 0.0137 + k as f64 * 0.0269;
            let (xa, za) = coarse.at(s);
            let (xb, zb) = fine.at(s);
            // O(h^4) Hermite on h = 2.5e-3 plus RK4 error: well under 1e-9.
            assert!((xa - xb).abs() < 1e-9 && (za - zb).abs() < 1e-9, "s={s}");
        }
    }
}
