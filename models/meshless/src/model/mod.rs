//! The `meshless` model: factory, settings and the time stepper.
//!
//! **Integrators** (fidelity `integrator`):
//! * `symplectic-euler`, `v += h (f / m + g - c v)`, `x += h v`
//!   (explicit, the seed's choice). Conditionally stable:
//!   `h < 2 / omega_max`, `omega_max^2` the largest eigenvalue of `M^-1 K`;
//!   [`MeshlessTissue::critical_dt`] estimates it by power iteration.
//! * `backward-euler`: each step minimises the incremental potential
//!   `sum m/(2h^2) |x - x_n - h v_n|^2 + c m/(2h) |x - x_n|^2 + U(x) - m g . x`
//!   by Newton's method with matrix-free conjugate gradients (exact
//!   Hessian-vector products) and an Armijo line search; unconditionally
//!   stable (numerically damped), `v = (x - x_n) / h`.
//! * `quasi-static`: the same Newton minimisation without the inertia
//!   terms (`U(x) - m g . x` with the boundary conditions at this step's
//!   command): every step is an equilibrium. Default when the scene settles.
//!
//! **Support radii.** Node `i`'s poly6 support is `h_i = support_factor
//! l_i` and the MLS radius of the surface particle on node `i` is
//! `mls_factor l_i`, with `l_i` the mean edge of the tets around node `i`
//! ([`local_edge_lengths`]). On the Kuhn-split blocks (congruent tets) `l_i`
//! is the global mean edge, so the radii are the single radius used before
//! (`support_factor` times the mean edge); on a graded mesh each node gets a
//! neighbourhood of about the same number of cells, coarse or fine (one
//! global radius left the coarse cells' nodes without a full neighbourhood
//! and smoothed the fine cells over many cells). Where that neighbourhood
//! is nearly flat (moment matrix `rcond < `[`RAISE_BELOW_RCOND`]: strongly
//! anisotropic cells; on the graded vessel-wall sector of wall-indentation
//! some nodes saw coplanar neighbours, rcond 7e-17 at level 0) both
//! radii are raised to `support_floor e_i`, `e_i` the longest edge at the
//! node ([`longest_edges`], [`DEFAULT_SUPPORT_FLOOR`]): the support then
//! holds the node's whole mesh star, which spans 3D. The energy stays a sum of
//! per-node terms, so forces and Hessian-vector products stay exact
//! ([`crate::elastic`]). A node whose neighbours still do not span 3D is
//! refused at build, naming the node.
//!
//! Newton stops when every node's largest free force component is under
//! `1e-9 E l_i^2` (N; `l_i` its local edge length), i.e. a residual stress
//! of `1e-9 E` at every node. (With one tolerance from the mean edge, the
//! fine cells of a graded mesh, whose forces scale with `l_i^2`, were held
//! to a looser relative residual: the sphere's reaction on wall-indentation
//! differed by 4e-6 of itself between rigidly moved frames.)
//!
//! **Boundary conditions.** Fixed nodes stay at rest, driven nodes sit at
//! `X + load d`, rollers (`partial_fixed`) hold the flagged world
//! components at rest.
//!
//! **Pressure loads** (`TissueBody::pressure_faces`) act on the scene's
//! boundary triangles, whose vertices are simulation nodes of this model
//! (every mesh node is a point primitive), so the consistent nodal forces
//! go straight to those nodes: no mapping is involved (the MLS surface
//! particles are a read-out of the nodes, not degrees of freedom). Each
//! face gives `-(s p / 6) (b - a) x (c - a)` to each of its nodes, on the
//! *current* configuration (follower load), `s` the command's load factor
//! ([`crate::pressure`], Bonet & Wood, Sec. 6.5). Newton's Hessian-vector
//! product carries the symmetric part of the exact load stiffness (CG
//! needs symmetry; the skew part lives on the border edges of an open
//! loaded surface and is `O(p/E)` relative to the elastic stiffness, so
//! Newton still converges, linearly at that rate). Its line search holds
//! the pressure at the iterate's value (a dead load within the search),
//! since a follower load on an open surface has no potential. The energy
//! probe and `EnergyObs` leave the pressure out for the same reason.
//!
//! **Sphere contact** (`TissueBody::indenter`): the penalty energy `E_c =
//! sum_i k_i / 2 <|x_i - c| - R>_-^2` over the surface nodes, `k_i = kappa
//! E* sqrt(A_i)` ([`crate::contact`], Wriggers 2006 eq. 6.47; the rule of the
//! `fem` model), is added to the Newton objective, its gradient and its
//! Hessian-vector product (exact), with the centre `c` at the command's
//! load factor, `SphereIndenter::centre_at(load)`. Backward Euler and
//! quasi-static only: the explicit integrator and the PBD corrections are
//! refused with a reason when the scene has a sphere.
//!
//! **Reports.** `hand_force` is the force the body exerts on whatever drives
//! it: the sum over driven nodes of the internal elastic force `-dU/dx` plus
//! their weight and any pressure on them, plus the force the body exerts on
//! the sphere, `sum_i k_i g_i n_i` (N). The contact energy counts in
//! `EnergyObs::elastic` and in the energy probe's potential. `TissueObs::inverted` counts nodes whose
//! deformation gradient has `det F <= 0`; `volume_error` uses the scene's
//! tets as virtual tetrahedra. With PBD on, the corrections change the
//! configuration; they are not forces and do not enter `hand_force`.
//!
//! Units are SI throughout.

