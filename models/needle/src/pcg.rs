//! Projected preconditioned conjugate gradient for an equality-constrained
//! symmetric positive definite system: the iterative solver the needle seed
//! uses for each LCP trial (Chentanez et al. 2009, Sec. 3.3 and Sec. 5: a
//! parallel CG over the whole coupled system), kept beside the Schur
//! complement so that the report can show the two side by side.
//!
//! One trial asks for `y` and `lambda` with
//!
//! ```text
//! K y = b + J^T lambda,    J y = c,
//! ```
//!
//! `K` the coupled step's matrix (needle Hessian and tissue matrix, block
//! diagonal, with the viscous rows' `c_i J_i^T J_i` added by the caller),
//! `J` the active constraint rows. The iterates stay on `J y = c`: the
//! preconditioned residual is projected onto the null space of `J` in the
//! metric of the Jacobi preconditioner `D`,
//! `P = D^-1 - D^-1 J^T (J D^-1 J^T)^-1 J D^-1` (Gould, Hribar and Nocedal
//! 2001, "On the solution of equality constrained quadratic programming
//! problems arising in optimization", SIAM J. Sci. Comput. 23, Alg. II).
//! At convergence `K y - b` lies in the range of `J^T`, and the projection
//! of it yields the multipliers `lambda = (J D^-1 J^T)^-1 J D^-1 (K y - b)`.

use nalgebra::{DMatrix, DVector, linalg::Cholesky};

/// One sparse row of `J`: `(unknown, coefficient)` pairs.
pub type Row = Vec<(usize, f64)>;

/// What a solve did.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Iterations (products with `K`) after the start.
    pub iterations: usize,
    /// Final `sqrt(r . P r) / sqrt(b . D^-1 b)`: the preconditioned residual
    /// left in the feasible subspace, relative to the right-hand side.
    pub relative_residual: f64,
    /// Whether it reached the tolerance within the iteration limit.
    pub converged: bool,
    /// The multipliers of the rows (`J^T lambda = K y - b`).
    pub lambda: Vec<f64>,
}

/// The projection of [`solve`]: rows, `D^-1` and the factor of `J D^-1 J^T`.
struct Projection<'a> {
    rows: &'a [Row],
    inv_d: &'a [f64],
    s: Option<Cholesky<f64, nalgebra::Dyn>>,
}

impl<'a> Projection<'a> {
    /// `None` if `J D^-1 J^T` is singular (dependent rows).
    fn new(rows: &'a [Row], inv_d: &'a [f64]) -> Option<Self> {
        let e = rows.len();
        if e == 0 {
            return Some(Self { rows, inv_d, s: None });
        }
        let mut s = DMatrix::zeros(e, e);
        // Rows touch a handful of unknowns each: a dense product of the
        // sparse rows through a scatter of one row at a time.
        let mut scatter = vec![0.0; inv_d.len()];
        for (i, ri) in rows.iter().enumerate() {
            for &(k, a) in ri {
                scatter[k] += a * inv_d[k];
            }
            for (j, rj) in rows.iter().enumerate().take(i + 1) {
                let v: f64 = rj.iter().map(|&(k, a)| a * scatter[k]).sum();
                s[(i, j)] = v;
                s[(j, i)] = v;
            }
            for &(k, _) in ri {
                scatter[k] = 0.0;
            }
        }
        Some(Self {
            rows,
            inv_d,
            s: Some(s.cholesky()?),
        })
    }

    /// `mu = (J D^-1 J^T)^-1 J D^-1 v` (empty without rows).
    fn multipliers(&self, v: &[f64]) -> Vec<f64> {
        let Some(s) = &self.s else {
            return Vec::new();
        };
        let jv = DVector::from_iterator(
            self.rows.len(),
            self.rows
                .iter()
                .map(|r| r.iter().map(|&(k, a)| a * self.inv_d[k] * v[k]).sum::<f64>()),
        );
        s.solve(&jv).iter().copied().collect()
    }

