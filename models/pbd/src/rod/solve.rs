//! One XPBD substep of the rod: prediction, contacts, stretch-shear and
//! bend-twist projections (Gauss-Seidel or the direct banded solve).

use super::*;
use surgbench_core::flow::{BLOOD_DENSITY, DRAG_NORMAL};
use surgbench_core::motion::carried;
use surgbench_core::{Mat3, Vec3};

impl PbdRod {
    pub(super) fn predict(&mut self, h: f64) {
        let damp = 1.0 / (1.0 + self.set.damping * h);
        let n = self.n;
        for i in 1..=n {
            let mut f = self.gravity * self.mass[i];
            if i == n {
                f += self.tip_force * self.load_scale;
            }
            // Damp the old velocity only, so the static load h^2 g is not scaled.
            let mut v = self.v[i] * damp + f * (h * self.w[i]);
            if let Some(flow) = &self.flow {
                // Quadratic cross-flow drag on the particle's share of the rod,
                // integrated implicitly in its linearised form for stability.
                let t = (self.x[i] - self.x[i - 1]
                    + if i < n {
                        self.x[i + 1] - self.x[i]
                    } else {
                        Vec3::zeros()
                    })
                .try_normalize(1e-300)
                .unwrap_or(Vec3::x());
                let rel = flow.velocity(&self.x[i]) - v;
                let rel_n = rel - t * t.dot(&rel);
                let share = if i == n { 0.5 * self.l } else { self.l };
                let c = 0.5 * BLOOD_DENSITY * DRAG_NORMAL * 2.0 * self.radius_node[i] * share * rel_n.norm();
                v += rel_n * (1.0 - 1.0 / (1.0 + h * c * self.w[i]));
            }
            self.v[i] = v;
            self.x_prev[i] = self.x[i];
            self.x[i] += v * h;
        }
        for j in 0..n {
            let r = rotmat(&self.q[j]);
            let [it, ia] = self.inertia[j];
            let ib = Vec3::new(it, it, ia);
            let mut wb = r.transpose() * self.omega[j] * damp;
            let mut tau = -wb.cross(&ib.component_mul(&wb));
            if j == n - 1 {
                tau += r.transpose() * (self.tip_torque * self.load_scale);
            }
            wb += tau.component_div(&ib) * h;
            self.omega[j] = r * wb;
            self.q_prev[j] = self.q[j];
            let dq = Quat::from_imag(self.omega[j] * (0.5 * h)) * self.q[j];
            self.q[j] = (self.q[j] + dq).normalize();
        }
    }

    /// Find the particles near the vessel wall and linearise the wall at
    /// those already on or past it ([`Contact`]). One `distance_gradient`
    /// query per particle at the prediction, none for a particle provably
    /// deep in the lumen: a signed distance field changes by at most `L |dx|`
    /// when the point moves by `dx` ([`SDF_LIPSCHITZ_BOUND`]), so the cached
    /// `phi` plus `L` times the distance moved since that query bounds `phi`
    /// from above. The same bound gates the re-queries of candidates during
    /// the solve ([`Self::solve_contacts`]).
    pub(super) fn detect_contacts(&mut self) {
        self.contacts.clear();
        let Some(sdf) = &self.vessel else { return };
        for i in 1..=self.n {
            let xi = self.x[i];
            let r = self.radius_node[i];
            let band = 2.0 * (xi - self.x_prev[i]).norm() + r;
            let (xc, phic) = self.sdf_cache[i];
            // A moving wall may come to the particle: no early-out (the
            // cached value is of another time's lumen).
            if self.moving.is_none() && phic + SDF_LIPSCHITZ_BOUND * (xi - xc).norm() + self.margin <= -band {
                continue;
            }
            let (phi, g) = sdf.distance_gradient(&xi);
            self.sdf_cache[i] = (xi, phi);
            let d0 = phi + self.margin;
            if d0 > -band {
                let wall_dx = match self.moving.as_ref().and_then(|e| e.vessel_motion.as_ref()) {
                    Some(m) => carried(m.as_ref(), &self.x_prev[i], self.wall_t.0, self.wall_t.1) - self.x_prev[i],
                    None => Vec3::zeros(),
                };
                let mut c = Contact {
                    i,
                    live: false,
                    normal: Vec3::zeros(),
                    d0,
                    x_ref: xi,
                    dx: Vec3::zeros(),
                    wall_dx,
                };
                c.linearise(d0, &g);
                self.contacts.push(c);
            }
        }
    }

