//! Quasi-static equilibrium: load stepping with full Newton to tolerance
//! and a backtracking line search on the total potential energy.
//!
//! At load factor `s = k / load_steps` the prescribed displacements are
//! `s u_c` and the loads `s f`; Newton solves `f_el(x) + s f = 0` on the
//! free DOFs, where `f_el = -dE/dx` is the elastic force.

use crate::FemError;
use crate::assembly::{LinearSolver, System};
use crate::contact::SphereContact;
use crate::core::Solid;
use crate::element::Jacobian;
use crate::material::Law;
use surgbench_core::{SolidMaterial, TetMesh, Vec3};

/// A Dirichlet condition on some axes of one node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Constraint {
    /// Node index.
    pub node: usize,
    /// Which axes (x, y, z) are prescribed.
    pub axes: [bool; 3],
    /// Displacement at full load (m); only the prescribed axes are used.
    pub displacement: Vec3,
}

impl Constraint {
    /// Node held at its rest position.
    pub fn fixed(node: usize) -> Self {
        Self {
            node,
            axes: [true; 3],
            displacement: Vec3::zeros(),
        }
    }
    /// Node moved by `u` (m) at full load.
    pub fn displaced(node: usize, u: Vec3) -> Self {
        Self {
            node,
            axes: [true; 3],
            displacement: u,
        }
    }
    /// One axis (0 = x, 1 = y, 2 = z) of a node moved by `value` (m); the
    /// other axes stay free (e.g. a symmetry plane with `value = 0`).
    pub fn axis(node: usize, axis: usize, value: f64) -> Self {
        let mut axes = [false; 3];
        let mut d = Vec3::zeros();
        if axis < 3 {
            axes[axis] = true;
            d[axis] = value;
        }
        Self {
            node,
            axes,
            displacement: d,
        }
    }
}

/// External loads at full load factor (dead loads, rest configuration).
#[derive(Default)]
pub struct Loads<'a> {
    /// Body force density `b(X)` (N/m^3) at rest position `X` (e.g. `rho g`).
    pub body_force: Option<&'a (dyn Fn(&Vec3) -> Vec3 + Sync)>,
    /// Point forces on nodes (N), e.g. from [`pressure_loads`].
    pub nodal: Vec<(usize, Vec3)>,
}

/// Nodal forces (N) of a uniform pressure `p` (Pa) on triangles: each node
/// of a face gets `-p A n / 3` with `n` the face's outward unit normal
/// (faces as returned by `mesh::boundary_faces`; positive `p` pushes into
/// the body). Dead load on the rest geometry.
pub fn pressure_loads(mesh: &TetMesh, faces: &[[usize; 3]], p: f64) -> Vec<(usize, Vec3)> {
    let mut out = Vec::with_capacity(3 * faces.len());
    for f in faces {
        let [a, b, c] = f.map(|i| mesh.nodes[i]);
        let an = (b - a).cross(&(c - a)) * 0.5; // area-weighted outward normal
        for &i in f {
            out.push((i, -an * (p / 3.0)));
        }
    }
    out
}

/// Settings of [`solve_static`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticParams {
    /// Number of equal load increments.
    pub load_steps: usize,
    /// Newton stops when the free-DOF force residual is below `tol` times
    /// the largest of the step's first residual and the applied load (N/N).
    pub tol: f64,
    /// Newton iteration cap per load step.
    pub max_newton: usize,
    /// Linear solver for the Newton systems.
    pub solver: LinearSolver,
    /// Worker threads for assembly.
    pub threads: usize,
    /// Cholesky only, modified Newton: `true` solves with the last
    /// factorization (of an earlier iteration or load step) and skips the
    /// Jacobian while each such iteration cuts the force residual by at
    /// least [`MODIFIED_RATE`]; an iteration that does not goes back to
    /// full Newton at that point (Jacobian, fresh factorization). `false`
    /// factorizes at every iteration.
    pub factor_reuse: bool,
}

/// Modified Newton keeps the stale factorization while each of its
/// iterations cuts the force residual to at most this fraction: its
/// contraction rate is about `|I - K_0^-1 K|`, and a full Newton iteration
/// costs an element Jacobian and a factorization where a modified one
/// costs a force evaluation and two triangular solves (the factorization
/// and Jacobian are ~80 % of a full iteration on the Lamé tube at level
/// 2, perf), so a modified iteration that at least quarters the residual
/// is the cheaper way to the tolerance.
const MODIFIED_RATE: f64 = 0.25;

