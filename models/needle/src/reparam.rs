//! Needle reparameterization (Chentanez et al. 2009, Sec. 3.4): when the
//! tip remeshing moves the needle's coupling nodes, the rod's nodes are
//! placed anew along its arclength and its fields carried over: Akima
//! interpolation ([`Akima`], Akima 1970) for the smooth ones (twist, rest
//! curvature, cumulative rest length, positions), linear for velocity and
//! acceleration ([`linear`]). Edges that are not held at both ends are
//! merged when shorter than half the smallest initial edge and split when
//! longer than four times the largest ([`resample`]).
//!
//! Arclengths in m; the fields in their own units.

/// Akima's interpolant (H. Akima, "A new method of interpolation and smooth
/// curve fitting based on local procedures", J. ACM 17(4), 1970): a cubic
/// Hermite curve whose slope at each point weighs the two neighbouring
/// chord slopes by how much the slopes beyond them change, so that it
/// follows the data without the wiggles of a global spline:
///
/// `t_i = (|m_{i+1} - m_i| m_{i-1} + |m_{i-1} - m_{i-2}| m_i) /
///        (|m_{i+1} - m_i| + |m_{i-1} - m_{i-2}|)`,
///
/// `m_i` the chord slope of `[x_i, x_{i+1}]`, the mean of `m_{i-1}` and
/// `m_i` when both weights vanish, and two chord slopes added past each
/// end by Akima's extrapolation `m_{-1} = 2 m_0 - m_1` (the data's
/// parabola continued).
///
/// By construction it is exact for straight lines (any spacing) and for
/// parabolas on equal spacing, and three collinear points keep the curve
/// straight between them (no overshoot next to a flat stretch). It does not
/// reproduce cubics in general: through `x^3` at `-2..2` its slope at 0 is
/// 1, not 0.
#[derive(Debug, Clone, PartialEq)]
pub struct Akima {
    x: Vec<f64>,
    y: Vec<f64>,
    t: Vec<f64>,
}

impl Akima {
    /// Through the points `(x_i, y_i)`, `x` strictly increasing, at least two.
    pub fn new(x: &[f64], y: &[f64]) -> Result<Self, String> {
        let n = x.len();
        if n < 2 || y.len() != n {
            return Err(format!(
                "Akima needs two or more points with one value each (got {n} and {})",
                y.len()
            ));
        }
        if x.iter().chain(y).any(|v| !v.is_finite()) || x.windows(2).any(|w| w[1] <= w[0]) {
            return Err("Akima needs finite values at strictly increasing abscissae".into());
        }
        // Chord slopes with two extrapolated past each end: m[k + 2] is
        // the slope of [x_k, x_{k+1}].
        let mut m = vec![0.0; n + 3];
        for k in 0..n - 1 {
            m[k + 2] = (y[k + 1] - y[k]) / (x[k + 1] - x[k]);
        }
        if n == 2 {
            m[1] = m[2];
            m[3] = m[2];
        } else {
            m[1] = 2.0 * m[2] - m[3];
            m[n + 1] = 2.0 * m[n] - m[n - 1];
        }
        m[0] = 2.0 * m[1] - m[2];
        m[n + 2] = 2.0 * m[n + 1] - m[n];
        let t = (0..n)
            .map(|i| {
                // Around point i: m[i] = m_{i-2}, m[i+1] = m_{i-1}, m[i+2] = m_i, m[i+3] = m_{i+1}.
                let w1 = (m[i + 3] - m[i + 2]).abs();
                let w2 = (m[i + 1] - m[i]).abs();
                if w1 + w2 == 0.0 {
                    0.5 * (m[i + 1] + m[i + 2])
                } else {
                    (w1 * m[i + 1] + w2 * m[i + 2]) / (w1 + w2)
                }
            })
            .collect();
        Ok(Self {
            x: x.to_vec(),
            y: y.to_vec(),
            t,
        })
    }

    /// The interval's index and the local coordinate in it; outside the
    /// data the end cubic continues.
    fn locate(&self, xq: f64) -> (usize, f64, f64) {
        let n = self.x.len();
        let k = self.x.partition_point(|&v| v <= xq).clamp(1, n - 1) - 1;
        let h = self.x[k + 1] - self.x[k];
        (k, (xq - self.x[k]) / h, h)
    }

