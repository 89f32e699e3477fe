//! Ghost collision surface of a hybrid vessel: the triangles of a tetrahedral
//! wall's inner boundary, carried by the wall's nodes and used only for
//! catheter / guidewire collision (the hybrid vessel of the PBD vessel seed
//! paper: a tetrahedral wall with thickness for the deformation, a triangle
//! surface on its inner side for the contact).
//!
//! * [`GhostSurface::from_inner_wall`] picks the boundary faces of the tet
//!   mesh whose three nodes satisfy a predicate (e.g. "on the inner radius"),
//!   oriented with the normal pointing out of the wall material, i.e. into
//!   the lumen;
//! * [`GhostSurface::update`] refits its bounding-volume hierarchy to the
//!   current node positions (the tree's topology is built once);
//! * [`GhostSurface::closest`] answers the closest surface point to a query
//!   point within a search radius (exact point-triangle distance, Ericson,
//!   "Real-Time Collision Detection", 2005, sec. 5.1.5), with the barycentric
//!   weights, the face normal and the signed gap along it;
//! * [`project_particle_triangle`] is the XPBD particle-triangle contact
//!   constraint that pushes a particle and the triangle's three nodes.
//!
//! Units are SI (m, kg).
//!
//! The contact constraint (Müller et al. 2007, "Position Based Dynamics",
//! sec. 4.4, in its XPBD form, Macklin et al. 2016 eqs. 17-18): with the
//! barycentric weights `b` and the face normal `n` frozen at detection,
//! `C = n . (p - sum_i b_i x_i) - thickness >= 0`, gradients `n` for the
//! particle and `-b_i n` for node `i`, so
//! `dlambda = -(C + alpha~ lambda) / (w_p + sum_i b_i^2 w_i + alpha~)`,
//! `p += w_p n dlambda`, `x_i -= w_i b_i n dlambda`, with the accumulated
//! `lambda >= 0` (contact pushes, never pulls). The mass-weighted sum of the
//! corrections is `n dlambda (1 - sum_i b_i) = 0`: the contact conserves
//! linear momentum for any masses.

use surgbench_core::{TetMesh, Vec3};

/// Leaves hold at most this many triangles.
const LEAF_SIZE: usize = 4;

/// A node of the bounding-volume hierarchy: an axis-aligned box and either
/// two children or a range of `order`.
#[derive(Debug, Clone, Copy)]
struct BvhNode {
    lo: Vec3,
    hi: Vec3,
    /// Children (internal node) or `usize::MAX`.
    left: usize,
    right: usize,
    /// Range of `order` (leaf).
    start: usize,
    end: usize,
}

/// Closest point of a ghost surface to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceHit {
    /// Triangle index (into [`GhostSurface::triangles`]).
    pub triangle: usize,
    /// Barycentric weights of the closest point on the triangle (sum to 1).
    pub bary: [f64; 3],
    /// Closest point (m).
    pub point: Vec3,
    /// Unit face normal, pointing out of the wall into the lumen.
    pub normal: Vec3,
    /// Euclidean distance from the query point to the surface (m).
    pub distance: f64,
    /// Signed gap `n . (p - point)` (m): positive on the lumen side,
    /// negative when the point is past the surface into the wall.
    pub gap: f64,
}

/// The inner-wall triangles of a tet mesh, carried by its nodes.
#[derive(Debug, Clone)]
pub struct GhostSurface {
    /// Triangles as tet-mesh node indices, ordered so that
    /// `(x1 - x0) x (x2 - x0)` points out of the wall into the lumen.
    pub triangles: Vec<[u32; 3]>,
    /// Current positions of the triangles' nodes (m), indexed like the mesh.
    positions: Vec<Vec3>,
    nodes: Vec<BvhNode>,
    order: Vec<u32>,
}

