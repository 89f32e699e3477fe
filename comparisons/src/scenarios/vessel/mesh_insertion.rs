//! `vessel-mesh-insertion`: a guidewire pushed into a lumen given as a
//! closed triangle surface — the built-in bent tube, or a user's STL/OBJ
//! vessel (`run-one --mesh FILE`). The surface becomes a voxel signed
//! distance (exact distances from parry3d sampled on a grid, read by
//! tricubic interpolation: cheap per query, and C1 for Newton solvers), and the
//! wire is fed from a clamp at the entry point along the entry direction.
//!
//! No reference solution exists for an arbitrary vessel, so the scores are
//! the ones that hold in any lumen: how deep the wire's surface goes past
//! the wall (0 for exact contact), hand force, how far the tip got. On the
//! built-in tube the tip's progress along the known centreline is scored
//! too, and the voxel grid's own error against the analytic tube.

use super::*;
use crate::params;
use crate::scenario::{
    Declared, Inputs, MeshKind, Metrics, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, Sweep, UsageError,
};
use std::sync::Arc;
use surgbench_core::Family;
use surgbench_core::io::TriSurface;
use surgbench_core::sdf::{CenterlineBuilder, CubicVoxelSdf, SweptTube, VoxelSdf, frame_along};

/// Lumen radius of the built-in tube (m): a 4 mm vessel (iliac/renal-like
/// calibre at the small end; the scene is geometric, not anatomical).
const TUBE_RADIUS: f64 = 2e-3;
/// The built-in tube's first straight (m), along +x from the origin.
const TUBE_STRAIGHT: f64 = 0.05;
/// Centreline radius (m) of its 90 degree bend towards +y.
const TUBE_BEND: f64 = 0.02;
/// Its exit straight (m).
const TUBE_EXIT: f64 = 0.03;

params! {
    /// Parameters of `vessel-mesh-insertion`.
    pub struct MeshInsertionParams {
        wire_radius: P_WIRE_RADIUS,
        body_youngs_modulus: P_BODY_E,
        tip_youngs_modulus: P_TIP_E,
        tip_length: P_TIP_LEN,
        density: P_DENSITY,
        poisson_ratio: P_POISSON,
        friction_static: P_MU_S,
        friction_dynamic: P_MU_D,
        gravity: P_GRAVITY,
        insertion_speed: ParamSpec::new("insertion_speed", 0.02, "m/s", Range::Positive, "constant feed speed"),
        initial_length: ParamSpec::new(
            "initial_length",
            0.04,
            "m",
            Range::Positive,
            "free wire length at t = 0, straight from the clamp along the entry direction",
        ),
        duration: ParamSpec::new("duration", 2.0, "s", Range::Positive, "simulated time (feed = speed x duration)"),
        entry_x: ParamSpec::new("entry_x", 5e-3, "m", Range::Any, "clamp position at t = 0, x (inside the lumen)"),
        entry_y: ParamSpec::new("entry_y", 0.0, "m", Range::Any, "clamp position, y"),
        entry_z: ParamSpec::new("entry_z", 0.0, "m", Range::Any, "clamp position, z"),
        entry_dir_x: ParamSpec::new("entry_dir_x", 1.0, "1", Range::Any, "feed direction, x (normalised)"),
        entry_dir_y: ParamSpec::new("entry_dir_y", 0.0, "1", Range::Any, "feed direction, y"),
        entry_dir_z: ParamSpec::new("entry_dir_z", 0.0, "1", Range::Any, "feed direction, z"),
        voxel_spacing: ParamSpec::new(
            "voxel_spacing",
            0.5e-3,
            "m",
            Range::Positive,
            "grid spacing of the voxel distance field built from the surface (tricubic: error O(spacing^3) away from the centreline)",
        ),
    }
}