use surgbench_core::{BuildError, EnergyObs, Fidelity, Mat3, Scene, Settings, Unsupported, Vec3};

use crate::contact::SphereContact;
use crate::elastic::{PointElastic, StateCache};
use crate::mls::MlsMap;
use crate::pbd::PbdConstraints;
use crate::pressure::PressureLoad;
use surgbench_core::sphere_contact::DEFAULT_KAPPA;

pub use crate::factory::{MESHLESS_KEYS, MeshlessFactory};

mod build;
mod harness;
mod solve;

/// The names of `integrator`, as integrators.
/// `variant` names: whether the seed's configuration is the default.
const VARIANTS: &[(&str, bool)] = &[("harness", false), ("seed", true)];

const INTEGRATORS: &[(&str, Integrator)] = &[
    ("symplectic-euler", Integrator::SymplecticEuler),
    ("backward-euler", Integrator::BackwardEuler),
    ("quasi-static", Integrator::QuasiStatic),
];

/// Time integrator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Integrator {
    /// Symplectic (semi-implicit) Euler, explicit.
    SymplecticEuler,
    /// Backward Euler by Newton-CG.
    BackwardEuler,
    /// Static equilibrium every step by Newton-CG.
    QuasiStatic,
}

/// Resolved knobs of a [`MeshlessTissue`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshlessSettings {
    /// Time step (s).
    pub dt: f64,
    /// PBD Gauss-Seidel sweeps per step.
    pub iterations: usize,
    /// Support radius over the node's local edge length.
    pub support_factor: f64,
    /// MLS radius over the surface node's local edge length.
    pub mls_factor: f64,
    /// Hourglass stiffness over `E`.
    pub stabilization: f64,
    /// Integrator.
    pub integrator: Integrator,
    /// Mass-proportional damping rate (1/s); `None` = the default.
    pub damping: Option<f64>,
    /// PBD corrections on.
    pub pbd: bool,
    /// PBD stretch stiffness.
    pub pbd_stretch: f64,
    /// PBD tet stiffness.
    pub pbd_tet: f64,
    /// Floor of the support and MLS radii over the longest mesh edge at the
    /// node where the plain support is nearly flat
    /// ([`DEFAULT_SUPPORT_FLOOR`], [`RAISE_BELOW_RCOND`]; 0 = off).
    pub support_floor: f64,
    /// Penalty factor `kappa` of the sphere contact ([`crate::contact`]).
    pub contact_stiffness: f64,
}

