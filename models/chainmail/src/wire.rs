//! The chain-mail guidewire: a chain of nodes (hinge points between small
//! rigid segments) moved by the paper's geometric rules, one step at a time.
//!
//! One [`ChainmailWire::step`] does, in order (SI units throughout):
//! 1. **Operations.** Push/pull: the wire behind the clamp is prescribed;
//!    it moves along the base tangent by the insertion increment and new
//!    elements are fed at the base (or taken out on retraction), so the
//!    free length and the node count change during a run. Rotate: the first
//!    tip element turns by the rotation increment about the axis of the
//!    first two body elements (the clamp axis).
//! 2. **External displacements** of every free element: gravity `g dt^2`
//!    (a geometric model has no momentum: gravity is a per-step
//!    displacement, so a sag is the equilibrium of that displacement against
//!    the boxes and the relaxation, and it depends on `dt` and `iterations`),
//!    and blood flow `v(x) dt` when the scene has a flow field.
//! 3. **Geometric deformation.** The rotated element (if any) sponsors its
//!    neighbours both ways; then the clamp sponsors the chain towards the
//!    tip. A neighbour outside its valid box ([`crate::rules::valid_box`])
//!    moves to the nearest point in it and sponsors the next.
//! 4. **Physical optimization.** `iterations` Gauss–Seidel sweeps from base
//!    to tip of `P* = mean(Q_i)`, `Q_i = P_i* + delta_i`.
//! 5. **Collision** with the scene's SDF: an element closer than `epsilon`
//!    to the wall (or past it) moves by `(phi + epsilon)` along `-grad phi`,
//!    then the paper's friction factor removes part of its tangential motion
//!    this step ([`crate::rules::friction_correction`]).

use crate::rules::{LinkParams, box_violation, friction_correction, project_into_box, relaxation_target};
use std::sync::Arc;
use surgbench_core::frames::{parallel_transport, rotate_about};
use surgbench_core::scene::FlowField;
use surgbench_core::{
    ContactObs, DeviceCommand, Iso3, Mat3, Model, Observation, RodBody, RodObs, Sdf, SimError, StepStats, Vec3,
};

/// The frame in which the valid boxes are axis-aligned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoxFrame {
    /// World axes, as the paper writes it. Not rotation-invariant: rigidly
    /// moving the scene changes the answer, and the wire cannot turn further
    /// from its rest direction than the boxes allow (about `atan(beta)`).
    World,
    /// Axes of the base clamp (x along the insertion direction). Identical to
    /// `World` for the harness's canonical scenes (clamp at the origin along
    /// +x), and moves rigidly with the scene.
    Base,
}

impl BoxFrame {
    /// From the fidelity extra `frame` (0 world, 1 base).
    pub fn from_code(c: f64) -> Option<BoxFrame> {
        match c {
            0.0 => Some(BoxFrame::World),
            1.0 => Some(BoxFrame::Base),
            _ => None,
        }
    }
}

/// Everything needed to build a wire besides the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WireConfig {
    /// Links over the initial free length.
    pub segments: usize,
    /// Relaxation sweeps per step.
    pub iterations: usize,
    /// Time step (s).
    pub dt: f64,
    /// Frame of the valid boxes.
    pub frame: BoxFrame,
    /// Constant `C` of the material mapping ([`crate::mapping`]).
    pub beta_constant: f64,
    /// A uniform `beta` for every link, replacing the material mapping
    /// (`alpha_min = alpha_max = 1` then).
    pub beta_override: Option<f64>,
    /// Haptic gain `k` (N/m) turning the paper's displacements into the hand
    /// force; `None` takes `E A / Delta` of the section at the clamp (the
    /// axial stiffness of one link).
    pub haptic_k: Option<f64>,
}

