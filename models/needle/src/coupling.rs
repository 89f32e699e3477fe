//! Where a coupling point sits: a tissue material point embedded in a tet
//! (barycentric weights, the embedded variant of the seed's coupling map
//! `W^`, Chentanez et al. 2009 Eq. 7) and a needle point at an arclength
//! (linear between two needle nodes).

use surgbench_core::Vec3;

/// A material point of the tissue: tet and barycentric weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Embedded {
    /// Tet index.
    pub tet: usize,
    /// Weights of the tet's four nodes (sum 1).
    pub w: [f64; 4],
}

impl Embedded {
    /// Its position (m) for node positions `nodes`.
    pub fn position(&self, tets: &[[usize; 4]], nodes: &[Vec3]) -> Vec3 {
        let t = tets[self.tet];
        (0..4).map(|a| nodes[t[a]] * self.w[a]).sum()
    }
}

/// Barycentric weights of `x` in the tet `p` (`None` if the tet is degenerate).
pub fn barycentric(p: [Vec3; 4], x: &Vec3) -> Option<[f64; 4]> {
    let m = nalgebra::Matrix3::from_columns(&[p[1] - p[0], p[2] - p[0], p[3] - p[0]]);
    let l = m.try_inverse()? * (x - p[0]);
    Some([1.0 - l.x - l.y - l.z, l.x, l.y, l.z])
}

/// The tet of the mesh (`tets` over `nodes`) that contains `x`, with its
/// weights; on a shared face or edge the tet whose smallest weight is the
/// largest. `None` if `x` is outside every tet by more than `1e-9` in
/// barycentric terms. Linear search: the caller does it once per new point.
pub fn locate(tets: &[[usize; 4]], nodes: &[Vec3], x: &Vec3) -> Option<Embedded> {
    locate_within(tets, nodes, x, 1e-9)
}

/// [`locate`] accepting `x` up to `slack` outside a tet in barycentric
/// terms (its smallest weight `>= -slack`), the tet whose smallest weight
/// is the largest. Where the tissue is strongly deformed around the tip,
/// inverted or sliver tets leave gaps in the deformed mesh that a strict
/// search falls through.
pub fn locate_within(tets: &[[usize; 4]], nodes: &[Vec3], x: &Vec3, slack: f64) -> Option<Embedded> {
    let mut best: Option<(f64, Embedded)> = None;
    for (e, t) in tets.iter().enumerate() {
        let p = t.map(|i| nodes[i]);
        let Some(w) = barycentric(p, x) else { continue };
        let lo = w.iter().copied().fold(f64::INFINITY, f64::min);
        if lo >= -slack && best.as_ref().is_none_or(|b| lo > b.0) {
            best = Some((lo, Embedded { tet: e, w }));
        }
    }
    best.map(|b| b.1)
}

/// A point on the needle: two consecutive nodes and their weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnNeedle {
    /// Node indices `k, k + 1`.
    pub nodes: [usize; 2],
    /// Weights (sum 1).
    pub w: [f64; 2],
}

/// The needle point at arclength `a` (m from the clamp) for node arclengths
/// `s` (node 1 at the clamp, `s[1] = 0`): on the edge that contains it,
/// clamped to the rod's ends.
pub fn on_needle(s: &[f64], a: f64) -> OnNeedle {
    let last = s.len() - 2;
    let k = (1..=last).find(|&k| a <= s[k + 1]).unwrap_or(last);
    let t = ((a - s[k]) / (s[k + 1] - s[k])).clamp(0.0, 1.0);
    OnNeedle {
        nodes: [k, k + 1],
        w: [1.0 - t, t],
    }
}

/// An orthonormal frame `[t, n1, n2]` (rows) with `t` the unit tangent.
pub fn frame(t: &Vec3) -> [Vec3; 3] {
    let helper = if t.x.abs() < 0.9 { Vec3::x() } else { Vec3::y() };
    let n1 = t.cross(&helper).normalize();
    let n2 = t.cross(&n1);
    [*t, n1, n2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn barycentric_weights_reproduce_the_point() {
        let p = [
            Vec3::zeros(),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0),
            Vec3::new(0.0, 0.0, 3.0),
        ];
        let x = Vec3::new(0.2, 0.3, 0.4);
        let w = barycentric(p, &x).unwrap();
        let back: Vec3 = (0..4).map(|a| p[a] * w[a]).sum();
        // Rounding only: a 3x3 inverse of O(1) entries.
        assert!((back - x).norm() < 1e-15);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn locate_finds_the_containing_tet_of_a_block() {
        let mesh = surgbench_core::mesh::block(Vec3::new(1.0, 1.0, 1.0), [2, 2, 2]);
        let x = Vec3::new(0.3, 0.7, 0.55);
        let e = locate(&mesh.tets, &mesh.nodes, &x).unwrap();
        assert!(e.w.iter().all(|&w| w >= -1e-9));
        assert!((e.position(&mesh.tets, &mesh.nodes) - x).norm() < 1e-14);
        assert!(locate(&mesh.tets, &mesh.nodes, &Vec3::new(-0.1, 0.5, 0.5)).is_none());
    }

    #[test]
    fn needle_points_interpolate_between_nodes() {
        let s = [-0.1, 0.0, 0.1, 0.2, 0.3];
        let p = on_needle(&s, 0.25);
        assert_eq!(p.nodes, [3, 4]);
        assert!((p.w[0] - 0.5).abs() < 1e-12);
        assert_eq!(on_needle(&s, 0.3).nodes, [3, 4]);
        assert_eq!(on_needle(&s, 0.0).nodes, [1, 2]);
        let f = frame(&Vec3::new(1.0, 0.0, 0.0));
        assert!((f[1].dot(&f[0])).abs() < 1e-15 && (f[2].norm() - 1.0).abs() < 1e-15);
    }
}
