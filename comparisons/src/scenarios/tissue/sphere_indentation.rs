//! `sphere-indentation`: a rigid sphere pressed into a block; force and
//! contact radius against Hertz.

use super::*;
use crate::params;
use crate::references::{hertz_contact_radius, hertz_force, sphere_force_exact};
use crate::scenario::{Declared, Inputs, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, UsageError};
use surgbench_core::{Family, Observation, Scene, TetMesh, TissueBody, Vec3};

/// Where the contact radius sits in the graded mesh's reference coordinate
/// `s` (0..1): it spans `3 n / 8` cells of a mesh with `n` cells per edge.
const SPHERE_A_AT: f64 = 0.375;
/// End of the uniform inner zone of the grading (reference coordinate).
const SPHERE_UNIFORM_TO: f64 = 0.5;

/// The grading map of the quarter block (see [`sphere_block_mesh`]): radius
/// `rho(s)` (m) of the cube shell at reference max-norm `s` in `[0, 1]`:
/// `rho = c s` for `s <= 1/2` (uniform cells of size `c / n`), then
/// `c s + (W - c) ((s - 1/2) / (1/2))^2` up to `rho(1) = W`; `c = a / (3/8)`
/// puts the Hertz contact radius `a` at `s = 3/8`.
pub fn sphere_grading(s: f64, a: f64, half_width: f64) -> f64 {
    let c = a / SPHERE_A_AT;
    let t = ((s - SPHERE_UNIFORM_TO) / (1.0 - SPHERE_UNIFORM_TO)).max(0.0);
    c * s + (half_width - c) * t * t
}

/// Quarter block `[0, W]^2 x [-W, 0]` (m) for a sphere pressed into its top
/// face `z = 0` at the corner `x = y = 0` (the symmetry axis), with
/// `n` cells per edge graded towards the contact: the structured block on
/// the unit cube, node `xi` (depth `zeta = xi_z`) moved to
/// `(xi_x, xi_y, -zeta) rho(s) / s` with `s = max(xi_x, xi_y, zeta)` and
/// `rho` = [`sphere_grading`]. Cube shells `s = const` map to cube shells,
/// so faces stay planar; cells are cubes of size `a / (3 n / 8)` inside
/// `s <= 1/2` (twice the contact radius) and grow outside, radially up to
/// `rho'(1) / rho(1) < 4 + c / W` times their tangential size. The map's
/// kinks (`xi_i = xi_j`) are planes of the Kuhn split, so every tet is the
/// image of one smooth piece.
pub fn sphere_block_mesh(a: f64, half_width: f64, n: usize) -> TetMesh {
    let mut m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [n, n, n]);
    for p in &mut m.nodes {
        let s = p.x.max(p.y).max(p.z);
        let f = if s > 0.0 {
            sphere_grading(s, a, half_width) / s
        } else {
            0.0
        };
        *p = Vec3::new(p.x * f, p.y * f, -p.z * f);
    }
    mesh::orient_positive(&mut m);
    m
}

params! {
    /// Parameters of `sphere-indentation`.
    pub struct SphereParams {
        sphere_radius: ParamSpec::new(
            "sphere_radius",
            1e-3,
            "m",
            Range::Positive,
            "indenter radius (a 6F catheter tip is 1 mm in radius)",
        ),
        depth: ParamSpec::new(
            "depth",
            1e-5,
            "m",
            Range::Positive,
            "indentation at the end of the ramp, <= 0.05 sphere_radius (Hertz is a small-strain theory; default delta/R = 0.01)",
        ),
        youngs_modulus: ParamSpec::new(
            "youngs_modulus",
            1e4,
            "Pa",
            Range::Positive,
            "Young's modulus (soft tissue, 10 kPa)",
        ),
        poisson_ratio: ParamSpec::new(
            "poisson_ratio",
            0.3,
            "1",
            Range::Closed(0.0, 0.45),
            "Poisson ratio (linear tets lock as it nears 1/2)",
        ),
        size_ratio: ParamSpec::new(
            "size_ratio",
            50.0,
            "1",
            Range::Closed(5.0, 500.0),
            "block half-width and depth over the Hertz contact radius sqrt(R delta)",
        ),
        density: DENSITY,
        ramp_time: RAMP,
        duration: DURATION,
        settle_tol: SETTLE,
    }
}

