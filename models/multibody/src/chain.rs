//! [`RigidChain`]: a rod as rapier3d rigid links joined by spherical joints
//! with bending and twisting springs, held by a clamp the operator turns.
//!
//! # Discretization (the Hencky bar chain with joints at cell centres)
//!
//! The rod of length `L` is cut into `n` cells of length `h = L / n`. Joint
//! `j` sits at the centre of cell `j`, at arclength `s_j = (j + 1/2) h`; the
//! half cell `[0, h/2]` is rigid with the clamp, links `0..n-1` run from
//! joint to joint and the last one is half a cell long, from `L - h/2` to the
//! tip. Each joint carries the elastic energy of its cell: for a bend angle
//! `phi` the discrete curvature integrated over the cell is `phi` (Bergou et
//! al. 2008, Sec. 4.2, the integrated curvature of a vertex over its Voronoi
//! length), so `E_cell = EI phi^2 / (2 h)` and the joint spring is
//! `k_b = EI(s_j) / h`, likewise `k_t = GJ(s_j) / h` for twist (the bar-chain
//! model of Hencky 1921; Wang, Zhang & Challamel, *Discrete and Non-Local
//! Models*, 2015). Since the cells tile `[0, L]`, the chain's compliance is the
//! midpoint rule of `int M m / EI ds`: exact for a constant moment (tip
//! torque, tip moment), second order in `h` otherwise (a tip force or
//! gravity, whose moment is exact at the joints because every link's weight
//! acts at its own centre of mass).
//!
//! # What rapier does with it
//!
//! - `joint = multibody`: rapier's reduced-coordinate multibody (the dense
//!   generalized mass matrix assembled and LU-factorized every substep:
//!   `O(n^3)` in the link count). The springs are rapier's implicit joint
//!   springs: the generalized force `-k (q - q_rest)` integrated by backward
//!   Euler at the substep `dt / substeps`, so a spring never makes the step
//!   unstable but takes `1 - exp(-pi omega dt / substeps)` of a mode's
//!   amplitude per period (the same as any backward-Euler model). For a
//!   spherical joint rapier's `q` is the time integral of the joint's
//!   angular velocity, which is the rotation vector only while the joint
//!   turns about a fixed axis; [`RigidChain::coord_drift`] measures how far
//!   it has drifted from the true relative rotation.
//! - `joint = impulse`: maximal coordinates, every link a free rigid body,
//!   the joints velocity constraints solved iteratively (soft TGS with
//!   `substeps` substeps and `iterations` inner iterations), the springs
//!   rapier's force-based joint motors. Joints can open: see
//!   [`RigidChain::max_joint_gap`].
//!
//! Gravity acts on every link; a tip force acts on the tip point of the last
//! link and a tip torque on the last link. The operator slides the clamp
//! along and turns it about its axis (two kinematic DOFs; the whole chain
//! advances with the clamp, as DER's clamp does). With a vessel
//! ([`RigidChain::add_wall`]) every link is a capsule against the wall's
//! triangle mesh, with rapier's Coulomb friction; with blood
//! ([`RigidChain::set_flow`]) each link feels the shared quadratic drag.
//! The hand force is the force the rod exerts on the clamp: the external
//! forces (wall contacts included, read back from rapier's contact
//! impulses) minus the rate of change of the rod's momentum (Newton-Euler
//! on the whole rod, the clamp's half cell included). SI units.

use rapier3d_f64::glamx::{DQuat, DVec3};
use rapier3d_f64::prelude::*;
use std::sync::Arc;
use surgbench_core::beam::first_bending_frequency;
use surgbench_core::flow::{FlowField, drag_per_length};
use surgbench_core::io::TriSurface;
use surgbench_core::{DeviceCommand, EnergyObs, Iso3, Mat3, RodBody, RodObs, RodVelocity, SimError, Vec3};

/// The impulse (N s, world frame) rapier's contact solver applied over the
/// last step to the first collider of a contact point: `-n` times the
/// normal impulse plus the friction impulse. rapier keeps the friction
/// impulse summed over the substeps only in the tangent basis
/// `(t1, n' x t1)` of its constraint (`n' = -n`, `t1` chosen from the
/// sliding direction each step), and the last substep's impulse both in
/// that basis `(a, b)` and in world coordinates `w`; `t1` follows from
/// them: `a w - b (n' x w) = (a^2 + b^2) t1`.
fn contact_impulse(normal: &Vec3, d: &ContactData) -> Vec3 {
    let dir = -normal;
    let (a, b) = (d.warmstart_tangent_impulse.x, d.warmstart_tangent_impulse.y);
    let w = nv(d.warmstart_tangent_world);
    let norm2 = a * a + b * b;
    let friction = if norm2 > 0.0 {
        let t1 = (a * w - b * dir.cross(&w)) / norm2;
        let t2 = dir.cross(&t1);
        t1 * d.tangent_impulse.x + t2 * d.tangent_impulse.y
    } else {
        // No friction in the last substep: the basis is lost; earlier
        // substeps' friction (if any) is taken as the last one's, zero.
        w
    };
    dir * d.impulse + friction
}

/// A collider that adds no mass (the links' mass comes from their
/// sections), with friction `friction` (the mean of both sides' is the
/// pair's), no restitution, in group `member` and touching only `touches`.
fn surface_collider(b: ColliderBuilder, friction: f64, member: Group, touches: Group) -> ColliderBuilder {
    b.density(0.0)
        .friction(friction)
        .friction_combine_rule(CoefficientCombineRule::Average)
        .restitution(0.0)
        .collision_groups(InteractionGroups::new(member, touches, InteractionTestMode::And))
}

