//! Converged static equilibrium of the tissue's own XPBD energy, as a
//! diagnostic that separates the iteration error of an under-iterated XPBD
//! solve from the model's discretisation error.
//!
//! XPBD with compliance `alpha` is, at its fixed point, the implicit-Euler
//! step of the potential `U = sum_j C_j^2 / (2 alpha_j)` (Macklin, Müller &
//! Chentanez 2016, sec. 4), so a settled and fully converged run rests at a
//! stationary point of `U - sum_i m_i g . x_i` over the free nodes, with the
//! fixed and driven nodes held. [`PbdTissue::static_equilibrium`] finds that
//! point directly by a damped Gauss-Newton iteration (Nocedal & Wright 2006,
//! "Numerical Optimization", sec. 10.3) whose linear systems are solved by
//! Jacobi-preconditioned conjugate gradients (ibid. alg. 5.3), and stops on
//! the gradient of the exact energy, never on an iteration count alone.
//! Rollers hold their flagged components (the free coordinates are the
//! unheld components of the free nodes). The hard sphere contact has no
//! energy: a scene with one is refused (the minimisation would need the
//! contact's inequality constraints).
//! Units are SI (m, N, J).

use surgbench_core::{Unsupported, Vec3};

use super::PbdTissue;
use surgbench_core::mesh::{tet_volume_gradients, tet_volume_of as tet_volume};

/// Knobs of [`PbdTissue::static_equilibrium`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticParams {
    /// Converged when the free nodes' out-of-balance force `|grad U|` (2-norm
    /// over the free coordinates, N) is at most `rel_tol` times the force
    /// scale (the 2-norm of the loads on the held nodes plus the weight).
    pub rel_tol: f64,
    /// Most Gauss-Newton steps.
    pub max_newton: usize,
    /// Most conjugate-gradient iterations per Gauss-Newton step.
    pub max_cg: usize,
}

impl Default for StaticParams {
    fn default() -> Self {
        Self {
            rel_tol: 1e-9,
            max_newton: 60,
            max_cg: 20_000,
        }
    }
}

/// What [`PbdTissue::static_equilibrium`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticInfo {
    /// Reaction on the driven nodes at the equilibrium, `-dU/dx_driven`
    /// plus their weight (N): the hand force a converged XPBD run reports.
    pub hand_force: Vec3,
    /// Node positions at the equilibrium (m).
    pub positions: Vec<Vec3>,
    /// Constraint energy `U` there (J).
    pub elastic_energy: f64,
    /// Gauss-Newton steps taken.
    pub newton_iterations: usize,
    /// Conjugate-gradient iterations over all steps.
    pub cg_iterations: usize,
    /// Final `|grad U|` over the free coordinates divided by the force scale.
    pub rel_residual: f64,
    /// Whether `rel_residual <= rel_tol`.
    pub converged: bool,
}

/// Per-edge and per-tet quantities of the Gauss-Newton matrix at one state.
struct Linearised {
    /// Edge blocks `k n n^T + t (I - n n^T)`: `(n, k, t)`.
    edges: Vec<(Vec3, f64, f64)>,
    /// Tet terms `k g g^T`: volume gradients and `k = 1 / alpha`.
    tets: Vec<([Vec3; 4], f64)>,
    /// Jacobi preconditioner (inverse diagonal; 0 on held coordinates).
    inv_diag: Vec<Vec3>,
    /// Free (1) and held (0) coordinates ([`PbdTissue::static_masks`]).
    mask: Vec<Vec3>,
}

impl PbdTissue {
    /// Which components of each node move in the static problem (1) or are
    /// held (0): none of fixed and driven nodes, the unheld ones on rollers.
    fn static_masks(&self) -> Vec<Vec3> {
        let mut m: Vec<Vec3> = self
            .w
            .iter()
            .map(|&w| if w > 0.0 { Vec3::repeat(1.0) } else { Vec3::zeros() })
            .collect();
        for &(j, axes) in &self.rollers {
            for a in 0..3 {
                if axes[a] {
                    m[j as usize][a] = 0.0;
                }
            }
        }
        m
    }

    /// `U(x) - sum m g . x` over the whole mesh (J).
    fn static_energy(&self, x: &[Vec3]) -> f64 {
        let mut u = 0.0;
        for (k, e) in self.edges.iter().enumerate() {
            let c = (x[e[1] as usize] - x[e[0] as usize]).norm() - self.edge_rest[k];
            u += 0.5 * c * c / self.edge_alpha[k];
        }
        for (t, tet) in self.tets.iter().enumerate() {
            let a = self.tet_alpha[t];
            if a.is_finite() {
                let c = tet_volume(&tet.map(|i| x[i as usize])) - self.tet_rest[t];
                u += 0.5 * c * c / a;
            }
        }
        u - x
            .iter()
            .zip(&self.mass)
            .map(|(p, m)| m * self.gravity.dot(p))
            .sum::<f64>()
    }