struct SphereRun {
    mesh: TetMesh,
    radius: f64,
    depth: f64,
    /// Hertz force on the whole sphere at full depth (N).
    force_ref: f64,
    contact_radius: f64,
    paraboloid_bias: f64,
    /// Top-surface nodes on the `y = 0` line, by rest `x`.
    line: Vec<usize>,
    top: Vec<usize>,
}

impl SphereRun {
    /// Force on the whole sphere (N): four quarters, the body pushes up.
    fn force(obs: &Observation) -> f64 {
        4.0 * obs.hand_force.z
    }
}

impl ForceCurve for SphereRun {
    fn full_depth(&self) -> f64 {
        self.depth
    }
    fn metrics(&self, scene: &Scene, obs: &Observation) -> Option<Metrics> {
        let mut m = Metrics::new();
        let t = tissue_of(obs, &self.mesh)?;
        let c = indenter_centre(scene, obs.time)?;
        let f = Self::force(obs);
        force_metrics(&mut m, f, self.force_ref);
        m.insert("paraboloid_bias_rel".into(), self.paraboloid_bias);
        let pen = self
            .top
            .iter()
            .map(|&i| self.radius - (t.nodes[i] - c).norm())
            .fold(0.0, f64::max);
        m.insert("penetration_over_depth".into(), pen / self.depth);
        // Contact edge on the y = 0 line: between the last node inside (or
        // on) the sphere and the next one, by deformed distance from the axis.
        let inside: Vec<bool> = self
            .line
            .iter()
            .map(|&i| (t.nodes[i] - c).norm() <= self.radius)
            .collect();
        if let Some(k) = inside.iter().rposition(|&b| b)
            && k + 1 < self.line.len()
        {
            let (x0, x1) = (t.nodes[self.line[k]].x, t.nodes[self.line[k + 1]].x);
            let a_h = 0.5 * (x0 + x1);
            m.insert(
                "contact_radius_error_rel".into(),
                (a_h - self.contact_radius).abs() / self.contact_radius,
            );
            m.insert(
                "contact_radius_resolution_rel".into(),
                0.5 * (x1 - x0) / self.contact_radius,
            );
        }
        common_metrics(&mut m, &self.mesh, t);
        Some(m)
    }
    fn curve_point(&self, scene: &Scene, obs: &Observation) -> Option<(f64, f64)> {
        let s = scene.control.command_at(obs.time).load;
        // Hertz along the ramp: F(s) = F_ref s^(3/2) at depth s delta.
        let want = self.force_ref * s.max(0.0).powf(1.5);
        Some((Self::force(obs), want))
    }
}

