//! Energy, gradient and banded Hessian of the rod with its contacts and
//! external loads, and the step limits they set.

use super::*;
use crate::energy::{self, Stencil, VertexTerms};
use surgbench_core::{Mat3, Sdf, Vec3};

impl DerRod {
    pub(super) fn dof_mass(&self, g: usize) -> f64 {
        if g % 4 == 3 {
            match self.params.twist {
                TwistDynamics::QuasiStatic => 0.0,
                TwistDynamics::Dynamic => self.rot_inertia[g / 4],
            }
        } else {
            self.node_mass[g / 4]
        }
    }

    pub(super) fn stencil(&self, i: usize) -> Stencil {
        Stencil {
            x: [self.node(i - 1), self.node(i), self.node(i + 1)],
            theta: [self.theta(i - 1), self.theta(i)],
            ref_d1: [self.a1[i - 1], self.a1[i]],
            ref_twist: self.rtwist[i],
        }
    }

    /// Dead loads as generalised forces at the current configuration.
    pub(super) fn external_forces(&mut self) {
        let n = self.n;
        self.fext.iter_mut().for_each(|f| *f = 0.0);
        for k in 0..n {
            let f = self.gravity * self.node_mass[k] + self.node_forces[k];
            for c in 0..3 {
                self.fext[4 * k + c] += f[c];
            }
        }
        let last = n - 1;
        let e = self.node(last) - self.node(last - 1);
        let t = self.tan[last - 1];
        let (tip_force, tip_torque) = (self.tip_force * self.load_scale, self.tip_torque * self.load_scale);
        let axial = tip_torque.dot(&t);
        let perp = tip_torque - t * axial;
        let couple = perp.cross(&e) / e.norm_squared();
        for c in 0..3 {
            self.fext[4 * last + c] += tip_force[c] + couple[c];
            self.fext[4 * (last - 1) + c] -= couple[c];
        }
        self.fext[4 * (last - 1) + 3] += axial;
    }

    /// Elastic energy (J) at the current coordinates and frames.
    pub fn elastic_energy(&self) -> f64 {
        let mut e = 0.0;
        for j in 0..self.n - 1 {
            e += energy::stretch_energy(&self.node(j), &self.node(j + 1), self.ea[j], self.rest_len[j]);
        }
        for i in 1..self.n - 1 {
            e += energy::bend_twist_energy(&self.stencil(i), &self.vparams[i]);
        }
        e
    }

    /// Gradient of the elastic energy over all DOFs at the current state
    /// (N for positions, N m for angles), without the Hessian.
    pub fn elastic_gradient(&self) -> Vec<f64> {
        let mut g = vec![0.0; self.q.len()];
        let mut terms = VertexTerms::default();
        for j in 0..self.n - 1 {
            let (_, gs, _) = energy::stretch(&self.node(j), &self.node(j + 1), self.ea[j], self.rest_len[j]);
            for c in 0..3 {
                g[4 * (j + 1) + c] += gs[c];
                g[4 * j + c] -= gs[c];
            }
        }
        for i in 1..self.n - 1 {
            energy::bend_twist(&self.stencil(i), &self.vparams[i], &mut terms);
            for (k, v) in terms.grad.iter().enumerate() {
                g[4 * (i - 1) + k] += v;
            }
        }
        g
    }

    /// Evaluate the incremental potential; with [`Eval::Full`] also its
    /// gradient over the free DOFs (`self.res`) and Hessian (`self.band`).
    pub(super) fn eval(&mut self, mode: Eval) -> (f64, f64) {
        let full = mode == Eval::Full;
        let mut phi = 0.0;
        let mut mag = 0.0;
        if full {
            self.grad.iter_mut().for_each(|g| *g = 0.0);
            self.band.clear();
        }
        self.add_stretch(full, &mut phi);
        self.add_bend_twist(full, &mut phi);
        if let Some(sdf) = self.vessel.clone() {
            self.add_wall(sdf.as_ref(), full, &mut phi);
        }
        if self.flow.is_some() && self.inertia.is_some() {
            self.add_drag(full, &mut phi);
        }
        let elastic = phi;
        self.add_linear_and_inertia(full, &mut phi, &mut mag);
        (phi, mag + elastic)
    }