    /// Rebuild the per-substep constants (`alpha / h^2` and the stretch-shear
    /// denominators) when the substep length changes.
    pub(super) fn refresh_caches(&mut self, h: f64) {
        if h == self.cache_h {
            return;
        }
        self.cache_h = h;
        let inv_h2 = 1.0 / (h * h);
        let inv_l2 = 1.0 / (self.l * self.l);
        for j in 0..self.n {
            let al = self.ss_alpha[j] * inv_h2;
            let wx = (self.w[j] + self.w[j + 1]) * inv_l2;
            let a = self.inv_inertia[j].x;
            self.ss_at[j] = al;
            self.ss_inv_den[j] = Vec3::new(1.0 / (wx + a + al.x), 1.0 / (wx + a + al.y), 1.0 / (wx + al.z));
            self.bt_at[j] = self.bt_alpha[j] * inv_h2;
        }
    }

    /// Stretch-shear constraint of segment `j` (XPBD, exact block, solved in
    /// the material frame where `J W J^T` is diagonal:
    /// `diag(wx + 1/I_t, wx + 1/I_t, wx)`, `wx = (w_j + w_{j+1}) / l^2`).
    #[inline]
    pub(super) fn solve_stretch_shear(&mut self, j: usize, last: bool) {
        let inv_l = self.inv_l;
        let qj = self.q[j];
        let r = rotmat(&qj);
        let gb = r.tr_mul(&((self.x[j + 1] - self.x[j]) * inv_l)) - Vec3::z();
        let rhs = -(gb + self.ss_at[j].component_mul(&self.lambda_ss[j]));
        if last {
            self.residual = self.residual.max(rhs.amax());
        }
        let dl = rhs.component_mul(&self.ss_inv_den[j]);
        self.lambda_ss[j] += dl;
        let dw = r * dl;
        self.x[j] -= dw * (self.w[j] * inv_l);
        self.x[j + 1] += dw * (self.w[j + 1] * inv_l);
        // World rotation (d1 dl_y - d2 dl_x) / I_t, i.e. body (dl_y, -dl_x, 0) / I_t.
        let a = self.inv_inertia[j].x;
        self.q[j] = rotate_body(&qj, &Vec3::new(dl.y * a, -dl.x * a, 0.0));
    }