impl Default for StaticParams {
    fn default() -> Self {
        Self {
            load_steps: 1,
            tol: 1e-9,
            max_newton: 30,
            solver: LinearSolver::default(),
            threads: 2,
            factor_reuse: false,
        }
    }
}

/// What [`solve_static`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticInfo {
    /// Node displacements `x - X` (m).
    pub displacements: Vec<Vec3>,
    /// Force the constraints exert on the body at every node (N; zero at
    /// free DOFs): `-(f_el + f_ext)` on constrained DOFs.
    pub reactions: Vec<Vec3>,
    /// Newton iterations of every load step.
    pub newton_iterations: Vec<usize>,
    /// Final relative residual.
    pub residual: f64,
    /// Elastic energy at equilibrium (J).
    pub energy: f64,
    /// Inverted elements at equilibrium.
    pub inverted: usize,
    /// Total CG iterations (0 with Cholesky).
    pub linear_iterations: usize,
    /// Newton iterations that fell back from the exact Jacobian to a
    /// positive definite one (warped or projected).
    pub jacobian_fallbacks: usize,
}

/// Free-DOF mask and per-DOF prescribed displacement from constraints.
pub(crate) fn dof_conditions(n_nodes: usize, constraints: &[Constraint]) -> Result<(Vec<bool>, Vec<f64>), FemError> {
    let mut free = vec![true; 3 * n_nodes];
    let mut u = vec![0.0; 3 * n_nodes];
    for c in constraints {
        if c.node >= n_nodes {
            return Err(FemError::BadInput(format!(
                "constraint on node {} but the mesh has {n_nodes} nodes",
                c.node
            )));
        }
        if !c.displacement.iter().all(|v| v.is_finite()) {
            return Err(FemError::BadInput(format!(
                "constraint on node {} is not finite",
                c.node
            )));
        }
        for i in 0..3 {
            if c.axes[i] {
                free[3 * c.node + i] = false;
                u[3 * c.node + i] = c.displacement[i];
            }
        }
    }
    Ok((free, u))
}

/// Solve for static equilibrium of `mesh` (rest positions, m) made of
/// `material` with constitutive `law`, under `constraints` and `loads`.
///
/// Errors: bad input, a Newton step that does not converge, inverted
/// elements under the neo-Hookean law, or a failed linear solve.
///
/// ```
/// use surgbench_core::{mesh, SolidMaterial, Vec3};
/// use surgbench_fem::{solve_static, Constraint, Law, Loads, StaticParams};
/// let m = mesh::block(Vec3::new(0.01, 0.01, 0.01), [2, 2, 2]);
/// let mat = SolidMaterial { youngs_modulus: 1e4, poisson_ratio: 0.3, density: 1000.0 };
/// let mut c: Vec<Constraint> = mesh::nodes_on_plane(&m, 2, 0.0, 1e-12).into_iter().map(Constraint::fixed).collect();
/// c.extend(mesh::nodes_on_plane(&m, 2, 0.01, 1e-12).into_iter().map(|n| Constraint::displaced(n, Vec3::new(0.0, 0.0, -1e-4))));
/// let info = solve_static(&m, &mat, Law::Corotational, &c, &Loads::default(), &StaticParams::default()).unwrap();
/// assert!(info.residual < 1e-9);
/// ```
pub fn solve_static(
    mesh: &TetMesh,
    material: &SolidMaterial,
    law: Law,
    constraints: &[Constraint],
    loads: &Loads,
    params: &StaticParams,
) -> Result<StaticInfo, FemError> {
    solve_static_materials(
        mesh,
        std::slice::from_ref(material),
        &[],
        law,
        constraints,
        loads,
        params,
    )
}