    /// Its value at `xq`.
    pub fn eval(&self, xq: f64) -> f64 {
        let (k, s, h) = self.locate(xq);
        let (s2, s3) = (s * s, s * s * s);
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        h00 * self.y[k] + h10 * h * self.t[k] + h01 * self.y[k + 1] + h11 * h * self.t[k + 1]
    }

    /// Its slope at `xq`.
    pub fn slope(&self, xq: f64) -> f64 {
        let (k, s, h) = self.locate(xq);
        let s2 = s * s;
        let d00 = 6.0 * s2 - 6.0 * s;
        let d10 = 3.0 * s2 - 4.0 * s + 1.0;
        let d01 = -6.0 * s2 + 6.0 * s;
        let d11 = 3.0 * s2 - 2.0 * s;
        (d00 * self.y[k] + d01 * self.y[k + 1]) / h + d10 * self.t[k] + d11 * self.t[k + 1]
    }
}

/// Piecewise-linear interpolation of `(x_i, y_i)` at `xq` (`x` increasing,
/// at least two points), the end segments continued outside.
pub fn linear(x: &[f64], y: &[f64], xq: f64) -> f64 {
    let n = x.len();
    let k = x.partition_point(|&v| v <= xq).clamp(1, n - 1) - 1;
    let s = (xq - x[k]) / (x[k + 1] - x[k]);
    y[k] + s * (y[k + 1] - y[k])
}