/// Force and torque about the world origin (N, N m) that the contacts of
/// collider `wall` put on the other colliders of their pairs over a step
/// of `dt` (s), from rapier's contact impulses.
fn wall_wrench_on_others(world: &PhysicsWorld, wall: ColliderHandle, dt: f64) -> (Vec3, Vec3) {
    let mut f = Vec3::zeros();
    let mut t = Vec3::zeros();
    for pair in world.narrow_phase.contact_pairs_with(wall) {
        let other_first = pair.collider1 != wall;
        let other = if other_first { pair.collider1 } else { pair.collider2 };
        let Some(pose) = world.colliders.get(other).map(|c| *c.position()) else {
            continue;
        };
        for m in pair.solver_manifolds() {
            let n = nv(m.data.normal);
            for pt in &m.points {
                let j1 = contact_impulse(&n, &pt.data);
                let (j, local) = if other_first {
                    (j1, pt.local_p1)
                } else {
                    (-j1, pt.local_p2)
                };
                let x = nv(pose.transform_point(local));
                f += j / dt;
                t += x.cross(&j) / dt;
            }
        }
    }
    (f, t)
}

/// How the links are joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// rapier's reduced-coordinate multibody joints (the default).
    Multibody,
    /// rapier's impulse joints: maximal coordinates, iterative constraints.
    Impulse,
}

/// Settings of a chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainParams {
    /// Number of links (cells of the rod), at least 1.
    pub links: usize,
    /// How the links are joined.
    pub joint: JointKind,
    /// rapier's solver substeps per step (`num_solver_iterations`).
    pub substeps: usize,
    /// rapier's inner PGS iterations per substep (`num_internal_pgs_iterations`).
    pub iterations: usize,
    /// Damping ratio of the first cantilever bending mode, realised by joint
    /// dampers proportional to the joint springs (`c = 2 zeta / omega_1 k`,
    /// stiffness-proportional damping: every mode `j` gets `zeta omega_j / omega_1`).
    pub damping_ratio: f64,
}

impl Default for ChainParams {
    fn default() -> Self {
        Self {
            links: 40,
            joint: JointKind::Multibody,
            substeps: 4,
            iterations: 1,
            damping_ratio: 0.0,
        }
    }
}

/// One rigid link: its body and its mass properties in its own frame
/// (origin at the joint it hangs from, `x` along the rod).
#[derive(Debug, Clone, Copy)]
struct Link {
    handle: RigidBodyHandle,
    length: f64,
    mass: f64,
    com: f64,
    /// Principal moments about the centre of mass: axial, transverse.
    inertia: [f64; 2],
}

/// The joints, by kind.
#[derive(Debug, Clone)]
enum Joints {
    /// Reduced coordinates: every joint's handle and the offset of its three
    /// DOFs in the multibody's generalized vectors (fixed once built).
    Multibody {
        handles: Vec<MultibodyJointHandle>,
        offsets: Vec<usize>,
    },
    /// Impulse joints (the world holds them; nothing to read back).
    Impulse,
}

/// A rod as a chain of rapier rigid links held by a clamp the operator turns.
pub struct RigidChain {
    world: PhysicsWorld,
    /// The clamp's half cell `[0, h/2]`: a body turned about the clamp's
    /// axis by the operator (a kinematic joint DOF of the multibody, whose
    /// root is fixed at the scene's clamp; a kinematic body with impulse
    /// joints).
    carriage: Link,
    /// The scene's clamp pose (before the operator's rotation).
    clamp: Iso3,
    /// The clamp pose now: the scene's, turned by the operator's rotation.
    clamp_now: Iso3,
    links: Vec<Link>,
    joints: Joints,
    /// Arclength of every joint (m).
    joint_s: Vec<f64>,
    /// Spring constants of every joint: twist, bend, bend (N m/rad).
    stiffness: Vec<[f64; 3]>,
    /// Rest rotation vector of every joint in its parent's frame (rad).
    rest: Vec<Vec3>,
    /// Node positions as built, on the rest shape (m).
    rest_nodes: Vec<Vec3>,
    body: RodBody,
    gravity: Vec3,
    time: f64,
    /// Linear momentum and angular momentum about the world origin after
    /// the last step, for the hand force.
    momentum: (Vec3, Vec3),
    /// Force and torque about the world origin the chain put on the clamp
    /// over the last step.
    hand: (Vec3, Vec3),
    /// The vessel wall's collider, if the scene has a vessel.
    wall: Option<ColliderHandle>,
    flow: Option<Arc<dyn FlowField>>,
    /// Drag force and torque about the origin applied over the last step.
    drag: (Vec3, Vec3),
    /// Force and torque about the origin the wall put on the chain over
    /// the last step.
    wall_wrench: (Vec3, Vec3),
}

fn dv(v: &Vec3) -> DVec3 {
    DVec3::new(v.x, v.y, v.z)
}

fn nv(v: DVec3) -> Vec3 {
    Vec3::new(v.x, v.y, v.z)
}

/// nalgebra isometry to rapier pose.
fn to_pose(p: &Iso3) -> Pose {
    let q = p.rotation.quaternion();
    Pose::from_parts(
        dv(&p.translation.vector),
        DQuat::from_xyzw(q.i, q.j, q.k, q.w).normalize(),
    )
}

/// Rotation matrix of a rapier rotation.
fn to_mat(r: &DQuat) -> Mat3 {
    let (x, y, z) = (r.mul_vec3(DVec3::X), r.mul_vec3(DVec3::Y), r.mul_vec3(DVec3::Z));
    Mat3::from_columns(&[nv(x), nv(y), nv(z)])
}