impl GhostSurface {
    /// Boundary faces of `mesh` whose three nodes' rest positions satisfy
    /// `on_inner_wall`, oriented away from their tet (into the lumen).
    /// `None` if no face qualifies.
    pub fn from_inner_wall(mesh: &TetMesh, on_inner_wall: impl Fn(&Vec3) -> bool) -> Option<Self> {
        let inner: Vec<bool> = mesh.nodes.iter().map(&on_inner_wall).collect();
        // Faces of a tet with the opposite vertex; a face seen once is on the boundary.
        let mut faces: Vec<([u32; 3], [u32; 3], usize)> = Vec::new();
        for t in &mesh.tets {
            for (f, opp) in [([1, 2, 3], 0), ([0, 3, 2], 1), ([0, 1, 3], 2), ([0, 2, 1], 3)] {
                let face = f.map(|k| t[k] as u32);
                let mut key = face;
                key.sort_unstable();
                faces.push((key, face, t[opp]));
            }
        }
        faces.sort_unstable_by_key(|f| f.0);
        let mut triangles = Vec::new();
        let mut k = 0;
        while k < faces.len() {
            let mut j = k + 1;
            while j < faces.len() && faces[j].0 == faces[k].0 {
                j += 1;
            }
            let (_, mut face, opp) = faces[k];
            if j == k + 1 && face.iter().all(|&i| inner[i as usize]) {
                let [a, b, c] = face.map(|i| mesh.nodes[i as usize]);
                // Normal away from the tet's fourth node, whatever the tet's sign.
                if (b - a).cross(&(c - a)).dot(&(mesh.nodes[opp] - a)) > 0.0 {
                    face.swap(1, 2);
                }
                triangles.push(face);
            }
            k = j;
        }
        if triangles.is_empty() {
            return None;
        }
        let mut s = Self {
            triangles,
            positions: mesh.nodes.clone(),
            nodes: Vec::new(),
            order: Vec::new(),
        };
        s.build();
        Some(s)
    }

    /// Box of triangle `t` at the current positions.
    fn tri_box(&self, t: usize) -> (Vec3, Vec3) {
        let [a, b, c] = self.triangles[t].map(|i| self.positions[i as usize]);
        (a.inf(&b).inf(&c), a.sup(&b).sup(&c))
    }