/// The simulated wire (one rod of a scene).
#[derive(Debug, Clone)]
pub struct ChainmailWire {
    frame: BoxFrame,
    iterations: usize,
    dt: f64,
    delta: f64,
    beta_constant: f64,
    beta_override: Option<f64>,
    rod: RodBody,
    base: Iso3,
    /// Base rotation as a matrix and its x axis (cached from `base`).
    rb: Mat3,
    tb: Vec3,
    /// Material arclength of every node at zero insertion (m).
    sigma: Vec<f64>,
    x: Vec<Vec3>,
    x_prev: Vec<Vec3>,
    /// Link `j` joins nodes `j` and `j + 1`.
    links: Vec<LinkParams>,
    /// The first `n_fixed` nodes are prescribed (at or behind the clamp).
    n_fixed: usize,
    insertion: f64,
    rotation: f64,
    gravity: Vec3,
    vessel: Option<Arc<dyn Sdf>>,
    flow: Option<Arc<dyn FlowField>>,
    margin: f64,
    friction: f64,
    haptic_k: f64,
    time: f64,
    first_link_len: f64,
    contacts: Vec<ContactObs>,
    hand_force: Vec3,
}

fn unit_or(v: Vec3, fallback: Vec3) -> Vec3 {
    let n = v.norm();
    if n > 0.0 { v / n } else { fallback }
}

impl ChainmailWire {
    /// Build the wire of `rod` in `scene`'s environment. Errors name the bad
    /// parameter.
    pub fn new(
        rod: &RodBody,
        gravity: Vec3,
        env: &surgbench_core::Environment,
        cfg: &WireConfig,
    ) -> Result<Self, String> {
        rod.validate()?;
        if cfg.segments == 0 {
            return Err("segments must be >= 1".into());
        }
        if cfg.iterations == 0 {
            return Err("iterations must be >= 1".into());
        }
        if !(cfg.dt > 0.0 && cfg.dt.is_finite()) {
            return Err(format!("dt must be > 0 s, got {}", cfg.dt));
        }
        if !(cfg.beta_constant >= 0.0 && cfg.beta_constant.is_finite()) {
            return Err(format!("beta constant must be >= 0, got {}", cfg.beta_constant));
        }
        if let Some(b) = cfg.beta_override
            && !(b >= 0.0 && b.is_finite())
        {
            return Err(format!("beta must be >= 0, got {b}"));
        }
        if let Some(k) = cfg.haptic_k
            && !(k >= 0.0 && k.is_finite())
        {
            return Err(format!("haptic_k must be >= 0 N/m, got {k}"));
        }
        let c = &env.contact;
        if !(0.0..=1.0).contains(&c.friction_static) {
            return Err(format!(
                "the chain-mail friction factor needs 0 <= C_f <= 1, got {}",
                c.friction_static
            ));
        }
        let delta = rod.length / cfg.segments as f64;
        let base = rod.base;
        let sec0 = rod.section_at(0.0);
        let mut w = Self {
            frame: cfg.frame,
            iterations: cfg.iterations,
            dt: cfg.dt,
            delta,
            beta_constant: cfg.beta_constant,
            beta_override: cfg.beta_override,
            rod: rod.clone(),
            base,
            rb: base.rotation.to_rotation_matrix().into_inner(),
            tb: base.rotation * Vec3::x(),
            sigma: Vec::new(),
            x: Vec::new(),
            x_prev: Vec::new(),
            links: Vec::new(),
            n_fixed: 2,
            insertion: 0.0,
            rotation: 0.0,
            gravity,
            vessel: env.vessel.clone(),
            flow: env.flow.clone(),
            margin: c.margin,
            friction: c.friction_static,
            haptic_k: cfg.haptic_k.unwrap_or(sec0.youngs_modulus * sec0.area() / delta),
            time: 0.0,
            first_link_len: delta,
            contacts: Vec::new(),
            hand_force: Vec3::zeros(),
        };
        // ghost node one link behind the clamp, the clamp, then the free nodes
        for k in 0..=cfg.segments + 1 {
            let s = (k as f64 - 1.0) * delta;
            w.sigma.push(s);
            w.x.push(w.rest_point(s));
        }
        for k in 0..=cfg.segments {
            let p = w.link_params_at(0.5 * (w.sigma[k] + w.sigma[k + 1]))?;
            w.links.push(p);
        }
        w.x_prev = w.x.clone();
        Ok(w)
    }

    fn link_params_at(&self, s: f64) -> Result<LinkParams, String> {
        let p = match self.beta_override {
            Some(beta) => LinkParams {
                alpha_min: 1.0,
                alpha_max: 1.0,
                beta,
            },
            None => crate::mapping::link_params(self.rod.section_at(s.max(0.0)), self.delta, self.beta_constant),
        };
        p.validate()?;
        Ok(p)
    }