impl MeshlessSettings {
    /// The tissue's knobs from `settings` resolved for `scene` (their
    /// ranges were checked by `surgbench_core::resolve` against
    /// [`crate::factory::MESHLESS_KEYS`]).
    pub fn from_settings(scene: &Scene, settings: &Settings) -> Result<Self, BuildError> {
        let f = settings.fidelity();
        let dt = f.dt.unwrap_or(1e-3);
        let iterations = f.iterations.unwrap_or(5);
        // The keys' ranges are declared in `MESHLESS_KEYS` and checked by
        // `surgbench_core::resolve` before a build; `dt` is a core knob.
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(BuildError::bad("dt", format!("must be > 0, got {dt}")));
        }
        // The seed variant ([`crate::factory::MESHLESS_KEYS`] `variant`):
        // explicit, PBD corrections on, no hourglass control, unless named.
        let seed = settings.pick("variant", VARIANTS, false)?;
        let default_integrator = if seed {
            Integrator::SymplecticEuler
        } else if scene.settle.is_some() {
            Integrator::QuasiStatic
        } else {
            Integrator::BackwardEuler
        };
        let integrator = settings.pick("integrator", INTEGRATORS, default_integrator)?;
        let damping = settings.number("damping");
        Ok(Self {
            dt,
            iterations,
            support_factor: settings.number_or("support_factor", 1.5),
            mls_factor: settings.number_or("mls_factor", 2.0),
            stabilization: settings.number_or("stabilization", if seed { 0.0 } else { 0.1 }),
            integrator,
            damping,
            pbd: settings.switch("pbd", seed),
            pbd_stretch: settings.number_or("pbd_stretch", 0.5),
            pbd_tet: settings.number_or("pbd_tet", 0.5),
            support_floor: settings.number_or("support_floor", DEFAULT_SUPPORT_FLOOR),
            contact_stiffness: settings.number_or("contact_stiffness", DEFAULT_KAPPA),
        })
    }
}

/// Local edge length `l_i` (m) of every node of `mesh`: the mean, over the
/// tets containing node `i`, of each tet's mean edge length,
/// `l_i = (1 / |T_i|) sum_{t in T_i} (1/6) sum_{e in t} |e|`. It is the
/// global mean edge (the same average over all tets, counting each tet's six
/// edges) restricted to the node's star, so on a mesh of congruent tets
/// (the Kuhn-split cubes of `mesh::block`) every `l_i` equals the global mean
/// edge up to rounding and the per-node radii are the old single radius; on
/// a graded mesh it follows the cell size, and it spans the node's own
/// incident edges and those opposite it, the extent of the star where its
/// neighbours lie. A node in no tet gets 0 (refused by the caller).
pub fn local_edge_lengths(mesh: &surgbench_core::TetMesh) -> Vec<f64> {
    let mut sum = vec![0.0; mesh.nodes.len()];
    let mut count = vec![0usize; mesh.nodes.len()];
    for t in &mesh.tets {
        let p = t.map(|i| mesh.nodes[i]);
        let mut e = 0.0;
        for a in 0..4 {
            for b in a + 1..4 {
                e += (p[b] - p[a]).norm();
            }
        }
        for &i in t {
            sum[i] += e / 6.0;
            count[i] += 1;
        }
    }
    sum.iter()
        .zip(&count)
        .map(|(&s, &c)| if c > 0 { s / c as f64 } else { 0.0 })
        .collect()
}

/// Default floor of a node's radii over the longest mesh edge at the node,
/// applied where the plain support gives a nearly flat neighbourhood
/// ([`RAISE_BELOW_RCOND`]). Above 1 the support contains the node's whole
/// mesh star, whose vertices span 3D (every tet has volume), so the moment
/// matrix is regular on any valid mesh; the longest star edge then weighs
/// `(1 - 1/1.05^2)^3 = 8e-4` of the centre. It is below the default
/// supports on the Kuhn blocks (`1.05 sqrt 3 a = 1.82 a` < `1.5 x 1.26 a =
/// 1.89 a`, `a` the cube edge), so it never acts there.
pub const DEFAULT_SUPPORT_FLOOR: f64 = 1.05;