    /// Bend-twist constraint of joint `k` between segment `k-1` (or the clamp
    /// frame for `k = 0`) and segment `k` (XPBD, exact 3x3 block).
    ///
    /// With `r = conj(q_a) q_b = (w, v)`, `B = w I + [v]_x` and `A = B^T`, the
    /// Jacobians on world rotation vectors are `J_a = -(1/len) A R_a^T` and
    /// `J_b = (1/len) B R_b^T`, so with body-frame inverse inertias `W_a`,
    /// `W_b`: `J W J^T = (B W_b B^T + A W_a A^T) / len^2`, and the body-frame
    /// rotations are `u_b = W_b A dlambda / len`, `u_a = -W_a B dlambda / len`.
    #[inline]
    pub(super) fn solve_bend_twist(&mut self, k: usize, last: bool) {
        let len = self.bt_len[k];
        let s = self.bt_inv_len[k];
        let qa = if k == 0 { self.clamp_q } else { self.q[k - 1] };
        let qb = self.q[k];
        // Darboux vector as in `darboux`, without its division.
        let mut r = conj_mul(&qa, &qb);
        if r.w < 0.0 {
            r = -r;
        }
        let (w, v) = (r.w, r.imag());
        let c = v * (2.0 * s) - self.omega0[k];
        // With W = diag(a, a, c) and |r| = 1 (so B B^T = B^T B = I - v v^T):
        // B W B^T = a (I - v v^T) + (c - a) b3 b3^T with b3 = B e3 = (v_y, -v_x, w),
        // A W A^T = a (I - v v^T) + (c - a) a3 a3^T with a3 = A e3 = (-v_y, v_x, w).
        let jc = self.bt_jw[k];
        let (b3, a3) = (Vec3::new(v.y, -v.x, w), Vec3::new(-v.y, v.x, w));
        let sv = v * jc.x;
        let tb = b3 * jc.y;
        let ta = a3 * jc.z;
        let al = self.bt_at[k];
        let kk = [
            jc.x - sv.x * v.x + tb.x * b3.x + ta.x * a3.x + al.x,
            -sv.x * v.y + tb.x * b3.y + ta.x * a3.y,
            -sv.x * v.z + tb.x * b3.z + ta.x * a3.z,
            jc.x - sv.y * v.y + tb.y * b3.y + ta.y * a3.y + al.y,
            -sv.y * v.z + tb.y * b3.z + ta.y * a3.z,
            jc.x - sv.z * v.z + tb.z * b3.z + ta.z * a3.z + al.z,
        ];
        let rhs = -(c + al.component_mul(&self.lambda_bt[k]));
        if last {
            // Dimensionless: rotation angle over the joint.
            self.residual = self.residual.max(rhs.amax() * len);
        }
        let Some(dl) = solve_spd3(kk, &rhs) else { return };
        self.lambda_bt[k] += dl;
        // A dl = w dl - v x dl, B dl = w dl + v x dl.
        let wdl = dl * w;
        let vxdl = v.cross(&dl);
        self.q[k] = rotate_body(&qb, &(self.inv_inertia[k].component_mul(&(wdl - vxdl)) * s));
        if k > 0 {
            let u = self.inv_inertia[k - 1].component_mul(&(wdl + vxdl)) * (-s);
            self.q[k - 1] = rotate_body(&qa, &u);
        }
    }

