//! One XPBD substep of the tissue (local activation, coloured parallel
//! projections, rollers and sphere contact) and the reaction forces it
//! reports.

use super::*;
use crate::ghost::{GhostSurface, project_particle_triangle};
use crate::hash::BoxHash;
use surgbench_core::Vec3;
use surgbench_core::mesh::{tet_volume_gradients, tet_volume_of as tet_volume};

impl PbdTissue {
    /// The boxes to activate this step, as sorted linear indices: the box
    /// holding the tool tip for a driven tool; for a coupled instrument
    /// (surface forces), every box holding a contact-surface node that
    /// carries a force, by its rest position (the grid partitions the rest
    /// mesh; a node on a box face does not flip between boxes as it moves).
    fn active_boxes(&self, hash: &BoxHash) -> Vec<usize> {
        let mut keys: Vec<usize> = if self.surface.is_empty() {
            vec![hash.linear_index(hash.box_of(&self.tool_tip()))]
        } else {
            self.surface
                .iter()
                .filter(|&&i| self.external[i] != Vec3::zeros())
                .map(|&i| hash.linear_index(hash.box_of(&self.rest[i])))
                .collect()
        };
        keys.sort_unstable();
        keys.dedup();
        keys
    }

    /// Recompute the active set if the boxes to activate changed: the tets
    /// of every active (expanded) box are solved; a node moves if every tet
    /// around it is active, and the nodes where the active tets meet the
    /// inactive ones are held where they are, the boundary of the local
    /// problem (no axis is privileged: the region follows the boxes in 3D).
    pub(super) fn update_active(&mut self) {
        let nn = self.x.len();
        let Some(hash) = &self.hash else {
            if self.active.key != [usize::MAX] {
                let edges: Vec<u32> = (0..self.edges.len() as u32).collect();
                let tets: Vec<u32> = (0..self.tets.len() as u32)
                    .filter(|&t| self.tet_alpha[t as usize].is_finite())
                    .collect();
                self.active = ActiveSet {
                    key: vec![usize::MAX],
                    edge_split: split_by_blocks(&edges, &self.part.edge_start),
                    tet_split: split_by_blocks(&tets, &self.part.tet_start),
                    edges,
                    tets,
                    nodes: (0..nn as u32).filter(|&i| self.w[i as usize] > 0.0).collect(),
                    w: self.w.clone(),
                    edge_on: vec![true; self.edges.len()],
                    tet_on: vec![true; self.tets.len()],
                };
            }
            return;
        };
        let key = self.active_boxes(hash);
        if key == self.active.key {
            return;
        }
        self.activations += 1;
        let mut edge_on = vec![false; self.edges.len()];
        let mut tet_on = vec![false; self.tets.len()];
        // Active tets around each node, against all tets around it.
        let mut around = vec![0u32; nn];
        let mut edges = Vec::new();
        let mut tets = Vec::new();
        for &k in &key {
            for &t in hash.tets(hash.box_at(k)) {
                if tet_on[t as usize] {
                    continue;
                }
                tet_on[t as usize] = true;
                if self.tet_alpha[t as usize].is_finite() {
                    tets.push(t);
                }
                for &e in &self.tet_edges[t as usize] {
                    if !edge_on[e as usize] {
                        edge_on[e as usize] = true;
                        edges.push(e);
                    }
                }
                for &i in &self.tets[t as usize] {
                    around[i as usize] += 1;
                }
            }
        }
        let mut w = vec![0.0; nn];
        let mut nodes = Vec::new();
        for i in 0..nn {
            if around[i] > 0 && around[i] == self.tets_around[i] && self.w[i] > 0.0 {
                w[i] = self.w[i];
                nodes.push(i as u32);
            }
        }
        // A node the region leaves stops where it is: it is held, and
        // starts from rest should the region come back to it.
        for &i in &self.active.nodes {
            if w[i as usize] == 0.0 {
                self.v[i as usize] = Vec3::zeros();
            }
        }
        // Storage order, so each block's share is contiguous.
        edges.sort_unstable();
        tets.sort_unstable();
        self.active = ActiveSet {
            key,
            edge_split: split_by_blocks(&edges, &self.part.edge_start),
            tet_split: split_by_blocks(&tets, &self.part.tet_start),
            edges,
            tets,
            nodes,
            w,
            edge_on,
            tet_on,
        };
    }

