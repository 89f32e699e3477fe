//! `wall-indentation`: a rigid frictionless sphere (a catheter tip)
//! pushed into a vessel-wall sector; force, contact extent and wall
//! displacement against the scikit-fem contact reference.

use super::*;
use crate::params;
use crate::references::WallReference;
use crate::scenario::{Declared, Inputs, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, UsageError};
use surgbench_core::{Family, Observation, Scene, TetMesh, TissueBody, Vec3};

/// Cells `(n_r, n_s)` of the quarter wall mesh at `level`: `2^(level+1)`
/// through the wall and twice that along the arc and along z, so each level
/// has 8x the tets of the one before (192, 1,536, 12,288, 98,304) and the
/// band cells are `band / n_r` (0.25, 0.125, 0.0625, 0.031 mm).
pub fn wall_sphere_cells(level: usize) -> (usize, usize) {
    (2 << level, 4 << level)
}

/// The quarter wall (`y >= 0`, `z >= length/2`) at `level`: the structured
/// block on the unit cube, node `(xi_r, xi_s, xi_z)` mapped to `r = a + t
/// expm1(kappa xi_r) / expm1(kappa)`, arc `s = rho(xi_s)` on the inner wall
/// (`theta = s / a`) and `z = length/2 + rho(xi_z)` ([`WallReference::grading`]):
/// the reference's own map with fewer cells.
pub fn wall_sphere_mesh(r: &WallReference, level: usize) -> TetMesh {
    let (n_r, n_s) = wall_sphere_cells(level);
    let mut m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [n_r, n_s, n_s]);
    let t = r.outer_radius - r.inner_radius;
    let k = r.radial_grading;
    let (arc, half) = (0.5 * r.inner_radius * r.sector_angle, 0.5 * r.length);
    for p in &mut m.nodes {
        let rad = r.inner_radius + t * (k * p.x).exp_m1() / k.exp_m1();
        let th = r.grading(p.y, arc) / r.inner_radius;
        *p = Vec3::new(rad * th.cos(), rad * th.sin(), half + r.grading(p.z, half));
    }
    mesh::orient_positive(&mut m);
    m
}

/// Young's modulus of the vessel-wall scenes (`wall-indentation`, `wall-punch`).
pub(super) const WALL_E: ParamSpec = ParamSpec::new(
    "youngs_modulus",
    1e6,
    "Pa",
    Range::Positive,
    "Young's modulus (arterial wall order of magnitude, Holzapfel et al. 2000)",
);
/// Density of the vessel-wall scenes.
pub(super) const WALL_DENSITY: ParamSpec = ParamSpec::new(
    "density",
    1060.0,
    "kg/m^3",
    Range::Positive,
    "density of the vessel wall",
);

params! {
    /// Parameters of `wall-indentation`.
    ///
    /// Geometry, `E`'s reference value and `nu` come from the reference; the
    /// depth is bounded by the reference's curve (1-20 % of the wall thickness).
    pub struct WallParams {
        depth: ParamSpec::new(
            "depth",
            1e-4,
            "m",
            Range::Positive,
            "sphere travel into the wall at the end of the ramp, 1e-5..2e-4 (1-20 % of the 1 mm wall, the reference's range)",
        ),
        youngs_modulus: WALL_E,
        density: WALL_DENSITY,
        ramp_time: RAMP,
        duration: DURATION,
        settle_tol: ParamSpec::new(
            "settle_tol",
            4e-6,
            "m/s",
            Range::Positive,
            "static equilibrium when every node is slower than this (after the ramp; ~1 % of the ramp's mean speed at the default depth)",
        ),
    }
}

struct WallSphereRun {
    mesh: TetMesh,
    depth: f64,
    force_ref: f64,
    extent_ref: f64,
    radius: f64,
    /// Inner-wall nodes (rest positions on `r = a`).
    inner: Vec<usize>,
    /// `(containing tet, weights, radial direction, reference u_r (m))` of
    /// each profile probe.
    probes: Vec<(usize, [f64; 4], Vec3, f64)>,
    reference: WallReference,
    e_scale: f64,
}