    /// Linearise every rod constraint at the current state and assemble the
    /// direct solver's system (Deul et al. 2018, sec. 4, eq. 10 with the
    /// XPBD compliance of Macklin et al. 2016, eq. 18):
    /// `(J W J^T + alpha~) dlambda = -(C + alpha~ lambda)` into
    /// `self.band` / `self.dsol`, unknowns ordered `[BT_0, SS_0, BT_1, SS_1,
    /// ...]` (joint `k` between segment `k-1`, or the clamp frame, and `k`).
    ///
    /// Generalised coordinates: the free particles `x_i` (world, inverse
    /// mass `w_i`; `w_0 = 0` at the clamp) and one body-frame rotation
    /// vector `u_j` per segment (`q_j <- q_j (1 + 1/2 (u_j, 0))`, inverse
    /// inertia `W_j = diag(a_j, a_j, c_j)`). The Jacobians are those the
    /// Gauss-Seidel path applies (see [`Self::solve_stretch_shear`] and
    /// [`Self::solve_bend_twist`]):
    ///
    /// * `SS_j` (material frame `R_j`): `-R_j^T / l` on `x_j`, `R_j^T / l`
    ///   on `x_{j+1}`, `E = [e3]_x` on `u_j` (the derivative of `-d3(q_j)`,
    ///   K&S 2016 eq. 31, expressed in the frame `R_j` of the linearisation);
    /// * `BT_k` (`r = conj(q_a) q_b = (w, v)`, `B = w I + [v]_x`):
    ///   `-B^T / len` on `u_{k-1}`, `B / len` on `u_k` (exact).
    ///
    /// Blocks of `J W J^T` (every pair sharing a body):
    /// `SS_j,SS_j = (w_j + w_{j+1}) / l^2 I + E W_j E^T`;
    /// `BT_k,BT_k = (B_k W_k B_k^T + B_k^T W_{k-1} B_k) / len_k^2`;
    /// `SS_k,BT_k = E W_k B_k^T / len_k`;
    /// `BT_k,SS_{k-1} = -B_k^T W_{k-1} E^T / len_k`;
    /// `BT_k,BT_{k-1} = -B_k^T W_{k-1} B_{k-1}^T / (len_k len_{k-1})`;
    /// `SS_k,SS_{k-1} = -w_k R_k^T R_{k-1} / l^2`. Only the lower triangle is
    /// stored. The right-hand side is `-(C + alpha~ lambda)` with the same
    /// constraint values as the Gauss-Seidel path. Sets `self.residual` to
    /// the largest residual (as [`Self::solve_stretch_shear`] /
    /// [`Self::solve_bend_twist`] do) when `last`.
    pub(crate) fn assemble_direct(&mut self, last: bool) {
        let n = self.n;
        if self.dsol.len() != 6 * n {
            self.dsol = vec![0.0; 6 * n];
            self.drot = vec![Mat3::identity(); n];
            self.drel = vec![Quat::identity(); n];
        }
        for j in 0..n {
            self.drot[j] = rotmat(&self.q[j]);
            let qa = if j == 0 { self.clamp_q } else { self.q[j - 1] };
            let mut r = conj_mul(&qa, &self.q[j]);
            if r.w < 0.0 {
                r = -r;
            }
            self.drel[j] = r;
        }
        let e = e3_cross();
        let inv_l = self.inv_l;
        let inv_l2 = inv_l * inv_l;
        let band = &mut self.band;
        band.clear();
        for k in 0..n {
            let s = self.bt_inv_len[k];
            let r = self.drel[k];
            let b = Mat3::identity() * r.w + skew(&r.imag());
            let wk = Mat3::from_diagonal(&self.inv_inertia[k]);
            // BT_k diagonal block.
            let mut kbt = b * wk * b.transpose() * (s * s) + Mat3::from_diagonal(&self.bt_at[k]);
            if k > 0 {
                let wa = Mat3::from_diagonal(&self.inv_inertia[k - 1]);
                kbt += b.transpose() * wa * b * (s * s);
            }
            add_block(band, 2 * k, 2 * k, &kbt);
            // SS_k diagonal block.
            let wx = (self.w[k] + self.w[k + 1]) * inv_l2;
            let kss = Mat3::identity() * wx + e * wk * e.transpose() + Mat3::from_diagonal(&self.ss_at[k]);
            add_block(band, 2 * k + 1, 2 * k + 1, &kss);
            // Off-diagonal blocks (row block > column block: all 9 entries).
            let mut offs: [(usize, usize, Mat3); 4] = [(0, 0, Mat3::zeros()); 4];
            let mut m = 0;
            offs[m] = (2 * k + 1, 2 * k, e * wk * b.transpose() * s);
            m += 1;
            if k > 0 {
                let wa = Mat3::from_diagonal(&self.inv_inertia[k - 1]);
                let rp = self.drel[k - 1];
                let bp = Mat3::identity() * rp.w + skew(&rp.imag());
                let sp = self.bt_inv_len[k - 1];
                offs[m] = (2 * k, 2 * k - 1, -(b.transpose() * wa * e.transpose()) * s);
                offs[m + 1] = (2 * k, 2 * k - 2, -(b.transpose() * wa * bp.transpose()) * (s * sp));
                offs[m + 2] = (
                    2 * k + 1,
                    2 * k - 1,
                    -(self.drot[k].tr_mul(&self.drot[k - 1])) * (self.w[k] * inv_l2),
                );
                m += 3;
            }
            for (bi, bj, blk) in &offs[..m] {
                add_block(band, *bi, *bj, blk);
            }
        }
        for k in 0..n {
            let r = self.drel[k];
            let c = r.imag() * (2.0 * self.bt_inv_len[k]) - self.omega0[k];
            let rbt = -(c + self.bt_at[k].component_mul(&self.lambda_bt[k]));
            let gb = self.drot[k].tr_mul(&((self.x[k + 1] - self.x[k]) * inv_l)) - Vec3::z();
            let rss = -(gb + self.ss_at[k].component_mul(&self.lambda_ss[k]));
            if last {
                self.residual = self.residual.max(rbt.amax() * self.bt_len[k]).max(rss.amax());
            }
            self.dsol[6 * k..6 * k + 3].copy_from_slice(rbt.as_slice());
            self.dsol[6 * k + 3..6 * k + 6].copy_from_slice(rss.as_slice());
        }
    }