    /// Start of a substep of length `h` (s) at the command `ins`: damped
    /// velocities plus gravity move the free active nodes, the driven nodes
    /// jump to their commanded positions, and the multipliers (and the
    /// sphere's, which moves to its place) restart from zero.
    fn predict(&mut self, h: f64, ins: f64) {
        let damp = 1.0 / (1.0 + self.set.damping * h);
        for &i in &self.active.nodes {
            let i = i as usize;
            self.v[i] = self.v[i] * damp + (self.gravity + self.w[i] * self.external[i]) * h;
            self.x_prev[i] = self.x[i];
            self.x[i] += self.v[i] * h;
        }
        for &(i, d) in &self.driven {
            self.x_prev[i] = self.x[i];
            self.x[i] = self.rest[i] + d * ins;
            self.v[i] = (self.x[i] - self.x_prev[i]) / h;
        }
        for &e in &self.active.edges {
            self.lambda_e[e as usize] = 0.0;
        }
        for &t in &self.active.tets {
            self.lambda_t[t as usize] = 0.0;
        }
        if let Some(sp) = &mut self.sphere {
            sp.centre = sp.path.centre_at(ins);
            sp.lambda.iter_mut().for_each(|l| *l = 0.0);
            sp.impulse = Vec3::zeros();
        }
    }

    pub(super) fn substep(&mut self, h: f64, ins: f64) {
        self.last_h = h;
        self.predict(h, ins);
        let h2 = h * h;
        let iters = self.set.iterations;
        // Positions move to the shared (atomic) buffer for the solve: only the
        // nodes that moved since the last solve (predicted and driven ones).
        for &i in &self.active.nodes {
            self.xa.set(i as usize, &self.x[i as usize]);
        }
        for &(i, _) in &self.driven {
            self.xa.set(i, &self.x[i]);
        }
        let ctx = SolveCtx {
            x: &self.xa.0,
            w: &self.active.w,
            edges: &self.edges,
            edge_rest: &self.edge_rest,
            edge_alpha: &self.edge_alpha,
            tets: &self.tets,
            tet_rest: &self.tet_rest,
            tet_alpha: &self.tet_alpha,
            act_edges: &self.active.edges,
            act_tets: &self.active.tets,
            edge_split: &self.active.edge_split,
            tet_split: &self.active.tet_split,
            edge_start: &self.part.edge_start,
            tet_start: &self.part.tet_start,
            inv_h2: 1.0 / h2,
            parallel: self.pool.is_some(),
        };
        let colors = self.part.color_start;
        let lambda_e = &mut self.lambda_e;
        let lambda_t = &mut self.lambda_t;
        let sphere = &mut self.sphere;
        let (rollers, rest) = (&self.rollers, &self.rest);
        let mut solve = || {
            let mut res = 0.0f64;
            for it in 0..iters {
                let last = it + 1 == iters;
                res = 0.0;
                for c in 0..2 {
                    let (b0, b1) = (colors[c], colors[c + 1]);
                    if b0 == b1 {
                        continue;
                    }
                    let (e0, e1) = (ctx.edge_start[b0], ctx.edge_start[b1]);
                    let (t0, t1) = (ctx.tet_start[b0], ctx.tet_start[b1]);
                    let r = ctx.solve_blocks(b0..b1, &mut lambda_e[e0..e1], &mut lambda_t[t0..t1], last);
                    res = res.max(r);
                }
                if let Some(sp) = sphere.as_mut() {
                    sp.project(ctx.x, ctx.w);
                }
                project_rollers(rollers, rest, ctx.x, ctx.w);
            }
            res
        };
        self.residual = match &self.pool {
            Some(pool) => pool.install(solve),
            None => solve(),
        };
        for &i in &self.active.nodes {
            self.x[i as usize] = self.xa.get(i as usize);
        }
        self.projections += (iters * (self.active.edges.len() + self.active.tets.len())) as u64;
        for &i in &self.active.nodes {
            let i = i as usize;
            self.v[i] = (self.x[i] - self.x_prev[i]) / h;
        }
        let weight: Vec3 = self.driven.iter().map(|(i, _)| self.gravity * self.mass[*i]).sum();
        self.sphere_force = self.sphere.as_ref().map_or(Vec3::zeros(), |sp| sp.reaction(h2));
        self.multiplier_force = self.reaction_from_multipliers(h2) + weight + self.sphere_force;
        self.hand_force = self.reaction_from_energy(h2) + weight + self.sphere_force;
    }