    /// `out = P v = D^-1 (v - J^T mu)`; returns `mu`.
    fn project(&self, v: &[f64], out: &mut [f64]) -> Vec<f64> {
        let mu = self.multipliers(v);
        out.copy_from_slice(v);
        self.subtract_rows(&mu, out);
        out.iter_mut().zip(self.inv_d).for_each(|(o, d)| *o *= d);
        mu
    }

    /// `out -= J^T mu`.
    fn subtract_rows(&self, mu: &[f64], out: &mut [f64]) {
        for (r, m) in self.rows.iter().zip(mu) {
            for &(k, a) in r {
                out[k] -= a * m;
            }
        }
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solve the constrained system (module docs) by projected PCG from the
/// warm start `y` (moved onto `J y = c` first, in the `D` metric), to
/// `sqrt(r . P r) <= tol sqrt(b . D^-1 b)` or `max_iter` products with `K`.
/// `apply(x, out)`: `out = K x`; `diag`: the diagonal of `K` (positive).
/// Returns `None` if the rows are dependent.
pub fn solve(
    apply: &mut dyn FnMut(&[f64], &mut [f64]),
    diag: &[f64],
    b: &[f64],
    rows: &[Row],
    c: &[f64],
    y: &mut [f64],
    tol: f64,
    max_iter: usize,
) -> Option<Outcome> {
    let n = b.len();
    assert!(diag.len() == n && y.len() == n && rows.len() == c.len());
    let inv_d: Vec<f64> = diag.iter().map(|d| 1.0 / d).collect();
    let proj = Projection::new(rows, &inv_d)?;
    // Feasible start: y -= D^-1 J^T S^-1 (J y - c) (the D-nearest point).
    if !rows.is_empty() {
        let s = proj.s.as_ref().expect("rows present");
        let res = DVector::from_iterator(
            rows.len(),
            rows.iter()
                .zip(c)
                .map(|(r, ci)| r.iter().map(|&(k, a)| a * y[k]).sum::<f64>() - ci),
        );
        let mu = s.solve(&res);
        for (r, m) in rows.iter().zip(mu.iter()) {
            for &(k, a) in r {
                y[k] -= inv_d[k] * a * m;
            }
        }
    }
    let scale = b.iter().zip(&inv_d).map(|(v, d)| v * v * d).sum::<f64>().sqrt();
    let mut r = vec![0.0; n];
    apply(y, &mut r);
    r.iter_mut().zip(b).for_each(|(ri, bi)| *ri -= bi);
    let mut g = vec![0.0; n];
    let mut mu = proj.project(&r, &mut g);
    // Iterative refinement of the residual (Gould et al. 2001, Sec. 6):
    // keep r orthogonal to the range of J^T so that round-off does not
    // accumulate along the constraint normals.
    proj.subtract_rows(&mu, &mut r);
    let mut rg = dot(&r, &g);
    let mut p: Vec<f64> = g.iter().map(|v| -v).collect();
    let mut kp = vec![0.0; n];
    let mut it = 0;
    let rel = |rg: f64| if scale > 0.0 { rg.max(0.0).sqrt() / scale } else { 0.0 };
    while rel(rg) > tol && it < max_iter {
        apply(&p, &mut kp);
        let pkp = dot(&p, &kp);
        if !(pkp > 0.0) {
            break;
        }
        let alpha = rg / pkp;
        y.iter_mut().zip(&p).for_each(|(yi, pi)| *yi += alpha * pi);
        r.iter_mut().zip(&kp).for_each(|(ri, ki)| *ri += alpha * ki);
        let m = proj.project(&r, &mut g);
        proj.subtract_rows(&m, &mut r);
        mu.iter_mut().zip(&m).for_each(|(a, b)| *a += b);
        let rg_new = dot(&r, &g);
        let beta = rg_new / rg;
        rg = rg_new;
        p.iter_mut().zip(&g).for_each(|(pi, gi)| *pi = -gi + beta * *pi);
        it += 1;
    }
    // `mu` has collected every part of the residual removed along J^T:
    // what remains of `K y - b` besides it is the (converged) null-space
    // part, so `K y - b = J^T mu` to the tolerance.
    Some(Outcome {
        iterations: it,
        relative_residual: rel(rg),
        converged: rel(rg) <= tol,
        lambda: mu,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small SPD matrix with unequal diagonal (so that the Jacobi metric
    /// matters) and two constraint rows; the answer by the dense KKT system.
    #[test]
    fn matches_the_dense_kkt_solution() {
        let n = 6;
        let k = DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                [4.0, 30.0, 2.0, 9.0, 50.0, 3.0][i]
            } else if i.abs_diff(j) == 1 {
                -1.0
            } else {
                0.0
            }
        });
        let b = [1.0, -2.0, 0.5, 3.0, 0.0, -1.0];
        let rows: Vec<Row> = vec![vec![(0, 1.0), (3, -0.5)], vec![(1, 0.3), (4, 1.0), (5, -2.0)]];
        let c = [0.2, -0.1];
        // Dense KKT: [K -J^T; J 0] [y; lambda] = [b; c].
        let e = rows.len();
        let mut kkt = DMatrix::zeros(n + e, n + e);
        kkt.view_mut((0, 0), (n, n)).copy_from(&k);
        for (i, r) in rows.iter().enumerate() {
            for &(col, a) in r {
                kkt[(n + i, col)] = a;
                kkt[(col, n + i)] = -a;
            }
        }
        let rhs = DVector::from_iterator(n + e, b.iter().chain(&c).copied());
        let exact = kkt.lu().solve(&rhs).unwrap();
        let mut apply = |x: &[f64], out: &mut [f64]| {
            let v = &k * DVector::from_column_slice(x);
            out.copy_from_slice(v.as_slice());
        };
        let diag: Vec<f64> = (0..n).map(|i| k[(i, i)]).collect();
        let mut y = vec![0.3; n];
        let out = solve(&mut apply, &diag, &b, &rows, &c, &mut y, 1e-13, 100).unwrap();
        assert!(out.converged);
        // CG ends in at most n - e steps in exact arithmetic (the null space's
        // dimension); one more for round-off.
        assert!(out.iterations <= n - e + 1, "{} iterations", out.iterations);
        for i in 0..n {
            // Tolerance 1e-13 on O(1) data and condition ~50: 1e-11 is ample.
            assert!((y[i] - exact[i]).abs() < 1e-11, "y[{i}] {} vs {}", y[i], exact[i]);
        }
        for i in 0..e {
            assert!((out.lambda[i] - exact[n + i]).abs() < 1e-11, "lambda[{i}]");
        }
    }

    #[test]
    fn without_rows_it_is_plain_pcg() {
        let k = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0]);
        let b = [1.0, 2.0, 3.0];
        let exact = k.clone().cholesky().unwrap().solve(&DVector::from_column_slice(&b));
        let mut apply = |x: &[f64], out: &mut [f64]| {
            out.copy_from_slice((&k * DVector::from_column_slice(x)).as_slice());
        };
        let mut y = vec![0.0; 3];
        let out = solve(&mut apply, &[4.0, 3.0, 2.0], &b, &[], &[], &mut y, 1e-14, 10).unwrap();
        assert!(out.converged && out.lambda.is_empty());
        assert!((0..3).all(|i| (y[i] - exact[i]).abs() < 1e-12));
    }

    #[test]
    fn dependent_rows_are_refused() {
        let rows: Vec<Row> = vec![vec![(0, 1.0)], vec![(0, 2.0)]];
        let mut apply = |x: &[f64], out: &mut [f64]| out.copy_from_slice(x);
        let mut y = vec![0.0; 2];
        assert!(
            solve(
                &mut apply,
                &[1.0, 1.0],
                &[1.0, 1.0],
                &rows,
                &[0.0, 0.0],
                &mut y,
                1e-10,
                10
            )
            .is_none()
        );
    }
}