/// The built-in lumen: 50 mm straight along +x, a 90 degree bend of 20 mm
/// centreline radius towards +y, 30 mm straight; 2 mm lumen radius.
pub fn builtin_tube() -> SweptTube {
    CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(TUBE_STRAIGHT)
        .arc(TUBE_BEND, PI / 2.0, Vec3::y())
        .line(TUBE_EXIT)
        .build_constant(TUBE_RADIUS)
        .expect("static tube geometry is valid")
}

/// The built-in tube as the closed surface a user's file would give: 48
/// vertices per ring, rings at most 0.5 mm apart, flat end caps.
pub fn builtin_surface() -> TriSurface {
    builtin_tube()
        .to_mesh(48, 0.5e-3)
        .expect("static tube geometry is valid")
}

struct MeshRun {
    wire_radius: f64,
    /// The analytic centreline, on the built-in tube only.
    tube: Option<SweptTube>,
    /// Voxel grid error against the analytic tube (m), built-in tube only.
    grid_error: Option<f64>,
}

/// Run-wide sums: where the tip started, how far it travelled.
#[derive(Default)]
struct MeshSums {
    start: Option<Vec3>,
    last: Option<Vec3>,
    travel: f64,
}

impl Trajectory for MeshRun {
    type Sums = MeshSums;
    fn wire_radius(&self) -> f64 {
        self.wire_radius
    }
    fn add(&self, sums: &mut MeshSums, _obs: &Observation, tip: &Vec3) {
        sums.start.get_or_insert(*tip);
        if let Some(last) = sums.last {
            sums.travel += (tip - last).norm();
        }
        sums.last = Some(*tip);
    }
    fn metrics(&self, sums: &MeshSums, common: &Common, _obs: &Observation, tip: &Vec3, m: &mut Metrics) {
        m.insert("penetration_rel".into(), common.max_penetration / self.wire_radius);
        m.insert("tip_path_m".into(), sums.travel);
        if let Some(s) = sums.start {
            m.insert("tip_displacement_m".into(), (tip - s).norm());
        }
        if let Some(tube) = &self.tube {
            let s = tube.project(tip).s;
            m.insert("tip_progress_m".into(), s);
            m.insert(
                "past_bend".into(),
                (s > TUBE_STRAIGHT + TUBE_BEND * PI / 2.0) as u8 as f64,
            );
        }
        if let Some(e) = self.grid_error {
            m.insert("diag_voxel_error_max_m".into(), e);
        }
    }
}

/// Push a guidewire into a lumen given as a triangle surface.
pub const MESH_INSERTION: Declared<MeshInsertionParams> = Declared {
    info: ScenarioInfo {
        id: "vessel-mesh-insertion",
        description: "guidewire pushed into a lumen from a closed surface: built-in 4 mm tube with a 90 deg bend, or --mesh",
        family: Family::Rod,
        reference: "no reference solution: wire surface depth past the wall (geometric, against the scene's voxel SDF), tip progress; any lumen",
        primary_error: "max_penetration_m",
        target: crate::scenario::Target::new(
            0.0001,
            "0.1 mm of penetration: half the radius of a 0.014 in coronary guidewire (0.18 mm)",
        ),
        params: MeshInsertionParams::SPECS,
        sweep: Sweep::Knob("segments", &[40.0, 80.0, 160.0]),
        quick: 2,
        mesh: Some(MeshKind::Surface),
    },
    datasets: None,
    build,
};

/// How far (m) from `entry` along `dir` a wire of radius `r` stays clear of
/// the wall of `sdf` (sampled every r / 2, up to `max`).
fn clear_run(sdf: &dyn Sdf, entry: &Vec3, dir: &Vec3, r: f64, max: f64) -> f64 {
    let step = 0.5 * r;
    let mut s = 0.0;
    while s <= max {
        if !(sdf.distance(&(entry + dir * s)) + r < 0.0) {
            return (s - step).max(0.0);
        }
        s += step;
    }
    max
}