    fn t_base(&self) -> Vec3 {
        self.tb
    }

    /// Straight rest position of material arclength `s` at the current
    /// insertion (m).
    fn rest_point(&self, s: f64) -> Vec3 {
        self.base.translation.vector + self.t_base() * (s + self.insertion)
    }

    /// Current node positions (m), ghost and clamp nodes first.
    pub fn nodes(&self) -> &[Vec3] {
        &self.x
    }

    /// Number of prescribed nodes at the base (at or behind the clamp).
    pub fn n_fixed(&self) -> usize {
        self.n_fixed
    }

    /// Link parameters, link `j` joining nodes `j` and `j + 1`.
    pub fn links(&self) -> &[LinkParams] {
        &self.links
    }

    /// Rest link length `Delta` (m).
    pub fn delta(&self) -> f64 {
        self.delta
    }

    /// Overwrite the free nodes' positions (tests and tools).
    pub fn set_nodes(&mut self, x: &[Vec3]) {
        let n = self.x.len().min(x.len());
        let a = self.n_fixed.min(n);
        self.x[a..n].copy_from_slice(&x[a..n]);
    }

    /// Box frame and rest difference (in that frame) for sponsor `i` and
    /// neighbour `i + dir` (`dir` = +1 towards the tip, -1 towards the base).
    fn box_geometry(&self, dir: isize) -> (Mat3, Vec3) {
        let s = dir as f64 * self.delta;
        match self.frame {
            BoxFrame::World => (Mat3::identity(), self.tb * s),
            BoxFrame::Base => (self.rb, Vec3::new(s, 0.0, 0.0)),
        }
    }

    fn link_of(i: usize, dir: isize) -> usize {
        if dir > 0 { i } else { i - 1 }
    }

