//! The chain-mail rules applied along the wire: box enforcement sweeps
//! from a moved node and the relaxation towards the rest shape.

use super::*;
use crate::rules::{box_violation, project_into_box, relaxation_target};
use surgbench_core::Vec3;
use surgbench_core::frames::parallel_transport;

impl ChainmailWire {
    /// Enforce the valid box of node `i + dir` around sponsor `i`; returns
    /// whether the neighbour moved. Prescribed nodes never move.
    pub(super) fn enforce(&mut self, i: usize, dir: isize) -> bool {
        let j = (i as isize + dir) as usize;
        if j < self.n_fixed {
            return false;
        }
        let (f, d) = if self.frame == BoxFrame::Link {
            self.link_box(i, dir, &self.link_frames())
        } else {
            self.box_geometry(dir)
        };
        let (q, moved) = project_into_box(&self.x[i], &self.x[j], &d, &f, &self.links[Self::link_of(i, dir)]);
        self.x[j] = q;
        moved
    }

    /// The paper's propagation from sponsor `k` (after it moved): each
    /// neighbour outside its box moves into it and sponsors the next; in each
    /// direction the wave stops at the first valid neighbour (or the clamp /
    /// the tip). Returns how many elements moved.
    pub fn propagate_from(&mut self, k: usize) -> usize {
        let n = self.x.len();
        let mut moved = 0;
        let mut i = k;
        while i + 1 < n && self.enforce(i, 1) {
            moved += 1;
            i += 1;
        }
        let mut i = k;
        while i > 0 && self.enforce(i, -1) {
            moved += 1;
            i -= 1;
        }
        moved
    }

    /// The clamp sponsors the whole chain: after every free element was
    /// displaced (gravity, flow), each one is checked against its base-side
    /// neighbour in order from the clamp to the tip.
    pub(super) fn sweep_from_base(&mut self) {
        if self.frame != BoxFrame::Link {
            for i in self.n_fixed - 1..self.x.len() - 1 {
                self.enforce(i, 1);
            }
            return;
        }
        // carry the frame of link i - 1 along (it depends on nodes already
        // enforced in this sweep only)
        let (mut t, mut d1) = (self.tb, self.d1b);
        for i in self.n_fixed - 1..self.x.len() - 1 {
            let (tp, dp) = Self::turned(&t, &d1, &self.turn[i], 1.0);
            let f = Self::axes(&tp, &dp);
            let d = Vec3::new(self.delta, 0.0, 0.0);
            let (q, _) = project_into_box(&self.x[i], &self.x[i + 1], &d, &f, &self.links[i]);
            self.x[i + 1] = q;
            let tn = unit_or(q - self.x[i], tp);
            d1 = parallel_transport(&dp, &tp, &tn);
            d1 = unit_or(d1 - tn * tn.dot(&d1), d1);
            t = tn;
        }
    }

    /// Predictions `Q` of free node `i` by its neighbours, into `out`.
    pub(super) fn predictions(&self, i: usize, out: &mut [Vec3; 2]) -> usize {
        let n = self.x.len();
        let tb = self.t_base();
        let d = self.delta;
        out[0] = self.x[i - 1] + tb * d;
        if i + 1 < n {
            out[1] = self.x[i + 1] - tb * d;
            2
        } else {
            1
        }
    }

    /// One Gauss–Seidel relaxation sweep, base to tip: each free element goes
    /// to `P* = mean(Q_i)`. In the `World`/`Base` frames this is exact
    /// coordinate minimization of [`ChainmailWire::relaxation_energy`] (each
    /// link's term `||P_j+1 - P_j - delta||^2` appears once per end), so the
    /// energy never increases.
    pub fn relax_sweep(&mut self) {
        if self.frame == BoxFrame::Link {
            self.relax_sweep_link();
            return;
        }
        let mut q = [Vec3::zeros(); 2];
        for i in self.n_fixed..self.x.len() {
            let m = self.predictions(i, &mut q);
            self.x[i] = relaxation_target(&q[..m]);
        }
    }