/// Mass, centre of mass (local `x`) and principal moments (axial,
/// transverse, about the centre of mass) of the piece `[a, b]` of the rod,
/// each section a solid cylinder, combined by the parallel-axis theorem.
fn piece_mass(body: &RodBody, a: f64, b: f64) -> (f64, f64, [f64; 2]) {
    let mut parts = Vec::new();
    let mut start = 0.0;
    for sec in &body.sections {
        let (lo, hi) = (start.max(a), sec.until.min(b));
        if hi > lo {
            let m = sec.density * sec.area() * (hi - lo);
            parts.push((m, 0.5 * (lo + hi) - a, hi - lo, sec.radius));
        }
        start = sec.until;
    }
    let mass: f64 = parts.iter().map(|p| p.0).sum();
    let com = parts.iter().map(|p| p.0 * p.1).sum::<f64>() / mass;
    let axial = parts.iter().map(|p| 0.5 * p.0 * p.3 * p.3).sum();
    let trans = parts
        .iter()
        .map(|&(m, c, len, r)| m * (3.0 * r * r + len * len) / 12.0 + m * (c - com).powi(2))
        .sum();
    (mass, com, [axial, trans])
}

impl RigidChain {
    /// Build the chain for `body` (clamp pose `body.base` turned by
    /// `rotation` rad about its axis) under `gravity` (m/s^2).
    ///
    /// The multibody's root is a fixed body at the scene's clamp; the
    /// operator turns the clamp's half cell through a kinematic joint DOF
    /// (its rate set each step so that it lands on the command). A kinematic
    /// root body would be simpler, but rapier 0.36.1 then advances the
    /// multibody's joints by twice their velocities each step (measured: a
    /// one-link chain oscillated sqrt(2) too fast with twice the set joint
    /// rate; with a fixed root it keeps its frequency and energy). The cause,
    /// read in its source (`dynamics/solver/staged_island_solver/helpers.rs`):
    /// the solver lists a multibody once per island body that is its link 0,
    /// or its link 1 when the root is not dynamic; a kinematic root is an
    /// island body, so the multibody is listed, and integrated, twice.
    pub fn new(body: &RodBody, gravity: Vec3, p: &ChainParams, rotation: f64) -> Result<Self, String> {
        body.validate()?;
        if p.links == 0 {
            return Err("the chain needs at least one link".into());
        }
        if !(p.damping_ratio >= 0.0 && p.damping_ratio.is_finite()) {
            return Err(format!("damping ratio must be >= 0, got {}", p.damping_ratio));
        }
        let n = p.links;
        let h = body.length / n as f64;
        let joint_s: Vec<f64> = (0..n).map(|j| (j as f64 + 0.5) * h).collect();
        let mut world = PhysicsWorld::new();
        world.gravity = dv(&gravity);
        world.integration_parameters.num_solver_iterations = p.substeps.max(1);
        world.integration_parameters.num_internal_pgs_iterations = p.iterations.max(1);
        let clamp = body.base;
        let clamp_now = clamp * turn(rotation);
        let root = world.insert_body(RigidBodyBuilder::fixed().pose(to_pose(&clamp)));
        let (mass, com, inertia) = piece_mass(body, 0.0, 0.5 * h);
        let carriage_body = match p.joint {
            JointKind::Multibody => RigidBodyBuilder::dynamic(),
            JointKind::Impulse => RigidBodyBuilder::kinematic_position_based(),
        };
        let carriage = Link {
            handle: world.insert_body(
                carriage_body
                    .pose(to_pose(&clamp_now))
                    .additional_mass_properties(MassProperties::new(
                        DVec3::new(com, 0.0, 0.0),
                        mass,
                        DVec3::new(inertia[0], inertia[1], inertia[1]),
                    ))
                    .can_sleep(false),
            ),
            length: 0.5 * h,
            mass,
            com,
            inertia,
        };
        // Rest rotation of every joint in its parent's frame (x = t, y = d1,
        // z = d2): the rest Darboux vector (0, kappa_1, kappa_2) integrated
        // over the joint's cell, so a rod with rest curvature is built on its
        // rest shape.
        let rest: Vec<Vec3> = joint_s
            .iter()
            .map(|&s| {
                let k = body.section_at(s).rest_curvature;
                Vec3::new(0.0, k[0] * h, k[1] * h)
            })
            .collect();
        let mut links = Vec::with_capacity(n);
        let mut pose = clamp_now;
        for (k, &s) in joint_s.iter().enumerate() {
            let end = if k + 1 < n { joint_s[k + 1] } else { body.length };
            let (mass, com, inertia) = piece_mass(body, s, end);
            let from = if k == 0 {
                s
            } else {
                links.last().map_or(0.0, |l: &Link| l.length)
            };
            pose = pose * Iso3::translation(from, 0.0, 0.0) * Iso3::rotation(rest[k]);
            let mprops = MassProperties::new(
                DVec3::new(com, 0.0, 0.0),
                mass,
                DVec3::new(inertia[0], inertia[1], inertia[1]),
            );
            let handle = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .pose(to_pose(&pose))
                    .additional_mass_properties(mprops)
                    .can_sleep(false),
            );
            links.push(Link {
                handle,
                length: end - s,
                mass,
                com,
                inertia,
            });
        }
        let stiffness: Vec<[f64; 3]> = joint_s
            .iter()
            .map(|&s| {
                let sec = body.section_at(s);
                let (ei, gj) = (
                    sec.youngs_modulus * sec.second_moment(),
                    sec.shear_modulus() * sec.polar_moment(),
                );
                [gj / h, ei / h, ei / h]
            })
            .collect();
        // Stiffness-proportional dampers: zeta_1 = beta omega_1 / 2.
        let omega1 = first_bending_frequency(body.section_at(0.0), body.length);
        let beta = 2.0 * p.damping_ratio / omega1;
        let anchor = |k: usize| if k == 0 { joint_s[0] } else { links[k - 1].length };
        let parent = |k: usize| if k == 0 { carriage.handle } else { links[k - 1].handle };
        let joints = match p.joint {
            JointKind::Multibody => {
                // The clamp's turn (and, later, its push) as kinematic DOFs
                // of the multibody: their velocities are set, not solved for.
                let slide_turn = GenericJointBuilder::new(
                    JointAxesMask::LIN_Y | JointAxesMask::LIN_Z | JointAxesMask::ANG_Y | JointAxesMask::ANG_Z,
                )
                .contacts_enabled(false);
                let ch = world
                    .multibody_joints
                    .insert_kinematic(root, carriage.handle, slide_turn, true)
                    .ok_or("rapier refused the clamp's joint")?;
                let (mb, id) = world.multibody_joints.get_mut(ch).ok_or("joint lost")?;
                mb.link_mut(id)
                    .ok_or("link lost")?
                    .joint
                    .apply_displacement(&[0.0, rotation]);
                let mut handles = Vec::with_capacity(n);
                for k in 0..n {
                    let joint = SphericalJointBuilder::new()
                        .local_anchor1(DVec3::new(anchor(k), 0.0, 0.0))
                        .local_anchor2(DVec3::ZERO)
                        .contacts_enabled(false);
                    let h = world
                        .insert_multibody_joint(parent(k), links[k].handle, joint)
                        .ok_or("rapier refused a multibody joint")?;
                    let (mb, id) = world.multibody_joints.get_mut(h).ok_or("joint lost")?;
                    let link = mb.link_mut(id).ok_or("link lost")?;
                    for (a, &kk) in stiffness[k].iter().enumerate() {
                        link.joint.set_spring(3 + a, kk, rest[k][a]);
                    }
                    // Start the joint at its rest rotation (coordinates and
                    // rotation both; rapier's joints start at zero).
                    link.joint.apply_displacement(rest[k].as_slice());
                    handles.push(h);
                }
                // Replace rapier's default joint damping (0.1 N m s/rad per
                // angular DOF) by the stated dampers.
                // The fixed root's free joint is dropped (its pose read
                // from the base body) when the forward kinematics runs.
                let (mb, _) = world.multibody_joints.get_mut(handles[0]).ok_or("joint lost")?;
                mb.forward_kinematics(&world.bodies, true);
                mb.update_rigid_bodies(&mut world.bodies, false);
                if mb.ndofs() != 3 * n + 2 {
                    return Err(format!("the multibody has {} DOFs, expected {}", mb.ndofs(), 3 * n + 2));
                }
                let mut offsets = Vec::with_capacity(n);
                for &h in &handles {
                    let (mb, id) = world.multibody_joints.get(h).ok_or("joint lost")?;
                    offsets.push((0..id).filter_map(|i| mb.link(i)).map(|l| l.joint().ndofs()).sum());
                }
                let (mb, _) = world.multibody_joints.get_mut(handles[0]).ok_or("joint lost")?;
                for (k, &offset) in offsets.iter().enumerate() {
                    for a in 0..3 {
                        mb.damping_mut()[offset + a] = beta * stiffness[k][a];
                    }
                }
                Joints::Multibody { handles, offsets }
            }
            JointKind::Impulse => {
                for k in 0..n {
                    let mut joint = SphericalJointBuilder::new()
                        .local_anchor1(DVec3::new(anchor(k), 0.0, 0.0))
                        .local_anchor2(DVec3::ZERO)
                        .contacts_enabled(false);
                    for (a, axis) in [JointAxis::AngX, JointAxis::AngY, JointAxis::AngZ]
                        .into_iter()
                        .enumerate()
                    {
                        let kk = stiffness[k][a];
                        joint = joint.motor_model(axis, MotorModel::ForceBased).motor_position(
                            axis,
                            rest[k][a],
                            kk,
                            beta * kk,
                        );
                    }
                    world.insert_impulse_joint(parent(k), links[k].handle, joint);
                }
                Joints::Impulse
            }
        };
        let mut chain = Self {
            world,
            carriage,
            clamp,
            clamp_now,
            links,
            joints,
            joint_s,
            stiffness,
            rest,
            rest_nodes: Vec::new(),
            body: body.clone(),
            gravity,
            time: 0.0,
            momentum: (Vec3::zeros(), Vec3::zeros()),
            hand: (Vec3::zeros(), Vec3::zeros()),
            wall: None,
            flow: None,
            drag: (Vec3::zeros(), Vec3::zeros()),
            wall_wrench: (Vec3::zeros(), Vec3::zeros()),
        };
        if let Some(v) = &body.initial_velocity {
            chain.set_initial_velocity(v);
        }
        chain.rest_nodes = chain.rod_obs().nodes;
        chain.momentum = chain.momenta();
        chain.hand = chain.external_wrench();
        Ok(chain)
    }

    /// Start the links moving with the field `v` sampled at each link's
    /// centre of mass: its angular velocity, and for free (impulse-joint)
    /// links its velocity too; a multibody's link velocities follow from
    /// the joint rates `R_parent^T (omega_k - omega_parent)`.
    fn set_initial_velocity(&mut self, v: &RodVelocity) {
        let mid = |k: usize, l: &Link| self.joint_s[k] + l.com;
        match &self.joints {
            Joints::Impulse => {
                for (k, l) in self.links.iter().enumerate() {
                    let (lin, ang) = v.at(mid(k, l));
                    let rb = &mut self.world.bodies[l.handle];
                    rb.set_linvel(dv(&lin), true);
                    rb.set_angvel(dv(&ang), true);
                }
            }
            Joints::Multibody { handles, offsets } => {
                let omega: Vec<Vec3> = self.links.iter().enumerate().map(|(k, l)| v.at(mid(k, l)).1).collect();
                let rot: Vec<DQuat> = self
                    .links
                    .iter()
                    .map(|l| self.world.bodies[l.handle].position().rotation)
                    .collect();
                let base_rot = self.clamp_now_rotation();
                let Some((mb, _)) = self.world.multibody_joints.get_mut(handles[0]) else {
                    return;
                };
                for (k, &offset) in offsets.iter().enumerate() {
                    let (parent_rot, parent_omega) = if k == 0 {
                        (base_rot, Vec3::zeros())
                    } else {
                        (rot[k - 1], omega[k - 1])
                    };
                    let rate = parent_rot.inverse().mul_vec3(dv(&(omega[k] - parent_omega)));
                    let mut gv = mb.generalized_velocity_mut();
                    for a in 0..3 {
                        gv[offset + a] = rate[a];
                    }
                }
                // The links' body velocities from the joint rates, by the
                // chain's kinematics (rapier writes them back only in a
                // step, and reads them in the first one: Coriolis terms).
                let mut joint_v = Vec3::zeros();
                for k in 0..self.links.len() {
                    let x = self.joint_point(k);
                    if k > 0 {
                        joint_v += omega[k - 1].cross(&(x - self.joint_point(k - 1)));
                    }
                    let (com, ..) = self.link_state(k);
                    let v = joint_v + omega[k].cross(&(com - x));
                    let rb = &mut self.world.bodies[self.links[k].handle];
                    rb.set_linvel(dv(&v), true);
                    rb.set_angvel(dv(&omega[k]), true);
                }
            }
        }
    }

    /// Put the vessel wall `surface` around the chain: its triangles wound
    /// with normals out of the lumen (as `surgbench_core::sdf::level_surface`
    /// gives them), friction coefficient `friction` between wire and wall,
    /// the wire's centreline kept `margin` (m) from it (the scene's contact
    /// margin: the wire radius in every vessel scene, as the other rod
    /// models read it). Every link becomes a capsule of radius `margin`
    /// around its segment; links do not collide with each other (no model
    /// here has self-contact). The wall is one-sided
    /// (parry's `FIX_INTERNAL_EDGES`, which also keeps a capsule sliding
    /// over the mesh from catching on the edges between facets), facing the
    /// lumen. rapier's tolerances (its linear slop, prediction distance and
    /// corrective speed, all "normalized" by `length_unit`) are scaled to
    /// the capsules' radius: at rapier's default of 1 m its slop alone
    /// (5 mm) exceeds a guidewire's lumen clearance.
    pub fn add_wall(
        &mut self,
        surface: &TriSurface,
        friction: f64,
        margin: f64,
        contact_hz: f64,
    ) -> Result<(), String> {
        if self.wall.is_some() {
            return Err("the chain already has a wall".into());
        }
        if surface.triangles.is_empty() {
            return Err("the vessel wall has no triangles near the wire".into());
        }
        if !(friction >= 0.0 && friction.is_finite() && margin > 0.0 && margin.is_finite()) {
            return Err(format!(
                "friction {friction} must be >= 0 and the contact margin {margin} (the capsules' radius) > 0 m"
            ));
        }
        let vertices = surface.vertices.iter().map(dv).collect();
        // parry keeps bodies on the side a one-sided mesh's normals point to.
        let indices = surface
            .triangles
            .iter()
            .map(|t| [t[0] as u32, t[2] as u32, t[1] as u32])
            .collect();
        let collider = ColliderBuilder::trimesh_with_flags(vertices, indices, TriMeshFlags::FIX_INTERNAL_EDGES)
            .map_err(|e| format!("rapier rejected the wall mesh: {e:?}"))?;
        let wall = self.world.insert_collider(
            surface_collider(collider, friction, Group::GROUP_2, Group::GROUP_1),
            None,
        );
        for k in 0..self.links.len() {
            let l = self.links[k];
            let capsule = surface_collider(
                ColliderBuilder::capsule_x(0.5 * l.length, margin).translation(DVec3::new(0.5 * l.length, 0.0, 0.0)),
                friction,
                Group::GROUP_1,
                Group::GROUP_2,
            );
            self.world.insert_collider(capsule, Some(l.handle));
        }
        self.world.integration_parameters.length_unit = margin;
        // rapier caps body speeds at 400 length units per second; scaled to
        // a guidewire that is 0.18 m/s, below a whipping tip's speed.
        self.world.integration_parameters.normalized_max_linear_velocity = f64::MAX;
        // One Coulomb cone per contact point, as multibody links always
        // get: impulse-joint links would otherwise get rapier's faster
        // "simplified" friction (one cone per four points plus a twist).
        self.world.integration_parameters.friction_model = FrictionModel::Coulomb;
        // rapier merges the contacts of a capsule with the many triangles
        // under it into clusters of at most four points per plane (its
        // default, "a large solver win on composite shapes"). On a tube
        // wall meshed at an eighth of its radius that inflates the normal
        // force: a 40-link wire resting on the floor of a 2 mm tube got
        // 2.7 times its weight from the wall (0.97 without clusters), and
        // stick-slip-threshold's sliding force came out 4.1 times mu_d N
        // (1.03 without). Off: every contact point is its own constraint.
        self.world.integration_parameters.contact_clustering = false;
        self.world
            .integration_parameters
            .static_contact_softness
            .natural_frequency = contact_hz;
        self.wall = Some(wall);
        Ok(())
    }

    /// Blood flow around the chain: each link feels the drag of
    /// `surgbench_core::flow` at its midpoint, from the flow and the link's
    /// velocity at the start of the step (explicit; its rate `c / m` is
    /// ~70 1/s for a 0.89 mm wire in 0.5 m/s blood, 0.07 of a 1 ms step).
    pub fn set_flow(&mut self, flow: Arc<dyn FlowField>) {
        self.flow = Some(flow);
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Number of links.
    pub fn num_links(&self) -> usize {
        self.links.len()
    }

    /// Spring constants (twist, bend, bend; N m/rad) of joint `j`.
    pub fn joint_stiffness(&self, j: usize) -> [f64; 3] {
        self.stiffness[j]
    }

    /// Arclength of joint `j` from the clamp (m).
    pub fn joint_arclength(&self, j: usize) -> f64 {
        self.joint_s[j]
    }

    /// Pose of link `k` (its joint end).
    fn link_pose(&self, k: usize) -> Pose {
        *self.world.bodies[self.links[k].handle].position()
    }

    /// Tip point (m).
    pub fn tip(&self) -> Vec3 {
        let k = self.links.len() - 1;
        nv(self
            .link_pose(k)
            .transform_point(DVec3::new(self.links[k].length, 0.0, 0.0)))
    }

    /// Rotation of joint `j`'s child relative to its parent, as a rotation
    /// vector in the parent's frame (rad): the joint's geometric bend and twist.
    pub fn relative_rotation(&self, j: usize) -> Vec3 {
        let parent = if j == 0 {
            self.clamp_now_rotation()
        } else {
            self.link_pose(j - 1).rotation
        };
        let child = self.link_pose(j).rotation;
        nv((parent.inverse() * child).to_scaled_axis())
    }

    fn clamp_now_rotation(&self) -> DQuat {
        self.world.bodies[self.carriage.handle].position().rotation
    }

    /// Largest difference (rad) between rapier's joint coordinates (what its
    /// springs act on: the integrated joint angular velocity) and the true
    /// relative rotation vector, over the joints; 0 for impulse joints,
    /// whose motors read the relative rotation itself.
    pub fn coord_drift(&self) -> f64 {
        let Joints::Multibody { handles, .. } = &self.joints else {
            return 0.0;
        };
        handles
            .iter()
            .enumerate()
            .filter_map(|(j, &jh)| {
                let (mb, id) = self.world.multibody_joints.get(jh)?;
                let c = mb.link(id)?.joint().coords();
                let q = Vec3::new(c[3], c[4], c[5]);
                Some((q - self.relative_rotation(j)).norm())
            })
            .fold(0.0, f64::max)
    }

    /// Largest opening (m) of a joint: the distance between the parent's end
    /// and the child's start (0 up to round-off for multibody joints).
    pub fn max_joint_gap(&self) -> f64 {
        (0..self.links.len())
            .map(|k| (self.joint_point_from_parent(k) - self.joint_point(k)).norm())
            .fold(0.0, f64::max)
    }

    /// Joint `k`'s point as the child link has it (m).
    fn joint_point(&self, k: usize) -> Vec3 {
        nv(self.link_pose(k).translation)
    }

    /// Joint `k`'s point as the parent (clamp or link) has it (m).
    fn joint_point_from_parent(&self, k: usize) -> Vec3 {
        if k == 0 {
            (self.clamp_now * nalgebra::Point3::new(self.joint_s[0], 0.0, 0.0)).coords
        } else {
            let l = &self.links[k - 1];
            nv(self.link_pose(k - 1).transform_point(DVec3::new(l.length, 0.0, 0.0)))
        }
    }

    /// Centre of mass, velocity, angular velocity and world inertia of link `k`.
    fn link_state(&self, k: usize) -> (Vec3, Vec3, Vec3, Mat3) {
        self.body_state(&self.links[k])
    }

    /// Centre of mass, velocity, angular velocity and world inertia of `l`.
    fn body_state(&self, l: &Link) -> (Vec3, Vec3, Vec3, Mat3) {
        let rb = &self.world.bodies[l.handle];
        let pose = rb.position();
        let x = nv(pose.transform_point(DVec3::new(l.com, 0.0, 0.0)));
        let r = to_mat(&pose.rotation);
        let i_local = Mat3::from_diagonal(&Vec3::new(l.inertia[0], l.inertia[1], l.inertia[1]));
        (x, nv(rb.linvel()), nv(rb.angvel()), r * i_local * r.transpose())
    }

    /// Velocity of the point `x` (m) of link `k` (m/s).
    fn velocity_at(&self, k: usize, x: &Vec3) -> Vec3 {
        self.body_velocity_at(&self.links[k], x)
    }

    /// Velocity of the point `x` (m) of the body `l` (m/s).
    fn body_velocity_at(&self, l: &Link, x: &Vec3) -> Vec3 {
        let (com, v, w, _) = self.body_state(l);
        v + w.cross(&(x - com))
    }

    /// Linear momentum and angular momentum about the world origin.
    fn momenta(&self) -> (Vec3, Vec3) {
        let mut p = Vec3::zeros();
        let mut l = Vec3::zeros();
        for b in std::iter::once(&self.carriage).chain(&self.links) {
            let (x, v, w, i) = self.body_state(b);
            p += b.mass * v;
            l += x.cross(&(b.mass * v)) + i * w;
        }
        (p, l)
    }

    /// External force and torque about the world origin on the rod:
    /// gravity (on the links and on the half cell the clamp holds), the tip
    /// loads at the current time, and the drag and wall forces of the last
    /// step.
    fn external_wrench(&self) -> (Vec3, Vec3) {
        let mut f = self.drag.0 + self.wall_wrench.0;
        let mut t = self.drag.1 + self.wall_wrench.1;
        for b in std::iter::once(&self.carriage).chain(&self.links) {
            let (x, ..) = self.body_state(b);
            let w = b.mass * self.gravity;
            f += w;
            t += x.cross(&w);
        }
        let tip_f = self.body.tip_force_at(self.time);
        f += tip_f;
        t += self.tip().cross(&tip_f) + self.body.tip_torque_at(self.time);
        (f, t)
    }

    /// Advance by `dt` (s) to the operator's command `cmd`.
    pub fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<(), SimError> {
        SimError::check_dt(self.time, dt)?;
        let t1 = self.time + dt;
        if cmd.base_pose.is_some_and(|p| p != self.clamp) {
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: "the rigid chain's clamp slides along and turns about its axis but does not move otherwise (a moving base pose)".into(),
            });
        }
        self.clamp_now = self.clamp * Iso3::translation(cmd.insertion, 0.0, 0.0) * turn(cmd.rotation);
        match &self.joints {
            Joints::Multibody { handles, .. } => {
                // The turn's rate that lands the kinematic DOF on the command
                // at the end of the step. The clamp's half cell is link 1
                // (after the fixed root), its DOFs the first two: slide, turn.
                let Some((mb, _)) = self.world.multibody_joints.get_mut(handles[0]) else {
                    return Err(SimError::SolverFailed {
                        t: self.time,
                        reason: "rapier lost the chain's multibody".into(),
                    });
                };
                let (slid, turned) = mb
                    .link(1)
                    .map_or((0.0, 0.0), |l| (l.joint().coords()[0], l.joint().coords()[3]));
                let mut gv = mb.generalized_velocity_mut();
                gv[0] = (cmd.insertion - slid) / dt;
                gv[1] = (cmd.rotation - turned) / dt;
            }
            Joints::Impulse => {
                let pose = to_pose(&self.clamp_now);
                self.world.bodies[self.carriage.handle].set_next_kinematic_position(pose);
            }
        }
        // Forces at points of the links: at the centre of mass plus their
        // moment about it (from this chain's own centre of mass: rapier's
        // world one is stale until the body's first step).
        let n = self.links.len();
        let mut loads = vec![(Vec3::zeros(), Vec3::zeros()); n];
        let tip_force = self.body.tip_force_at(t1);
        let (com, ..) = self.link_state(n - 1);
        loads[n - 1] = (
            tip_force,
            (self.tip() - com).cross(&tip_force) + self.body.tip_torque_at(t1),
        );
        self.drag = (Vec3::zeros(), Vec3::zeros());
        if let Some(flow) = self.flow.clone() {
            for (k, load) in loads.iter_mut().enumerate() {
                let l = self.links[k];
                let pose = self.link_pose(k);
                let mid = nv(pose.transform_point(DVec3::new(0.5 * l.length, 0.0, 0.0)));
                let tangent = nv(pose.rotation.mul_vec3(DVec3::X));
                let d = 2.0 * self.body.section_at(self.joint_s[k] + 0.5 * l.length).radius;
                let u = flow.velocity(&mid) - self.velocity_at(k, &mid);
                let f = drag_per_length(&u, &tangent, d) * l.length;
                let (com, ..) = self.link_state(k);
                load.0 += f;
                load.1 += (mid - com).cross(&f);
                self.drag.0 += f;
                self.drag.1 += mid.cross(&f);
            }
        }
        for (k, (force, torque)) in loads.iter().enumerate() {
            let rb = &mut self.world.bodies[self.links[k].handle];
            // rapier keeps user forces and torques until reset.
            rb.reset_forces(false);
            rb.reset_torques(false);
            rb.add_force(dv(force), true);
            rb.add_torque(dv(torque), true);
        }
        self.world.integration_parameters.dt = dt;
        self.world.step();
        self.time = t1;
        if let Some(w) = self.wall {
            self.wall_wrench = wall_wrench_on_others(&self.world, w, dt);
        }
        let finite = self.links.iter().all(|l| {
            let rb = &self.world.bodies[l.handle];
            rb.translation().is_finite() && rb.linvel().is_finite() && rb.angvel().is_finite()
        });
        if !finite {
            return Err(SimError::Diverged {
                t: t1,
                reason: "a link's pose or velocity is not finite".into(),
            });
        }
        let (p, l) = self.momenta();
        let (f, t) = self.external_wrench();
        self.hand = (f - (p - self.momentum.0) / dt, t - (l - self.momentum.1) / dt);
        self.momentum = (p, l);
        Ok(())
    }

    /// Force and torque (about the clamp point) the chain exerts on the
    /// clamp over the last step (N, N m).
    pub fn hand_wrench(&self) -> (Vec3, Vec3) {
        self.about_clamp(self.hand)
    }

    /// Force and torque (about the clamp point) the wall put on the chain
    /// over the last step (N, N m); zero without a wall.
    pub fn wall_wrench(&self) -> (Vec3, Vec3) {
        self.about_clamp(self.wall_wrench)
    }

    /// A wrench about the world origin moved to the clamp point:
    /// `(f, t - c x f)`.
    fn about_clamp(&self, (f, t): (Vec3, Vec3)) -> (Vec3, Vec3) {
        (f, t - self.clamp_now.translation.vector.cross(&f))
    }

    /// The chain as a rod: nodes at the clamp, at every joint and at the
    /// tip; edge 0 is the half cell held by the clamp, edge `k + 1` link `k`.
    pub fn rod_obs(&self) -> RodObs {
        let n = self.links.len();
        let mut arclength = Vec::with_capacity(n + 2);
        let mut nodes = Vec::with_capacity(n + 2);
        let mut velocities = Vec::with_capacity(n + 2);
        let mut frames = Vec::with_capacity(n + 1);
        let c = self.clamp_now.translation.vector;
        arclength.push(0.0);
        nodes.push(c);
        velocities.push(self.body_velocity_at(&self.carriage, &c));
        let material = |r: Mat3| {
            Mat3::from_columns(&[
                r.column(1).into_owned(),
                r.column(2).into_owned(),
                r.column(0).into_owned(),
            ])
        };
        frames.push(material(self.clamp_now.rotation.to_rotation_matrix().into_inner()));
        for k in 0..n {
            let rb = &self.world.bodies[self.links[k].handle];
            let x = self.joint_point(k);
            arclength.push(self.joint_s[k]);
            nodes.push(x);
            velocities.push(self.velocity_at(k, &x));
            frames.push(material(to_mat(&rb.position().rotation)));
        }
        let tip = self.tip();
        arclength.push(self.body.length);
        nodes.push(tip);
        velocities.push(self.velocity_at(n - 1, &tip));
        let rest = self.rest_nodes.clone();
        let h = self.body.length / n as f64;
        RodObs {
            arclength,
            rest,
            nodes,
            velocities,
            frames,
            max_stretch: self.max_joint_gap() / h,
        }
    }

    /// Kinetic energy of the links, elastic energy of the joint springs on
    /// the true relative rotations, and the potential of gravity and the
    /// tip force (the tip torque has none here) (J).
    pub fn energies(&self) -> EnergyObs {
        let mut e = EnergyObs::default();
        for k in 0..self.links.len() {
            let (x, v, w, i) = self.link_state(k);
            let m = self.links[k].mass;
            e.kinetic += 0.5 * m * v.norm_squared() + 0.5 * w.dot(&(i * w));
            e.external -= m * self.gravity.dot(&x);
            let q = self.relative_rotation(k) - self.rest[k];
            e.elastic += 0.5 * (0..3).map(|a| self.stiffness[k][a] * q[a] * q[a]).sum::<f64>();
        }
        e.external -= self.body.tip_force_at(self.time).dot(&self.tip());
        e
    }
}