/// A rigid sphere pressed into the flat top of a large block: Hertz.
///
/// The catheter tip, in its textbook form: a rigid frictionless
/// sphere of radius `R` (the scene's [`surgbench_core::scene::SphereIndenter`],
/// so it needs `Capability::TissueContact`) touches the top face `z = 0` of
/// a block at the origin and moves down by `depth` (`delta`) along the
/// ramp. One quarter is modelled: the block is `[0, W]^2 x [-W, 0]` with
/// `W = size_ratio a` (`a = sqrt(R delta)` the Hertz contact radius),
/// rollers on the symmetry planes `x = 0` (x held) and `y = 0` (y held),
/// the bottom `z = -W` fixed, the outer sides free. The mesh
/// ([`sphere_block_mesh`]) is graded: uniform cubes of size `a / (3 n / 8)`
/// out to `2a` (the contact radius spans 1.5, 3, 6, 12 cells at mesh levels
/// 0-3), growing outside.
///
/// The model reports the force the body exerts on the sphere as
/// `hand_force`; the scene is a quarter, so the full force is
/// `4 hand_force.z`. Scores: `force_error_rel` (primary) at full depth
/// against Hertz ([`hertz_force`]), `force_curve_error_rel` (RMS over the
/// ramp against `F_H(s delta)` at every step's load factor `s`, accumulated
/// in [`Scorer::observe_step`](crate::Scorer::observe_step)), `contact_radius_error_rel` (the
/// contact edge located between the last touching and first free surface
/// node on the `y = 0` line, so resolved to half a cell:
/// `contact_radius_resolution_rel` says how much), `penetration_over_depth`
/// (deepest surface node inside the sphere), and
/// `paraboloid_bias_rel` (the exact-sphere force of
/// [`sphere_force_exact`] over Hertz, minus one: the part of the error that
/// is Hertz's, not the model's).
///
/// Expected biases of Hertz against an exact solution of this scene (all
/// make the block stiffer than Hertz, except the free sides and the
/// sphere): the paraboloid, `-delta / (10 R)` to first order (`-0.1 %` at
/// the default `delta / R = 0.01`); the finite depth, a layer bonded to a rigid base is
/// stiffer by `1 + 0.88 a / h + ...` at `nu = 0.3` (Dimitriadis et al.
/// 2002, Biophys. J. 82, eq. 12, with `h = W`: `+1.8 %` at `W = 50 a`);
/// finite strain (the default corotational law; strains ~ `a / R`): of
/// order `a / R = 10 %` times a small constant — the linear law
/// (`material_law = "linear"`) removes it. Measured values are in
/// `comparisons/tests/sphere_indentation.rs`.
pub const SPHERE_INDENTATION: Declared<SphereParams> = Declared {
    info: ScenarioInfo {
        id: "sphere-indentation",
        description: "rigid frictionless sphere (R 1 mm) pressed into a large block (quarter, graded mesh): contact force and radius",
        family: Family::Tissue,
        reference: "Hertz 1882 (Johnson 1985 eq. 4.22-4.23): F = 4/3 E* sqrt(R) delta^1.5, a = sqrt(R delta); biased by the finite block (+~2 %) and the paraboloid (-0.1 %)",
        primary_error: "force_error_rel",
        target: crate::scenario::Target::new(0.05, "5 % of the Hertz force: the project's default for tissue forces"),
        params: SphereParams::SPECS,
        sweep: CONTACT_LEVELS,
        quick: 2,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &SphereParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let level = mesh_level(SPHERE_INDENTATION.info.id, inputs.fidelity)?;
    let (radius, depth, e, nu) = (p.sphere_radius, p.depth, p.youngs_modulus, p.poisson_ratio);
    if depth > 0.05 * radius {
        return Err(UsageError(format!(
            "sphere-indentation: depth {depth} m is past 0.05 sphere_radius ({} m): Hertz is a small-strain theory",
            0.05 * radius
        )));
    }
    let a = hertz_contact_radius(radius, depth);
    let w = p.size_ratio * a;
    let n = block_cells(level);
    let mesh = sphere_block_mesh(a, w, n);
    let tol = 1e-9 * w;
    let mut body = TissueBody::new(mesh.clone(), material(p.youngs_modulus, p.density, nu));
    body.fixed_nodes = mesh::nodes_on_plane(&mesh, 2, -w, tol);
    body.partial_fixed = rollers(&mesh, &body.fixed_nodes, |x| {
        [x.x.abs() <= tol, x.y.abs() <= tol, false]
    });
    body.indenter = Some(surgbench_core::scene::SphereIndenter {
        centre: Vec3::new(0.0, 0.0, radius),
        radius,
        travel: Vec3::new(0.0, 0.0, -depth),
    });
    let top = mesh::nodes_on_plane(&mesh, 2, 0.0, tol);
    let mut line: Vec<usize> = top.iter().copied().filter(|&i| mesh.nodes[i].y.abs() <= tol).collect();
    line.sort_by(|&i, &j| mesh.nodes[i].x.total_cmp(&mesh.nodes[j].x));
    let force_ref = hertz_force(radius, depth, e, nu);
    let paraboloid_bias = sphere_force_exact(radius, depth, e, nu).0 / force_ref - 1.0;
    let scene = static_scene(SPHERE_INDENTATION.info.id, body, p.ramp_time, p.duration, p.settle_tol)?;
    // Hertz work (2/5) F delta on the quarter, with a factor 10 of room.
    let work = force_ref * depth;
    let run = SphereRun {
        mesh,
        radius,
        depth,
        force_ref,
        contact_radius: a,
        paraboloid_bias,
        line,
        top,
    };
    Ok(ScenarioRun::new(scene, Curve(run), work, w))
}

/// Time step of the sphere-indentation sweep (s): 8 quasi-static load
/// increments over the default 0.25 s ramp (the load factor is sampled at
/// the steps; the force curve is scored at each).
pub const SPHERE_DT: f64 = 1.0 / 32.0;