    /// Gradient of [`Self::static_energy`] at every node (N).
    fn static_gradient(&self, x: &[Vec3]) -> Vec<Vec3> {
        let mut g: Vec<Vec3> = self.mass.iter().map(|m| -self.gravity * *m).collect();
        for (k, e) in self.edges.iter().enumerate() {
            let [a, b] = e.map(|i| i as usize);
            let d = x[b] - x[a];
            let len = d.norm();
            if len == 0.0 {
                continue;
            }
            let f = d * ((len - self.edge_rest[k]) / (self.edge_alpha[k] * len));
            g[b] += f;
            g[a] -= f;
        }
        for (t, tet) in self.tets.iter().enumerate() {
            let a = self.tet_alpha[t];
            if !a.is_finite() {
                continue;
            }
            let idx = tet.map(|i| i as usize);
            let p = idx.map(|i| x[i]);
            let s = (tet_volume(&p) - self.tet_rest[t]) / a;
            let gv = tet_volume_gradients(&p);
            for k in 0..4 {
                g[idx[k]] += gv[k] * s;
            }
        }
        g
    }

    /// Gauss-Newton matrix of the energy at `x`: the constraint Jacobians'
    /// `J^T alpha^-1 J` plus, for stretched edges, the (positive) transverse
    /// stiffness `k (1 - L0/len) (I - n n^T)` of the exact Hessian. Dropped:
    /// the compressive transverse term and `C d^2V` (indefinite); they change
    /// the path, not the stationary point the gradient test certifies.
    fn linearise(&self, x: &[Vec3]) -> Linearised {
        let mut diag = vec![Vec3::zeros(); x.len()];
        let mut edges = Vec::with_capacity(self.edges.len());
        for (k, e) in self.edges.iter().enumerate() {
            let [a, b] = e.map(|i| i as usize);
            let d = x[b] - x[a];
            let len = d.norm();
            let n = if len > 0.0 { d / len } else { Vec3::zeros() };
            let kk = 1.0 / self.edge_alpha[k];
            let t = if len > 0.0 {
                kk * (1.0 - self.edge_rest[k] / len).max(0.0)
            } else {
                0.0
            };
            let dg = n.component_mul(&n) * (kk - t) + Vec3::repeat(t);
            diag[a] += dg;
            diag[b] += dg;
            edges.push((n, kk, t));
        }
        let mut tets = Vec::with_capacity(self.tets.len());
        for (t, tet) in self.tets.iter().enumerate() {
            let a = self.tet_alpha[t];
            if !a.is_finite() {
                tets.push(([Vec3::zeros(); 4], 0.0));
                continue;
            }
            let idx = tet.map(|i| i as usize);
            let gv = tet_volume_gradients(&idx.map(|i| x[i]));
            for k in 0..4 {
                diag[idx[k]] += gv[k].component_mul(&gv[k]) / a;
            }
            tets.push((gv, 1.0 / a));
        }
        let mask = self.static_masks();
        let inv_diag = diag
            .iter()
            .zip(&mask)
            .map(|(d, m)| d.map(|c| if c > 0.0 { 1.0 / c } else { 0.0 }).component_mul(m))
            .collect();
        Linearised {
            edges,
            tets,
            inv_diag,
            mask,
        }
    }

    /// `out = H p` on the free coordinates (`p` must vanish on held nodes).
    fn apply_gn(&self, lin: &Linearised, p: &[Vec3], out: &mut [Vec3]) {
        out.fill(Vec3::zeros());
        for (e, &(n, k, t)) in self.edges.iter().zip(&lin.edges) {
            let [a, b] = e.map(|i| i as usize);
            let d = p[b] - p[a];
            let dn = n.dot(&d);
            let f = n * ((k - t) * dn) + d * t;
            out[b] += f;
            out[a] -= f;
        }
        for (tet, (gv, k)) in self.tets.iter().zip(&lin.tets) {
            if *k == 0.0 {
                continue;
            }
            let idx = tet.map(|i| i as usize);
            let s: f64 = (0..4).map(|j| gv[j].dot(&p[idx[j]])).sum::<f64>() * k;
            for j in 0..4 {
                out[idx[j]] += gv[j] * s;
            }
        }
        for (o, m) in out.iter_mut().zip(&lin.mask) {
            *o = o.component_mul(m);
        }
    }

    /// Preconditioned CG for `H d = -g` to `|r| <= tol`; returns `(d, iterations)`.
    fn solve_gn(&self, lin: &Linearised, g: &[Vec3], tol: f64, max_it: usize) -> (Vec<Vec3>, usize) {
        let n = g.len();
        let dot = |a: &[Vec3], b: &[Vec3]| a.iter().zip(b).map(|(u, v)| u.dot(v)).sum::<f64>();
        let mut d = vec![Vec3::zeros(); n];
        let mut r: Vec<Vec3> = (0..n).map(|i| -g[i].component_mul(&lin.mask[i])).collect();
        let mut z: Vec<Vec3> = r.iter().zip(&lin.inv_diag).map(|(a, b)| a.component_mul(b)).collect();
        let mut p = z.clone();
        let mut hp = vec![Vec3::zeros(); n];
        let mut rz = dot(&r, &z);
        for it in 0..max_it {
            if dot(&r, &r).sqrt() <= tol {
                return (d, it);
            }
            self.apply_gn(lin, &p, &mut hp);
            let php = dot(&p, &hp);
            if !(php > 0.0) {
                return (d, it);
            }
            let a = rz / php;
            for i in 0..n {
                d[i] += p[i] * a;
                r[i] -= hp[i] * a;
                z[i] = r[i].component_mul(&lin.inv_diag[i]);
            }
            let rz_new = dot(&r, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                p[i] = z[i] + p[i] * beta;
            }
        }
        (d, max_it)
    }