    /// Top-down median split on the longest axis of the centroids' box.
    fn build(&mut self) {
        self.order = (0..self.triangles.len() as u32).collect();
        self.nodes.clear();
        let cent: Vec<Vec3> = (0..self.triangles.len())
            .map(|t| {
                self.triangles[t]
                    .iter()
                    .map(|&i| self.positions[i as usize])
                    .sum::<Vec3>()
                    / 3.0
            })
            .collect();
        let mut stack = vec![(0usize, self.order.len(), usize::MAX, false)];
        while let Some((start, end, parent, is_right)) = stack.pop() {
            let id = self.nodes.len();
            self.nodes.push(BvhNode {
                lo: Vec3::zeros(),
                hi: Vec3::zeros(),
                left: usize::MAX,
                right: usize::MAX,
                start,
                end,
            });
            if parent != usize::MAX {
                if is_right {
                    self.nodes[parent].right = id;
                } else {
                    self.nodes[parent].left = id;
                }
            }
            if end - start > LEAF_SIZE {
                let mut lo = Vec3::repeat(f64::INFINITY);
                let mut hi = Vec3::repeat(f64::NEG_INFINITY);
                for &t in &self.order[start..end] {
                    lo = lo.inf(&cent[t as usize]);
                    hi = hi.sup(&cent[t as usize]);
                }
                let axis = (hi - lo).imax();
                let mid = (start + end) / 2;
                self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                    cent[a as usize][axis]
                        .total_cmp(&cent[b as usize][axis])
                        .then(a.cmp(&b))
                });
                stack.push((mid, end, id, true));
                stack.push((start, mid, id, false));
            }
        }
        self.refit();
    }

    /// Recompute every box bottom-up (children are stored after parents).
    fn refit(&mut self) {
        for id in (0..self.nodes.len()).rev() {
            let n = self.nodes[id];
            let (lo, hi) = if n.left == usize::MAX {
                let mut lo = Vec3::repeat(f64::INFINITY);
                let mut hi = Vec3::repeat(f64::NEG_INFINITY);
                for &t in &self.order[n.start..n.end] {
                    let (a, b) = self.tri_box(t as usize);
                    lo = lo.inf(&a);
                    hi = hi.sup(&b);
                }
                (lo, hi)
            } else {
                let (l, r) = (self.nodes[n.left], self.nodes[n.right]);
                (l.lo.inf(&r.lo), l.hi.sup(&r.hi))
            };
            self.nodes[id].lo = lo;
            self.nodes[id].hi = hi;
        }
    }

    /// Follow the wall: take the current node positions (m, indexed like the
    /// mesh the surface was built from) and refit the hierarchy. Panics if
    /// `x` is shorter than that mesh's node list.
    pub fn update(&mut self, x: &[Vec3]) {
        let n = self.positions.len();
        self.positions.copy_from_slice(&x[..n]);
        self.refit();
    }

    /// Corner positions of triangle `t` (m).
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    /// The closest surface point to `p` within `max_dist` (m), or `None`.
    /// Ties go to the lower triangle index (deterministic).
    pub fn closest(&self, p: &Vec3, max_dist: f64) -> Option<SurfaceHit> {
        let mut best: Option<(f64, usize, [f64; 3], Vec3)> = None;
        let mut bound2 = max_dist * max_dist;
        let mut stack = vec![0usize];
        while let Some(id) = stack.pop() {
            let n = &self.nodes[id];
            let d = (n.lo - p).sup(&(p - n.hi)).sup(&Vec3::zeros());
            if d.norm_squared() > bound2 {
                continue;
            }
            if n.left == usize::MAX {
                for &t in &self.order[n.start..n.end] {
                    let t = t as usize;
                    let [a, b, c] = self.corners(t);
                    let (q, bary) = closest_on_triangle(p, &a, &b, &c);
                    let d2 = (p - q).norm_squared();
                    let better = match best {
                        None => d2 <= bound2,
                        Some((bd, bt, _, _)) => d2 < bd || (d2 == bd && t < bt),
                    };
                    if better {
                        best = Some((d2, t, bary, q));
                        bound2 = d2;
                    }
                }
            } else {
                stack.push(n.right);
                stack.push(n.left);
            }
        }
        best.map(|(d2, t, bary, q)| {
            let [a, b, c] = self.corners(t);
            let normal = (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or(Vec3::zeros());
            SurfaceHit {
                triangle: t,
                bary,
                point: q,
                normal,
                distance: d2.sqrt(),
                gap: normal.dot(&(p - q)),
            }
        })
    }
}

/// Closest point on triangle `abc` to `p` and its barycentric weights
/// (Ericson 2005, sec. 5.1.5: Voronoi regions of vertices, edges, face).
pub fn closest_on_triangle(p: &Vec3, a: &Vec3, b: &Vec3, c: &Vec3) -> (Vec3, [f64; 3]) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

