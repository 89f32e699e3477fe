//! Tetrahedral meshing shared by every tissue model and tissue scenario:
//! structured builders ([`block`], [`tube`], [`tube_sector`]), node sets by
//! predicate, boundary faces, mesh quality ([`quality`]), and the
//! [`TetMesh`] type itself; file readers are in [`crate::io`].
//!
//! Units are SI (metres). Every builder returns positively oriented tets
//! (`(b - a) x (c - a) . (d - a) > 0`).
//!
//! Structured builders split each hexahedral cell into six tetrahedra along
//! its main diagonal (the Kuhn / Freudenthal subdivision). Neighbouring cells
//! then share face diagonals, so the mesh is conforming, also across the
//! periodic seam of a full tube.
//!
//! ```
//! use surgbench_core::{mesh, Vec3};
//! let m = mesh::block(Vec3::new(0.01, 0.01, 0.02), [2, 2, 4]);
//! assert_eq!(m.tets.len(), 6 * 2 * 2 * 4);
//! let bottom = mesh::nodes_on_plane(&m, 2, 0.0, 1e-9);
//! assert_eq!(bottom.len(), 9);
//! let q = mesh::quality(&m);
//! assert_eq!(q.inverted, 0);
//! assert!((q.volume - 0.01 * 0.01 * 0.02).abs() < 1e-15);
//! ```

use crate::Vec3;
use std::collections::HashMap;

/// Linear tetrahedral mesh: node positions (m) and 4-node elements.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TetMesh {
    /// Node positions (m).
    pub nodes: Vec<Vec3>,
    /// Elements as node indices.
    pub tets: Vec<[usize; 4]>,
}

impl TetMesh {
    /// Check indices and that no element is degenerate.
    pub fn validate(&self) -> Result<(), String> {
        for (e, t) in self.tets.iter().enumerate() {
            for &i in t {
                if i >= self.nodes.len() {
                    return Err(format!(
                        "tet {e} refers to node {i} but the mesh has {} nodes",
                        self.nodes.len()
                    ));
                }
            }
            let [a, b, c, d] = t.map(|i| self.nodes[i]);
            let vol = tet_volume(&a, &b, &c, &d);
            if !(vol.abs() > 0.0) {
                return Err(format!("tet {e} is degenerate (volume {vol})"));
            }
        }
        Ok(())
    }
}

/// Signed volume of the tet `(a, b, c, d)` (m^3); positive when
/// `(b - a) x (c - a)` points towards `d`.
#[inline]
pub fn tet_volume(a: &Vec3, b: &Vec3, c: &Vec3, d: &Vec3) -> f64 {
    (b - a).cross(&(c - a)).dot(&(d - a)) / 6.0
}

/// [`tet_volume`] of the four corners `p` (m^3).
#[inline]
pub fn tet_volume_of(p: &[Vec3; 4]) -> f64 {
    tet_volume(&p[0], &p[1], &p[2], &p[3])
}

/// Gradients of [`tet_volume`] with respect to `p1..p4` (m^2):
/// `(1/6)(p4-p2) x (p3-p2)`, `(1/6)(p3-p1) x (p4-p1)`,
/// `(1/6)(p4-p1) x (p2-p1)`, `(1/6)(p2-p1) x (p3-p1)`.
#[inline]
pub fn tet_volume_gradients(p: &[Vec3; 4]) -> [Vec3; 4] {
    let s = 1.0 / 6.0;
    [
        (p[3] - p[1]).cross(&(p[2] - p[1])) * s,
        (p[2] - p[0]).cross(&(p[3] - p[0])) * s,
        (p[3] - p[0]).cross(&(p[1] - p[0])) * s,
        (p[1] - p[0]).cross(&(p[2] - p[0])) * s,
    ]
}