    /// Link-frame relaxation sweep, base to tip. The paper's rule with
    /// body-frame offsets, `P* = (Q_1 + Q_2)/2` with the straight
    /// continuations `Q_1 = 2 P_{i-1} - P_{i-2}` and `Q_2 = 2 P_{i+1} - P_{i+2}`
    /// (linearized), multiplies a zigzag `(-1)^k a` by `-3` per sweep and
    /// diverges (seen on `arch-insertion`). So each node goes to the
    /// minimizer of the three body-frame residuals it appears in,
    /// `P* = (Q_1 + Q_2 + 4 Q_M) / 6` (weights from the discrete bending
    /// form `sum_i ||P_{i+1} - 2 P_i + P_{i-1}||^2`, whose Gauss–Seidel
    /// converges): `Q_1 = P_{i-1} + Delta t'` (link `i - 2`'s tangent turned
    /// forwards at node `i - 1`), `Q_2 = P_{i+1} - Delta t''` (link `i + 1`'s
    /// tangent turned backwards at node `i + 1`), and the vertex prediction
    /// `Q_M = (P_{i-1} + P_{i+1})/2 + Delta (R(-phi/2) c - R(phi/2) c)/2`
    /// (`c` the chord direction, `phi` the rest turning at node `i`: the
    /// vertex of two rest links around that chord). Terms that do not exist
    /// at the tip drop out with their weights.
    ///
    /// Cost: on a wire without rest curvature every turning is zero, so the
    /// directors `d1` never enter a prediction; the sweep then carries only
    /// the tangents and takes link `i + 1`'s tangent straight from its nodes
    /// (the value [`ChainmailWire::link_frames`] would give, to the bit,
    /// unless the link has zero length), skipping the frame transport.
    pub(super) fn relax_sweep_link(&mut self) {
        let n = self.x.len();
        let curved = self.turn.iter().any(|k| *k != [0.0, 0.0]);
        let fr = if curved { self.link_frames() } else { Vec::new() };
        let (mut t, mut d1) = (self.tb, self.d1b);
        for i in self.n_fixed..n {
            let (tp, dp) = if curved {
                Self::turned(&t, &d1, &self.turn[i - 1], 1.0)
            } else {
                (t, d1)
            };
            let mut sum = self.x[i - 1] + tp * self.delta;
            let mut w = 1.0;
            if i + 1 < n {
                let c = unit_or(self.x[i + 1] - self.x[i - 1], tp);
                let k = self.turn[i];
                let mut qm = 0.5 * (self.x[i - 1] + self.x[i + 1]);
                if k != [0.0, 0.0] {
                    let om = dp * k[0] + tp.cross(&dp) * k[1];
                    let a = om.norm();
                    let axis = om / a;
                    // R(-a/2) c - R(a/2) c with one sin_cos (sin is odd,
                    // cos even: the same bits as two evaluations)
                    let (s, co) = (0.5 * a).sin_cos();
                    let d = rodrigues(&c, &axis, -s, co) - rodrigues(&c, &axis, s, co);
                    qm += d * (0.5 * self.delta);
                }
                sum += 4.0 * qm;
                w += 4.0;
            }
            if i + 2 < n {
                let tq = if curved {
                    Self::turned(&fr[i + 1].0, &fr[i + 1].1, &self.turn[i + 1], -1.0).0
                } else {
                    unit_or(self.x[i + 2] - self.x[i + 1], tp)
                };
                sum += self.x[i + 1] - tq * self.delta;
                w += 1.0;
            }
            let p = sum / w;
            self.x[i] = p;
            let tn = unit_or(p - self.x[i - 1], tp);
            if curved {
                d1 = parallel_transport(&dp, &tp, &tn);
                d1 = unit_or(d1 - tn * tn.dot(&d1), d1);
            }
            t = tn;
        }
    }

    /// The paper's relaxation energy `sum_P sum_i ||P - Q_i||^2` over every
    /// element `P` and its neighbours' predictions `Q_i` (m^2).
    pub fn relaxation_energy(&self) -> f64 {
        let n = self.x.len();
        let mut e = 0.0;
        let mut q = [Vec3::zeros(); 2];
        for i in 2..n {
            let m = self.predictions(i, &mut q);
            for qq in &q[..m] {
                e += (self.x[i] - qq).norm_squared();
            }
        }
        // the clamp's prediction from the first free element
        if n > 2 {
            e += (self.x[1] - (self.x[2] - self.t_base() * self.delta)).norm_squared();
        }
        e
    }

    /// Largest box violation over all links, relative to `Delta`.
    pub fn box_residual(&self) -> f64 {
        let mut r: f64 = 0.0;
        let fr = if self.frame == BoxFrame::Link {
            self.link_frames()
        } else {
            Vec::new()
        };
        for i in 1..self.x.len() - 1 {
            let (f, d) = if self.frame == BoxFrame::Link {
                self.link_box(i, 1, &fr)
            } else {
                self.box_geometry(1)
            };
            r = r.max(box_violation(&self.x[i], &self.x[i + 1], &d, &f, &self.links[i]));
        }
        r / self.delta
    }
}
