//! Frame utilities rod models share: parallel transport and signed angles
//! (Bergou et al. 2008, "Discrete Elastic Rods", section 4.2).

use crate::{Iso3, Vec3};

/// Parallel-transport `u` from the unit tangent `t0` to the unit tangent `t1`:
/// rotate about `t0 x t1` by the angle between them. Exact for `t0 == t1`;
/// for antiparallel tangents the transport is undefined and `u` is returned.
pub fn parallel_transport(u: &Vec3, t0: &Vec3, t1: &Vec3) -> Vec3 {
    let b = t0.cross(t1);
    let s = b.norm();
    let c = t0.dot(t1);
    if s < 1e-300 {
        return *u;
    }
    if c <= -1.0 + 1e-15 {
        return *u;
    }
    // Rodrigues' rotation about the unit axis n = b/|b| by angle phi with
    // sin(phi) = s, cos(phi) = c:  u' = u c + (n x u) s + n (n.u)(1 - c),
    // written with b to avoid dividing by small s:  (1-c)/s^2 = 1/(1+c).
    u * c + b.cross(u) + b * (b.dot(u) / (1.0 + c))
}

/// Signed angle from `u` to `v` about the axis `axis` (rad, in (-pi, pi]).
pub fn signed_angle(u: &Vec3, v: &Vec3, axis: &Vec3) -> f64 {
    let w = u.cross(v);
    let s = w.dot(axis) / axis.norm();
    let c = u.dot(v);
    s.atan2(c)
}

/// Rotate `v` about the unit `axis` by `angle` (rad) (Rodrigues).
pub fn rotate_about(v: &Vec3, axis: &Vec3, angle: f64) -> Vec3 {
    let (s, c) = angle.sin_cos();
    v * c + axis.cross(v) * s + axis * (axis.dot(v) * (1.0 - c))
}

/// If `iso`'s rotation maps world axes onto world axes (a signed
/// permutation), the source axis of each new axis; else `None`.
pub fn axis_permutation(iso: &Iso3) -> Option<[usize; 3]> {
    let r = iso.rotation.to_rotation_matrix();
    let m = r.matrix();
    let mut perm = [0usize; 3];
    for i in 0..3 {
        let j = (0..3).find(|&j| (m[(i, j)].abs() - 1.0).abs() < 1e-12)?;
        perm[i] = j;
    }
    Some(perm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transport_maps_tangent_to_tangent_and_keeps_angles() {
        let t0 = Vec3::new(1.0, 0.2, -0.3).normalize();
        let t1 = Vec3::new(0.1, 1.0, 0.4).normalize();
        let u = t0.cross(&Vec3::z()).normalize();
        let pu = parallel_transport(&u, &t0, &t1);
        let pt = parallel_transport(&t0, &t0, &t1);
        assert!((pt - t1).norm() < 1e-14, "tangent maps to tangent");
        assert!(pu.dot(&t1).abs() < 1e-14, "normal stays normal");
        assert!((pu.norm() - 1.0).abs() < 1e-14, "length kept");
    }

    #[test]
    fn signed_angle_quarter_turn() {
        let a = signed_angle(&Vec3::y(), &Vec3::z(), &Vec3::x());
        assert!((a - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    }
}