    /// Add the stretching energy of every edge to `phi` (and, if `full`, its
    /// gradient and Hessian).
    fn add_stretch(&mut self, full: bool, phi: &mut f64) {
        let n = self.n;
        for j in 0..n - 1 {
            let (x0, x1) = (self.node(j), self.node(j + 1));
            if !full {
                *phi += energy::stretch_energy(&x0, &x1, self.ea[j], self.rest_len[j]);
                continue;
            }
            // Exact Hessian, including the negative transverse stiffness of a
            // compressed edge; `newton` drops that part only if the matrix is
            // then not positive definite (see `drop_compressive_stiffness`).
            let (e, g, h) = energy::stretch(&x0, &x1, self.ea[j], self.rest_len[j]);
            *phi += e;
            for c in 0..3 {
                self.grad[4 * (j + 1) + c] += g[c];
                self.grad[4 * j + c] -= g[c];
            }
            self.add_edge_block(j, &h);
        }
    }

    /// Add the bending and twisting energy of every interior vertex to `phi`
    /// (and, if `full`, its gradient and symmetrised Hessian).
    fn add_bend_twist(&mut self, full: bool, phi: &mut f64) {
        let n = self.n;
        for i in 1..n - 1 {
            let st = self.stencil(i);
            if !full {
                *phi += energy::bend_twist_energy(&st, &self.vparams[i]);
                continue;
            }
            let mut terms = std::mem::take(&mut self.terms);
            energy::bend_twist(&st, &self.vparams[i], &mut terms);
            *phi += terms.energy;
            let off = 4 * (i - 1);
            for r in 0..energy::VERTEX_DOFS {
                self.grad[off + r] += terms.grad[r];
                for c in 0..=r {
                    self.band_add(off + r, off + c, 0.5 * (terms.jac[r][c] + terms.jac[c][r]));
                }
            }
            self.terms = terms;
        }
    }

    /// Add the wall penalty and the lagged friction of every free vertex to
    /// `phi` (and, if `full`, the gaps, gradients and Hessians).
    fn add_wall(&mut self, sdf: &dyn Sdf, full: bool, phi: &mut f64) {
        let n = self.n;
        let kc = self.contact_stiffness;
        // Friction only in dynamic steps (it dissipates the step's slip).
        let friction = self.inertia.is_some();
        let eps = self.friction_eps;
        for k in 2..n {
            let x = self.node(k);
            let d = sdf.distance(&x) + self.contact.margin;
            if full {
                self.gap[k] = d;
            }
            if d > 0.0 {
                let (e, de, dde) = penalty(kc, self.contact_onset, d);
                *phi += e;
                if full {
                    let g = sdf.gradient(&x);
                    let gn = g.norm();
                    let nn = if gn > 0.0 { g / gn } else { g };
                    let h = nn * nn.transpose() * dde + Self::wall_curvature(sdf, &x, &g) * de;
                    for r in 0..3 {
                        self.grad[4 * k + r] += de * nn[r];
                        for c in 0..=r {
                            self.band_add(4 * k + r, 4 * k + c, h[(r, c)]);
                        }
                    }
                }
            }
            let fr = self.friction[k];
            if friction && fr.bound > 0.0 {
                if !full {
                    *phi += fr.energy(&x, eps);
                    continue;
                }
                let fe = fr.eval(&x, eps);
                *phi += fe.energy;
                for r in 0..3 {
                    self.grad[4 * k + r] += fe.gradient[r];
                    for c in 0..=r {
                        self.band_add(4 * k + r, 4 * k + c, fe.hessian[(r, c)]);
                    }
                }
            }
        }
    }

    /// Add the lagged quadratic drag as a convex potential of the step (see
    /// the module docs) to `phi`: value `sum (c |u|^3 / 3) / a`, gradient
    /// `-f`, Hessian `a dF/du`.
    fn add_drag(&mut self, full: bool, phi: &mut f64) {
        let n = self.n;
        let a = self.drag_a;
        let newmark = self.params.integrator == Integrator::Newmark;
        for k in 2..n {
            let x = self.node(k);
            let x0 = Vec3::new(self.q0[4 * k], self.q0[4 * k + 1], self.q0[4 * k + 2]);
            let mut v = (x - x0) * a;
            if newmark {
                v -= self.node_velocity(k);
            }
            let w = self.drag_flow[k];
            let t = Self::half_edge_tangents(&self.drag_tan[..n - 1], k);
            let u = w - v;
            for (i, j) in [k - 1, k].into_iter().enumerate() {
                let [cn, ct] = self.half_edge_drag(j);
                let ut = t[i] * t[i].dot(&u);
                let un = u - ut;
                *phi += (cn * un.norm().powi(3) + ct * ut.norm().powi(3)) / (3.0 * a);
            }
            if full {
                let (f, h) = self.node_drag(k, &v, &w, t);
                for r in 0..3 {
                    self.grad[4 * k + r] -= f[r];
                    for c in 0..=r {
                        self.band_add(4 * k + r, 4 * k + c, a * h[(r, c)]);
                    }
                }
            }
        }
    }