/// Rotation about the clamp's own axis (local `x`) by `angle` rad.
fn turn(angle: f64) -> Iso3 {
    Iso3::rotation(Vec3::new(angle, 0.0, 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A free capsule on a triangle floor under tilted gravity: the wall
    /// impulse read back from rapier's contacts closes the capsule's
    /// momentum balance, `m dv = (m g + F_wall) dt`, both while it slides
    /// (tilt past the friction angle) and while friction holds it.
    #[test]
    fn wall_impulse_closes_the_momentum_balance() {
        for (tilt, mu) in [(0.5f64, 0.2), (0.1, 0.3)] {
            let mut world = PhysicsWorld::new();
            let g = Vec3::new(9.81 * tilt.sin(), 0.0, -9.81 * tilt.cos());
            world.gravity = dv(&g);
            world.integration_parameters.dt = 1e-3;
            world.integration_parameters.length_unit = 1e-3;
            // As in the chain: rapier's speed cap (400 length units/s) off.
            world.integration_parameters.normalized_max_linear_velocity = f64::MAX;
            world.integration_parameters.friction_model = FrictionModel::Coulomb;
            let floor = ColliderBuilder::trimesh(
                vec![
                    DVec3::new(-1.0, -1.0, 0.0),
                    DVec3::new(1.0, -1.0, 0.0),
                    DVec3::new(1.0, 1.0, 0.0),
                    DVec3::new(-1.0, 1.0, 0.0),
                ],
                vec![[0, 1, 2], [0, 2, 3]],
            )
            .unwrap()
            .friction(mu);
            let wall = world.insert_collider(floor, None);
            let m = 1e-3;
            let body = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .translation(DVec3::new(0.0, 0.0, 1e-3))
                    .additional_mass_properties(MassProperties::new(DVec3::ZERO, m, DVec3::splat(1e-9)))
                    .can_sleep(false),
            );
            world.insert_collider(
                ColliderBuilder::capsule_x(5e-3, 1e-3).density(0.0).friction(mu),
                Some(body),
            );
            let mut worst: f64 = 0.0;
            let mut wall_force = Vec3::zeros();
            for _ in 0..400 {
                let v0 = nv(world.bodies[body].linvel());
                world.step();
                let v1 = nv(world.bodies[body].linvel());
                wall_force = wall_wrench_on_others(&world, wall, 1e-3).0;
                let residual = m * (v1 - v0) / 1e-3 - (m * g + wall_force);
                worst = worst.max(residual.norm() / (m * 9.81));
            }
            // Impulses and velocities are the same floating-point sums.
            assert!(worst < 1e-9, "tilt {tilt}: momentum residual {worst:e} of the weight");
            let normal = wall_force.z;
            let weight_n = m * 9.81 * tilt.cos();
            // Resting on the floor at the end: normal force = weight's
            // normal part (to the solver's softness), friction mu N while
            // sliding (tan 0.5 > 0.2; Coulomb on the measured N), the
            // weight's tangential part while stuck (tan 0.1 < 0.3).
            assert!(
                (normal - weight_n).abs() < 1e-6 * weight_n,
                "normal {normal} vs {weight_n}"
            );
            let friction = Vec3::new(wall_force.x, wall_force.y, 0.0).norm();
            let want = if tilt.tan() > mu {
                mu * normal
            } else {
                m * 9.81 * tilt.sin()
            };
            // 1e-4: the held capsule still creeps on rapier's soft contact
            // after 0.4 s (measured 9e-6).
            assert!((friction - want).abs() < 1e-4 * want, "friction {friction} vs {want}");
        }
    }

    /// Two sections: the mass is the sum of the two cylinders, the centre
    /// of mass their weighted mean (exact arithmetic up to round-off).
    #[test]
    fn piece_mass_splits_at_sections() {
        let mut body = RodBody::uniform(1.0, 0.01, 1e9, 0.3, 1000.0);
        let mut tip = body.sections[0].clone();
        body.sections[0].until = 0.5;
        tip.density = 3000.0;
        body.sections.push(tip);
        let a = std::f64::consts::PI * 1e-4;
        let (m, com, _) = piece_mass(&body, 0.25, 0.75);
        let (m1, m2) = (1000.0 * a * 0.25, 3000.0 * a * 0.25);
        assert!((m - (m1 + m2)).abs() < 1e-12 * m);
        let want = (m1 * 0.125 + m2 * 0.375) / (m1 + m2);
        assert!((com - want).abs() < 1e-12);
    }
}
