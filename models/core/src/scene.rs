//! Scene description: everything a run needs and nothing more.
//!
//! Conventions every rod scene shares: the base is clamped at the origin with
//! the rod along +x (the base pose's local x axis), gravity and transverse
//! loads along -z. A scene without a vessel pays nothing for collision, a
//! scene without flow has no blood: both are `Option`s.
//!
//! ```
//! use surgbench_core::{Scene, RodBody, Vec3};
//! let mut scene = Scene::empty("sag");
//! scene.bodies.push(RodBody::uniform(0.2, 5e-4, 5e10, 0.3, 6450.0).into());
//! scene.gravity = Vec3::new(0.0, 0.0, -9.81);
//! scene.validate().unwrap();
//! ```

use crate::capability::Capability;
use crate::flow::{FlowField, MovingFlow, TransformedFlow};
use crate::frames::axis_permutation;
use crate::material::SolidMaterial;
use crate::mesh::TetMesh;
use crate::motion::{MovingSdf, TransformedMotion, VesselMotion};
use crate::sdf::{Sdf, TransformedSdf};
use crate::{Iso3, Vec3};
use std::sync::Arc;

pub use crate::rod::{LoadRamp, RodBody, RodSection, RodVelocity, VelocitySample};

/// A deformable solid (tissue, vessel wall, gel phantom).
#[derive(Debug, Clone, PartialEq)]
pub struct TissueBody {
    /// The mesh at rest (m).
    pub mesh: TetMesh,
    /// Material of every tet no region of [`TissueBody::regions`] claims.
    pub material: SolidMaterial,
    /// Parts of the body made of another material (a skin layer, a capsule,
    /// an inclusion); empty for a uniform body. Needs
    /// [`Capability::MaterialRegions`].
    pub regions: Vec<TissueRegion>,
    /// Nodes held fixed.
    pub fixed_nodes: Vec<usize>,
    /// Nodes driven to a displacement (m) by the end of the control ramp;
    /// the control timeline's `load` (0..1) scales it.
    pub driven_nodes: Vec<(usize, Vec3)>,
    /// Nodes fixed along some axes only (`true` = that world component held
    /// at rest): rollers, symmetry planes, plane-strain ends.
    pub partial_fixed: Vec<(usize, [bool; 3])>,
    /// Pressure loads (Pa) on boundary faces: the face's nodes in the order
    /// whose right-hand normal points out of the body; the pressure pushes
    /// against that normal (into the body) and follows the deformed face.
    /// Scaled by the control timeline's `load` (0..1) like the driven
    /// displacements.
    pub pressure_faces: Vec<([usize; 3], f64)>,
    /// A rigid sphere pressed into the body (catheter tip, indenter), if
    /// any: frictionless unilateral contact with the body's boundary nodes.
    /// Needs [`Capability::TissueContact`].
    pub indenter: Option<SphereIndenter>,
    /// The surface an instrument touches (a vessel's inner wall): triangles
    /// over mesh nodes whose right-hand normal points out of the body (into
    /// the lumen). Empty for a body no instrument touches. In a scene with
    /// a rod, the rod moves in `Environment::vessel` (the lumen at rest,
    /// bounded by this surface) as the body deforms; needs
    /// [`Capability::SurfaceForces`].
    pub contact_surface: Vec<[usize; 3]>,
    /// Velocity of every mesh node at `t = 0` (m/s), in mesh order; empty
    /// = at rest. Free vibration needs momentum; held components (fixed,
    /// driven, rolled) start still whatever is given here
    /// ([`TissueBody::start_velocities`]). Needs
    /// [`Capability::InitialVelocity`].
    pub initial_velocity: Vec<Vec3>,
}

/// A part of a tissue body made of its own material: the tets it claims.
#[derive(Debug, Clone, PartialEq)]
pub struct TissueRegion {
    /// Name for reports and errors (`skin`, `capsule`).
    pub name: String,
    /// Its material.
    pub material: SolidMaterial,
    /// Its tets (indices into the body's mesh); no tet is in two regions.
    pub tets: Vec<usize>,
    /// Force a needle tip needs to cut this region (N); `None`: the
    /// needle interaction's own `cutting_force` (the seed's per-layer
    /// `f_cut`: a membrane takes more than the tissue around it).
    pub cutting_force: Option<f64>,
}