    /// Add the external loads (linear terms measured from the start of the
    /// step, `q - q0`: the potential differs by a constant, but its value
    /// and rounding do not depend on where the scene sits in space) and the
    /// inertia to `phi` and their magnitudes to `mag`; if `full`, write the
    /// free residual `self.res` and the mass terms of the Hessian.
    fn add_linear_and_inertia(&mut self, full: bool, phi: &mut f64, mag: &mut f64) {
        let inertia = self.inertia;
        for g in 0..self.q.len() {
            let q = self.q[g];
            let dq = q - self.q0[g];
            *phi -= self.fext[g] * dq;
            *mag += (self.fext[g] * dq).abs();
            let mut r = self.grad[g] - self.fext[g];
            if let Some(Inertia { ka, kc }) = inertia {
                let m = self.dof_mass(g);
                if m > 0.0 && g >= CLAMPED_DOFS {
                    let da = q - self.qtilde[g];
                    let inert = m * (0.5 * ka * da * da + 0.5 * kc * dq * dq - self.lin[g] * dq);
                    *phi += inert;
                    *mag += inert.abs();
                    r += m * (ka * da + kc * dq - self.lin[g]);
                    if full {
                        self.band_add(g, g, m * (ka + kc));
                    }
                }
            }
            if full && g >= CLAMPED_DOFS {
                self.res[g - CLAMPED_DOFS] = r;
            }
        }
    }

    /// A compressed edge has a negative transverse stiffness
    /// `EA strain / |e|` that can swamp bending and inertia (e.g. right after
    /// the clamp is pushed forward, or a wire wedged in a dead end). When the
    /// exact Newton matrix is not positive definite, remove those terms
    /// (projected Newton: the matrix becomes positive definite; the gradient
    /// is exact, so the converged state is unchanged, only the convergence
    /// rate drops to linear). With every edge in tension nothing changes.
    pub(super) fn drop_compressive_stiffness(&mut self) {
        for j in 0..self.n - 1 {
            let (x0, x1) = (self.node(j), self.node(j + 1));
            let l = (x1 - x0).norm();
            let strain = l / self.rest_len[j] - 1.0;
            if !(strain < 0.0) {
                continue;
            }
            let t = (x1 - x0) / l;
            let h = (Mat3::identity() - t * t.transpose()) * (-self.ea[j] * strain / l);
            self.add_edge_block(j, &h);
        }
    }

    /// Add the Hessian block `h` of edge `j` (the same 3x3 block on both its
    /// end nodes, its negative between them) to the band.
    #[inline]
    fn add_edge_block(&mut self, j: usize, h: &Mat3) {
        let (a, b) = (4 * j, 4 * (j + 1));
        for r in 0..3 {
            for c in 0..3 {
                // `band_add` keeps the lower triangle only.
                let v = h[(r, c)];
                self.band_add(b + r, b + c, v);
                self.band_add(a + r, a + c, v);
                self.band_add(b + r, a + c, -v);
            }
        }
    }

    #[inline]
    pub(super) fn band_add(&mut self, r: usize, c: usize, v: f64) {
        if c >= CLAMPED_DOFS && r >= c {
            self.band.add(r - CLAMPED_DOFS, c - CLAMPED_DOFS, v);
        }
    }