    /// Reaction of the active constraints on the driven nodes from this
    /// substep's multipliers, `sum_j grad C_j lambda_j / h^2` (N; Macklin et
    /// al. 2016, eq. 9 with `f = grad C^T lambda / h^2`). Equals the elastic
    /// force only when the substep's solve converged (`C + alpha~ lambda = 0`);
    /// the multipliers restart from zero each substep, so a stiff mesh solved
    /// by a few iterations leaves them far short of it.
    pub(super) fn reaction_from_multipliers(&self, h2: f64) -> Vec3 {
        let mut f = Vec3::zeros();
        for &e in &self.driven_edges {
            let e = e as usize;
            if !self.active.edge_on[e] {
                continue;
            }
            let [a, b] = self.edges[e].map(|i| i as usize);
            let n = (self.x[b] - self.x[a]).try_normalize(0.0).unwrap_or(Vec3::zeros());
            if self.driven_mark[a] {
                f -= n * self.lambda_e[e];
            }
            if self.driven_mark[b] {
                f += n * self.lambda_e[e];
            }
        }
        for &t in &self.driven_tets {
            let t = t as usize;
            if !self.active.tet_on[t] || !self.tet_alpha[t].is_finite() {
                continue;
            }
            let idx = self.tets[t].map(|i| i as usize);
            let g = tet_volume_gradients(&idx.map(|i| self.x[i]));
            for k in 0..4 {
                if self.driven_mark[idx[k]] {
                    f += g[k] * self.lambda_t[t];
                }
            }
        }
        f / h2
    }

    /// Reaction of the active constraints on the driven nodes at the current
    /// positions: minus the gradient of the constraint energy
    /// `U = sum_j C_j^2 / (2 alpha_j)` with respect to the driven nodes,
    /// `-sum_j grad C_j C_j / alpha_j` (N). This is the force the model's
    /// elastic potential exerts in the configuration it reports, whether or
    /// not the last solve converged; at convergence it equals
    /// [`Self::reaction_from_multipliers`] (`lambda_j / h^2 = -C_j / alpha_j`,
    /// Macklin et al. 2016, eq. 18 at its fixed point). Hard constraints
    /// (`alpha = 0`, `nu = 1/2`) have no energy and keep their multiplier force.
    pub(super) fn reaction_from_energy(&self, h2: f64) -> Vec3 {
        let mut f = Vec3::zeros();
        for &e in &self.driven_edges {
            let e = e as usize;
            if !self.active.edge_on[e] {
                continue;
            }
            let [a, b] = self.edges[e].map(|i| i as usize);
            let d = self.x[b] - self.x[a];
            let len = d.norm();
            if len == 0.0 {
                continue;
            }
            let n = d / len;
            let alpha = self.edge_alpha[e];
            // Force along +grad C (as lambda / h^2 would be).
            let s = if alpha > 0.0 {
                -(len - self.edge_rest[e]) / alpha
            } else {
                self.lambda_e[e] / h2
            };
            if self.driven_mark[a] {
                f -= n * s;
            }
            if self.driven_mark[b] {
                f += n * s;
            }
        }
        for &t in &self.driven_tets {
            let t = t as usize;
            let alpha = self.tet_alpha[t];
            if !self.active.tet_on[t] || !alpha.is_finite() {
                continue;
            }
            let idx = self.tets[t].map(|i| i as usize);
            let p = idx.map(|i| self.x[i]);
            let g = tet_volume_gradients(&p);
            let s = if alpha > 0.0 {
                -(tet_volume(&p) - self.tet_rest[t]) / alpha
            } else {
                self.lambda_t[t] / h2
            };
            for k in 0..4 {
                if self.driven_mark[idx[k]] {
                    f += g[k] * s;
                }
            }
        }
        f
    }