/// One XPBD projection of the particle-triangle contact (module docs): moves
/// the particle `p` (inverse mass `wp`, 1/kg) and the triangle's nodes
/// `tri` (inverse masses `wt`) along `normal` so that the particle is at
/// least `thickness` (m) on the lumen side of the point with barycentric
/// weights `bary`. `alpha_tilde = alpha / h^2` (0 for a hard contact);
/// `lambda` accumulates the multiplier (kept >= 0). Returns the constraint
/// value `C` before the projection (m; negative = penetrating).
pub fn project_particle_triangle(
    p: &mut Vec3,
    wp: f64,
    tri: &mut [Vec3; 3],
    wt: [f64; 3],
    bary: [f64; 3],
    normal: &Vec3,
    thickness: f64,
    alpha_tilde: f64,
    lambda: &mut f64,
) -> f64 {
    let q = tri[0] * bary[0] + tri[1] * bary[1] + tri[2] * bary[2];
    let c = normal.dot(&(*p - q)) - thickness;
    let den = wp + (0..3).map(|k| bary[k] * bary[k] * wt[k]).sum::<f64>() + alpha_tilde;
    if den == 0.0 {
        return c;
    }
    // Inequality: project only while violated, and never pull (lambda >= 0).
    let dl = (-(c + alpha_tilde * *lambda) / den).max(-*lambda);
    if dl == 0.0 {
        return c;
    }
    *lambda += dl;
    *p += normal * (wp * dl);
    for k in 0..3 {
        tri[k] -= normal * (wt[k] * bary[k] * dl);
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::testrng::Rng;

    #[test]
    fn closest_point_on_triangle_is_the_minimum_over_a_dense_sampling() {
        let mut rng = Rng(3);
        for case in 0..200 {
            let [a, b, c, p] = [
                rng.signed_vec(),
                rng.signed_vec(),
                rng.signed_vec(),
                rng.signed_vec() * 2.0,
            ];
            let (q, bary) = closest_on_triangle(&p, &a, &b, &c);
            let recon = a * bary[0] + b * bary[1] + c * bary[2];
            assert!(
                (recon - q).norm() < 1e-12,
                "case {case}: bary {bary:?} do not give {q:?}"
            );
            assert!(bary.iter().all(|&x| x >= -1e-12), "case {case}: bary {bary:?}");
            let d = (p - q).norm();
            // Sampled minimum over a 100 x 100 barycentric grid can only be
            // larger (up to the grid's resolution); it must never be smaller.
            let n = 100;
            let mut dmin = f64::INFINITY;
            for i in 0..=n {
                for j in 0..=(n - i) {
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    dmin = dmin.min((p - (a * (1.0 - u - v) + b * u + c * v)).norm());
                }
            }
            assert!(d <= dmin + 1e-12, "case {case}: closest {d} but a sample is at {dmin}");
        }
    }

    #[test]
    fn contact_correction_conserves_momentum_and_resolves_the_penetration() {
        let mut rng = Rng(9);
        for case in 0..50 {
            let mut tri = [rng.signed_vec(), rng.signed_vec(), rng.signed_vec()];
            let n = (tri[1] - tri[0]).cross(&(tri[2] - tri[0])).normalize();
            let bary = {
                let (u, v) = (0.5 * (rng.signed() + 1.0), 0.5 * (rng.signed() + 1.0));
                let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
                [1.0 - u - v, u, v]
            };
            let q = tri[0] * bary[0] + tri[1] * bary[1] + tri[2] * bary[2];
            let mut p = q - n * 0.1 * (1.0 + rng.signed()).max(0.01);
            let masses = [1.0, 1.0 + rng.signed().abs(), 2.0, 0.5 + rng.signed().abs()];
            let (p0, t0) = (p, tri);
            let mut lambda = 0.0;
            let c = project_particle_triangle(
                &mut p,
                1.0 / masses[0],
                &mut tri,
                [1.0 / masses[1], 1.0 / masses[2], 1.0 / masses[3]],
                bary,
                &n,
                0.0,
                0.0,
                &mut lambda,
            );
            assert!(c < 0.0, "case {case}: not penetrating, C = {c}");
            let momentum = (p - p0) * masses[0] + (0..3).map(|k| (tri[k] - t0[k]) * masses[k + 1]).sum::<Vec3>();
            // sum_i b_i = 1 up to roundoff: the impulse balance is exact to eps * |dx|.
            assert!(momentum.norm() < 1e-14, "case {case}: momentum change {momentum:?}");
            let q1 = tri[0] * bary[0] + tri[1] * bary[1] + tri[2] * bary[2];
            // A hard contact with frozen n and b is linear: one projection resolves it.
            let c1 = n.dot(&(p - q1));
            assert!(c1.abs() < 1e-14, "case {case}: C after projection {c1}");
            // A separated pair is left alone.
            let (pp, tt) = (p + n * 0.1, tri);
            let mut p2 = pp;
            let mut t2 = tt;
            let mut l2 = 0.0;
            project_particle_triangle(&mut p2, 1.0, &mut t2, [1.0; 3], bary, &n, 0.0, 0.0, &mut l2);
            assert!(p2 == pp && t2 == tt && l2 == 0.0, "case {case}: separated pair moved");
        }
    }
}