/// A rigid sphere in frictionless, unilateral contact with a tissue body:
/// no boundary node of the body may enter it, and it pulls on nothing.
///
/// Its centre moves along a straight line: at the control timeline's load
/// factor `s` (`load`, 0..1, the factor that scales
/// [`TissueBody::driven_nodes`] and [`TissueBody::pressure_faces`]) the
/// centre is `centre + s travel`. The force the body exerts on the sphere is
/// reported as `Observation::hand_force`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereIndenter {
    /// Centre at `s = 0` (m).
    pub centre: Vec3,
    /// Radius (m), > 0.
    pub radius: f64,
    /// Displacement of the centre at `s = 1` (m).
    pub travel: Vec3,
}

impl SphereIndenter {
    /// Centre (m) at load factor `s`: `centre + s travel`.
    pub fn centre_at(&self, s: f64) -> Vec3 {
        self.centre + self.travel * s
    }

    /// Check that every value is finite and the radius positive.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return Err(format!("indenter radius must be > 0 m and finite, got {}", self.radius));
        }
        if !self.centre.iter().chain(self.travel.iter()).all(|v| v.is_finite()) {
            return Err(format!(
                "indenter centre {:?} and travel {:?} must be finite",
                self.centre, self.travel
            ));
        }
        Ok(())
    }
}

impl TissueBody {
    /// A body with no boundary conditions yet.
    pub fn new(mesh: TetMesh, material: SolidMaterial) -> Self {
        Self {
            mesh,
            material,
            regions: Vec::new(),
            fixed_nodes: Vec::new(),
            driven_nodes: Vec::new(),
            partial_fixed: Vec::new(),
            pressure_faces: Vec::new(),
            indenter: None,
            contact_surface: Vec::new(),
            initial_velocity: Vec::new(),
        }
    }

    /// Every material of the body, [`TissueBody::material`] first then the
    /// regions' in order, and each tet's index into that list (empty when
    /// the body has no regions: every tet is of the first).
    pub fn tet_materials(&self) -> (Vec<SolidMaterial>, Vec<usize>) {
        let mut materials = vec![self.material];
        materials.extend(self.regions.iter().map(|r| r.material));
        if self.regions.is_empty() {
            return (materials, Vec::new());
        }
        let mut of = vec![0; self.mesh.tets.len()];
        for (k, r) in self.regions.iter().enumerate() {
            for &t in &r.tets {
                if let Some(m) = of.get_mut(t) {
                    *m = k + 1;
                }
            }
        }
        (materials, of)
    }

    /// The velocity every node starts with (m/s): [`TissueBody::initial_velocity`]
    /// (zeros when empty) with the held components set to zero, so that a
    /// model starts consistent with its boundary conditions.
    pub fn start_velocities(&self) -> Vec<Vec3> {
        let n = self.mesh.nodes.len();
        let mut v = if self.initial_velocity.len() == n {
            self.initial_velocity.clone()
        } else {
            vec![Vec3::zeros(); n]
        };
        for i in self
            .fixed_nodes
            .iter()
            .copied()
            .chain(self.driven_nodes.iter().map(|d| d.0))
        {
            v[i] = Vec3::zeros();
        }
        for &(i, axes) in &self.partial_fixed {
            for k in 0..3 {
                if axes[k] {
                    v[i][k] = 0.0;
                }
            }
        }
        v
    }

    /// The nodes of [`TissueBody::contact_surface`], ascending: the order of
    /// `Model::surface_positions` and `Model::set_surface_forces`.
    pub fn surface_vertices(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self.contact_surface.iter().flatten().copied().collect();
        v.sort_unstable();
        v.dedup();
        v
    }
}

/// A body in the scene.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Body {
    /// A 1D rod.
    Rod(RodBody),
    /// A 3D deformable solid.
    Tissue(TissueBody),
}

impl From<RodBody> for Body {
    fn from(r: RodBody) -> Self {
        Body::Rod(r)
    }
}

/// Contact and friction parameters shared by every model in a scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactParams {
    /// Static friction coefficient.
    pub friction_static: f64,
    /// Dynamic (sliding) friction coefficient.
    pub friction_dynamic: f64,
    /// Contact margin `epsilon` (m): nodes are kept this far inside the wall.
    pub margin: f64,
}