    /// Collide point-like bodies (e.g. catheter particles) with `ghost`, the
    /// inner-wall surface built from this tissue's mesh
    /// ([`GhostSurface::from_inner_wall`]), after a [`Model::step`].
    ///
    /// Each of the `iterations` rounds refits the surface to the current
    /// nodes, finds every particle closer than its radius to it (closest
    /// triangle, barycentric weights, face normal) and projects that hard
    /// contact once ([`project_particle_triangle`]), pushing the particle and
    /// the triangle's nodes apart with zero net momentum: a Gauss-Seidel
    /// solve re-linearised every round, so the contact follows the wall as
    /// it tents under a point load. Held nodes (fixed, driven, outside the
    /// active box) do not move; moved nodes get the velocity change `dx / h`
    /// of the last substep, as if the contact had been solved in it. The
    /// particles' velocities are the caller's. Returns one record per
    /// particle in contact (the last round's geometry, the summed multiplier).
    pub fn collide_particles(
        &mut self,
        ghost: &mut GhostSurface,
        particles: &mut [ContactParticle],
        iterations: usize,
    ) -> Vec<ParticleContact> {
        let mut contacts: Vec<ParticleContact> = Vec::new();
        let h = self.last_h;
        for _ in 0..iterations {
            ghost.update(&self.x);
            for (k, p) in particles.iter_mut().enumerate() {
                // Search a little beyond the radius so a particle that moved
                // past a thin wall still finds the surface it crossed.
                let Some(hit) = ghost.closest(&p.x, 2.0 * p.radius + self.scale * 1e-3) else {
                    continue;
                };
                if hit.gap >= p.radius {
                    continue;
                }
                let tri = ghost.triangles[hit.triangle].map(|i| i as usize);
                let mut tx = tri.map(|i| self.x[i]);
                let before = tx;
                let wt = tri.map(|i| self.active.w[i]);
                let mut lambda = 0.0;
                project_particle_triangle(
                    &mut p.x,
                    p.inv_mass,
                    &mut tx,
                    wt,
                    hit.bary,
                    &hit.normal,
                    p.radius,
                    0.0,
                    &mut lambda,
                );
                for j in 0..3 {
                    let i = tri[j];
                    let dx = tx[j] - before[j];
                    if dx != Vec3::zeros() {
                        self.x[i] = tx[j];
                        self.v[i] += dx / h;
                        self.xa.set(i, &tx[j]);
                    }
                }
                let rec = ParticleContact {
                    particle: k,
                    triangle: hit.triangle,
                    bary: hit.bary,
                    normal: hit.normal,
                    lambda,
                };
                match contacts.iter_mut().find(|c| c.particle == k) {
                    Some(c) => {
                        *c = ParticleContact {
                            lambda: c.lambda + lambda,
                            ..rec
                        }
                    }
                    None => contacts.push(rec),
                }
            }
        }
        ghost.update(&self.x);
        contacts
    }
}
