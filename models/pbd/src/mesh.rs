//! A structured tetrahedral block, for tests and benchmarks (the harness's
//! tissue scenes bring their own meshes).

use surgbench_core::{TetMesh, Vec3};

/// Axis-aligned block `[0, size.x] x [0, size.y] x [0, size.z]` (m) split into
/// `cells[0] x cells[1] x cells[2]` cubes of 6 tetrahedra each (Kuhn /
/// Freudenthal subdivision along the main diagonal, conforming across cells).
/// Every tet is positively oriented. Node `(i, j, k)` has index
/// `i + (cells[0] + 1) * (j + (cells[1] + 1) * k)`.
///
/// ```
/// let m = surgbench_pbd::block_tet_mesh([2, 1, 1], surgbench_core::Vec3::new(2.0, 1.0, 1.0));
/// assert_eq!(m.tets.len(), 12);
/// assert_eq!(m.nodes.len(), 12);
/// ```
pub fn block_tet_mesh(cells: [usize; 3], size: Vec3) -> TetMesh {
    let [nx, ny, nz] = cells;
    let id = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);
    let mut nodes = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                nodes.push(Vec3::new(
                    size.x * i as f64 / nx as f64,
                    size.y * j as f64 / ny as f64,
                    size.z * k as f64 / nz as f64,
                ));
            }
        }
    }
    const PERMS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for p in PERMS {
                    let mut c = [i, j, k];
                    let mut t = [id(c[0], c[1], c[2]); 4];
                    for (s, &axis) in p.iter().enumerate() {
                        c[axis] += 1;
                        t[s + 1] = id(c[0], c[1], c[2]);
                    }
                    let [a, b, cc, d] = t.map(|n| nodes[n]);
                    if (b - a).cross(&(cc - a)).dot(&(d - a)) < 0.0 {
                        t.swap(2, 3);
                    }
                    tets.push(t);
                }
            }
        }
    }
    TetMesh { nodes, tets }
}