/// A node's support is raised to the floor when its moment matrix at
/// `support_factor l_i` has `lambda_min / lambda_max` below this: its
/// neighbours lie nearly in a plane (measured on the graded vessel-wall
/// sector of wall-indentation: rcond 7e-17, -2e-16 and 6e-11 at levels 0-2
/// without the raise), and the gradient across it would rest on a
/// near-singular fit. Applied only there, so graded but
/// well-shaped cells (the sphere-indentation block) keep their local
/// supports.
pub const RAISE_BELOW_RCOND: f64 = 1e-3;

/// Longest tet edge (m) at every node of `mesh` (0 for a node in no tet).
pub fn longest_edges(mesh: &surgbench_core::TetMesh) -> Vec<f64> {
    let mut out = vec![0.0f64; mesh.nodes.len()];
    for t in &mesh.tets {
        for a in 0..4 {
            for b in a + 1..4 {
                let l = (mesh.nodes[t[b]] - mesh.nodes[t[a]]).norm();
                out[t[a]] = out[t[a]].max(l);
                out[t[b]] = out[t[b]].max(l);
            }
        }
    }
    out
}

/// A neighbourhood that does not span 3D (`reason` names the node or
/// surface particle). With the default radius factor `knob` and floor the
/// scene's mesh is what cannot be modelled (a degenerate star), so
/// `Unsupported`; with a factor or floor the caller chose, that is the bad
/// parameter.
fn refusal(fidelity: &Fidelity, knob: &str, reason: String) -> BuildError {
    if fidelity.extras.contains_key(knob) || fidelity.extras.contains_key("support_floor") {
        BuildError::bad(knob, reason)
    } else {
        Unsupported::new(format!(
            "meshless at the default {knob} and support_floor: {reason} (the node's mesh star is degenerate)"
        ))
        .into()
    }
}

/// Distances between MLS-mapped surface particles and where they should be (m).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MappingError {
    /// Root mean square over the surface particles (m).
    pub rms: f64,
    /// Largest (m).
    pub max: f64,
    /// Number of surface particles.
    pub count: usize,
}

impl MappingError {
    fn of(d: impl Iterator<Item = f64>) -> Self {
        let (mut s2, mut max, mut count) = (0.0, 0.0f64, 0usize);
        for v in d {
            s2 += v * v;
            max = max.max(v);
            count += 1;
        }
        Self {
            rms: if count > 0 { (s2 / count as f64).sqrt() } else { 0.0 },
            max,
            count,
        }
    }
}

/// Newton-CG result.
#[derive(Debug, Clone, Copy)]
struct SolveInfo {
    iterations: u32,
    residual: f64,
    converged: bool,
}

/// The point-primitive tissue. Build through [`MeshlessFactory`] or
/// [`MeshlessTissue::new`].
#[derive(Debug, Clone)]
pub struct MeshlessTissue {
    set: MeshlessSettings,
    el: PointElastic,
    cache: StateCache,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    mass: Vec<f64>,
    /// 1 where a component moves, 0 where it is held.
    axis_free: Vec<Vec3>,
    /// Held components' positions at zero load (m).
    driven: Vec<(usize, Vec3)>,
    gravity: Vec3,
    damping: f64,
    tets: Vec<[usize; 4]>,
    rest_volume: f64,
    pbd: Option<PbdConstraints>,
    pbd_residual: f64,
    surface_nodes: Vec<usize>,
    surface_faces: Vec<[usize; 3]>,
    mls: MlsMap,
    mean_edge: f64,
    local_edge: Vec<f64>,
    raised: Vec<usize>,
    scale: f64,
    /// Newton tolerance per node, `1e-9 E l_i^2` (N).
    tol: Vec<f64>,
    time: f64,
    hand_force: Vec3,
    forces: Vec<Vec3>,
    /// Whether `forces` holds the internal forces at the current `x`.
    forces_at_x: bool,
    pressure: PressureLoad,
    /// Load factor of the pressure this step (the command's `load`).
    load_scale: f64,
    /// Quasi-static load stepping so far: increments solved to
    /// equilibrium and failed solves retried with half the increment
    /// (reported as diagnostics).
    load_stepping: (usize, usize),
    /// Pressure nodal forces at the last gradient evaluation (N).
    pforces: Vec<Vec3>,
    /// Penalty contact with the scene's rigid sphere, if any, centred where
    /// the last step's command put it.
    contact: Option<SphereContact>,
    /// The scene's contact-surface vertices (`TissueBody::surface_vertices`)
    /// as indices into the MLS surface particles.
    contact_particles: Vec<usize>,
    /// Dead nodal forces from a coupled instrument (N): the surface forces
    /// spread over the nodes by the MLS shape functions.
    external: Vec<Vec3>,
}

