//! The zero level set of any [`Sdf`] as a triangle surface
//! ([`level_surface`]): the wall a collision engine needs as a mesh when
//! the scene gives the lumen only as a signed distance.

use super::Sdf;
use crate::io::TriSurface;
use crate::{Iso3, Vec3};
// Neighbouring cubes cut their shared faces along the same diagonal, so
// the surface has no cracks.
use crate::mesh::KUHN;
use std::collections::HashMap;

/// Grid sample index.
type Node = [i64; 3];

/// Samples of the SDF on the grid, evaluated once each and only where a
/// cell may hold the surface.
struct Grid<'a> {
    sdf: &'a dyn Sdf,
    level: f64,
    frame: Iso3,
    lo: Vec3,
    h: f64,
    values: HashMap<Node, f64>,
}

impl Grid<'_> {
    /// Grid node `n` in world coordinates.
    fn point(&self, n: Node) -> Vec3 {
        let local = self.lo + Vec3::new(n[0] as f64, n[1] as f64, n[2] as f64) * self.h;
        self.frame.transform_point(&local.into()).coords
    }

    fn value(&mut self, n: Node) -> f64 {
        if let Some(&v) = self.values.get(&n) {
            return v;
        }
        let v = self.sdf.distance(&self.point(n)) - self.level;
        self.values.insert(n, v);
        v
    }
}

/// Triangles of the level set `phi = level` (m) of `sdf` inside the box
/// `[lo, hi]` (m) of the frame `frame` (world coordinates out: a scene
/// moved rigidly with its frame gets the same mesh, moved), by marching
/// tetrahedra on a grid of spacing `spacing` (m) along the frame's axes,
/// oriented with their normals (right-hand rule) towards positive
/// distance, i.e. out of the lumen into the wall. `level = 0` is the wall;
/// a positive level moves the surface out by that much, e.g. so that the
/// facets, chords of a round lumen, do not cut into it.
///
/// Vertices lie where the SDF, linear along each grid edge, crosses zero:
/// for a smooth wall of radius of curvature `R` they are within about
/// `spacing^2 / (8 R)` of it, and a flat facet between them sags at most
/// as much (a chord of length `spacing`). Only cells whose centre is
/// within `2 x` their half-diagonal plus one spacing of the surface are
/// visited (an octree descent; the margin covers SDFs that are Lipschitz
/// up to 2, e.g. interpolated grids), so the cost scales with the wall's
/// area over `spacing^2`, not with the box's volume. The surface is cut
/// open where the box clips the wall; vertices on a shared grid edge are
/// shared, so it is a connected mesh where the wall is. Zero-area
/// triangles (a vertex exactly on a sample) are dropped.
pub fn level_surface(
    sdf: &dyn Sdf,
    level: f64,
    frame: &Iso3,
    lo: Vec3,
    hi: Vec3,
    spacing: f64,
) -> Result<TriSurface, String> {
    if !(spacing > 0.0 && spacing.is_finite()) {
        return Err(format!("grid spacing must be > 0, got {spacing}"));
    }
    let ext = hi - lo;
    if !(ext.min() > 0.0 && ext.iter().all(|v| v.is_finite())) {
        return Err(format!("empty or unbounded box {lo:?} .. {hi:?}"));
    }
    let cells: Vec<i64> = ext.iter().map(|e| (e / spacing).ceil() as i64).collect();
    let total: f64 = cells.iter().map(|&c| c as f64).product();
    if total > 1e12 {
        return Err(format!("box of {total:.1e} cells at spacing {spacing} m: too fine"));
    }
    if !level.is_finite() {
        return Err(format!("level must be finite, got {level}"));
    }
    let mut grid = Grid {
        sdf,
        level,
        frame: *frame,
        lo,
        h: spacing,
        values: HashMap::new(),
    };
    let mut out = Mesher::default();
    // Octree descent over cubes of 2^k cells from one covering the box.
    let mut size = 1i64;
    while size < *cells.iter().max().unwrap_or(&1) {
        size *= 2;
    }
    let mut stack = vec![([0i64; 3], size)];
    while let Some((at, size)) = stack.pop() {
        if (0..3).any(|a| at[a] >= cells[a]) {
            continue;
        }
        let half_diag = 0.5 * 3f64.sqrt() * size as f64 * spacing;
        let local = grid.lo
            + Vec3::new(at[0] as f64, at[1] as f64, at[2] as f64) * spacing
            + Vec3::repeat(0.5 * size as f64 * spacing);
        let centre = grid.frame.transform_point(&local.into()).coords;
        if (sdf.distance(&centre) - level).abs() > 2.0 * half_diag + spacing {
            continue;
        }
        if size == 1 {
            out.cell(&mut grid, at);
            continue;
        }
        let s = size / 2;
        for c in 0..8 {
            stack.push((
                [
                    at[0] + s * (c & 1),
                    at[1] + s * ((c >> 1) & 1),
                    at[2] + s * ((c >> 2) & 1),
                ],
                s,
            ));
        }
    }
    Ok(out.surface)
}