    /// Enforce the valid box of node `i + dir` around sponsor `i`; returns
    /// whether the neighbour moved. Prescribed nodes never move.
    fn enforce(&mut self, i: usize, dir: isize) -> bool {
        let j = (i as isize + dir) as usize;
        if j < self.n_fixed {
            return false;
        }
        let (f, d) = self.box_geometry(dir);
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
    fn sweep_from_base(&mut self) {
        for i in self.n_fixed - 1..self.x.len() - 1 {
            self.enforce(i, 1);
        }
    }

    /// Predictions `Q` of free node `i` by its neighbours, into `out`.
    fn predictions(&self, i: usize, out: &mut [Vec3; 2]) -> usize {
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
        let mut q = [Vec3::zeros(); 2];
        for i in self.n_fixed..self.x.len() {
            let m = self.predictions(i, &mut q);
            self.x[i] = relaxation_target(&q[..m]);
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
        for i in 1..self.x.len() - 1 {
            let (f, d) = self.box_geometry(1);
            r = r.max(box_violation(&self.x[i], &self.x[i + 1], &d, &f, &self.links[i]));
        }
        r / self.delta
    }

    /// Feed or withdraw wire at the base for the current insertion and place
    /// the prescribed nodes on the clamp axis.
    fn update_feed(&mut self) -> Result<(), String> {
        let tol = 1e-9 * self.delta;
        let fixed = |w: &Self, k: usize| w.sigma[k] + w.insertion <= tol;
        // retraction: drop elements that went more than one link behind
        while self.x.len() > 2 && fixed(self, 2) {
            self.sigma.remove(0);
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
    fn tip_element(&self) -> usize {
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

    fn collide(&mut self) {
        self.contacts.clear();
        self.hand_force = Vec3::zeros();
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
            let n = g / gn;
            let depth = phi + eps;
            let dp_n = -n * depth;
            self.x[i] += dp_n;
            let m = self.x[i] - self.x_prev[i];
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
        }
    }

    fn first_link(&self) -> f64 {
        let a = self.n_fixed - 1;
        (self.x[a + 1] - self.x[a]).norm()
    }

    fn check_finite(&self) -> Result<(), SimError> {
        if let Some(i) = self.x.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(SimError::Diverged {
                t: self.time,
                reason: format!("node {i} is not finite: {:?}", self.x[i]),
            });
        }
        Ok(())
    }

    /// Advance one step of `dt` seconds with the operator's command.
    pub fn advance(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        if !(dt > 0.0 && dt.is_finite() && cmd.insertion.is_finite() && cmd.rotation.is_finite()) {
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: format!("bad step input dt={dt}, command {cmd:?}"),
            });
        }
        self.time += dt;
        self.x_prev.clone_from(&self.x);
        if let Some(b) = cmd.base_pose {
            self.base = b;
            self.rb = b.rotation.to_rotation_matrix().into_inner();
            self.tb = b.rotation * Vec3::x();
        }
        self.insertion = cmd.insertion;
        let d_rot = cmd.rotation - self.rotation;
        self.rotation = cmd.rotation;
        self.update_feed()
            .map_err(|reason| SimError::SolverFailed { t: self.time, reason })?;

        let gd = self.gravity * (dt * dt);
        for i in self.n_fixed..self.x.len() {
            let mut d = gd;
            if let Some(fl) = &self.flow {
                d += fl.velocity(&self.x[i]) * dt;
            }
            self.x[i] += d;
        }
        if d_rot != 0.0 {
            let k = self.tip_element();
            let o = self.x[self.n_fixed - 1];
            let axis = unit_or(o - self.x[self.n_fixed - 2], self.t_base());
            self.x[k] = o + rotate_about(&(self.x[k] - o), &axis, d_rot);
            self.propagate_from(k);
        }
        self.sweep_from_base();
        for _ in 0..self.iterations {
            self.relax_sweep();
        }
        self.collide();
        self.check_finite()?;

        let l = self.first_link();
        let ta = unit_or(self.x[self.n_fixed] - self.x[self.n_fixed - 1], self.t_base());
        self.hand_force += ta * (self.haptic_k * (l - self.first_link_len));
        self.first_link_len = l;
        let residual = self.box_residual();
        Ok(StepStats {
            iterations: self.iterations as u32,
            residual,
            converged: residual <= 1e-9,
        })
    }

    fn frames(&self) -> Vec<Mat3> {
        let rb = self.rb;
        let tb = self.tb;
        let mut d1 = rotate_about(&rb.column(1).into_owned(), &tb, self.rotation);
        let mut t_prev = tb;
        let mut out = Vec::with_capacity(self.x.len() - 1);
        for j in 0..self.x.len() - 1 {
            let t = unit_or(self.x[j + 1] - self.x[j], t_prev);
            d1 = parallel_transport(&d1, &t_prev, &t);
            d1 = (d1 - t * t.dot(&d1)).normalize();
            out.push(Mat3::from_columns(&[d1, t.cross(&d1), t]));
            t_prev = t;
        }
        out
    }

    /// Current state in the shared observation format.
    pub fn observation(&self) -> Observation {
        let mut max_stretch: f64 = 0.0;
        for j in 0..self.x.len() - 1 {
            let s = (self.x[j + 1] - self.x[j]).norm() / self.delta - 1.0;
            if s.abs() > max_stretch.abs() {
                max_stretch = s;
            }
        }
        let rod = RodObs {
            arclength: self.sigma.iter().map(|s| s + self.insertion).collect(),
            rest: self.sigma.iter().map(|&s| self.rest_point(s)).collect(),
            nodes: self.x.clone(),
            velocities: self
                .x
                .iter()
                .zip(&self.x_prev)
                .map(|(a, b)| (a - b) / self.dt)
                .collect(),
            frames: self.frames(),
            max_stretch,
        };
        Observation {
            time: self.time,
            rods: vec![rod],
            contacts: self.contacts.clone(),
            hand_force: self.hand_force,
            constraint_residual: Some(self.box_residual()),
            ..Default::default()
        }
    }

    /// Largest node displacement over the last step divided by `dt` (m/s).
    pub fn max_speed(&self) -> f64 {
        let mut v: f64 = 0.0;
        for (a, b) in self.x.iter().zip(&self.x_prev) {
            v = v.max((a - b).norm());
        }
        v / self.dt
    }

    /// The constant `C` this wire was built with.
    pub fn beta_constant(&self) -> f64 {
        self.beta_constant
    }
}

impl Model for ChainmailWire {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.advance(dt, cmd)
    }
    fn observe(&self) -> Observation {
        self.observation()
    }
    fn dt(&self) -> f64 {
        self.dt
    }
}