    /// One direct iteration ([`RodSolver::Direct`]): assemble
    /// ([`Self::assemble_direct`]), factor and solve by banded Cholesky
    /// (`O(n)`, [`surgbench_core::band`]), then apply `dlambda` to the
    /// multipliers and `W J^T dlambda` to the particles and (body-frame) to
    /// the segment rotations, with the same quaternion update as the
    /// Gauss-Seidel path.
    pub(super) fn solve_direct(&mut self, last: bool) -> Result<(), String> {
        self.assemble_direct(last);
        self.band.factor(0.0).map_err(|e| {
            format!(
                "direct rod solve: J W J^T + alpha~ is not positive definite at row {} of {}",
                e.row,
                6 * self.n
            )
        })?;
        self.band.solve(&mut self.dsol);
        let n = self.n;
        let inv_l = self.inv_l;
        let dl =
            |k: usize, o: usize| Vec3::new(self.dsol[6 * k + o], self.dsol[6 * k + o + 1], self.dsol[6 * k + o + 2]);
        for k in 0..n {
            self.lambda_bt[k] += dl(k, 0);
            self.lambda_ss[k] += dl(k, 3);
        }
        // Particles: dx_i = w_i (R_{i-1} dl_ss_{i-1} - R_i dl_ss_i) / l.
        for i in 1..=n {
            let mut f = self.drot[i - 1] * dl(i - 1, 3);
            if i < n {
                f -= self.drot[i] * dl(i, 3);
            }
            self.x[i] += f * (self.w[i] * inv_l);
        }
        // Segments: u_j = W_j (E^T dl_ss_j + B_j^T dl_bt_j / len_j
        // - B_{j+1} dl_bt_{j+1} / len_{j+1}); E^T d = (d_y, -d_x, 0),
        // B^T d = w d - v x d, B d = w d + v x d.
        for j in 0..n {
            let ds = dl(j, 3);
            let mut g = Vec3::new(ds.y, -ds.x, 0.0);
            let (r, db) = (self.drel[j], dl(j, 0));
            g += (db * r.w - r.imag().cross(&db)) * self.bt_inv_len[j];
            if j + 1 < n {
                let (r, db) = (self.drel[j + 1], dl(j + 1, 0));
                g -= (db * r.w + r.imag().cross(&db)) * self.bt_inv_len[j + 1];
            }
            self.q[j] = rotate_body(&self.q[j], &self.inv_inertia[j].component_mul(&g));
        }
        Ok(())
    }

    /// Contact plane constraints with position-level Coulomb friction
    /// (Macklin et al. 2014, sec. 6.1, eqs. 24-25).
    /// One projection of every live contact, with Coulomb friction; a
    /// candidate that may have reached the wall since its last query (the
    /// Lipschitz bound of [`Self::detect_contacts`]) is queried again at its
    /// current position and goes live there if it has.
    pub(super) fn solve_contacts(&mut self) {
        for c in &mut self.contacts {
            let i = c.i;
            if !c.live {
                let Some(sdf) = &self.vessel else { continue };
                let xi = self.x[i];
                let (xc, phic) = self.sdf_cache[i];
                if phic + SDF_LIPSCHITZ_BOUND * (xi - xc).norm() + self.margin < 0.0 {
                    continue;
                }
                let (phi, g) = sdf.distance_gradient(&xi);
                self.sdf_cache[i] = (xi, phi);
                c.x_ref = xi;
                if !c.linearise(phi + self.margin, &g) {
                    continue;
                }
            }
            let d = c.d0 + c.normal.dot(&(self.x[i] - c.x_ref));
            if d <= 0.0 {
                continue;
            }
            let mut dx = -c.normal * d;
            let moved = self.x[i] + dx - self.x_prev[i] - c.wall_dx;
            let dt_ = moved - c.normal * c.normal.dot(&moved);
            let s = dt_.norm();
            if s > 0.0 {
                if s < self.mu_s * d {
                    dx -= dt_;
                } else {
                    dx -= dt_ * (self.mu_k * d / s).min(1.0);
                }
            }
            self.x[i] += dx;
            c.dx += dx;
        }
        self.projections += self.contacts.len() as u64;
    }