/// Builds the surface cell by cell, one vertex per crossed grid edge.
#[derive(Default)]
struct Mesher {
    surface: TriSurface,
    edge_vertex: HashMap<(Node, Node), usize>,
}

impl Mesher {
    fn cell(&mut self, grid: &mut Grid<'_>, at: Node) {
        let corner = |c: usize| {
            [
                at[0] + (c & 1) as i64,
                at[1] + ((c >> 1) & 1) as i64,
                at[2] + ((c >> 2) & 1) as i64,
            ]
        };
        let values: Vec<f64> = (0..8).map(|c| grid.value(corner(c))).collect();
        if values.iter().all(|&v| v >= 0.0) || values.iter().all(|&v| v < 0.0) {
            return;
        }
        for tet in KUHN {
            let nodes = tet.map(corner);
            let vals = tet.map(|c| values[c]);
            let (pos, neg): (Vec<usize>, Vec<usize>) = (0..4).partition(|&i| vals[i] >= 0.0);
            // Crossed edges in cyclic order around the cut.
            let edges: Vec<(usize, usize)> = match (pos.len(), neg.len()) {
                (1, 3) => neg.iter().map(|&n| (pos[0], n)).collect(),
                (3, 1) => pos.iter().map(|&p| (p, neg[0])).collect(),
                (2, 2) => vec![(pos[0], neg[0]), (pos[0], neg[1]), (pos[1], neg[1]), (pos[1], neg[0])],
                _ => continue,
            };
            let verts: Vec<usize> = edges
                .iter()
                .map(|&(p, n)| self.vertex(grid, nodes[p], vals[p], nodes[n], vals[n]))
                .collect();
            // Direction of increasing distance through this tet.
            let up: Vec3 = pos.iter().map(|&i| grid.point(nodes[i])).sum::<Vec3>() / pos.len() as f64
                - neg.iter().map(|&i| grid.point(nodes[i])).sum::<Vec3>() / neg.len() as f64;
            self.triangle([verts[0], verts[1], verts[2]], &up);
            if verts.len() == 4 {
                self.triangle([verts[0], verts[2], verts[3]], &up);
            }
        }
    }

    /// The vertex where the SDF crosses zero on the edge from `p` (>= 0) to
    /// `n` (< 0), linear along the edge.
    fn vertex(&mut self, grid: &Grid<'_>, p: Node, vp: f64, n: Node, vn: f64) -> usize {
        let key = if p < n { (p, n) } else { (n, p) };
        if let Some(&v) = self.edge_vertex.get(&key) {
            return v;
        }
        let t = vp / (vp - vn);
        let x = grid.point(p) + (grid.point(n) - grid.point(p)) * t;
        self.surface.vertices.push(x);
        let id = self.surface.vertices.len() - 1;
        self.edge_vertex.insert(key, id);
        id
    }