/// New node arclengths for a rod with node arclengths `s` (increasing):
/// an edge with a free end (`held[i]` false) shorter than `min_len` loses
/// that end (an interior node; the inner one when both are free), and an
/// edge longer than `max_len` gains evenly spaced nodes until none is
/// longer. The seed's bounds: `min_len` half the smallest initial edge,
/// `max_len` four times the largest. Held nodes and both ends are kept.
pub fn resample(s: &[f64], held: &[bool], min_len: f64, max_len: f64) -> Vec<f64> {
    assert_eq!(s.len(), held.len(), "one flag per node");
    assert!(
        min_len > 0.0 && max_len >= 2.0 * min_len,
        "bounds that splitting cannot undo"
    );
    let last = s.len() - 1;
    // Merge: walk from the clamp; drop a free interior node that makes a
    // short edge with the last kept node.
    let mut keep: Vec<usize> = vec![0];
    for i in 1..=last {
        let prev = *keep.last().expect("starts with the clamp");
        let short = s[i] - s[prev] < min_len;
        let can_drop_i = i != last && !held[i];
        let can_drop_prev = prev != 0 && !held[prev] && keep.len() > 1;
        if short && can_drop_i {
            continue;
        }
        if short && can_drop_prev {
            keep.pop();
        }
        keep.push(i);
    }
    // Split: even subdivision of every edge longer than max_len.
    let mut out = vec![s[keep[0]]];
    for w in keep.windows(2) {
        let (a, b) = (s[w[0]], s[w[1]]);
        let parts = ((b - a) / max_len).ceil().max(1.0) as usize;
        for k in 1..=parts {
            out.push(if k == parts {
                b
            } else {
                a + (b - a) * k as f64 / parts as f64
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_lines_at_any_spacing_are_exact() {
        let x = [0.0, 0.1, 0.35, 0.4, 1.0];
        let y: Vec<f64> = x.iter().map(|v| 3.0 - 2.0 * v).collect();
        let a = Akima::new(&x, &y).unwrap();
        for k in 0..=50 {
            let q = k as f64 / 50.0;
            // Rounding of a few O(1) products.
            assert!((a.eval(q) - (3.0 - 2.0 * q)).abs() < 1e-14);
            assert!((a.slope(q) + 2.0).abs() < 1e-13);
        }
    }

    #[test]
    fn parabolas_on_equal_spacing_are_exact() {
        let x: Vec<f64> = (0..5).map(|k| k as f64 * 0.25).collect();
        let f = |v: f64| 1.0 + v - 4.0 * v * v;
        let y: Vec<f64> = x.iter().map(|&v| f(v)).collect();
        let a = Akima::new(&x, &y).unwrap();
        for k in 0..=40 {
            let q = k as f64 / 40.0;
            // Exact in exact arithmetic (equal weights: the mean chord slope
            // is the parabola's slope); rounding of O(10) values.
            assert!((a.eval(q) - f(q)).abs() < 1e-13, "{q}");
            assert!((a.slope(q) - (1.0 - 8.0 * q)).abs() < 1e-12, "{q}");
        }
    }

    #[test]
    fn cubics_are_not_reproduced() {
        // The doc's counterexample: x^3 at -2..2, chord slopes 7, 1, 1, 7,
        // equal weights 6 at 0, so the slope there is 1 (exact in binary).
        let x = [-2.0, -1.0, 0.0, 1.0, 2.0];
        let y: Vec<f64> = x.iter().map(|v: &f64| v.powi(3)).collect();
        assert_eq!(Akima::new(&x, &y).unwrap().slope(0.0), 1.0);
    }

    #[test]
    fn it_is_c1_and_passes_through_the_points() {
        let x = [0.0, 0.3, 0.5, 1.1, 1.2, 2.0];
        let y = [0.0, 1.0, -0.5, 0.2, 0.9, 0.1];
        let a = Akima::new(&x, &y).unwrap();
        for i in 0..x.len() {
            assert!((a.eval(x[i]) - y[i]).abs() < 1e-15);
        }
        for &xi in &x[1..x.len() - 1] {
            let e = 1e-9;
            // The slope's jump across a point is O(e) times the curvature.
            assert!((a.slope(xi - e) - a.slope(xi + e)).abs() < 1e-6);
        }
    }

    #[test]
    fn a_step_does_not_overshoot() {
        // Three collinear points on each side: Akima's slope there is the
        // flat chord's, so the curve stays flat and the rise is monotone.
        let x = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let y = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let a = Akima::new(&x, &y).unwrap();
        let mut prev = f64::NEG_INFINITY;
        for k in 0..=500 {
            let q = k as f64 / 100.0;
            let v = a.eval(q);
            assert!((0.0..=1.0).contains(&v), "{q}: {v}");
            assert!(v >= prev, "monotone at {q}");
            prev = v;
            if q <= 2.0 {
                assert_eq!(v, 0.0, "flat before the step at {q}");
            }
        }
    }

    #[test]
    fn bad_data_is_refused() {
        assert!(Akima::new(&[0.0], &[1.0]).is_err());
        assert!(Akima::new(&[0.0, 0.0], &[1.0, 2.0]).is_err());
        assert!(Akima::new(&[0.0, 1.0], &[1.0, f64::NAN]).is_err());
        let two = Akima::new(&[0.0, 2.0], &[1.0, 3.0]).unwrap();
        assert_eq!(two.eval(1.0), 2.0);
    }

    #[test]
    fn linear_interpolates_and_continues_the_ends() {
        let x = [0.0, 1.0, 3.0];
        let y = [0.0, 2.0, 0.0];
        assert_eq!(linear(&x, &y, 0.5), 1.0);
        assert_eq!(linear(&x, &y, 2.0), 1.0);
        assert_eq!(linear(&x, &y, 4.0), -1.0);
    }

    #[test]
    fn resampling_merges_short_free_edges_and_splits_long_ones() {
        let s = [0.0, 0.01, 0.0102, 0.02, 0.03, 0.08, 0.0801, 0.09];
        let held = [true, false, false, true, false, false, true, false];
        let out = resample(&s, &held, 0.005, 0.02);
        // Held nodes and both ends stay.
        for (i, &h) in held.iter().enumerate() {
            if h || i == 0 || i == s.len() - 1 {
                assert!(out.contains(&s[i]), "node {i} at {} kept", s[i]);
            }
        }
        // No edge longer than the bound; a short edge only between two
        // nodes that may not go (held or ends).
        for w in out.windows(2) {
            let l = w[1] - w[0];
            assert!(l <= 0.02 + 1e-15, "{w:?}");
            if l < 0.005 {
                let fixed = |v: f64| {
                    s.iter()
                        .position(|&x| x == v)
                        .is_some_and(|i| held[i] || i == 0 || i == s.len() - 1)
                };
                assert!(fixed(w[0]) && fixed(w[1]), "short edge {w:?} between free nodes");
            }
        }
        // The 0.05 edge 0.03..0.08 became three.
        assert!(out.iter().filter(|&&v| v > 0.03 && v < 0.08).count() == 2);
        assert!(out.windows(2).all(|w| w[1] > w[0]));
    }
}