    /// One substep: predict, then `iterations` constraint solves (each
    /// followed by one contact projection), then velocities and the
    /// reaction at the clamp. Fails only if the direct solver's matrix is
    /// not positive definite (reason in the error).
    pub(super) fn substep(&mut self, h: f64, clamp: (Vec3, Quat)) -> Result<(), String> {
        let old_clamp = self.clamp_pos;
        self.clamp_pos = clamp.0;
        self.clamp_q = clamp.1;
        self.last_h = h;
        self.predict(h);
        self.x_prev[0] = self.x[0];
        self.x[0] = self.clamp_pos;
        self.v[0] = (self.clamp_pos - old_clamp) / h;
        self.detect_contacts();
        self.refresh_caches(h);
        self.lambda_ss.fill(Vec3::zeros());
        self.lambda_bt.fill(Vec3::zeros());
        let h2 = h * h;
        let iters = self.set.iterations;
        for it in 0..iters {
            let last = it + 1 == iters;
            if last {
                self.residual = 0.0;
            }
            match self.set.solver {
                RodSolver::GaussSeidel => {
                    self.solve_bend_twist(0, last);
                    for j in 0..self.n {
                        self.solve_stretch_shear(j, last);
                        if j + 1 < self.n {
                            self.solve_bend_twist(j + 1, last);
                        }
                    }
                }
                RodSolver::Direct => self.solve_direct(last)?,
            }
            self.projections += 2 * self.n as u64;
            if !self.contacts.is_empty() {
                self.solve_contacts();
            }
        }
        for i in 1..=self.n {
            self.v[i] = (self.x[i] - self.x_prev[i]) / h;
        }
        for j in 0..self.n {
            let mut dq = self.q[j] * self.q_prev[j].conjugate();
            if dq.w < 0.0 {
                dq = -dq;
            }
            self.omega[j] = dq.imag() * (2.0 / h);
        }
        // Reaction on the clamp: constraint forces J^T lambda / h^2 on the
        // clamped particle (stretch-shear 0) and clamp frame (joint 0), plus the
        // weight of the clamped particle's half segment.
        let r0 = rotmat(&self.q[0]);
        self.hand_force = -(r0 * self.lambda_ss[0]) / (self.l * h2) + self.gravity * self.mass[0];
        let (_, w, v) = darboux(&self.clamp_q, &self.q[0], self.bt_len[0]);
        let rc = rotmat(&self.clamp_q);
        let a_blk_t = Mat3::identity() * w + skew(&v); // (wI - [v])^T
        self.hand_torque = -(rc * (a_blk_t * self.lambda_bt[0])) / (self.bt_len[0] * h2);
        Ok(())
    }

    pub(super) fn diverged(&self) -> Option<String> {
        let lim = 4.0 * self.l * self.n as f64;
        for (i, p) in self.x.iter().enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                return Some(format!("particle {i} is not finite"));
            }
            if (p - self.clamp_pos).norm() > lim {
                return Some(format!(
                    "particle {i} is {:.3e} m from the clamp, rod length {:.3e} m",
                    (p - self.clamp_pos).norm(),
                    self.l * self.n as f64
                ));
            }
        }
        if !self.q.iter().all(|q| q.coords.iter().all(|c| c.is_finite())) {
            return Some("orientation is not finite".into());
        }
        None
    }
}