/// [`solve_static`] for a body of several materials: tet `e` is made of
/// `materials[tet_material[e]]` (all of the first when `tet_material` is
/// empty; `TissueBody::tet_materials` gives both).
pub fn solve_static_materials(
    mesh: &TetMesh,
    materials: &[SolidMaterial],
    tet_material: &[usize],
    law: Law,
    constraints: &[Constraint],
    loads: &Loads,
    params: &StaticParams,
) -> Result<StaticInfo, FemError> {
    if params.load_steps == 0 || params.max_newton == 0 || !(params.tol > 0.0) {
        return Err(FemError::BadInput(format!(
            "StaticParams needs load_steps >= 1, max_newton >= 1, tol > 0: {params:?}"
        )));
    }
    let mut solid = Solid::with_materials(mesh, materials, tet_material, law, params.threads)?;
    let n = solid.n_nodes();
    let (free, uc) = dof_conditions(n, constraints)?;
    let mut fext = vec![Vec3::zeros(); n];
    if let Some(b) = loads.body_force {
        fext = solid.body_loads(b);
    }
    for &(i, f) in &loads.nodal {
        if i >= n || !f.iter().all(|v| v.is_finite()) {
            return Err(FemError::BadInput(format!(
                "nodal load {f:?} on node {i} (mesh has {n} nodes)"
            )));
        }
        fext[i] += f;
    }
    let mut sys = System::new(&solid.pat, free.clone());
    let rest = solid.rest.clone();
    let mut x = rest.clone();
    let mut iters = Vec::with_capacity(params.load_steps);
    let mut last = Newton::default();
    let mut fallbacks = 0;
    for step in 1..=params.load_steps {
        let s = step as f64 / params.load_steps as f64;
        for d in 0..3 * n {
            if !free[d] {
                x[d / 3][d % 3] = rest[d / 3][d % 3] + s * uc[d];
            }
        }
        let load: Vec<f64> = fext.iter().flat_map(|f| [f.x * s, f.y * s, f.z * s]).collect();
        last = equilibrate(&mut solid, &mut sys, &mut x, &load, None, None, params, step)?;
        fallbacks += last.fallbacks;
        iters.push(last.iterations);
    }
    let mut reactions = vec![Vec3::zeros(); n];
    for d in 0..3 * n {
        if !free[d] {
            reactions[d / 3][d % 3] = -last.r[d];
        }
    }
    Ok(StaticInfo {
        displacements: x.iter().zip(&rest).map(|(a, b)| a - b).collect(),
        reactions,
        newton_iterations: iters,
        residual: last.residual,
        energy: last.energy,
        inverted: last.inverted,
        linear_iterations: sys.cg_iterations,
        jacobian_fallbacks: fallbacks,
    })
}

/// Outcome of one [`equilibrate`] call.
#[derive(Debug, Clone, Default)]
pub(crate) struct Newton {
    pub iterations: usize,
    pub residual: f64,
    pub energy: f64,
    pub inverted: usize,
    pub fallbacks: usize,
    /// Numeric Cholesky factorizations (a fallback's second counts too).
    pub factorizations: usize,
    /// Final force residual `f_el + load` per DOF (N).
    pub r: Vec<f64>,
}

/// Configuration-dependent (follower) load per DOF (N) at positions `x`.
pub(crate) type Follower<'a> = &'a dyn Fn(&[Vec3]) -> Vec<f64>;

