//! A layered tissue (`TissueBody::regions`) under tip remeshing: the
//! material of every tet the remesher makes, read off the mesh as built.
//!
//! A split's children lie inside their parent, so the built tet holding a
//! child's centroid is its parent and the label is exact. A snap moves a
//! node of the built mesh onto the needle without changing connectivity:
//! its tets keep their labels, so a snapped node on a layer face moves
//! that face with it (by at most the snap's offset, which
//! `remesh_max_offset` bounds).

use crate::coupling::barycentric;
use surgbench_core::{TetMesh, TissueBody, Vec3};

/// The mesh as built, each tet's material index
/// (`TissueBody::tet_materials`: 0 the body's, `k + 1` region `k`'s) and
/// the built tets around each built node.
pub struct BuiltLabels {
    mesh: TetMesh,
    label: Vec<usize>,
    around: Vec<Vec<usize>>,
}

impl BuiltLabels {
    /// The labels of `body` as built.
    pub fn new(body: &TissueBody) -> Self {
        let (_, label) = body.tet_materials();
        let label = if label.is_empty() {
            vec![0; body.mesh.tets.len()]
        } else {
            label
        };
        let mut around = vec![Vec::new(); body.mesh.nodes.len()];
        for (e, t) in body.mesh.tets.iter().enumerate() {
            for &i in t {
                around[i].push(e);
            }
        }
        Self {
            mesh: body.mesh.clone(),
            label,
            around,
        }
    }

    /// The material index of every tet of `mesh`, a remeshing of the built
    /// mesh (its first nodes are the built ones, some moved by snaps). A tet
    /// the built mesh has in the same slot keeps its label; another takes
    /// that of the built tet holding its rest centroid best (largest
    /// smallest barycentric weight), searched among the built tets around
    /// its built corners, or among all of them if it has none.
    pub fn labels(&self, mesh: &TetMesh) -> Vec<usize> {
        mesh.tets
            .iter()
            .enumerate()
            .map(|(e, t)| {
                if self.mesh.tets.get(e) == Some(t) {
                    return self.label[e];
                }
                let c = t.iter().map(|&i| mesh.nodes[i]).sum::<Vec3>() / 4.0;
                let mut near: Vec<usize> = t
                    .iter()
                    .filter_map(|&i| self.around.get(i))
                    .flatten()
                    .copied()
                    .collect();
                if near.is_empty() {
                    near = (0..self.mesh.tets.len()).collect();
                }
                near.sort_unstable();
                near.dedup();
                near.iter()
                    .filter_map(|&b| {
                        let w = barycentric(self.mesh.tets[b].map(|i| self.mesh.nodes[i]), &c)?;
                        Some((b, w.iter().copied().fold(f64::INFINITY, f64::min)))
                    })
                    .fold(None, |best: Option<(usize, f64)>, (b, m)| match best {
                        Some((_, bm)) if bm >= m => best,
                        _ => Some((b, m)),
                    })
                    .map_or(0, |(b, _)| self.label[b])
            })
            .collect()
    }

    /// Set the tets of `body`'s regions from `labels` (one per tet of its
    /// mesh, as [`BuiltLabels::labels`] gives them).
    pub fn relabel(body: &mut TissueBody, labels: &[usize]) {
        for r in &mut body.regions {
            r.tets.clear();
        }
        for (e, &k) in labels.iter().enumerate() {
            if k > 0 {
                body.regions[k - 1].tets.push(e);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::remesh::{Place, Remesher};
    use surgbench_core::{SolidMaterial, TissueRegion, mesh};

    /// A 2 x 1 x 1 block whose second cell (x > 1) is a region: every tet a
    /// split makes takes its parent's label, the built tets keep theirs,
    /// and undoing every operation gives the built labels back.
    #[test]
    fn the_tets_a_split_makes_take_their_parents_label() {
        let m = mesh::block_mirrored(Vec3::new(2.0, 1.0, 1.0), [2, 1, 1]);
        let gel = SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.3,
            density: 1e3,
        };
        let centroid = |m: &TetMesh, e: usize| m.tets[e].iter().map(|&i| m.nodes[i]).sum::<Vec3>() / 4.0;
        let second: Vec<usize> = (0..m.tets.len()).filter(|&e| centroid(&m, e).x > 1.0).collect();
        let mut body = TissueBody::new(m.clone(), gel);
        body.regions.push(TissueRegion {
            name: "b".into(),
            material: gel,
            tets: second,
            cutting_force: Some(1.0),
        });
        let built = BuiltLabels::new(&body);
        assert_eq!(built.labels(&m), body.tet_materials().1);
        let mut r = Remesher::new(&m);
        // No snaps: points strictly inside a tet of each cell split it.
        r.set_max_offset(0.0);
        for u in [Vec3::new(0.55, 0.4, 0.3), Vec3::new(1.45, 0.6, 0.35)] {
            r.place(u, Place::New).unwrap();
        }
        let after = r.mesh();
        assert!(after.tets.len() > m.tets.len());
        let l = built.labels(&after);
        for (e, k) in l.iter().enumerate() {
            // The cell face x = 1 is a grid plane: no tet straddles it.
            assert_eq!(*k, usize::from(centroid(&after, e).x > 1.0), "tet {e}");
        }
        let mut b2 = body.clone();
        b2.mesh = after;
        BuiltLabels::relabel(&mut b2, &l);
        assert_eq!(b2.tet_materials().1, l);
        while r.pop().is_some() {}
        assert_eq!(built.labels(&r.mesh()), body.tet_materials().1);
    }
}
