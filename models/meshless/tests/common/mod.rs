//! Shared test fixtures: seeded RNG, block scenes, jittered point sets.
#![allow(dead_code)]

use surgbench_core::{
    Body, ControlKey, ControlTimeline, Scene, Settle, SolidMaterial, TetMesh, TissueBody, Vec3, mesh,
};
use surgbench_meshless::{PointElastic, StateCache};

/// xorshift64* in [-0.5, 0.5).
pub struct Rng(pub u64);
impl Rng {
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
    pub fn vec(&mut self) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next())
    }
}

pub fn material(nu: f64) -> SolidMaterial {
    SolidMaterial {
        youngs_modulus: 1e4,
        poisson_ratio: nu,
        density: 1000.0,
    }
}

/// A block with its nodes jittered by up to `jitter` of the cell size
/// (still positively oriented tets for jitter <= 0.15).
pub fn jittered_block(size: Vec3, cells: [usize; 3], jitter: f64, seed: u64) -> TetMesh {
    let mut m = mesh::block(size, cells);
    let h = Vec3::new(
        size.x / cells[0] as f64,
        size.y / cells[1] as f64,
        size.z / cells[2] as f64,
    );
    let mut r = Rng(seed);
    for p in &mut m.nodes {
        *p += r.vec().component_mul(&h) * (2.0 * jitter);
    }
    m
}

pub fn tissue_scene(mesh: TetMesh, mat: SolidMaterial) -> Scene {
    tissue_scene_with(TissueBody::new(mesh, mat), "meshless-test")
}

/// A scene holding one prepared tissue body.
pub fn tissue_scene_with(body: TissueBody, name: &str) -> Scene {
    let mut s = Scene::empty(name);
    s.bodies.push(Body::Tissue(body));
    s
}

/// Cube of edge `l` with `n` cells per side, bottom (z = 0) fixed, top driven
/// by `(0, 0, -strain l)`, ramped over `ramp_time` s, settling.
pub fn compression_scene(l: f64, n: usize, strain: f64, nu: f64, ramp_time: f64) -> Scene {
    let m = mesh::block(Vec3::repeat(l), [n, n, n]);
    let mut body = TissueBody::new(m.clone(), material(nu));
    body.fixed_nodes = mesh::nodes_on_plane(&m, 2, 0.0, 1e-9 * l);
    body.driven_nodes = mesh::nodes_on_plane(&m, 2, l, 1e-9 * l)
        .into_iter()
        .map(|i| (i, Vec3::new(0.0, 0.0, -strain * l)))
        .collect();
    let mut s = tissue_scene_with(body, "meshless-compression");
    s.control = ramp(ramp_time);
    s.settle = Some(Settle {
        velocity_tol: 1e-6,
        min_time: ramp_time,
    });
    s.duration = 10.0 * ramp_time;
    s
}

/// Load ramp from 0 at t = 0 to 1 at `ramp` s, then held.
pub fn ramp(ramp: f64) -> ControlTimeline {
    ControlTimeline {
        keys: vec![ControlKey::load(0.0, 0.0), ControlKey::load(ramp, 1.0)],
    }
}

/// Node volumes: a quarter of each tet around the node (m^3).
pub fn volumes(m: &TetMesh) -> Vec<f64> {
    let mut v = vec![0.0; m.nodes.len()];
    for t in &m.tets {
        let p = t.map(|i| m.nodes[i]);
        let vol = mesh::tet_volume(&p[0], &p[1], &p[2], &p[3]).abs();
        for &i in t {
            v[i] += vol / 4.0;
        }
    }
    v
}

/// The elastic forces of `el` at positions `x` (N).
pub fn forces(el: &PointElastic, x: &[Vec3]) -> Vec<Vec3> {
    let mut c = StateCache::default();
    el.prepare(x, &mut c);
    let mut f = vec![Vec3::zeros(); x.len()];
    el.add_forces(x, &c, &mut f);
    f
}

/// The elastic plus hourglass energy of `el` at positions `x` (J).
pub fn total(el: &PointElastic, x: &[Vec3]) -> f64 {
    let (u, hg) = el.energy(x);
    u + hg
}