impl Default for ContactParams {
    fn default() -> Self {
        Self {
            friction_static: 0.0,
            friction_dynamic: 0.0,
            margin: 0.0,
        }
    }
}

/// Everything around the bodies.
#[derive(Debug, Clone, Default)]
pub struct Environment {
    /// Vessel lumen as a signed distance (negative inside the lumen).
    pub vessel: Option<Arc<dyn Sdf>>,
    /// Blood flow; only scenes with blood have one.
    pub flow: Option<Arc<dyn FlowField>>,
    /// Prescribed motion of the vessel (and the blood in it); `vessel` is the
    /// lumen at rest. Only scenes with a beating vessel have one.
    pub vessel_motion: Option<Arc<dyn VesselMotion>>,
    /// Contact and friction.
    pub contact: ContactParams,
}

impl Environment {
    /// The lumen at time `t` (s): the vessel itself, or, when it moves, the
    /// rest lumen pulled back through the motion ([`MovingSdf`]).
    pub fn vessel_at(&self, t: f64) -> Option<Arc<dyn Sdf>> {
        let v = self.vessel.as_ref()?;
        Some(match &self.vessel_motion {
            Some(m) => Arc::new(MovingSdf::new(v.clone(), m.clone(), t)),
            None => v.clone(),
        })
    }

    /// The blood flow at time `t` (s), carried by the vessel's motion if any
    /// ([`MovingFlow`]).
    pub fn flow_at(&self, t: f64) -> Option<Arc<dyn FlowField>> {
        let f = self.flow.as_ref()?;
        Some(match &self.vessel_motion {
            Some(m) => Arc::new(MovingFlow::new(f.clone(), m.clone(), t)),
            None => f.clone(),
        })
    }
}

/// What the operator's hands do at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceCommand {
    /// Length advanced along the base tangent since the start (m).
    pub insertion: f64,
    /// Rotation of the base about its tangent since the start (rad).
    pub rotation: f64,
    /// Tissue load factor (dimensionless, 0 at rest, 1 at full load): the
    /// fraction of a tissue's driven displacements, pressures and indenter
    /// travel applied now.
    pub load: f64,
    /// Optional moving base pose (overrides the scene's base pose).
    pub base_pose: Option<Iso3>,
}

impl Default for DeviceCommand {
    fn default() -> Self {
        Self {
            insertion: 0.0,
            rotation: 0.0,
            load: 0.0,
            base_pose: None,
        }
    }
}

/// One key of the control timeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlKey {
    /// Time (s).
    pub t: f64,
    /// Insertion at `t` (m).
    pub insertion: f64,
    /// Base rotation at `t` (rad).
    pub rotation: f64,
    /// Tissue load factor at `t` (dimensionless, see [`DeviceCommand::load`]).
    pub load: f64,
}

impl ControlKey {
    /// The hands of an instrument at `t` (s): `insertion` (m) and
    /// `rotation` (rad), no tissue load.
    pub fn feed(t: f64, insertion: f64, rotation: f64) -> Self {
        Self {
            t,
            insertion,
            rotation,
            load: 0.0,
        }
    }
    /// A tissue load factor `load` at `t` (s), no instrument motion.
    pub fn load(t: f64, load: f64) -> Self {
        Self {
            t,
            insertion: 0.0,
            rotation: 0.0,
            load,
        }
    }
}

/// Piecewise-linear control timeline; before the first key and after the
/// last, the nearest key's values hold.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ControlTimeline {
    /// Keys in increasing time.
    pub keys: Vec<ControlKey>,
}

impl ControlTimeline {
    /// Hold a constant base rotation from `t = 0` (rad).
    pub fn hold_rotation(rotation: f64) -> Self {
        Self {
            keys: vec![ControlKey::feed(0.0, 0.0, rotation)],
        }
    }