impl WallSphereRun {
    /// Indentation force on the whole sphere (N): four quarters, the body
    /// pushes the sphere back along `-x`.
    fn force(obs: &Observation) -> f64 {
        -4.0 * obs.hand_force.x
    }
}

impl ForceCurve for WallSphereRun {
    fn full_depth(&self) -> f64 {
        self.depth
    }
    fn metrics(&self, scene: &Scene, obs: &Observation) -> Option<Metrics> {
        let mut m = Metrics::new();
        let (Some(t), Some(c)) = (tissue_of(obs, &self.mesh), indenter_centre(scene, obs.time)) else {
            return None;
        };
        let f = Self::force(obs);
        force_metrics(&mut m, f, self.force_ref);
        let (mut pen, mut extent) = (0.0f64, 0.0f64);
        let zc = 0.5 * self.reference.length;
        for &i in &self.inner {
            let gap = (t.nodes[i] - c).norm() - self.radius;
            pen = pen.max(-gap);
            // Touching: inside, or on the sphere to round-off.
            if gap <= 1e-9 * self.radius {
                extent = extent.max(self.mesh.nodes[i].z - zc);
            }
        }
        m.insert("penetration_over_depth".into(), pen / self.depth);
        m.insert("contact_extent_z_m".into(), extent);
        m.insert("reference_contact_extent_z_m".into(), self.extent_ref);
        let radial = self
            .probes
            .iter()
            .map(|(e, w, dir, want)| (probe_displacement(&self.mesh, t, *e, w).dot(dir), *want));
        surface_metrics(&mut m, radial, self.depth);
        common_metrics(&mut m, &self.mesh, t);
        Some(m)
    }
    fn curve_point(&self, scene: &Scene, obs: &Observation) -> Option<(f64, f64)> {
        let s = scene.control.command_at(obs.time).load;
        // The reference at this step's depth; none below its first row.
        let want = self.reference.force(s * self.depth, self.e_scale)?;
        Some((Self::force(obs), want))
    }
}

