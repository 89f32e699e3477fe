//! The implicit step of the meshless tissue: the objective, its gradient
//! and the Newton-CG that minimises it.

use super::*;
use surgbench_core::Vec3;

impl MeshlessTissue {
    /// Set the held components to their targets at load factor `load`.
    pub(super) fn apply_targets(&self, x: &mut [Vec3], load: f64) {
        for i in 0..x.len() {
            let h = Vec3::repeat(1.0) - self.axis_free[i];
            x[i] = x[i].component_mul(&self.axis_free[i]) + self.el.rest[i].component_mul(&h);
        }
        for &(i, d) in &self.driven {
            x[i] = self.el.rest[i] + d * load;
        }
    }

    /// Internal forces at `x` into `self.forces` (cache prepared at `x`).
    pub(super) fn internal_forces(&mut self, x: &[Vec3]) {
        self.el.prepare(x, &mut self.cache);
        self.forces.iter_mut().for_each(|f| *f = Vec3::zeros());
        self.el.add_forces(x, &self.cache, &mut self.forces);
    }

    /// Potential of the incremental problem at `x` (J), with the pressure
    /// held at the nodal forces `frozen` (N) as a dead load.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn objective(
        &self,
        x: &[Vec3],
        xn: &[Vec3],
        xt: &[Vec3],
        a_in: f64,
        a_damp: f64,
        frozen: &[Vec3],
    ) -> f64 {
        let (u, hg) = self.el.energy(x);
        let mut e = u + hg + self.contact.as_ref().map_or(0.0, |c| c.energy(x));
        for i in 0..x.len() {
            let m = self.mass[i];
            e -= m * self.gravity.dot(&x[i]) + frozen[i].dot(&x[i]);
            if a_in > 0.0 {
                e += 0.5 * m * a_in * (x[i] - xt[i]).norm_squared() + 0.5 * m * a_damp * (x[i] - xn[i]).norm_squared();
            }
        }
        e
    }

    /// Pressure nodal forces at `x` into `self.pforces` (N), with the dead
    /// forces of a coupled instrument (`self.external`) added: every
    /// integrator takes both as the step's applied loads.
    pub(super) fn pressure_forces(&mut self, x: &[Vec3]) {
        self.pforces.clone_from(&self.external);
        self.pressure.add_forces(x, self.load_scale, &mut self.pforces);
    }

    /// Gradient of [`Self::objective`] with the pressure frozen at `x`,
    /// masked to the free components; leaves the pressure forces at `x` in
    /// `self.pforces`.
    pub(super) fn gradient(&mut self, x: &[Vec3], xn: &[Vec3], xt: &[Vec3], a_in: f64, a_damp: f64, g: &mut [Vec3]) {
        self.internal_forces(x);
        self.pressure_forces(x);
        g.iter_mut().for_each(|v| *v = Vec3::zeros());
        if let Some(c) = &self.contact {
            c.add_gradient(x, g);
        }
        for i in 0..x.len() {
            let m = self.mass[i];
            let mut gi = g[i] - self.forces[i] - self.pforces[i] - self.gravity * m;
            if a_in > 0.0 {
                gi += (x[i] - xt[i]) * (m * a_in) + (x[i] - xn[i]) * (m * a_damp);
            }
            g[i] = gi.component_mul(&self.axis_free[i]);
        }
    }

    /// Newton direction `dx` at `x` with gradient `g`: CG on the masked
    /// `(H + diag M) dx = -g` to a relative residual of 1e-2, at most
    /// `max_cg` iterations; on negative curvature (Steihaug) the current
    /// iterate, or steepest descent if there is none yet. `work` holds the
    /// CG's residual, direction and product vectors.
    fn newton_direction(
        &self,
        x: &[Vec3],
        g: &[Vec3],
        diag: f64,
        max_cg: usize,
        dx: &mut [Vec3],
        work: [&mut Vec<Vec3>; 3],
    ) {
        let n = x.len();
        let [r, p, hp] = work;
        dx.iter_mut().for_each(|v| *v = Vec3::zeros());
        let mut rr = 0.0;
        for i in 0..n {
            r[i] = -g[i];
            p[i] = r[i];
            rr += r[i].norm_squared();
        }
        let stop = rr * 1e-4;
        for k in 0..max_cg {
            hp.iter_mut().for_each(|v| *v = Vec3::zeros());
            self.el.add_hess_vec(&self.cache, p, hp);
            self.pressure.add_sym_stiffness(x, self.load_scale, p, hp);
            if let Some(c) = &self.contact {
                c.add_hess_vec(x, p, hp);
            }
            let mut php = 0.0;
            for i in 0..n {
                hp[i] = (hp[i] + p[i] * (self.mass[i] * diag)).component_mul(&self.axis_free[i]);
                php += p[i].dot(&hp[i]);
            }
            if !(php > 0.0) {
                // Negative curvature (Steihaug): keep the current iterate,
                // or steepest descent if there is none yet.
                if k == 0 {
                    for i in 0..n {
                        dx[i] = -g[i];
                    }
                }
                break;
            }
            let alpha = rr / php;
            let mut rr_new = 0.0;
            for i in 0..n {
                dx[i] += p[i] * alpha;
                r[i] -= hp[i] * alpha;
                rr_new += r[i].norm_squared();
            }
            if rr_new <= stop {
                break;
            }
            let beta = rr_new / rr;
            rr = rr_new;
            for i in 0..n {
                p[i] = r[i] + p[i] * beta;
            }
        }
    }

    /// Minimise the incremental potential by Newton-CG. `a_in = 1/h^2` and
    /// `a_damp = c/h` weight the inertia and damping terms (0 = quasi-static).
    pub(super) fn newton(&mut self, xn: &[Vec3], xt: &[Vec3], a_in: f64, a_damp: f64) -> SolveInfo {
        let n = self.x.len();
        let mut x = std::mem::take(&mut self.x);
        let mut g = vec![Vec3::zeros(); n];
        let mut dx = vec![Vec3::zeros(); n];
        let mut xtry = vec![Vec3::zeros(); n];
        let (mut r, mut p, mut hp) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
        let diag = a_in + a_damp;
        let max_cg = (3 * n).clamp(50, 5000);
        let mut info = SolveInfo {
            iterations: 0,
            residual: f64::INFINITY,
            converged: false,
        };
        for it in 0..50 {
            self.gradient(&x, xn, xt, a_in, a_damp, &mut g);
            let res = g.iter().map(|v| v.amax()).fold(0.0, f64::max);
            info.iterations = it;
            info.residual = res;
            if !res.is_finite() {
                break;
            }
            if g.iter().zip(&self.tol).all(|(v, t)| v.amax() <= *t) {
                info.converged = true;
                break;
            }
            // CG on H dx = -g (masked), relative tolerance 1e-2.
            self.newton_direction(&x, &g, diag, max_cg, &mut dx, [&mut r, &mut p, &mut hp]);
            // Armijo backtracking on the potential.
            let frozen = std::mem::take(&mut self.pforces);
            let phi0 = self.objective(&x, xn, xt, a_in, a_damp, &frozen);
            let slope: f64 = (0..n).map(|i| g[i].dot(&dx[i])).sum();
            let mut step = 1.0;
            let mut accepted = false;
            for _ in 0..30 {
                for i in 0..n {
                    xtry[i] = x[i] + dx[i] * step;
                }
                let phi = self.objective(&xtry, xn, xt, a_in, a_damp, &frozen);
                // The 1e-13 |phi0| slack absorbs rounding of the energy sum near convergence.
                if phi <= phi0 + 1e-4 * step * slope + 1e-13 * phi0.abs() {
                    accepted = true;
                    break;
                }
                step *= 0.5;
            }
            self.pforces = frozen;
            if !accepted {
                break;
            }
            std::mem::swap(&mut x, &mut xtry);
        }
        self.x = x;
        info
    }
}