/// Kuhn subdivision of the unit cube: corner `k` has offset bits
/// `(k & 1, k >> 1 & 1, k >> 2 & 1)`; each tet walks from corner 0 to
/// corner 7 along one permutation of the axes.
pub(crate) const KUHN: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// Build tets from a structured `(ni+1) x (nj+1) x (nk+1)` lattice whose node
/// index is `node(i, j, k)`; orientation is fixed from the node positions.
fn lattice_tets(nodes: &[Vec3], cells: [usize; 3], node: impl Fn(usize, usize, usize) -> usize) -> Vec<[usize; 4]> {
    split_lattice(nodes, cells, false, node)
}

/// [`lattice_tets`], with every cell's split mirrored along each axis whose
/// cell index is odd when `mirror` is set.
fn split_lattice(
    nodes: &[Vec3],
    cells: [usize; 3],
    mirror: bool,
    node: impl Fn(usize, usize, usize) -> usize,
) -> Vec<[usize; 4]> {
    let mut tets = Vec::with_capacity(6 * cells[0] * cells[1] * cells[2]);
    for k in 0..cells[2] {
        for j in 0..cells[1] {
            for i in 0..cells[0] {
                let flip = if mirror {
                    (i & 1) | (j & 1) << 1 | (k & 1) << 2
                } else {
                    0
                };
                let corner = |c: usize| {
                    let c = c ^ flip;
                    node(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))
                };
                for t in KUHN {
                    let mut tet = t.map(corner);
                    let [a, b, c, d] = tet.map(|n| nodes[n]);
                    if tet_volume(&a, &b, &c, &d) < 0.0 {
                        tet.swap(2, 3);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    tets
}

/// Axis-aligned box `[0, size.x] x [0, size.y] x [0, size.z]` (m) with
/// `cells[i]` hexahedral cells along axis `i`, six tets per cell.
///
/// Node `(i, j, k)` has index `i + (cells[0] + 1) * (j + (cells[1] + 1) * k)`.
/// A zero cell count is raised to one.
pub fn block(size: Vec3, cells: [usize; 3]) -> TetMesh {
    block_split(size, cells, false)
}

/// [`block`] with each cell's six-tet split mirrored across the cell faces
/// whose index along that axis is odd, so that the mesh is symmetric under
/// reflection in every grid plane through a node with even indices. The
/// plain [`block`] splits every cell along the same diagonal, and a line
/// load along a grid line then drifts sideways along that diagonal
/// (measured on the needle scenes). Same nodes and node numbering as
/// [`block`]; shared faces stay conforming (a mirrored neighbour splits the
/// shared face along the same diagonal).
pub fn block_mirrored(size: Vec3, cells: [usize; 3]) -> TetMesh {
    block_split(size, cells, true)
}

/// The lattice of [`block`], its cells split as [`split_lattice`] does.
fn block_split(size: Vec3, cells: [usize; 3], mirror: bool) -> TetMesh {
    let c = cells.map(|n| n.max(1));
    let planes: Vec<Vec<f64>> = (0..3)
        .map(|a| (0..=c[a]).map(|i| size[a] * i as f64 / c[a] as f64).collect())
        .collect();
    lattice_block(&planes[0], &planes[1], &planes[2], mirror)
}

/// The box whose grid planes along x, y and z are at `x`, `y` and `z` (m,
/// each strictly increasing, at least two): a graded lattice whose planes
/// can follow material layers (a 1 mm skin, a 0.5 mm capsule). Cells are
/// split as [`block_mirrored`] splits them, so the mesh is symmetric under
/// reflection in a grid plane through nodes of even index when the planes
/// are. Node `(i, j, k)` has index `i + x.len() * (j + y.len() * k)`.
pub fn graded_block(x: &[f64], y: &[f64], z: &[f64]) -> Result<TetMesh, String> {
    for (name, p) in [("x", x), ("y", y), ("z", z)] {
        if p.len() < 2 || !p.iter().all(|v| v.is_finite()) || p.windows(2).any(|w| !(w[1] > w[0])) {
            return Err(format!(
                "graded block: the {name} planes must be at least two, finite and strictly increasing, got {p:?}"
            ));
        }
    }
    Ok(lattice_block(x, y, z, true))
}

/// The lattice with grid planes `x`, `y`, `z` (m), cells split as
/// [`split_lattice`] does.
fn lattice_block(x: &[f64], y: &[f64], z: &[f64], mirror: bool) -> TetMesh {
    let (nx, ny, nz) = (x.len(), y.len(), z.len());
    let mut nodes = Vec::with_capacity(nx * ny * nz);
    for &zk in z {
        for &yj in y {
            for &xi in x {
                nodes.push(Vec3::new(xi, yj, zk));
            }
        }
    }
    let tets = split_lattice(&nodes, [nx - 1, ny - 1, nz - 1], mirror, |i, j, k| {
        i + nx * (j + ny * k)
    });
    TetMesh { nodes, tets }
}

/// Full thick-walled tube about the z axis: radii `inner..outer` (m),
/// `z` in `[0, height]`, with `n_theta >= 3` cells around, `n_r` through the
/// wall and `n_z` along the axis. The circles are approximated by polygons
/// with `n_theta` sides (nodes lie exactly on the circles).
pub fn tube(inner: f64, outer: f64, height: f64, n_theta: usize, n_r: usize, n_z: usize) -> TetMesh {
    cylindrical(
        inner,
        outer,
        height,
        std::f64::consts::TAU,
        n_theta.max(3),
        n_r,
        n_z,
        true,
    )
}

/// Sector `0 <= theta <= angle` (rad, from +x towards +y) of a thick-walled
/// tube about the z axis; see [`tube`]. With `angle = pi/2` and symmetry
/// conditions (`u_y = 0` on `y = 0`, `u_x = 0` on `x = 0`) it models the
/// full tube at a quarter of the cost.
pub fn tube_sector(inner: f64, outer: f64, height: f64, angle: f64, n_theta: usize, n_r: usize, n_z: usize) -> TetMesh {
    cylindrical(inner, outer, height, angle, n_theta.max(1), n_r, n_z, false)
}

fn cylindrical(
    inner: f64,
    outer: f64,
    height: f64,
    angle: f64,
    n_t: usize,
    n_r: usize,
    n_z: usize,
    periodic: bool,
) -> TetMesh {
    let (n_r, n_z) = (n_r.max(1), n_z.max(1));
    let nt_nodes = if periodic { n_t } else { n_t + 1 };
    let (nr_nodes, nz_nodes) = (n_r + 1, n_z + 1);
    let mut nodes = Vec::with_capacity(nt_nodes * nr_nodes * nz_nodes);
    for k in 0..nz_nodes {
        for j in 0..nt_nodes {
            for i in 0..nr_nodes {
                let r = inner + (outer - inner) * i as f64 / n_r as f64;
                let th = angle * j as f64 / n_t as f64;
                let z = height * k as f64 / n_z as f64;
                let (s, c) = th.sin_cos();
                // Exact zeros on the symmetry planes keep node sets crisp.
                let x = if (th - std::f64::consts::FRAC_PI_2).abs() < 1e-14 {
                    0.0
                } else {
                    r * c
                };
                let y = if th == 0.0 { 0.0 } else { r * s };
                nodes.push(Vec3::new(x, y, z));
            }
        }
    }
    let tets = lattice_tets(&nodes, [n_r, n_t, n_z], |i, j, k| {
        i + nr_nodes * ((j % nt_nodes) + nt_nodes * k)
    });
    TetMesh { nodes, tets }
}

/// The wall of a tube swept along a centreline: `frame(s)` gives the
/// centreline frame at arclength `s` in `[0, length]` (m; local x the
/// tangent, the section in local y-z), radii `inner..outer` (m), `n_theta
/// >= 3` cells around, `n_r` through the wall and `n_s` along. Node
/// `(i, j, k)` (radial, around, along; `i = 0` on the inner wall, `i = n_r`
/// on the outer) has index `i + (n_r + 1) (j + n_theta k)`. Six tets per
/// cell as [`tube`] (which is this along a straight axis).
pub fn swept_wall(
    frame: impl Fn(f64) -> crate::Iso3,
    length: f64,
    inner: f64,
    outer: f64,
    n_theta: usize,
    n_r: usize,
    n_s: usize,
) -> TetMesh {
    let (n_t, n_r, n_s) = (n_theta.max(3), n_r.max(1), n_s.max(1));
    let nr_nodes = n_r + 1;
    let mut nodes = Vec::with_capacity(nr_nodes * n_t * (n_s + 1));
    for k in 0..=n_s {
        let f = frame(length * k as f64 / n_s as f64);
        for j in 0..n_t {
            let th = std::f64::consts::TAU * j as f64 / n_t as f64;
            for i in 0..nr_nodes {
                let r = inner + (outer - inner) * i as f64 / n_r as f64;
                nodes.push(f.translation.vector + f.rotation * Vec3::new(0.0, r * th.cos(), r * th.sin()));
            }
        }
    }
    let tets = lattice_tets(&nodes, [n_r, n_t, n_s], |i, j, k| i + nr_nodes * ((j % n_t) + n_t * k));
    TetMesh { nodes, tets }
}

/// A copy of `mesh` with every node moved by `offset` (m).
pub fn translated(mesh: &TetMesh, offset: Vec3) -> TetMesh {
    TetMesh {
        nodes: mesh.nodes.iter().map(|p| p + offset).collect(),
        tets: mesh.tets.clone(),
    }
}

/// A copy of `mesh` with coordinates multiplied by `factor` (e.g. `1e-3` for
/// a file written in millimetres).
pub fn scaled(mesh: &TetMesh, factor: f64) -> TetMesh {
    TetMesh {
        nodes: mesh.nodes.iter().map(|p| p * factor).collect(),
        tets: mesh.tets.clone(),
    }
}

/// Indices of the nodes whose rest position satisfies `pred`, ascending.
pub fn nodes_where(mesh: &TetMesh, pred: impl Fn(&Vec3) -> bool) -> Vec<usize> {
    (0..mesh.nodes.len()).filter(|&i| pred(&mesh.nodes[i])).collect()
}

/// Nodes with `|p[axis] - value| <= tol` (axis 0 = x, 1 = y, 2 = z).
pub fn nodes_on_plane(mesh: &TetMesh, axis: usize, value: f64, tol: f64) -> Vec<usize> {
    nodes_where(mesh, |p| (p[axis] - value).abs() <= tol)
}

/// Nodes at distance `radius` (within `tol`) from the z axis.
pub fn nodes_on_cylinder(mesh: &TetMesh, radius: f64, tol: f64) -> Vec<usize> {
    nodes_where(mesh, |p| (p.x.hypot(p.y) - radius).abs() <= tol)
}

/// Axis-aligned bounding box `(min, max)` of the nodes (m).
pub fn bounds(mesh: &TetMesh) -> (Vec3, Vec3) {
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for p in &mesh.nodes {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (lo, hi)
}

/// Boundary triangles (faces used by exactly one tet), each ordered so that
/// its normal `(b - a) x (c - a)` points out of the mesh (for positively
/// oriented tets). Sorted for determinism.
pub fn boundary_faces(mesh: &TetMesh) -> Vec<[usize; 3]> {
    // Faces of a positive tet (a,b,c,d) with outward normals.
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
    let mut count: HashMap<[usize; 3], (usize, [usize; 3])> = HashMap::new();
    for t in &mesh.tets {
        for f in FACES {
            let face = f.map(|i| t[i]);
            let mut key = face;
            key.sort_unstable();
            count.entry(key).and_modify(|e| e.0 += 1).or_insert((1, face));
        }
    }
    let mut out: Vec<[usize; 3]> = count.into_values().filter(|(n, _)| *n == 1).map(|(_, f)| f).collect();
    out.sort_unstable();
    out
}

/// Geometric quality of a tet mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshQuality {
    /// Smallest dihedral angle over all tets (degrees).
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle over all tets (degrees).
    pub max_dihedral_deg: f64,
    /// Smallest signed tet volume (m^3); negative means an inverted tet.
    pub min_volume: f64,
    /// Largest signed tet volume (m^3).
    pub max_volume: f64,
    /// Sum of signed volumes (m^3).
    pub volume: f64,
    /// Count of tets with non-positive volume.
    pub inverted: usize,
}

/// The six dihedral angles of a tet (radians), one per edge.
pub fn dihedral_angles(p: [Vec3; 4]) -> [f64; 6] {
    const EDGES: [[usize; 4]; 6] = [
        [0, 1, 2, 3],
        [0, 2, 1, 3],
        [0, 3, 1, 2],
        [1, 2, 0, 3],
        [1, 3, 0, 2],
        [2, 3, 0, 1],
    ];
    EDGES.map(|[i, j, k, l]| {
        let e = (p[j] - p[i]).normalize();
        let u = p[k] - p[i];
        let w = p[l] - p[i];
        let u = u - e * u.dot(&e);
        let w = w - e * w.dot(&e);
        (u.dot(&w) / (u.norm() * w.norm())).clamp(-1.0, 1.0).acos()
    })
}

/// Dihedral angles, volumes and inverted count of `mesh` at its rest nodes.
pub fn quality(mesh: &TetMesh) -> MeshQuality {
    quality_at(mesh, &mesh.nodes)
}

/// Like [`quality`] but at deformed node positions `x` (m).
pub fn quality_at(mesh: &TetMesh, x: &[Vec3]) -> MeshQuality {
    let mut q = MeshQuality {
        min_dihedral_deg: f64::INFINITY,
        max_dihedral_deg: f64::NEG_INFINITY,
        min_volume: f64::INFINITY,
        max_volume: f64::NEG_INFINITY,
        volume: 0.0,
        inverted: 0,
    };
    for t in &mesh.tets {
        let p = t.map(|i| x[i]);
        let v = tet_volume(&p[0], &p[1], &p[2], &p[3]);
        q.volume += v;
        q.min_volume = q.min_volume.min(v);
        q.max_volume = q.max_volume.max(v);
        if v <= 0.0 {
            q.inverted += 1;
        }
        for a in dihedral_angles(p) {
            q.min_dihedral_deg = q.min_dihedral_deg.min(a.to_degrees());
            q.max_dihedral_deg = q.max_dihedral_deg.max(a.to_degrees());
        }
    }
    q
}

/// Flip every negatively oriented tet so that all volumes are positive
/// (file formats do not agree on orientation). Returns how many were flipped.
pub fn orient_positive(mesh: &mut TetMesh) -> usize {
    let mut flipped = 0;
    for t in &mut mesh.tets {
        let [a, b, c, d] = t.map(|i| mesh.nodes[i]);
        if tet_volume(&a, &b, &c, &d) < 0.0 {
            t.swap(2, 3);
            flipped += 1;
        }
    }
    flipped
}

/// The tet of `mesh` containing `p` and the barycentric weights of `p` in
/// it; for a point outside every tet (by more than round-off), the tet in
/// which its smallest weight is largest (nearest, extrapolating). `None`
/// only for a mesh without tets.
pub fn locate(mesh: &TetMesh, p: &Vec3) -> Option<(usize, [f64; 4])> {
    locate_in(&mesh.nodes, &mesh.tets, p)
}

/// [`locate`] in the tets `tets` over the positions `nodes` (a deformed
/// state of a mesh, without copying it into a [`TetMesh`]).
pub fn locate_in(nodes: &[Vec3], tets: &[[usize; 4]], p: &Vec3) -> Option<(usize, [f64; 4])> {
    let mut best: Option<(usize, [f64; 4], f64)> = None;
    for (e, t) in tets.iter().enumerate() {
        let [a, b, c, d] = t.map(|i| nodes[i]);
        let m = crate::Mat3::from_columns(&[b - a, c - a, d - a]);
        let Some(inv) = m.try_inverse() else { continue };
        let l = inv * (p - a);
        let w = [1.0 - l.x - l.y - l.z, l.x, l.y, l.z];
        let min = w.iter().copied().fold(f64::INFINITY, f64::min);
        if best.as_ref().is_none_or(|b| min > b.2) {
            best = Some((e, w, min));
            if min >= 0.0 {
                break;
            }
        }
    }
    best.map(|(e, w, _)| (e, w))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_volume_orientation_and_node_sets() {
        let size = Vec3::new(0.02, 0.03, 0.05);
        let m = block(size, [3, 4, 5]);
        assert_eq!(m.nodes.len(), 4 * 5 * 6);
        assert_eq!(m.tets.len(), 6 * 3 * 4 * 5);
        m.validate().unwrap();
        let q = quality(&m);
        assert_eq!(q.inverted, 0, "{q:?}");
        // Volumes sum to the box volume up to round-off (1e-12 relative).
        let v = size.x * size.y * size.z;
        assert!((q.volume - v).abs() < 1e-12 * v, "volume {} vs {v}", q.volume);
        assert_eq!(nodes_on_plane(&m, 2, 0.0, 1e-12).len(), 4 * 5);
        assert_eq!(nodes_on_plane(&m, 0, 0.02, 1e-12).len(), 5 * 6);
        // Boundary: 2 triangles per cell face on each of the six sides.
        let nf = boundary_faces(&m).len();
        assert_eq!(nf, 2 * 2 * (3 * 4 + 4 * 5 + 3 * 5), "boundary faces {nf}");
    }

    #[test]
    fn mirrored_block_is_conforming_and_mirror_symmetric() {
        let size = Vec3::new(0.04, 0.02, 0.02);
        let m = block_mirrored(size, [4, 2, 2]);
        m.validate().unwrap();
        let q = quality(&m);
        assert_eq!(q.inverted, 0, "{q:?}");
        let v = size.x * size.y * size.z;
        assert!((q.volume - v).abs() < 1e-12 * v, "volume {} vs {v}", q.volume);
        // Conforming: every interior face is shared by two tets, so the
        // boundary holds exactly the 2 triangles per cell face of the sides.
        let nf = boundary_faces(&m).len();
        assert_eq!(nf, 2 * 2 * (4 * 2 + 2 * 2 + 4 * 2), "boundary faces {nf}");
        // Reflection in the plane y = size.y / 2 (through the middle nodes,
        // index 1) maps the tet set onto itself.
        let key = |t: [usize; 4]| {
            let mut k = t;
            k.sort_unstable();
            k
        };
        let set: std::collections::HashSet<[usize; 4]> = m.tets.iter().map(|t| key(*t)).collect();
        let (nx, ny) = (5, 3);
        let mirror_y = |n: usize| {
            let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
            i + nx * ((ny - 1 - j) + ny * k)
        };
        assert!(m.tets.iter().all(|t| set.contains(&key(t.map(mirror_y)))));
        // The plain block is not symmetric so.
        let plain = block(size, [4, 2, 2]);
        let set: std::collections::HashSet<[usize; 4]> = plain.tets.iter().map(|t| key(*t)).collect();
        assert!(!plain.tets.iter().all(|t| set.contains(&key(t.map(mirror_y)))));
    }

    #[test]
    fn graded_block_follows_its_planes_and_mirrors_about_its_middle() {
        // A 1 mm layer, then coarse cells; across, symmetric planes with a
        // thin shell at +-5 mm (the prostate scene's layout, small).
        let x = [0.0, 1e-3, 6e-3, 6.5e-3, 12e-3];
        let y = [-12e-3, -5.5e-3, -5e-3, -2.5e-3, 0.0, 2.5e-3, 5e-3, 5.5e-3, 12e-3];
        let m = graded_block(&x, &y, &y).unwrap();
        m.validate().unwrap();
        assert_eq!(m.nodes.len(), 5 * 9 * 9);
        assert_eq!(m.tets.len(), 6 * 4 * 8 * 8);
        let q = quality(&m);
        assert_eq!(q.inverted, 0, "{q:?}");
        let v = 12e-3 * 24e-3 * 24e-3;
        assert!((q.volume - v).abs() < 1e-12 * v, "volume {} vs {v}", q.volume);
        for (axis, planes) in [(0, &x[..]), (1, &y[..])] {
            for &p in planes {
                assert_eq!(nodes_on_plane(&m, axis, p, 1e-12).len(), m.nodes.len() / planes.len());
            }
        }
        // Reflection y -> -y maps the tet set onto itself.
        let key = |t: [usize; 4]| {
            let mut k = t;
            k.sort_unstable();
            k
        };
        let set: std::collections::HashSet<[usize; 4]> = m.tets.iter().map(|t| key(*t)).collect();
        let (nx, ny) = (x.len(), y.len());
        let mirror_y = |n: usize| {
            let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
            i + nx * ((ny - 1 - j) + ny * k)
        };
        assert!(m.tets.iter().all(|t| set.contains(&key(t.map(mirror_y)))));
        // Planes out of order, repeated or too few are refused.
        assert!(graded_block(&[0.0, 1.0, 1.0], &y, &y).is_err());
        assert!(graded_block(&[0.0], &y, &y).is_err());
        assert!(graded_block(&[1.0, 0.0], &y, &y).is_err());
        assert!(graded_block(&x, &y, &[0.0, f64::NAN]).is_err());
    }

    #[test]
    fn boundary_faces_point_outwards() {
        // Divergence theorem: sum over boundary of (x . n) dA = 3 V.
        let m = tube(0.01, 0.02, 0.03, 12, 3, 2);
        let q = quality(&m);
        let mut flux = 0.0;
        for f in boundary_faces(&m) {
            let [a, b, c] = f.map(|i| m.nodes[i]);
            let an = (b - a).cross(&(c - a)) / 2.0;
            flux += ((a + b + c) / 3.0).dot(&an);
        }
        assert!(
            (flux - 3.0 * q.volume).abs() < 1e-12 * q.volume.abs() * 3.0,
            "flux {flux} vs 3V {}",
            3.0 * q.volume
        );
    }

    #[test]
    fn tube_is_closed_and_converges_to_annulus_volume() {
        let (a, b, h) = (0.01, 0.02, 0.05);
        let m = tube(a, b, h, 64, 4, 3);
        m.validate().unwrap();
        let q = quality(&m);
        assert_eq!(q.inverted, 0);
        // Polygon area n/2 sin(2 pi/n) (b^2 - a^2): exact for the faceted tube.
        let n = 64.0;
        let exact = n / 2.0 * (std::f64::consts::TAU / n).sin() * (b * b - a * a) * h;
        assert!((q.volume - exact).abs() < 1e-12 * exact, "{} vs {exact}", q.volume);
        // Periodic: no boundary faces on a seam, so only inner, outer, ends.
        let nf = boundary_faces(&m).len();
        assert_eq!(nf, 2 * (64 * 3 * 2 + 64 * 4 * 2), "boundary faces {nf}");
        assert_eq!(nodes_on_cylinder(&m, a, 1e-12).len(), 64 * 4);
    }

    #[test]
    fn tube_sector_planes_and_quality() {
        let m = tube_sector(0.01, 0.02, 0.01, std::f64::consts::FRAC_PI_2, 8, 4, 1);
        m.validate().unwrap();
        assert_eq!(nodes_on_plane(&m, 1, 0.0, 0.0).len(), 5 * 2);
        assert_eq!(nodes_on_plane(&m, 0, 0.0, 0.0).len(), 5 * 2);
        let q = quality(&m);
        assert!(q.min_dihedral_deg > 10.0 && q.max_dihedral_deg < 170.0, "{q:?}");
    }

    #[test]
    fn dihedral_angles_of_regular_tet() {
        let p = [
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
        ];
        // Regular tet: every dihedral angle is acos(1/3) = 70.5288 deg.
        for a in dihedral_angles(p) {
            assert!((a - (1.0f64 / 3.0).acos()).abs() < 1e-12, "{a}");
        }
        // Kuhn cube tets: angles are 45, 60, 90 degrees.
        let q = quality(&block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]));
        assert!(
            (q.min_dihedral_deg - 45.0).abs() < 1e-9 && (q.max_dihedral_deg - 90.0).abs() < 1e-9,
            "{q:?}"
        );
    }
}