    /// Add `t` wound so that its normal points along `up`; drop it if it has
    /// no area.
    fn triangle(&mut self, t: [usize; 3], up: &Vec3) {
        let v = &self.surface.vertices;
        let n = (v[t[1]] - v[t[0]]).cross(&(v[t[2]] - v[t[0]]));
        let d = n.dot(up);
        if n.norm_squared() == 0.0 || d == 0.0 {
            return;
        }
        self.surface
            .triangles
            .push(if d > 0.0 { t } else { [t[0], t[2], t[1]] });
    }
}

/// The lumen's radius near `p` (m): the deepest distance to the wall along
/// the ray from `p` away from its nearest wall point (for a round lumen
/// the ray meets the axis at `-phi = R`); `None` if `p` is not inside.
/// Sizes a wall mesh's spacing to the lumen a wire starts in.
pub fn lumen_radius_at(vessel: &dyn Sdf, p: &Vec3) -> Option<f64> {
    let (d0, g) = vessel.distance_gradient(p);
    if !(d0 < 0.0) || g.norm() == 0.0 {
        return (d0 < 0.0).then_some(-d0);
    }
    let inward = -g.normalize();
    let f = |t: f64| vessel.distance(&(p + inward * t));
    // Steps growing by 1.5 while the distance deepens bracket its deepest
    // point in [lo, hi] (mid the deepest sample so far) ...
    let (mut lo, mut mid, mut f_mid) = (0.0, 0.0, d0);
    let mut step = -0.25 * d0;
    let (mut hi, mut f_hi) = (step, f(step));
    for _ in 0..200 {
        if !(f_hi < f_mid) {
            break;
        }
        (lo, mid, f_mid) = (mid, hi, f_hi);
        step *= 1.5;
        hi = mid + step;
        f_hi = f(hi);
    }
    // ... and a golden-section search narrows the bracket to 1e-3 of the
    // depth: the distance falls at slope 1 towards a round lumen's axis, so
    // the deepest value is then within 0.1 % of the radius.
    let k = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut c) = (lo, hi);
    let (mut x1, mut x2) = (c - k * (c - a), a + k * (c - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    let mut best = f_mid.min(f1).min(f2);
    for _ in 0..200 {
        if c - a <= -1e-3 * best {
            break;
        }
        if f1 < f2 {
            (c, x2, f2) = (x2, x1, f1);
            x1 = c - k * (c - a);
            f1 = f(x1);
        } else {
            (a, x1, f1) = (x1, x2, f2);
            x2 = a + k * (c - a);
            f2 = f(x2);
        }
        best = best.min(f1).min(f2);
    }
    Some(-best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::{CenterlineBuilder, StraightTube};

    /// A straight tube clipped by a box: every vertex on the wall to the
    /// chord-sag bound, every normal pointing out of the lumen, and the
    /// facets' area short of `2 pi R L` by no more than an inscribed
    /// polygon's.
    #[test]
    fn straight_tube_is_on_the_wall_and_faces_out() {
        let r = 2e-3;
        let tube = StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: r,
        };
        let len = 10e-3;
        let h = r / 8.0;
        let s = level_surface(
            &tube,
            0.0,
            &Iso3::identity(),
            Vec3::new(0.0, -3e-3, -3e-3),
            Vec3::new(len, 3e-3, 3e-3),
            h,
        )
        .unwrap();
        assert!(s.triangles.len() > 1000);
        let sag = h * h / (8.0 * r);
        for v in &s.vertices {
            // Vertices interpolate the exact distance linearly along edges
            // of length up to sqrt(3) h: error <= 3 h^2 / (8 R).
            assert!(
                tube.distance(v).abs() <= 3.0 * sag,
                "vertex {v:?} off the wall by {}",
                tube.distance(v)
            );
        }
        let mut area = 0.0;
        let mut worst_cos: f64 = 1.0;
        for t in &s.triangles {
            let [a, b, c] = t.map(|i| s.vertices[i]);
            let n = (b - a).cross(&(c - a));
            area += 0.5 * n.norm();
            let centroid = (a + b + c) / 3.0;
            let radial = Vec3::new(0.0, centroid.y, centroid.z);
            assert!(n.dot(&radial) > 0.0, "triangle {t:?} faces into the lumen");
            let cosang = n.normalize().dot(&radial.normalize());
            worst_cos = worst_cos.min(cosang);
        }
        let want = 2.0 * std::f64::consts::PI * r * len;
        // Facets are chords of the wall: the area falls short of it by the
        // inscribed polygon's deficit, (l/R)^2/24 for chords of length l
        // <= sqrt(3) h, so at most 3 (h/R)^2 / 24 = 2.0e-3 at h = R/8
        // (measured 7.4e-4, and 1.8e-4 at h = R/16: order 2).
        eprintln!("worst facet tilt {} deg", worst_cos.acos().to_degrees());
        let deficit = 1.0 - area / want;
        assert!(
            deficit > 0.0 && deficit <= 3.0 * (h / r).powi(2) / 24.0,
            "area {area} against {want}"
        );
    }

    /// A bent swept tube: the mesh is watertight inside the box (every
    /// edge shared by exactly two triangles except along the box's faces)
    /// and consistently wound (a shared edge runs opposite ways).
    #[test]
    fn bent_tube_mesh_is_manifold_and_consistent() {
        let tube = CenterlineBuilder::new(Vec3::new(-0.02, 0.0, 0.0), Vec3::x())
            .line(0.02)
            .arc(0.01, std::f64::consts::FRAC_PI_2, Vec3::y())
            .line(0.02)
            .build_constant(1.5e-3)
            .unwrap();
        let s = level_surface(
            &tube,
            0.0,
            &Iso3::identity(),
            Vec3::new(-0.01, -0.005, -0.005),
            Vec3::new(0.015, 0.03, 0.005),
            2e-4,
        )
        .unwrap();
        let mut edges: HashMap<(usize, usize), i32> = HashMap::new();
        for t in &s.triangles {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        let near_box = |v: &Vec3| v.x < -0.01 + 2e-4 || v.y > 0.03 - 2e-4;
        let mut open = 0;
        for (&(a, b), &c) in &edges {
            // Each directed edge once; its reverse once unless at the cut.
            assert_eq!(c, 1, "edge {a}-{b} used twice the same way");
            if !edges.contains_key(&(b, a)) {
                open += 1;
                assert!(
                    near_box(&s.vertices[a]) && near_box(&s.vertices[b]),
                    "open edge inside the box"
                );
            }
        }
        assert!(open > 0, "the box cuts the tube, so the mesh must be open there");
    }
    #[test]
    fn the_lumen_radius_is_found_from_off_axis() {
        let r = 3e-3;
        let tube = StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: r,
        };
        // From every depth, near the axis to near the wall (a search that
        // only stepped forward overshot the axis by up to 18 % of R).
        for k in 1..100 {
            let off = r * k as f64 / 100.0;
            let p = Vec3::new(0.01, 0.6 * off, -0.8 * off);
            let got = lumen_radius_at(&tube, &p).unwrap();
            // The line search stops within 0.1 % of the radius (its doc).
            assert!((got - r).abs() <= 1e-3 * r, "{got} vs {r} from {p:?}");
        }
        // On the axis the gradient vanishes: the distance itself is R.
        assert!((lumen_radius_at(&tube, &Vec3::zeros()).unwrap() - r).abs() < 1e-15);
        assert_eq!(lumen_radius_at(&tube, &Vec3::new(0.0, 4e-3, 0.0)), None);
    }
}