    /// The command at time `t` (s).
    pub fn command_at(&self, t: f64) -> DeviceCommand {
        let k = &self.keys;
        let at = |key: &ControlKey| DeviceCommand {
            insertion: key.insertion,
            rotation: key.rotation,
            load: key.load,
            base_pose: None,
        };
        match k.len() {
            0 => DeviceCommand::default(),
            _ if t <= k[0].t => at(&k[0]),
            _ if t >= k[k.len() - 1].t => at(&k[k.len() - 1]),
            _ => {
                let i = k.partition_point(|key| key.t <= t) - 1;
                let (a, b) = (k[i], k[i + 1]);
                let w = (t - a.t) / (b.t - a.t);
                DeviceCommand {
                    insertion: a.insertion + w * (b.insertion - a.insertion),
                    rotation: a.rotation + w * (b.rotation - a.rotation),
                    load: a.load + w * (b.load - a.load),
                    base_pose: None,
                }
            }
        }
    }

    /// Whether the base ever rotates.
    pub fn rotates(&self) -> bool {
        self.keys.iter().any(|k| k.rotation != 0.0)
    }

    /// Whether the wire is ever inserted or retracted.
    pub fn inserts(&self) -> bool {
        self.keys.iter().any(|k| k.insertion != 0.0)
    }
}

/// The scene asks for static equilibrium: stop when every node's speed is
/// under `velocity_tol` (m/s) after `min_time` (s), or at `Scene::duration`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settle {
    /// Largest node speed at equilibrium (m/s).
    pub velocity_tol: f64,
    /// Do not stop before this time (s): loads and controls may still ramp.
    pub min_time: f64,
}

/// A complete scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Scenario id that built it.
    pub name: String,
    /// Bodies.
    pub bodies: Vec<Body>,
    /// Vessel, flow, contact.
    pub environment: Environment,
    /// Gravity (m/s^2, world frame).
    pub gravity: Vec3,
    /// Largest simulated time (s).
    pub duration: f64,
    /// What the operator does.
    pub control: ControlTimeline,
    /// Static scenes: run to equilibrium.
    pub settle: Option<Settle>,
    /// Needle scenes: how the one rod (the needle) acts on the one tissue.
    pub needle: Option<crate::needle::NeedleTissue>,
}

impl Scene {
    /// A scene with no bodies, no gravity and one second of time.
    pub fn empty(name: &str) -> Self {
        Self {
            name: name.to_string(),
            bodies: Vec::new(),
            environment: Environment::default(),
            gravity: Vec3::zeros(),
            duration: 1.0,
            control: ControlTimeline::default(),
            settle: None,
            needle: None,
        }
    }

    /// The rods of the scene.
    pub fn rods(&self) -> impl Iterator<Item = &RodBody> {
        self.bodies.iter().filter_map(|b| match b {
            Body::Rod(r) => Some(r),
            _ => None,
        })
    }

    /// The tissues of the scene.
    pub fn tissues(&self) -> impl Iterator<Item = &TissueBody> {
        self.bodies.iter().filter_map(|b| match b {
            Body::Tissue(t) => Some(t),
            _ => None,
        })
    }

    /// The time (s) from which nothing the scene prescribes changes any
    /// more: the last key of the control timeline and of every rod's tip
    /// load ramp, and the settle rule's `min_time`; `None` when a moving
    /// vessel keeps changing it. A quasi-static model can reach this
    /// scene's equilibrium in one step to this time, and a step that starts
    /// after it and leaves the state unchanged has found that equilibrium.
    pub fn inputs_held_from(&self) -> Option<f64> {
        if self.environment.vessel_motion.is_some() {
            return None;
        }
        let controls = self.control.keys.last().map_or(0.0, |k| k.t);
        let ramps = self
            .rods()
            .filter_map(|r| r.tip_load_ramp.as_ref())
            .filter_map(|r| r.keys.last().map(|k| k.0))
            .fold(0.0, f64::max);
        let min_time = self.settle.map_or(0.0, |s| s.min_time);
        Some(controls.max(ramps).max(min_time).max(0.0))
    }