fn build(p: &MeshInsertionParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let id = MESH_INSERTION.info.id;
    let wire = wire!(p);
    let (surface, tube, file) = match inputs.mesh.and_then(|m| m.surface()) {
        Some(s) => (s.clone(), None, inputs.mesh.map(|m| m.path.display().to_string())),
        None => {
            check_lumen(wire.radius, TUBE_RADIUS, "built-in tube")?;
            (builtin_surface(), Some(builtin_tube()), None)
        }
    };
    let what = file.as_deref().unwrap_or("the built-in tube");
    let spacing = p.voxel_spacing;
    // Read by tricubic interpolation: its gradient is continuous across
    // cell faces, which a Newton contact solve needs (on the trilinear
    // field DER took 470 Newton iterations a step, 4.5 on the analytic tube).
    let grid = VoxelSdf::from_mesh(&surface, spacing, 3.0 * spacing)
        .map(CubicVoxelSdf::new)
        .map_err(|e| {
            UsageError(format!(
                "{id}: voxel distance of {what} at voxel_spacing {spacing} m: {e}"
            ))
        })?;
    let entry = Vec3::new(p.entry_x, p.entry_y, p.entry_z);
    let dir = Vec3::new(p.entry_dir_x, p.entry_dir_y, p.entry_dir_z);
    let Some(dir) = dir.try_normalize(1e-12) else {
        return Err(UsageError(format!("{id}: entry_dir_x/y/z is the zero vector")));
    };
    let phi = grid.distance(&entry);
    if !(phi + wire.radius < 0.0) {
        return Err(UsageError(format!(
            "{id}: the entry point ({:.4}, {:.4}, {:.4}) m is not inside the lumen of {what} with room for the wire (signed distance {phi:.3e} m, wire radius {:.3e} m); set entry_x/entry_y/entry_z to a point near the centreline",
            entry.x, entry.y, entry.z, wire.radius
        )));
    }
    let (lo, hi) = surface.bounds();
    let size = (hi - lo).norm();
    let feed = p.insertion_speed * p.duration;
    let l0 = p.initial_length;
    // The clamp slides along the entry direction and the wire starts
    // straight along it: both must stay in the lumen.
    let clear = clear_run(&grid, &entry, &dir, wire.radius, size);
    if l0 > clear {
        return Err(UsageError(format!(
            "{id}: the initial wire ({l0} m straight along the entry direction) leaves the lumen of {what} after {clear:.4} m; shorten initial_length or change the entry"
        )));
    }
    let feed_limit = FeedLimit {
        start: 0.0,
        straight: clear,
        what: "straight lumen ahead of the entry",
    };
    feed_limit.check(feed)?;
    let rod = wire.rod(l0, frame_along(&entry, &dir))?;
    let contact = contact(p.friction_static, p.friction_dynamic, wire.radius)?;
    let grid_error = tube.as_ref().map(|t| {
        // Away from the flat end caps (the analytic tube's caps are round).
        let keep = |x: &Vec3| {
            let s = t.project(x).s;
            s > 5e-3 && s < t.length() - 5e-3
        };
        grid.error_against(t, 2000, 7, 2.0 * wire.radius, keep).max
    });
    let mut scene = wire_scene(id, p.duration, rod, Arc::new(grid), contact);
    scene.gravity = Vec3::new(0.0, 0.0, -p.gravity);
    scene.control = timeline(&[(0.0, 0.0, 0.0), (p.duration, feed, 0.0)]);
    scene.validate().map_err(UsageError)?;
    // The whole wire bent to ten wire radii: far tighter than any lumen it fits.
    let energy = wire.body_ei() * (l0 + feed) / (10.0 * wire.radius).powi(2);
    let run = MeshRun {
        wire_radius: wire.radius,
        tube,
        grid_error,
    };
    Ok(vessel_run(scene, run, energy, size + entry.norm()).with_feed_limit(feed_limit))
}
