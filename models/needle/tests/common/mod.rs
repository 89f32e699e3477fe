//! A small needle scene for the crate's tests: a stiff steel needle along +x
//! into a gel block `[0, 20] x [-5, 5] x [-5, 5]` mm held at its far face.

use surgbench_core::{
    ControlKey, ControlTimeline, Iso3, NeedleTissue, RodBody, Scene, SolidMaterial, TissueBody, Vec3,
};

/// Needle tip 1 mm outside the block at `t = 0`.
pub const TIP_START: f64 = -1e-3;
/// Needle free length (m).
pub const NEEDLE_LENGTH: f64 = 0.04;

/// The scene: insertion `feed` keys `(t, insertion)`, block cells `cells`,
/// friction per length (N/m), cutting force (N).
pub fn scene(feed: &[(f64, f64)], cells: [usize; 3], f_perlen: f64, f_cut: f64) -> Scene {
    let size = Vec3::new(0.02, 0.01, 0.01);
    let mut mesh = surgbench_core::mesh::block_mirrored(size, cells);
    for p in &mut mesh.nodes {
        p.y -= 0.005;
        p.z -= 0.005;
    }
    // Gel: E and nu of 10 wt% gelatin as issue 17 gives them; density of water.
    let material = SolidMaterial {
        youngs_modulus: 14.8e3,
        poisson_ratio: 0.475,
        density: 1000.0,
    };
    let mut tissue = TissueBody::new(mesh, material);
    tissue.fixed_nodes = (0..tissue.mesh.nodes.len())
        .filter(|&i| (tissue.mesh.nodes[i].x - size.x).abs() < 1e-12)
        .collect();
    // Steel needle (E = 200 GPa), 0.83 mm diameter.
    let mut rod = RodBody::uniform(NEEDLE_LENGTH, 0.415e-3, 200e9, 0.3, 7850.0);
    rod.base = Iso3::translation(TIP_START - NEEDLE_LENGTH, 0.0, 0.0);
    let mut s = Scene::empty("needle-test");
    s.bodies = vec![rod.into(), surgbench_core::Body::Tissue(tissue)];
    s.duration = feed.last().map_or(1.0, |k| k.0);
    s.control = ControlTimeline {
        keys: feed.iter().map(|&(t, x)| ControlKey::feed(t, x, 0.0)).collect(),
    };
    s.needle = Some(NeedleTissue {
        friction_per_length: f_perlen,
        cutting_force: f_cut,
        viscous_friction: 0.0,
        bevel_angle: 0.0,
    });
    s
}

/// A stiff needle pre-inserted `depth` (m) along +x into a free gel block
/// (same size and gel as [`scene`], no node held), its base held still; a
/// uniform pressure `pressure` (Pa) on the entry face `x = 0`, scaled by the
/// `load` keys `(t, factor)`, pushes the block along +x, off the needle.
#[allow(dead_code)]
pub fn pulled_scene(depth: f64, cells: [usize; 3], f_perlen: f64, pressure: f64, load: &[(f64, f64)]) -> Scene {
    let mut s = scene(&[(0.0, 0.0)], cells, f_perlen, 0.05);
    let surgbench_core::Body::Tissue(t) = &mut s.bodies[1] else {
        unreachable!("the block is the second body")
    };
    t.fixed_nodes.clear();
    t.pressure_faces = surgbench_core::mesh::boundary_faces(&t.mesh)
        .into_iter()
        .filter(|f| f.iter().all(|&i| t.mesh.nodes[i].x.abs() < 1e-12))
        .map(|f| (f, pressure))
        .collect();
    let surgbench_core::Body::Rod(r) = &mut s.bodies[0] else {
        unreachable!("the needle is the first body")
    };
    r.base = Iso3::translation(depth - NEEDLE_LENGTH, 0.0, 0.0);
    s.duration = load.last().map_or(1.0, |k| k.0);
    s.control = ControlTimeline {
        keys: load.iter().map(|&(t, l)| ControlKey::load(t, l)).collect(),
    };
    s
}