    /// Capabilities a model needs to run this scene, sorted.
    pub fn required_capabilities(&self) -> Vec<Capability> {
        let mut c = Vec::new();
        for b in &self.bodies {
            match b {
                Body::Rod(r) => {
                    c.push(Capability::Rod);
                    if r.sections.len() > 1 {
                        c.push(Capability::VaryingProperties);
                    }
                    if r.sections.iter().any(|s| s.rest_curvature != [0.0, 0.0]) {
                        c.push(Capability::RestCurvature);
                    }
                    if r.tip_force != Vec3::zeros() {
                        c.push(Capability::TipForce);
                    }
                    if r.tip_load_ramp.is_some() && (r.tip_force != Vec3::zeros() || r.tip_torque != Vec3::zeros()) {
                        c.push(Capability::LoadRamp);
                    }
                    if r.tip_torque != Vec3::zeros() || self.control.rotates() {
                        c.push(Capability::Twist);
                    }
                    if self.control.inserts() {
                        c.push(Capability::Insertion);
                    }
                    if r.initial_velocity.is_some() {
                        c.push(Capability::InitialVelocity);
                    }
                }
                Body::Tissue(t) => {
                    c.push(Capability::Tissue);
                    if !t.pressure_faces.is_empty() {
                        c.push(Capability::PressureLoad);
                    }
                    if !t.partial_fixed.is_empty() {
                        c.push(Capability::RollerConstraint);
                    }
                    if t.indenter.is_some() {
                        c.push(Capability::TissueContact);
                    }
                    if !t.regions.is_empty() {
                        c.push(Capability::MaterialRegions);
                    }
                    if !t.contact_surface.is_empty() {
                        c.push(Capability::SurfaceForces);
                    }
                    if !t.initial_velocity.is_empty() {
                        c.push(Capability::InitialVelocity);
                    }
                }
            }
        }
        if self.environment.vessel.is_some() {
            c.push(Capability::VesselContact);
            if self.environment.contact.friction_static > 0.0 || self.environment.contact.friction_dynamic > 0.0 {
                c.push(Capability::Friction);
            }
        }
        if self.environment.flow.is_some() {
            c.push(Capability::Flow);
        }
        if self.environment.vessel_motion.is_some() {
            c.push(Capability::MovingVessel);
        }
        if self.needle.is_some() {
            c.push(Capability::NeedleTissue);
        }
        if self.rods().next().is_some() && self.tissues().any(|t| !t.contact_surface.is_empty()) {
            c.push(Capability::DeformableLumen);
        }
        c.sort();
        c.dedup();
        c
    }