    /// The statics solver minimises an energy: hard volume constraints and
    /// the hard sphere contact have none.
    fn check_static(&self) -> Result<(), Unsupported> {
        if self.tet_alpha.contains(&0.0) {
            return Err(Unsupported::new(
                "static equilibrium: hard volume constraints (nu = 1/2) have no energy to minimise",
            ));
        }
        if let Some(sp) = &self.sphere {
            return Err(Unsupported::new(format!(
                "static equilibrium: the hard sphere contact (radius {} m) has no energy to minimise; its inequality constraints are not in this solver",
                sp.path.radius
            )));
        }
        Ok(())
    }

    /// Backtracking along `d` from `x` (energy `u`, directional derivative
    /// `slope`, free-gradient norm `r`): the first of 40 halvings that
    /// decreases the energy enough (Armijo, `1e-4`) or, once energy
    /// differences are at roundoff level, halves the free gradient. The
    /// accepted positions with their energy and gradient, `None` if none is.
    fn backtrack(
        &self,
        x: &[Vec3],
        d: &[Vec3],
        u: f64,
        slope: f64,
        r: f64,
        free_norm: &dyn Fn(&[Vec3]) -> f64,
    ) -> Option<(Vec<Vec3>, f64, Vec<Vec3>)> {
        let mut step = 1.0;
        for _ in 0..40 {
            let xt: Vec<Vec3> = x.iter().zip(d).map(|(p, q)| p + q * step).collect();
            let ut = self.static_energy(&xt);
            let gt = self.static_gradient(&xt);
            if ut <= u + 1e-4 * step * slope || free_norm(&gt) < 0.5 * r {
                return Some((xt, ut, gt));
            }
            step *= 0.5;
        }
        None
    }

    /// Static equilibrium of this model's energy with the fixed and driven
    /// nodes where they are now (the whole mesh, whatever the local
    /// activation box), started from the current state. Its hand force is
    /// what the model reports once XPBD has converged and the tissue has
    /// settled: the gap to the reference is the model's own discretisation
    /// and material-mapping error; the gap to [`Self`]'s observed hand force
    /// is iteration (and settling) error.
    ///
    /// Hard volume constraints (`nu = 1/2`, zero compliance) have no energy
    /// to minimise: [`Unsupported`].
    pub fn static_equilibrium(&self, params: &StaticParams) -> Result<StaticInfo, Unsupported> {
        self.check_static()?;
        let mut x = self.x.clone();
        let mask = self.static_masks();
        let free_norm = |g: &[Vec3]| -> f64 {
            g.iter()
                .zip(&mask)
                .map(|(v, m)| v.component_mul(m).norm_squared())
                .sum::<f64>()
                .sqrt()
        };
        let weight: f64 = self.mass.iter().sum::<f64>() * self.gravity.norm();
        let mut g = self.static_gradient(&x);
        let mut u = self.static_energy(&x);
        let (mut newton, mut cg) = (0, 0);
        let mut rel;
        loop {
            let held: f64 = g
                .iter()
                .zip(&mask)
                .map(|(v, m)| (v - v.component_mul(m)).norm_squared())
                .sum::<f64>()
                .sqrt();
            let scale = held + weight;
            let r = free_norm(&g);
            rel = if scale > 0.0 {
                r / scale
            } else if r == 0.0 {
                0.0
            } else {
                f64::INFINITY
            };
            if rel <= params.rel_tol || newton >= params.max_newton {
                break;
            }
            newton += 1;
            let lin = self.linearise(&x);
            // Inexact Newton forcing term (Eisenstat & Walker 1996): solve
            // the linear system only as well as the step can use.
            let eta = (rel.sqrt()).min(0.1);
            let (d, k) = self.solve_gn(&lin, &g, eta * r, params.max_cg);
            cg += k;
            let slope: f64 = g.iter().zip(&d).map(|(a, b)| a.dot(b)).sum();
            match self.backtrack(&x, &d, u, slope, r, &free_norm) {
                Some((xt, ut, gt)) => {
                    x = xt;
                    u = ut;
                    g = gt;
                }
                None => break,
            }
        }
        let hand_force = (0..x.len())
            .filter(|&i| self.driven_mark[i])
            .map(|i| -g[i])
            .sum::<Vec3>();
        let elastic_energy = u + x
            .iter()
            .zip(&self.mass)
            .map(|(p, m)| m * self.gravity.dot(p))
            .sum::<f64>();
        Ok(StaticInfo {
            hand_force,
            positions: x,
            elastic_energy,
            newton_iterations: newton,
            cg_iterations: cg,
            rel_residual: rel,
            converged: rel <= params.rel_tol,
        })
    }
}