/// Full Newton for `f_el(x) + load + follower(x) + f_c(x) = 0` on the free
/// DOFs of `sys`; the constrained DOFs of `x` are already at their targets.
/// The follower load's derivative is left out of the Jacobian (it keeps the
/// system symmetric; Newton then converges linearly, at a rate set by
/// pressure over stiffness). The sphere contact's forces `f_c` and exact
/// Hessian ([`SphereContact`]) enter the residual, the Jacobian's diagonal
/// blocks and the line search's energy; with a contact the line search runs
/// for every law (the penalty's active set changes between iterations, and
/// the energy keeps Newton from cycling between two sets).
#[allow(clippy::too_many_arguments)]
pub(crate) fn equilibrate(
    solid: &mut Solid,
    sys: &mut System,
    x: &mut Vec<Vec3>,
    dead_load: &[f64],
    follower: Option<Follower>,
    contact: Option<&SphereContact>,
    params: &StaticParams,
    step: usize,
) -> Result<Newton, FemError> {
    let n = solid.n_nodes();
    let law = solid.mat.law;
    let rest = solid.rest.clone();
    let free = sys.free.clone();
    let zero_mass = vec![0.0; n];
    let mut out = Newton {
        r: vec![0.0; 3 * n],
        ..Default::default()
    };
    let jac = match law {
        Law::Linear => Jacobian::Warped,
        _ => Jacobian::Exact,
    };
    let total = |x: &[Vec3]| -> Vec<f64> {
        match follower {
            Some(f) => f(x).iter().zip(dead_load).map(|(a, b)| a + b).collect(),
            None => dead_load.to_vec(),
        }
    };
    let mut scale = free_norm(&total(x), &free);
    let mut it = 0;
    let mut prev_rn = f64::INFINITY;
    // Modified Newton from the start when a factorization is at hand, and
    // after each full iteration, until a modified iteration contracts too
    // slowly: from then on full Newton to the end of this solve (near a
    // limit point a stale factor is poorest, and full Newton's quadratic
    // convergence is what the solve needs there).
    let mut reuse = params.factor_reuse && matches!(params.solver, LinearSolver::Cholesky(_));
    let mut modified = reuse && sys.has_factorization();
    // Whether the last update was a full Newton iteration (the stall rule
    // below judges those only).
    let mut last_full = false;
    loop {
        let load = total(x);
        let load = &load[..];
        evaluate_residual(solid, x, load, contact, (!modified).then_some(jac), step, &mut out)?;
        let rn = free_norm(&out.r, &free);
        if it == 0 {
            // Force level of the body: the step's first residual, the load,
            // and the elastic forces on all DOFs (at the constrained ones,
            // the reactions). Without the last, a step whose load does not
            // change (first residual ~ round-off, no load) measured the
            // residual against round-off and could never converge.
            let all = solid.forces.iter().map(|f| f.norm_squared()).sum::<f64>().sqrt();
            scale = scale.max(rn).max(all);
        }
        out.residual = if scale > 0.0 { rn / scale } else { 0.0 };
        out.iterations = it;
        if !rn.is_finite() || (it >= params.max_newton && rn > params.tol * scale) {
            return Err(FemError::NotConverged {
                step,
                iterations: it,
                residual: out.residual,
            });
        }
        // Converged: under the tolerance, or stalled at the rounding floor.
        // The floor grows with the coordinates' magnitude (a block far from
        // the origin has fewer significant digits in x - X), so a stall
        // (no halving of the residual) already below 1e-5 of the load scale
        // counts as converged: it keeps the answer independent of where the
        // scene sits (rigid-motion conformance).
        // A modified Newton iteration that slows down is not a stall: it
        // hands over to full Newton below.
        let stalled = it >= 2 && last_full && rn >= 0.5 * prev_rn && rn <= 1e-5 * scale;
        if rn <= params.tol * scale || rn == 0.0 || stalled {
            return Ok(out);
        }
        if modified && rn > MODIFIED_RATE * prev_rn {
            // The stale factor no longer serves: full Newton from here.
            modified = false;
            reuse = false;
            evaluate_residual(solid, x, load, contact, Some(jac), step, &mut out)?;
        }
        prev_rn = rn;
        it += 1;
        last_full = !modified;
        let dx = if modified {
            let mut dx = out.r.clone();
            sys.solve_cholesky(&mut dx);
            dx
        } else {
            let dx = newton_update(solid, sys, x, contact, params, jac, &zero_mass, &mut out)?;
            modified = reuse;
            dx
        };
        let alpha = if law != Law::Linear || contact.is_some() {
            backtrack(solid, x, &dx, load, &rest, contact, &out)
        } else {
            1.0
        };
        *x = add_scaled(x, &dx, alpha);
    }
}

/// Euclidean norm of `v` over the free DOFs.
fn free_norm(v: &[f64], free: &[bool]) -> f64 {
    v.iter()
        .zip(free)
        .filter(|(_, f)| **f)
        .map(|(a, _)| a * a)
        .sum::<f64>()
        .sqrt()
}

/// Evaluate the body at `x` (with the Jacobian `jac`, if any) into `out`: energy
/// (contact included), inverted elements (an error for neo-Hookean) and
/// the force residual `r = f_el + load (+ f_c)` per DOF (N).
fn evaluate_residual(
    solid: &mut Solid,
    x: &[Vec3],
    load: &[f64],
    contact: Option<&SphereContact>,
    jac: Option<Jacobian>,
    step: usize,
    out: &mut Newton,
) -> Result<(), FemError> {
    let st = solid.evaluate(x, jac, 0.0);
    out.energy = st.energy + contact.map_or(0.0, |c| c.energy(x));
    out.inverted = st.inverted;
    if solid.mat.law == Law::NeoHookean && st.inverted > 0 {
        return Err(FemError::Inverted {
            step,
            elements: st.inverted,
        });
    }
    let r = &mut out.r;
    for i in 0..solid.n_nodes() {
        for a in 0..3 {
            r[3 * i + a] = solid.forces[i][a] + load[3 * i + a];
        }
    }
    if let Some(c) = contact {
        c.add_forces(x, r);
    }
    Ok(())
}