    /// Check every body and setting; the message names the problem.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.duration > 0.0 && self.duration.is_finite()) {
            return Err(format!("duration must be > 0 s, got {}", self.duration));
        }
        if !self.gravity.iter().all(|g| g.is_finite()) {
            return Err("gravity must be finite".into());
        }
        for b in &self.bodies {
            match b {
                Body::Rod(r) => r.validate()?,
                Body::Tissue(t) => {
                    t.mesh.validate()?;
                    let n = t.mesh.nodes.len();
                    let bad = t
                        .fixed_nodes
                        .iter()
                        .copied()
                        .chain(t.driven_nodes.iter().map(|d| d.0))
                        .chain(t.partial_fixed.iter().map(|d| d.0))
                        .chain(t.pressure_faces.iter().flat_map(|f| f.0))
                        .chain(t.contact_surface.iter().flatten().copied())
                        .find(|&i| i >= n);
                    if let Some(i) = bad {
                        return Err(format!(
                            "tissue boundary condition refers to node {i} but the mesh has {n} nodes"
                        ));
                    }
                    if t.pressure_faces.iter().any(|f| !f.1.is_finite()) {
                        return Err("tissue pressure must be finite".into());
                    }
                    if let Some(ind) = &t.indenter {
                        ind.validate()?;
                    }
                    let nv = t.initial_velocity.len();
                    if nv != 0 && nv != n {
                        return Err(format!(
                            "tissue initial velocity has {nv} entries but the mesh has {n} nodes (give one per node, or none)"
                        ));
                    }
                    if !t.initial_velocity.iter().all(|v| v.iter().all(|c| c.is_finite())) {
                        return Err("tissue initial velocity must be finite".into());
                    }
                    let bad_material = |m: &SolidMaterial| {
                        !(m.youngs_modulus > 0.0
                            && m.youngs_modulus.is_finite()
                            && m.poisson_ratio > -1.0
                            && m.poisson_ratio < 0.5
                            && m.density > 0.0
                            && m.density.is_finite())
                    };
                    if bad_material(&t.material) {
                        return Err(format!("bad tissue material {:?}", t.material));
                    }
                    let mut claimed = vec![false; t.mesh.tets.len()];
                    for r in &t.regions {
                        if bad_material(&r.material) {
                            return Err(format!("bad material {:?} of tissue region `{}`", r.material, r.name));
                        }
                        if r.cutting_force.is_some_and(|f| !(f >= 0.0 && f.is_finite())) {
                            return Err(format!(
                                "tissue region `{}`: cutting_force must be >= 0 N and finite, got {:?}",
                                r.name, r.cutting_force
                            ));
                        }
                        for &e in &r.tets {
                            match claimed.get_mut(e) {
                                None => {
                                    return Err(format!(
                                        "tissue region `{}` claims tet {e} but the mesh has {} tets",
                                        r.name,
                                        t.mesh.tets.len()
                                    ));
                                }
                                Some(c) if *c => {
                                    return Err(format!("tet {e} is in two tissue regions (the second: `{}`)", r.name));
                                }
                                Some(c) => *c = true,
                            }
                        }
                    }
                }
            }
        }
        let c = &self.environment.contact;
        if !(c.friction_static >= 0.0 && c.friction_dynamic >= 0.0 && c.friction_dynamic <= c.friction_static) {
            return Err(format!("friction needs 0 <= dynamic <= static, got {c:?}"));
        }
        if !(c.margin >= 0.0) {
            return Err(format!("contact margin must be >= 0 m, got {}", c.margin));
        }
        if self.environment.vessel_motion.is_some() && self.environment.vessel.is_none() {
            return Err("a vessel motion needs a vessel".into());
        }
        if self.tissues().any(|t| !t.contact_surface.is_empty()) && self.rods().next().is_some() {
            if self.environment.vessel.is_none() {
                return Err("a rod in a tissue's contact surface needs the lumen at rest (environment.vessel)".into());
            }
            if self.rods().count() != 1 || self.tissues().count() != 1 || self.needle.is_some() {
                return Err("an instrument in a deformable lumen is one rod and one tissue, without a needle".into());
            }
        }
        if let Some(n) = &self.needle {
            n.validate()?;
            if self.rods().count() != 1 || self.tissues().count() != 1 {
                return Err("a needle scene has exactly one rod (the needle) and one tissue".into());
            }
        }
        Ok(())
    }

    /// The same scene moved rigidly by `iso`: poses, loads, gravity, meshes
    /// and the vessel. A model's answer must move with it (conformance).
    pub fn transformed(&self, iso: &Iso3) -> Scene {
        let mut s = self.clone();
        let rot = iso.rotation;
        s.gravity = rot * self.gravity;
        for b in &mut s.bodies {
            match b {
                Body::Rod(r) => {
                    r.base = iso * r.base;
                    r.tip_force = rot * r.tip_force;
                    r.tip_torque = rot * r.tip_torque;
                    if let Some(v) = &mut r.initial_velocity {
                        for k in &mut v.samples {
                            k.velocity = rot * k.velocity;
                            k.angular_velocity = rot * k.angular_velocity;
                        }
                    }
                }
                Body::Tissue(t) => {
                    for p in &mut t.mesh.nodes {
                        *p = iso.transform_point(&(*p).into()).coords;
                    }
                    for (_, d) in &mut t.driven_nodes {
                        *d = rot * *d;
                    }
                    for v in &mut t.initial_velocity {
                        *v = rot * *v;
                    }
                    if let Some(ind) = &mut t.indenter {
                        ind.centre = iso.transform_point(&ind.centre.into()).coords;
                        ind.travel = rot * ind.travel;
                    }
                    // Axis-aligned partial constraints: a rotation that maps
                    // axes to axes permutes them; any other rotation cannot
                    // be expressed with world-axis flags, and they are kept
                    // as they are (see `axis_permutation`).
                    if let Some(perm) = axis_permutation(iso) {
                        for (_, axes) in &mut t.partial_fixed {
                            let old = *axes;
                            for (i, j) in perm.iter().enumerate() {
                                axes[i] = old[*j];
                            }
                        }
                    }
                }
            }
        }
        if let Some(v) = &self.environment.vessel {
            s.environment.vessel = Some(Arc::new(TransformedSdf::new(v.clone(), *iso)));
        }
        if let Some(f) = &self.environment.flow {
            s.environment.flow = Some(Arc::new(TransformedFlow::new(f.clone(), *iso)));
        }
        if let Some(m) = &self.environment.vessel_motion {
            s.environment.vessel_motion = Some(Arc::new(TransformedMotion::new(m.clone(), *iso)));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh;

    fn block() -> TissueBody {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]);
        let mut b = TissueBody::new(
            m,
            SolidMaterial {
                youngs_modulus: 1e3,
                poisson_ratio: 0.3,
                density: 1e3,
            },
        );
        b.fixed_nodes = mesh::nodes_on_plane(&b.mesh, 2, 0.0, 1e-9);
        b.partial_fixed = vec![(b.mesh.nodes.len() - 1, [true, false, false])];
        b
    }

    /// A tissue's initial velocity: one per node or none, finite; the
    /// capability is asked for only when given; held components start still.
    #[test]
    fn tissue_initial_velocity_is_checked_and_respects_the_holds() {
        let mut s = Scene::empty("v");
        let mut b = block();
        let n = b.mesh.nodes.len();
        assert_eq!(b.start_velocities(), vec![Vec3::zeros(); n]);
        b.initial_velocity = vec![Vec3::new(1.0, 2.0, 3.0); n];
        let v = b.start_velocities();
        for i in 0..n {
            let want = if b.fixed_nodes.contains(&i) {
                Vec3::zeros()
            } else if i == n - 1 {
                Vec3::new(0.0, 2.0, 3.0)
            } else {
                Vec3::new(1.0, 2.0, 3.0)
            };
            assert_eq!(v[i], want, "node {i}");
        }
        s.bodies.push(Body::Tissue(b.clone()));
        s.validate().unwrap();
        assert!(s.required_capabilities().contains(&Capability::InitialVelocity));
        let mut short = b.clone();
        short.initial_velocity.pop();
        s.bodies = vec![Body::Tissue(short)];
        assert!(s.validate().unwrap_err().contains("one per node"));
        let mut nan = b;
        nan.initial_velocity[0].x = f64::NAN;
        s.bodies = vec![Body::Tissue(nan)];
        assert!(s.validate().unwrap_err().contains("finite"));
        s.bodies = vec![Body::Tissue(block())];
        assert!(!s.required_capabilities().contains(&Capability::InitialVelocity));
    }

    /// Regions: each tet in one region at most, in range, with a valid
    /// material and cutting force; the materials list puts the body's first.
    #[test]
    fn tissue_regions_are_checked_and_index_their_tets() {
        let mut s = Scene::empty("r");
        let mut b = block();
        let stiff = SolidMaterial {
            youngs_modulus: 5e3,
            ..b.material
        };
        b.regions.push(TissueRegion {
            name: "a".into(),
            material: stiff,
            tets: vec![0, 2],
            cutting_force: Some(0.5),
        });
        let (mats, of) = b.tet_materials();
        assert_eq!(mats, vec![b.material, stiff]);
        assert_eq!(of.len(), b.mesh.tets.len());
        assert_eq!((of[0], of[1], of[2]), (1, 0, 1));
        s.bodies = vec![Body::Tissue(b.clone())];
        s.validate().unwrap();
        assert!(s.required_capabilities().contains(&Capability::MaterialRegions));
        let region = |tets: Vec<usize>, cut: Option<f64>, e: f64| TissueRegion {
            name: "b".into(),
            material: SolidMaterial {
                youngs_modulus: e,
                ..stiff
            },
            tets,
            cutting_force: cut,
        };
        for (r, msg) in [
            (region(vec![2], None, 1e3), "two tissue regions"),
            (region(vec![usize::MAX], None, 1e3), "claims tet"),
            (region(vec![1], Some(-1.0), 1e3), "cutting_force"),
            (region(vec![1], None, f64::INFINITY), "bad material"),
        ] {
            let mut bad = b.clone();
            bad.regions.push(r);
            s.bodies = vec![Body::Tissue(bad)];
            let e = s.validate().unwrap_err();
            assert!(e.contains(msg), "{e}");
        }
        s.bodies = vec![Body::Tissue(block())];
        assert!(!s.required_capabilities().contains(&Capability::MaterialRegions));
        assert!(block().tet_materials().1.is_empty());
    }
}