    /// Curvature part of the penalty Hessian at a node at `x` with SDF
    /// gradient `g`: the Jacobian of the unit wall normal
    /// `n = g / |g|`, `dn/dx = (I - n n^T) Hess phi / |g|` (`Hess phi` itself
    /// for an exact SDF, 1/m), from [`Sdf::hessian`] (analytic for the
    /// tubes and vessels of `surgbench_core::sdf`, central differences
    /// otherwise), symmetrised, with its negative eigenvalues clamped to zero.
    ///
    /// Why: the gradient of the penalty `P(d(x))` is `P'(d) n`; its exact
    /// Jacobian is `P'' n n^T + P' dn/dx`. Without the second term (Gauss-Newton)
    /// a node pressed onto the concave inside of a tube has too soft a matrix
    /// across the tube (by `P'/rho`, rho the node's distance from the tube
    /// axis: 1 N / 0.26 mm = 4e3 N/m in `capstan`), and Newton overshoots that
    /// mode by a factor `1 - (P'/rho + h)/h`: with `|.| > 1` it grows instead
    /// of converging. It starts from rounding only when the scene is not
    /// aligned with the axes (identically zero out of plane otherwise), so
    /// the step converged in 3 iterations in one frame and stalled at the
    /// iteration limit in a rotated one. The clamp keeps only the stiffening
    /// (concave wall) part: the matrix is never softer than Gauss-Newton
    /// (convex obstacles keep the linear but safe Gauss-Newton convergence).
    pub(super) fn wall_curvature(sdf: &dyn Sdf, x: &Vec3, g: &Vec3) -> Mat3 {
        let gn = g.norm();
        if !(gn > 0.0 && gn.is_finite()) {
            return Mat3::zeros();
        }
        let n = g / gn;
        let j = (Mat3::identity() - n * n.transpose()) * sdf.hessian(x) / gn;
        let sym = (j + j.transpose()) * 0.5;
        if !sym.iter().all(|v| v.is_finite()) {
            return Mat3::zeros();
        }
        let eig = sym.symmetric_eigen();
        let mut out = Mat3::zeros();
        for i in 0..3 {
            let l = eig.eigenvalues[i];
            if l > 0.0 {
                let v = eig.eigenvectors.column(i);
                out += v * v.transpose() * l;
            }
        }
        out
    }

    /// Largest move of node `k` in one Newton iterate in a contact scene
    /// (m): a fraction of its distance to the margin surface (`-gap`, from
    /// the last full evaluation; the SDF is 1-Lipschitz, so the node cannot
    /// cross the surface), at least a small fraction of its edge so a node
    /// on the wall can slide, at most half of the edge so no edge flips
    /// (a continuous-collision-style step bound, cf. the CCD line-search
    /// filter of Li et al. 2020, "Incremental Potential Contact", sec. 4).
    pub(super) fn move_allowance(&self, k: usize) -> f64 {
        let l = self.node_len[k];
        let free = (-self.gap[k]).max(0.0) * CCD_FRACTION;
        free.max(SLIDE_FRACTION * l).min(TRUST_FRACTION * l)
    }

    /// The largest `alpha <= 1` such that `alpha dz` moves every node at
    /// most [`Self::move_allowance`] and takes no sliding node past the
    /// apex of its friction cone.
    ///
    /// Friction apex: a node sliding (slip `y >= eps`) sees a friction force
    /// of constant size along its slip, so the Newton model has no friction
    /// curvature there. If the solution sticks, the Newton step reverses the
    /// slip and carries the node through the apex `u = 0` far to the other
    /// side (measured on `capstan`: from `y` = 1e-8 m to 1e-4 m), where the
    /// same happens back: Newton cycles, and the line search cannot resolve
    /// the `eps`-wide kink (1e-9 m) above its smallest step. The step
    /// therefore stops where the node's slip `u + alpha T dz` is shortest
    /// (its closest approach to the apex); the next iterate sees the
    /// stick-regime curvature `2 mu lambda / eps` and converges.
    pub(super) fn step_cap(&self) -> f64 {
        let mut alpha: f64 = 1.0;
        let friction = self.inertia.is_some();
        for k in 2..self.n {
            let f = 4 * k - CLAMPED_DOFS;
            let d = Vec3::new(self.dz[f], self.dz[f + 1], self.dz[f + 2]);
            let dx = d.norm();
            if dx > 0.0 {
                alpha = alpha.min(self.move_allowance(k) / dx);
            }
            let fr = self.friction[k];
            if friction && fr.bound > 0.0 {
                let u = fr.slip_vector(&self.node(k));
                let w = d - fr.normal * fr.normal.dot(&d);
                let (uw, ww) = (u.dot(&w), w.norm_squared());
                if u.norm() >= self.friction_eps && uw < 0.0 && ww > 0.0 {
                    alpha = alpha.min(-uw / ww);
                }
            }
        }
        alpha
    }
}