/// A spherical catheter tip indenting a vessel-wall segment.
///
/// The scene: a rigid frictionless sphere of radius `R` (1 mm: a 6F
/// catheter is 2 mm across) inside the lumen touches the inner wall at
/// `theta = 0, z = length/2` and moves radially outward (`+x`) by `depth`
/// along the load ramp ([`TissueBody::indenter`], so it needs
/// `Capability::TissueContact`); the contact footprint grows with the
/// depth. One quarter is modelled (`y >= 0`, `z >= length/2`) with rollers
/// on the symmetry planes (`y` held on `y = 0`, `z` on `z = length/2`), the
/// far end and the straight edge clamped, the outer surface free; the mesh
/// ([`wall_sphere_mesh`]) is the reference's graded map. Geometry and
/// material as [`WALL_PUNCH`] (inner radius 4 mm, wall 1 mm, 120 deg sector
/// 8 mm long, `E = 1 MPa`, `nu = 0.45`, Holzapfel, Gasser & Ogden 2000).
///
/// The model reports the force the body exerts on the sphere as
/// `hand_force`; the full force is `-4 hand_force.x`. Scores against the
/// scikit-fem reference ([`WallReference`]): `force_error_rel` (primary)
/// at full depth, `force_curve_error_rel` (RMS over the ramp against the
/// reference at every step's depth `s depth`, accumulated in
/// [`Scorer::observe_step`](crate::Scorer::observe_step)), `surface_error_rel` (the inner wall's
/// radial displacement along the axial line through the tip and around the
/// circumferential line through it, RMS error over RMS reference),
/// `penetration_over_depth` (deepest inner-wall node inside the sphere) and
/// `contact_extent_z_m` beside the reference's (the farthest inner-wall
/// node along z touching the sphere: a cell's resolution).
pub const WALL_INDENTATION: Declared<WallParams> = Declared {
    info: ScenarioInfo {
        id: "wall-indentation",
        description: "vessel-wall sector (r 4-5 mm, quarter) indented by a rigid frictionless sphere (catheter tip, R 1 mm): force-depth curve, deformed inner wall, contact extent",
        family: Family::Tissue,
        reference: "scikit-fem P2, LINEAR elasticity, frictionless unilateral contact with the exact gap (datasets/reference/wall-indentation)",
        primary_error: "force_error_rel",
        target: crate::scenario::Target::new(
            0.05,
            "5 % of the reference force: the project's default for tissue forces",
        ),
        params: WallParams::SPECS,
        sweep: CONTACT_LEVELS,
        quick: 2,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &WallParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let level = mesh_level(WALL_INDENTATION.info.id, inputs.fidelity)?;
    let r = WallReference::load(inputs.datasets)?;
    let (depth, e) = (p.depth, p.youngs_modulus);
    let (lo, hi) = r.depth_range();
    let (Some(force_ref), Some(extent_ref), Some(profile)) =
        (r.force(depth, e), r.contact_extent(depth), r.profile(depth))
    else {
        return Err(UsageError(format!(
            "wall-indentation: depth {depth} m is outside the reference's [{lo}, {hi}] m"
        )));
    };
    let mesh = wall_sphere_mesh(&r, level);
    let (a, half_angle, zc) = (r.inner_radius, 0.5 * r.sector_angle, 0.5 * r.length);
    let tol = 1e-9 * r.outer_radius;
    let mut body = TissueBody::new(mesh.clone(), material(p.youngs_modulus, p.density, r.poisson_ratio));
    body.fixed_nodes = mesh::nodes_where(&mesh, |x| x.y.atan2(x.x) >= half_angle - 1e-9 || x.z >= r.length - tol);
    body.partial_fixed = rollers(&mesh, &body.fixed_nodes, |x| {
        [false, x.y <= tol, (x.z - zc).abs() <= tol]
    });
    body.indenter = Some(surgbench_core::scene::SphereIndenter {
        centre: Vec3::new(a - r.tip_radius, 0.0, zc),
        radius: r.tip_radius,
        travel: Vec3::new(depth, 0.0, 0.0),
    });
    let inner = mesh::nodes_on_cylinder(&mesh, a, tol);
    // Probes mirrored onto the quarter, a hair inside the wall, the
    // clamped ends pulled in by 1e-9 of their extent (as the script).
    let rp = a * (1.0 + 1e-9);
    let probes = profile
        .iter()
        .map(|&(line, coord, want)| {
            let (x, dir) = if line == 0 {
                let z = (zc + (coord - zc).abs()).min(r.length * (1.0 - 1e-9));
                (Vec3::new(rp, 0.0, z), Vec3::x())
            } else {
                let th = coord.abs().min(half_angle * (1.0 - 1e-9));
                let dir = Vec3::new(th.cos(), th.sin(), 0.0);
                (rp * dir + Vec3::new(0.0, 0.0, zc), dir)
            };
            let (e, w) = locate(&mesh, &x).expect("wall mesh has tets");
            (e, w, dir, want)
        })
        .collect();
    let scene = static_scene(WALL_INDENTATION.info.id, body, p.ramp_time, p.duration, p.settle_tol)?;
    // The work is below F depth (the force grows with the depth).
    let (work, length) = (force_ref * depth, r.length);
    let run = WallSphereRun {
        mesh,
        depth,
        force_ref,
        extent_ref,
        radius: r.tip_radius,
        inner,
        probes,
        e_scale: e,
        reference: r,
    };
    Ok(ScenarioRun::new(scene, Curve(run), work, length))
}
