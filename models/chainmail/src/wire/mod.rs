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
//!    this step ([`crate::rules::friction_correction`]). In the `Link`
//!    frame the wall is also projected inside every relaxation iteration,
//!    and after friction one length-restoring pass (boxes from the clamp,
//!    then the wall) puts the links friction moved back in their boxes.

use crate::mapping::BetaMapping;
use crate::rules::LinkParams;
use crate::volume::VesselLattice;
use std::sync::Arc;
use surgbench_core::flow::FlowField;
use surgbench_core::frames::{parallel_transport, rotate_about};
use surgbench_core::{
    ContactObs, DeviceCommand, Iso3, Mat3, Model, Observation, RodBody, RodObs, Sdf, SimError, StepStats, Vec3,
};

mod collide;
mod relax;

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
    /// Axes of the sponsor's link (its material frame `t, d1, d2`,
    /// parallel-transported from the clamp), turned by the rest curvature at
    /// the sponsor: the rest offsets `delta_i` live in the link's body frame,
    /// so the wire can follow a curved vessel (each link may turn by about
    /// `atan(beta)` from its predecessor, not from the clamp) and a pre-curved
    /// rest shape is a shape the rules preserve. Rotation-invariant.
    Link,
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
    /// Constant `C` of the weight mapping ([`crate::mapping`]).
    pub beta_constant: f64,
    /// Which material mapping gives the link parameters
    /// ([`crate::mapping::BetaMapping`]).
    pub beta_mapping: BetaMapping,
    /// A uniform `beta` for every link, replacing the material mapping
    /// (`alpha_min = alpha_max = 1` then).
    pub beta_override: Option<f64>,
    /// Haptic gain `k` (N/m) turning the paper's displacements into the hand
    /// force; `None` takes `E A / Delta` of the section at the clamp (the
    /// axial stiffness of one link).
    pub haptic_k: Option<f64>,
}

impl WireConfig {
    /// The settings are in range (the messages name the knob).
    pub fn validate(&self) -> Result<(), String> {
        if self.segments == 0 {
            return Err("segments must be >= 1".into());
        }
        if self.iterations == 0 {
            return Err("iterations must be >= 1".into());
        }
        if !(self.dt > 0.0 && self.dt.is_finite()) {
            return Err(format!("dt must be > 0 s, got {}", self.dt));
        }
        if !(self.beta_constant >= 0.0 && self.beta_constant.is_finite()) {
            return Err(format!("beta constant must be >= 0, got {}", self.beta_constant));
        }
        if let BetaMapping::Navigation { yield_strain } = self.beta_mapping
            && !(yield_strain > 0.0 && yield_strain < 1.0)
        {
            return Err(format!("yield_strain must be in (0, 1), got {yield_strain}"));
        }
        if let Some(b) = self.beta_override
            && !(b >= 0.0 && b.is_finite())
        {
            return Err(format!("beta must be >= 0, got {b}"));
        }
        if let Some(k) = self.haptic_k
            && !(k >= 0.0 && k.is_finite())
        {
            return Err(format!("haptic_k must be >= 0 N/m, got {k}"));
        }
        Ok(())
    }
}

/// The simulated wire (one rod of a scene).
#[derive(Debug, Clone)]
pub struct ChainmailWire {
    frame: BoxFrame,
    iterations: usize,
    dt: f64,
    delta: f64,
    beta_constant: f64,
    beta_mapping: BetaMapping,
    beta_override: Option<f64>,
    rod: RodBody,
    base: Iso3,
    /// Base rotation as a matrix and its x axis (cached from `base`).
    rb: Mat3,
    tb: Vec3,
    /// Material director `d1` at the clamp: the base pose's local y turned by
    /// the commanded rotation about the clamp axis.
    d1b: Vec3,
    /// Rest turning at every node (`Link` frame): the rest Darboux vector
    /// integrated over the node's Voronoi interval, components on `(d1, d2)`
    /// (rad).
    turn: Vec<[f64; 2]>,
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
    /// Normal wall corrections accumulated per node during this step's
    /// relaxation iterations (`Link` frame), m.
    wall_depth: Vec<f64>,
    /// The volumetric chain-mail of a moving vessel ([`crate::volume`]);
    /// `vessel` is then this lattice's lumen.
    lattice: Option<Arc<VesselLattice>>,
}