impl MeshlessTissue {
    /// Resolved settings.
    pub fn settings(&self) -> MeshlessSettings {
        self.set
    }

    /// The point discretisation (neighbourhoods, weights, material).
    pub fn elastic(&self) -> &PointElastic {
        &self.el
    }

    /// Node positions (m).
    pub fn positions(&self) -> &[Vec3] {
        &self.x
    }

    /// Node velocities (m/s).
    pub fn velocities(&self) -> &[Vec3] {
        &self.v
    }

    /// Node masses (kg): density times the node volume (a quarter of each
    /// adjacent tet's volume).
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }

    /// Mean mesh edge length (m) over all tets (each tet's six edges).
    pub fn mean_edge(&self) -> f64 {
        self.mean_edge
    }

    /// Local edge length of every node (m), the unit of its support and MLS
    /// radii ([`local_edge_lengths`]).
    pub fn local_edge(&self) -> &[f64] {
        &self.local_edge
    }

    /// Nodes whose radii were raised to the floor (`support_floor` times
    /// their longest edge) because `support_factor` times their local edge
    /// gave a nearly flat neighbourhood ([`RAISE_BELOW_RCOND`]), ascending.
    pub fn raised_supports(&self) -> &[usize] {
        &self.raised
    }

    /// Mass-proportional damping rate in use (1/s).
    pub fn damping(&self) -> f64 {
        self.damping
    }

    /// Deformation gradient of node `i` at the current positions.
    pub fn deformation_gradient(&self, i: usize) -> Mat3 {
        self.el.deformation_gradient(i, &self.x)
    }

    /// Mesh node index of every surface particle (boundary vertices).
    pub fn surface_nodes(&self) -> &[usize] {
        &self.surface_nodes
    }

    /// Surface triangles, indices into [`Self::surface_positions`], normals out.
    pub fn surface_faces(&self) -> &[[usize; 3]] {
        &self.surface_faces
    }

    /// Surface particle positions mapped from the nodes by MLS (m).
    pub fn surface_positions(&self) -> Vec<Vec3> {
        self.mls.map(&self.x)
    }

    /// The MLS map from nodes to surface particles.
    pub fn mls(&self) -> &MlsMap {
        &self.mls
    }

    /// Largest distance between an MLS-mapped surface particle and the
    /// simulated node it sits on (m): the error the mapping adds on its own.
    pub fn surface_mapping_error(&self) -> f64 {
        self.surface_nodes
            .iter()
            .enumerate()
            .map(|(k, &i)| (self.mls.map_one(k, &self.x) - self.x[i]).norm())
            .fold(0.0, f64::max)
    }

    /// RMS and max distance (m) between each MLS-mapped surface particle
    /// and the simulated node it sits on, at the current configuration (the
    /// same distances as [`Self::surface_mapping_error`], which is their max).
    pub fn surface_mapping_errors(&self) -> MappingError {
        MappingError::of(
            self.surface_nodes
                .iter()
                .enumerate()
                .map(|(k, &i)| (self.mls.map_one(k, &self.x) - self.x[i]).norm()),
        )
    }

    /// The error the MLS surface mapping adds on its own for a known
    /// displacement field `u` (m of rest position -> m): nodes placed at
    /// `X_j + u(X_j)`, surface particles mapped from them and compared with
    /// the exact surface `X_s + u(X_s)`. Independent of the simulated state.
    /// Zero (to rounding) for affine `u`; `O(R^2)` for smooth `u`, `R` the
    /// MLS radius.
    pub fn mls_mapping_error_of(&self, u: impl Fn(&Vec3) -> Vec3) -> MappingError {
        let x: Vec<Vec3> = self.el.rest.iter().map(|p| p + u(p)).collect();
        MappingError::of(self.surface_nodes.iter().enumerate().map(|(k, &i)| {
            let xs = self.el.rest[i];
            (self.mls.map_one(k, &x) - (xs + u(&xs))).norm()
        }))
    }

    /// Stability limit of the explicit integrator at rest, `2 / omega_max`
    /// (s), with `omega_max^2` the largest eigenvalue of `M^-1 K` over the
    /// free components, estimated by `iters` power iterations (from below,
    /// so the returned step is an upper estimate of the limit).
    pub fn critical_dt(&self, iters: usize) -> f64 {
        let n = self.x.len();
        let mut cache = StateCache::default();
        self.el.prepare(&self.el.rest, &mut cache);
        let mut s = 0x2545F4914F6CDD1Du64;
        let mut q: Vec<Vec3> = (0..n)
            .map(|i| {
                let mut r = || {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                };
                Vec3::new(r(), r(), r()).component_mul(&self.axis_free[i])
            })
            .collect();
        let mut lam = 0.0;
        let mut kq = vec![Vec3::zeros(); n];
        for _ in 0..iters {
            kq.iter_mut().for_each(|v| *v = Vec3::zeros());
            self.el.add_hess_vec(&cache, &q, &mut kq);
            let (mut num, mut den) = (0.0, 0.0);
            for i in 0..n {
                num += q[i].dot(&kq[i]);
                den += self.mass[i] * q[i].norm_squared();
            }
            lam = num / den;
            let mut norm = 0.0;
            for i in 0..n {
                q[i] = (kq[i] / self.mass[i]).component_mul(&self.axis_free[i]);
                norm += self.mass[i] * q[i].norm_squared();
            }
            let norm = norm.sqrt();
            if !(norm > 0.0) {
                break;
            }
            q.iter_mut().for_each(|v| *v /= norm);
        }
        2.0 / lam.sqrt()
    }

    /// Signed volume of the virtual tets over their rest volume, minus one.
    fn volume_error(&self) -> f64 {
        let v: f64 = self
            .tets
            .iter()
            .map(|t| {
                let p = t.map(|i| self.x[i]);
                surgbench_core::mesh::tet_volume(&p[0], &p[1], &p[2], &p[3])
            })
            .sum();
        v / self.rest_volume - 1.0
    }

    fn check_state(&self) -> Option<String> {
        let lim = 10.0 * self.scale;
        for (i, p) in self.x.iter().enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                return Some(format!("node {i} is not finite"));
            }
            let u = (p - self.el.rest[i]).norm();
            if u > lim {
                return Some(format!(
                    "node {i} moved {u:.3e} m, 10x the body size {:.3e} m",
                    self.scale
                ));
            }
        }
        None
    }

    fn energies(&self) -> EnergyObs {
        let (u, hg) = self.el.energy(&self.x);
        let mut e = EnergyObs {
            elastic: u + hg + self.contact.as_ref().map_or(0.0, |c| c.energy(&self.x)),
            ..Default::default()
        };
        for i in 0..self.x.len() {
            e.kinetic += 0.5 * self.mass[i] * self.v[i].norm_squared();
            e.external -= (self.mass[i] * self.gravity + self.external[i]).dot(&self.x[i]);
        }
        e
    }
}