/// The Newton update `dx` solving `K dx = r` for the residual `out.r`, with
/// the elastic Jacobian plus the contact blocks when a node touches. An
/// indefinite exact Hessian falls back to the projected one for this
/// iteration (counted in `out.fallbacks`).
#[allow(clippy::too_many_arguments)]
fn newton_update(
    solid: &mut Solid,
    sys: &mut System,
    x: &[Vec3],
    contact: Option<&SphereContact>,
    params: &StaticParams,
    jac: Jacobian,
    zero_mass: &[f64],
    out: &mut Newton,
) -> Result<Vec<f64>, FemError> {
    let n = solid.n_nodes();
    let r = &out.r;
    let mut kc = contact.and_then(|c| c.add_to(&solid.kmat, &solid.pat.diag, x, false));
    let mut dx = r.clone();
    match params.solver {
        LinearSolver::Cholesky(ord) => {
            sys.set_values(&solid.pat, kc.as_deref().unwrap_or(&solid.kmat), 1.0, zero_mass, 0.0);
            out.factorizations += 1;
            if let Err(e) = sys.factorize(&solid.pat, ord) {
                if jac != Jacobian::Exact {
                    return Err(FemError::LinearSolver(e));
                }
                // Indefinite exact Hessian: for this iteration only,
                // clamp each element's negative eigenvalues (keeps the
                // curvature of the rotation and volume terms). The
                // warped stiffness `R K0 R^T` drops
                // `(lambda tr(S - I) - 2 mu) dR`, which for nu -> 1/2
                // under compression is large: Newton then crawled (rate
                // ~0.8 per iteration at nu = 0.499) and failed the
                // truth-cube scene at 12.5 % compression. The next
                // iteration tries the exact Hessian again (quadratic
                // convergence once it is positive definite: see
                // tests/issue_newton_exact_after_fallback.rs).
                solid.evaluate(x, Some(Jacobian::Projected), 0.0);
                out.fallbacks += 1;
                kc = contact.and_then(|c| c.add_to(&solid.kmat, &solid.pat.diag, x, true));
                sys.set_values(&solid.pat, kc.as_deref().unwrap_or(&solid.kmat), 1.0, zero_mass, 0.0);
                out.factorizations += 1;
                sys.factorize(&solid.pat, ord).map_err(FemError::LinearSolver)?;
            }
            sys.solve_cholesky(&mut dx);
        }
        LinearSolver::Cg { tol, max_iter } => {
            sys.set_values(&solid.pat, kc.as_deref().unwrap_or(&solid.kmat), 1.0, zero_mass, 0.0);
            let mut sol = vec![0.0; 3 * n];
            let pat = &solid.pat;
            let kmat = kc.as_deref().unwrap_or(&solid.kmat);
            solid.install(|| sys.solve_cg(pat, kmat, 1.0, zero_mass, 0.0, r, &mut sol, tol, max_iter));
            dx = sol;
        }
    }
    Ok(dx)
}

/// Backtracking on `Pi(x) = E(x) - load . (x - X)` along `dx` from the
/// state of `out` (energy, residual); the slope along `dx` is `-r . dx < 0`
/// for a positive definite Jacobian. Returns the step fraction.
fn backtrack(
    solid: &mut Solid,
    x: &[Vec3],
    dx: &[f64],
    load: &[f64],
    rest: &[Vec3],
    contact: Option<&SphereContact>,
    out: &Newton,
) -> f64 {
    let mut alpha = 1.0;
    let pi0 = out.energy - dot_disp(load, x, rest);
    let slope = -out.r.iter().zip(dx).map(|(a, b)| a * b).sum::<f64>();
    for _ in 0..20 {
        let xt = add_scaled(x, dx, alpha);
        let e = solid.evaluate(&xt, None, 0.0).energy + contact.map_or(0.0, |c| c.energy(&xt));
        let pi = e - dot_disp(load, &xt, rest);
        if pi.is_finite() && pi <= pi0 + 1e-4 * alpha * slope + 1e-12 * pi0.abs() {
            break;
        }
        alpha *= 0.5;
    }
    alpha
}

fn add_scaled(x: &[Vec3], dx: &[f64], a: f64) -> Vec<Vec3> {
    x.iter()
        .enumerate()
        .map(|(i, p)| p + Vec3::new(dx[3 * i], dx[3 * i + 1], dx[3 * i + 2]) * a)
        .collect()
}

fn dot_disp(load: &[f64], x: &[Vec3], rest: &[Vec3]) -> f64 {
    let mut s = 0.0;
    for i in 0..x.len() {
        let u = x[i] - rest[i];
        s += load[3 * i] * u.x + load[3 * i + 1] * u.y + load[3 * i + 2] * u.z;
    }
    s
}
