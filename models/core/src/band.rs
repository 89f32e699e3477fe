//! Banded symmetric positive-definite solver: Cholesky `A = L L^T` in band
//! storage, `O(n b^2)` to factor and `O(n b)` to solve for half-bandwidth `b`
//! (Golub & Van Loan, "Matrix Computations", 4th ed., algorithm 4.3.6).
//!
//! Shared by the rod models whose unknowns form a chain: the discrete elastic
//! rod (`surgbench-der`) interleaves its DOFs `[x_0, theta_0, x_1, theta_1,
//! ...]`, so every stencil touches 11 consecutive unknowns (half-bandwidth
//! 10); the direct Cosserat-PBD solver (`surgbench-pbd`, Deul et al. 2018)
//! orders its constraint multipliers `[BT_0, SS_0, BT_1, SS_1, ...]` in 3x3
//! blocks that couple only their two neighbours (half-bandwidth 8).
//!
//! ```
//! use surgbench_core::band::BandMatrix;
//! let mut a = BandMatrix::new(3, 1);
//! for i in 0..3 { a.add(i, i, 2.0); }
//! a.add(1, 0, -1.0);
//! a.add(2, 1, -1.0);
//! let mut x = vec![1.0, 0.0, 1.0];
//! a.factor_and_solve(&mut x, 0.0).unwrap();
//! assert!((x[0] - 1.0).abs() < 1e-14 && (x[1] - 1.0).abs() < 1e-14);
//! ```

/// Lower band of a symmetric matrix: entry `(i, j)` with `0 <= i - j <= b`.
#[derive(Debug, Clone)]
pub struct BandMatrix {
    n: usize,
    b: usize,
    a: Vec<f64>,
    l: Vec<f64>,
}

/// The matrix (with the shift tried last) is not positive definite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotPositiveDefinite {
    /// Row where a non-positive pivot appeared.
    pub row: usize,
}

impl BandMatrix {
    /// A zero `n x n` matrix of half-bandwidth `b`.
    pub fn new(n: usize, b: usize) -> Self {
        Self {
            n,
            b,
            a: vec![0.0; n * (b + 1)],
            l: vec![0.0; n * (b + 1)],
        }
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Reset every entry to zero (keeps the allocation).
    pub fn clear(&mut self) {
        self.a.iter_mut().for_each(|v| *v = 0.0);
    }

    /// Add `v` to entry `(i, j)` (and implicitly `(j, i)`); needs `j <= i <= j + b`.
    #[inline]
    pub fn add(&mut self, i: usize, j: usize, v: f64) {
        debug_assert!(j <= i && i - j <= self.b && i < self.n);
        self.a[i * (self.b + 1) + (i - j)] += v;
    }

    /// Entry `(i, j)` of the symmetric matrix (zero outside the band).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        if i - j > self.b {
            0.0
        } else {
            self.a[i * (self.b + 1) + (i - j)]
        }
    }

    /// `y = A x`.
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        let w = self.b + 1;
        y.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..self.n {
            y[i] += self.a[i * w] * x[i];
            for k in 1..=self.b.min(i) {
                let v = self.a[i * w + k];
                y[i] += v * x[i - k];
                y[i - k] += v * x[i];
            }
        }
    }

    /// Factor `A + shift * diag(A)` (Cholesky in band storage). Fails if a
    /// pivot is not positive relative to its diagonal entry.
    pub fn factor(&mut self, shift: f64) -> Result<(), NotPositiveDefinite> {
        let (n, b, w) = (self.n, self.b, self.b + 1);
        self.l.copy_from_slice(&self.a);
        for i in 0..n {
            let d = self.a[i * w];
            self.l[i * w] = d + shift * d.abs();
        }
        for i in 0..n {
            let j0 = i.saturating_sub(b);
            for j in j0..=i {
                let mut s = self.l[i * w + (i - j)];
                // L(i,k) L(j,k) for k in max(j0, j - b)..j; since j >= j0 >= i - b, j - b <= j0.
                for k in j0..j {
                    s -= self.l[i * w + (i - k)] * self.l[j * w + (j - k)];
                }
                if i == j {
                    let scale = self.a[i * w].abs().max(f64::MIN_POSITIVE);
                    if !(s > 1e-13 * scale) || !s.is_finite() {
                        return Err(NotPositiveDefinite { row: i });
                    }
                    self.l[i * w] = s.sqrt();
                } else {
                    self.l[i * w + (i - j)] = s / self.l[j * w];
                }
            }
        }
        Ok(())
    }

    /// Solve `L L^T x = rhs` in place with the last successful factorisation.
    pub fn solve(&self, x: &mut [f64]) {
        let (n, b, w) = (self.n, self.b, self.b + 1);
        for i in 0..n {
            let mut s = x[i];
            for k in i.saturating_sub(b)..i {
                s -= self.l[i * w + (i - k)] * x[k];
            }
            x[i] = s / self.l[i * w];
        }
        for i in (0..n).rev() {
            let mut s = x[i];
            for k in i + 1..(i + b + 1).min(n) {
                s -= self.l[k * w + (k - i)] * x[k];
            }
            x[i] = s / self.l[i * w];
        }
    }

    /// Factor with `shift` (relative to the diagonal), retrying with a shift
    /// growing by 100x from `1e-8` while the matrix is not positive definite,
    /// then solve in place. Returns the shift that succeeded.
    pub fn factor_and_solve(&mut self, x: &mut [f64], shift: f64) -> Result<f64, NotPositiveDefinite> {
        let mut s = shift;
        loop {
            match self.factor(s) {
                Ok(()) => {
                    self.solve(x);
                    return Ok(s);
                }
                Err(e) => {
                    s = if s == 0.0 { 1e-8 } else { s * 100.0 };
                    if s > 1e4 {
                        return Err(e);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random SPD band matrix: solution matches a dense reference to roundoff.
    #[test]
    fn band_cholesky_solves_random_spd_system() {
        let (n, b) = (40, 10);
        let mut seed = 12345u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut m = BandMatrix::new(n, b);
        for i in 0..n {
            for j in i.saturating_sub(b)..i {
                m.add(i, j, rnd());
            }
            m.add(i, i, 2.0 * b as f64 + 1.0); // diagonally dominant => SPD
        }
        let xs: Vec<f64> = (0..n).map(|_| rnd()).collect();
        let mut rhs = vec![0.0; n];
        m.mul(&xs, &mut rhs);
        let shift = m.factor_and_solve(&mut rhs, 0.0).unwrap();
        assert_eq!(shift, 0.0);
        let err = xs.iter().zip(&rhs).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        // Condition number ~3 here: error a few ulps.
        assert!(err < 1e-13, "max error {err:e}");
    }

    #[test]
    fn indefinite_matrix_gets_shifted_or_rejected() {
        let mut m = BandMatrix::new(2, 1);
        m.add(0, 0, 1.0);
        m.add(1, 1, 1.0);
        m.add(1, 0, 2.0); // eigenvalues -1 and 3
        assert!(m.factor(0.0).is_err());
        let mut x = vec![1.0, 1.0];
        let s = m.factor_and_solve(&mut x, 0.0).unwrap();
        assert!(s >= 1.0, "needs a shift of at least 1 (diag + shift*diag > 2), got {s}");
    }
}