/// Rotate `v` about the unit `axis` by the angle whose sine and cosine are
/// `s`, `c` (Rodrigues; the expression of `surgbench_core::frames::rotate_about`
/// with its `sin_cos` hoisted, so that callers rotating several vectors by
/// one angle get the same bits for one trigonometric evaluation).
#[inline]
fn rodrigues(v: &Vec3, axis: &Vec3, s: f64, c: f64) -> Vec3 {
    v * c + axis.cross(v) * s + axis * (axis.dot(v) * (1.0 - c))
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
        cfg.validate()?;
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
            beta_mapping: cfg.beta_mapping,
            beta_override: cfg.beta_override,
            rod: rod.clone(),
            base,
            rb: base.rotation.to_rotation_matrix().into_inner(),
            tb: base.rotation * Vec3::x(),
            d1b: base.rotation * Vec3::y(),
            turn: Vec::new(),
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
            wall_depth: Vec::new(),
            lattice: None,
        };
        let curved = rod.sections.iter().any(|s| s.rest_curvature != [0.0, 0.0]);
        if curved && cfg.frame != BoxFrame::Link {
            return Err(format!(
                "rest curvature needs the link-frame boxes (frame=link): the {:?} boxes keep every link near the clamp direction",
                cfg.frame
            ));
        }
        // ghost node one link behind the clamp, the clamp, then the free nodes
        for k in 0..=cfg.segments + 1 {
            let s = (k as f64 - 1.0) * delta;
            w.sigma.push(s);
            w.turn.push(w.turn_at(s));
            w.x.push(w.rest_point(s));
        }
        w.x = w.rest_shape();
        for k in 0..=cfg.segments {
            let p = w.link_params_at(0.5 * (w.sigma[k] + w.sigma[k + 1]))?;
            w.links.push(p);
        }
        w.x_prev = w.x.clone();
        Ok(w)
    }

    /// Let the wire move through a beating vessel carried by `lattice`
    /// ([`crate::volume`]): its lumen replaces the scene's rest lumen.
    pub fn set_vessel_lattice(&mut self, lattice: VesselLattice) {
        let lat = Arc::new(lattice);
        self.vessel = Some(lat.clone());
        self.lattice = Some(lat);
    }

    fn link_params_at(&self, s: f64) -> Result<LinkParams, String> {
        let p = match self.beta_override {
            Some(beta) => LinkParams {
                alpha_min: 1.0,
                alpha_max: 1.0,
                beta,
            },
            None => self
                .beta_mapping
                .link_params(self.rod.section_at(s.max(0.0)), self.delta, self.beta_constant),
        };
        p.validate()?;
        Ok(p)
    }

    fn t_base(&self) -> Vec3 {
        self.tb
    }

    /// Rest turning of the node at material arclength `s` (rad, on
    /// `(d1, d2)`): `int kappa ds` over `[s - Delta/2, s + Delta/2]`, the
    /// node's Voronoi interval, clipped to the rod (material fed in behind
    /// the clamp carries the first section's curvature). Summed over the
    /// nodes this integrates the rest curvature exactly, so the direction of
    /// link `j` is the rest tangent at its midpoint.
    fn turn_at(&self, s: f64) -> [f64; 2] {
        let (a, b) = (s - 0.5 * self.delta, (s + 0.5 * self.delta).min(self.rod.length));
        let mut out = [0.0; 2];
        let mut start = f64::NEG_INFINITY;
        for sec in &self.rod.sections {
            let lo = a.max(start);
            let hi = b.min(sec.until);
            if hi > lo {
                out[0] += sec.rest_curvature[0] * (hi - lo);
                out[1] += sec.rest_curvature[1] * (hi - lo);
            }
            start = sec.until;
        }
        out
    }

    /// Turn the frame `(t, d1)` by the rest turning `k` (rad on `(d1, d2)`,
    /// `d2 = t x d1`), forwards (`sign = 1`) or backwards (`-1`): rotation
    /// about `k1 d1 + k2 d2` by its norm (Kirchhoff: `t' = Omega x t`).
    fn turned(t: &Vec3, d1: &Vec3, k: &[f64; 2], sign: f64) -> (Vec3, Vec3) {
        if k[0] == 0.0 && k[1] == 0.0 {
            return (*t, *d1);
        }
        let om = d1 * k[0] + t.cross(d1) * k[1];
        let a = om.norm();
        let axis = om / a;
        // one sin_cos for both vectors (the same numbers `rotate_about`
        // computes twice)
        let (s, c) = (sign * a).sin_cos();
        (rodrigues(t, &axis, s, c), rodrigues(d1, &axis, s, c))
    }

    /// Material frames `(t, d1)` of every link, parallel-transported from the
    /// clamp: the prescribed links lie along the clamp axis with `d1b`; each
    /// free link's `d1` is the rest-turned `d1` of its predecessor
    /// transported onto its actual tangent.
    fn link_frames(&self) -> Vec<(Vec3, Vec3)> {
        let n = self.x.len();
        let mut out = Vec::with_capacity(n - 1);
        let (mut t, mut d1) = (self.tb, self.d1b);
        for j in 0..n - 1 {
            if j + 1 < self.n_fixed {
                out.push((self.tb, self.d1b));
                continue;
            }
            let (tp, dp) = Self::turned(&t, &d1, &self.turn[j], 1.0);
            let tn = unit_or(self.x[j + 1] - self.x[j], tp);
            d1 = parallel_transport(&dp, &tp, &tn);
            d1 = unit_or(d1 - tn * tn.dot(&d1), d1);
            t = tn;
            out.push((t, d1));
        }
        out
    }

    /// Box axes `[t, d1, d2]` as columns.
    fn axes(t: &Vec3, d1: &Vec3) -> Mat3 {
        Mat3::from_columns(&[*t, *d1, t.cross(d1)])
    }

    /// Rest shape at the current insertion (m): straight on the clamp axis
    /// up to the clamp, then each free link along its predecessor's direction
    /// turned by the rest turning of the node between them.
    fn rest_shape(&self) -> Vec<Vec3> {
        let n = self.x.len();
        let mut out: Vec<Vec3> = self.sigma.iter().map(|&s| self.rest_point(s)).collect();
        let (mut t, mut d1) = (self.tb, self.d1b);
        for j in self.n_fixed.max(1) - 1..n - 1 {
            (t, d1) = Self::turned(&t, &d1, &self.turn[j], 1.0);
            out[j + 1] = out[j] + t * self.delta;
        }
        out
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
            BoxFrame::Base | BoxFrame::Link => (self.rb, Vec3::new(s, 0.0, 0.0)),
        }
    }

    /// Link-frame box of neighbour `i + dir` around sponsor `i` from the link
    /// frames `fr`: towards the tip, the frame of link `i - 1` turned
    /// forwards at node `i`; towards the base, the frame of link `i` turned
    /// backwards at node `i` (the tip node, with no link beyond, uses its
    /// own link: only the length is then bounded).
    fn link_box(&self, i: usize, dir: isize, fr: &[(Vec3, Vec3)]) -> (Mat3, Vec3) {
        let (t, d1) = if dir > 0 {
            let (t, d1) = fr[i - 1];
            Self::turned(&t, &d1, &self.turn[i], 1.0)
        } else if i < fr.len() {
            let (t, d1) = fr[i];
            Self::turned(&t, &d1, &self.turn[i], -1.0)
        } else {
            fr[i - 1]
        };
        (Self::axes(&t, &d1), Vec3::new(dir as f64 * self.delta, 0.0, 0.0))
    }

    fn link_of(i: usize, dir: isize) -> usize {
        if dir > 0 { i } else { i - 1 }
    }

    /// Move the free elements by gravity over the step (`g dt^2`) and,
    /// with flow, by the blood's displacement `v dt` (carried by the
    /// vessel's lattice when it moves).
    fn drift(&mut self, dt: f64) {
        let gd = self.gravity * (dt * dt);
        for i in self.n_fixed..self.x.len() {
            let mut d = gd;
            if let Some(fl) = &self.flow {
                d += match &self.lattice {
                    // blood carried by the vessel: the rest flow at the
                    // element's rest point plus the lattice's motion
                    Some(lat) => fl.velocity(&lat.rest_point(&self.x[i])) * dt + lat.step_motion(&self.x[i]),
                    None => fl.velocity(&self.x[i]) * dt,
                };
            }
            self.x[i] += d;
        }
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
        self.d1b = rotate_about(&self.rb.column(1).into_owned(), &self.tb, self.rotation);
        self.update_feed()
            .map_err(|reason| SimError::SolverFailed { t: self.time, reason })?;
        if let Some(mut lat) = self.lattice.take() {
            // the only other holder is `vessel`: drop it so the lattice is
            // updated in place (a cloned wire copies it instead)
            self.vessel = None;
            Arc::make_mut(&mut lat).advance(self.time);
            self.vessel = Some(lat.clone());
            self.lattice = Some(lat);
        }

        self.drift(dt);
        // in the link frame the rotation reaches the wire through `d1b`: the
        // frames carry it rigidly to every link (and turn a curved tip)
        if d_rot != 0.0 && self.frame != BoxFrame::Link {
            let k = self.tip_element();
            let o = self.x[self.n_fixed - 1];
            let axis = unit_or(o - self.x[self.n_fixed - 2], self.t_base());
            self.x[k] = o + rotate_about(&(self.x[k] - o), &axis, d_rot);
            self.propagate_from(k);
        }
        self.sweep_from_base();
        if self.frame == BoxFrame::Link {
            // contact resolved inside the iterations, as constraints are in
            // position-based solvers: relax, restore the boxes (link length
            // and bend), leave the wall; friction once at the end on the
            // accumulated normal correction
            self.wall_depth.clear();
            self.wall_depth.resize(self.x.len(), 0.0);
            for _ in 0..self.iterations {
                self.relax_sweep();
                self.sweep_from_base();
                self.wall_pass(true);
            }
        } else {
            for _ in 0..self.iterations {
                self.relax_sweep();
            }
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
        if self.frame == BoxFrame::Link {
            return self
                .link_frames()
                .iter()
                .map(|(t, d1)| Mat3::from_columns(&[*d1, t.cross(d1), *t]))
                .collect();
        }
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
            rest: self.rest_shape(),
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
    /// With a moving vessel: how far the chain-mail's wall lags the
    /// prescribed motion (`vessel_lag_rms_m`, `vessel_lag_max_m`).
    fn diagnostics(&self) -> std::collections::BTreeMap<String, f64> {
        let mut d = std::collections::BTreeMap::new();
        if let Some(lat) = &self.lattice {
            let (rms, max) = lat.tracking_error();
            d.insert("vessel_lag_rms_m".into(), rms);
            d.insert("vessel_lag_max_m".into(), max);
        }
        d
    }
    fn observe(&self) -> Observation {
        self.observation()
    }
    fn dt(&self) -> f64 {
        self.dt
    }
}
