//! Feeding the wire at the base and pushing it out of the vessel wall
//! (with friction), and the state checks of a step.

use super::*;
use crate::rules::friction_correction;
use surgbench_core::{ContactObs, SimError, Vec3};

impl ChainmailWire {
    /// Feed or withdraw wire at the base for the current insertion and place
    /// the prescribed nodes on the clamp axis.
    pub(super) fn update_feed(&mut self) -> Result<(), String> {
        let tol = 1e-9 * self.delta;
        let fixed = |w: &Self, k: usize| w.sigma[k] + w.insertion <= tol;
        // retraction: drop elements that went more than one link behind
        while self.x.len() > 2 && fixed(self, 2) {
            self.sigma.remove(0);
            self.turn.remove(0);
            self.x.remove(0);
            self.x_prev.remove(0);
            self.links.remove(0);
        }
        // insertion: feed new elements so that two are always prescribed
        while !fixed(self, 1) {
            let s = self.sigma[0] - self.delta;
            let p = self.link_params_at(s + 0.5 * self.delta)?;
            let r = self.rest_point(s);
            self.sigma.insert(0, s);
            let k = self.turn_at(s);
            self.turn.insert(0, k);
            self.x.insert(0, r);
            self.x_prev.insert(0, r);
            self.links.insert(0, p);
        }
        self.n_fixed = (0..self.x.len()).take_while(|&k| fixed(self, k)).count();
        if self.n_fixed >= self.x.len() {
            return Err(format!("wire withdrawn past its tip (insertion {} m)", self.insertion));
        }
        for k in 0..self.n_fixed {
            self.x[k] = self.rest_point(self.sigma[k]);
        }
        Ok(())
    }

    /// Index of the first tip element: the first node of the last section
    /// when the wire has several, otherwise the distal node.
    pub(super) fn tip_element(&self) -> usize {
        let n = self.x.len();
        let secs = &self.rod.sections;
        if secs.len() > 1 {
            let start = secs[secs.len() - 2].until;
            (self.n_fixed..n)
                .find(|&k| self.sigma[k] >= start - 1e-12)
                .unwrap_or(n - 1)
        } else {
            n - 1
        }
    }

    /// Normal wall projection inside the relaxation loop (`Link` frame):
    /// every free element closer than `epsilon` moves by `(phi + epsilon)`
    /// along `-grad phi`; the corrections add up in `wall_depth` for the
    /// friction factor at the end of the step.
    pub(super) fn wall_pass(&mut self, accumulate: bool) {
        let Some(sdf) = self.vessel.clone() else {
            return;
        };
        let eps = self.margin;
        for i in self.n_fixed..self.x.len() {
            let phi = sdf.distance(&self.x[i]);
            if phi <= -eps {
                continue;
            }
            let g = sdf.gradient(&self.x[i]);
            let gn = g.norm();
            if gn.is_nan() || gn <= 0.0 {
                continue;
            }
            self.x[i] -= g * ((phi + eps) / gn);
            if accumulate {
                self.wall_depth[i] += phi + eps;
            }
        }
    }

    pub(super) fn collide(&mut self) {
        self.contacts.clear();
        self.hand_force = Vec3::zeros();
        let Some(sdf) = self.vessel.clone() else {
            return;
        };
        let eps = self.margin;
        // a node the in-loop wall passes left on the wall (to rounding)
        let tol = 1e-9 * self.delta;
        let mut touched = Vec::new();
        for i in self.n_fixed..self.x.len() {
            let phi = sdf.distance(&self.x[i]);
            let prior = self.wall_depth.get(i).copied().unwrap_or(0.0);
            if phi <= -eps - if prior > 0.0 { tol } else { 0.0 } {
                continue;
            }
            let g = sdf.gradient(&self.x[i]);
            let gn = g.norm();
            if gn.is_nan() || gn <= 0.0 {
                continue;
            }
            let n = g / gn;
            let depth = (phi + eps).max(0.0);
            let dp_n = -n * depth;
            let depth = depth + prior;
            self.x[i] += dp_n;
            // slip against the wall, which itself moved if the vessel beats
            let mut m = self.x[i] - self.x_prev[i];
            if let Some(lat) = &self.lattice {
                m -= lat.step_motion(&self.x[i]);
            }
            let m_t = m - n * m.dot(&n);
            let f = friction_correction(&m_t, depth, self.friction);
            self.x[i] += f;
            let pen = sdf.distance(&self.x[i]).max(0.0);
            self.contacts.push(ContactObs {
                point: self.x[i],
                force: (dp_n + f) * self.haptic_k,
                penetration: pen,
            });
            self.hand_force += f * self.haptic_k;
            touched.push(i);
        }
        if self.frame == BoxFrame::Link && !touched.is_empty() {
            self.restore_boxes_on_wall();
            for (c, &i) in self.contacts.iter_mut().zip(&touched) {
                c.point = self.x[i];
                c.penetration = sdf.distance(&self.x[i]).max(0.0);
            }
        }
    }

    /// The final length-restoring pass (`Link` frame, after friction): the
    /// friction correction moves contact elements off their boxes (the
    /// relaxation ran before it), e.g. a sticking tip whose neighbour was
    /// pushed on, so the clamp sponsors the chain once more
    /// ([`ChainmailWire::sweep_from_base`]: every link back in its box) and a
    /// last normal wall projection keeps non-penetration. The friction's
    /// share of the hand force is the correction it made; the links carry it
    /// back to the clamp. Measured on `coronary-tortuous` (40 segments,
    /// `beta_mapping=navigation`): without it the tip link ends compressed by 5.3 %
    /// at 38.0 s (2.6 % from the last wall pass, 2.7 % from friction); with
    /// it the first watchdog trip moves to 43.7 s (see the crate report).
    pub(super) fn restore_boxes_on_wall(&mut self) {
        self.sweep_from_base();
        self.wall_pass(false);
    }

    pub(super) fn first_link(&self) -> f64 {
        let a = self.n_fixed - 1;
        (self.x[a + 1] - self.x[a]).norm()
    }

    pub(super) fn check_finite(&self) -> Result<(), SimError> {
        if let Some(i) = self.x.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(SimError::Diverged {
                t: self.time,
                reason: format!("node {i} is not finite: {:?}", self.x[i]),
            });
        }
        Ok(())
    }
}
