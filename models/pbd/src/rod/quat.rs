//! Quaternion and small-matrix helpers of the Cosserat rod: rotations,
//! Darboux vectors and 3x3 SPD solves.

use super::*;
use nalgebra::{Matrix3, UnitQuaternion};
use surgbench_core::band::BandMatrix;
use surgbench_core::{Mat3, Vec3};

/// Add the 3x3 block `m` at block position `(bi, bj)`, `bi >= bj`, of a
/// symmetric band matrix that stores the lower triangle (on the diagonal,
/// only `m`'s lower triangle is read).
pub(super) fn add_block(band: &mut BandMatrix, bi: usize, bj: usize, m: &Mat3) {
    for r in 0..3 {
        let cmax = if bi == bj { r + 1 } else { 3 };
        for c in 0..cmax {
            band.add(3 * bi + r, 3 * bj + c, m[(r, c)]);
        }
    }
}

/// `[e3]_x`: body-frame Jacobian of the stretch-shear constraint on its
/// segment's rotation (see [`PbdRod::assemble_direct`]).
pub(super) fn e3_cross() -> Mat3 {
    Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
}

/// Rotation matrix of a unit quaternion: columns are the directors `(d1, d2, d3)`.
pub(super) fn rotmat(q: &Quat) -> Mat3 {
    UnitQuaternion::new_unchecked(*q).to_rotation_matrix().into_inner()
}

/// Skew matrix `[v]_x` with `[v]_x u = v x u`.
pub(super) fn skew(v: &Vec3) -> Mat3 {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Material frame of the clamp: `d3` along the base's local x, `(d1, d2)` =
/// local `(y, z)`. The map `(e1, e2, e3) -> (y, z, x)` is the rotation by
/// 120 degrees about `(1, 1, 1)/sqrt(3)`: quaternion `(1/2, 1/2, 1/2, 1/2)`
/// (exact in floating point, no matrix-to-quaternion iteration per substep).
pub(super) fn material_of_base(rot: &UnitQuaternion<f64>) -> Quat {
    rot.into_inner() * Quat::new(0.5, 0.5, 0.5, 0.5)
}

/// `q (u, 0)`: right product with a pure quaternion. For a unit `q` with
/// rotation `R`, `(R u, 0) q = q (u, 0)`, so a world-frame rotation vector
/// `R u` applied as `q + 1/2 (R u, 0) q` is `q + 1/2 q (u, 0)` with the
/// body-frame `u`: no rotation matrix needed.
#[inline]
pub(super) fn mul_pure(q: &Quat, u: &Vec3) -> Quat {
    let v = q.imag();
    Quat::from_parts(-v.dot(u), u * q.w + v.cross(u))
}

/// `normalize(q + 1/2 q (u, 0))`: the XPBD orientation update with a
/// body-frame rotation vector `u` (rad).
///
/// For a near-unit `p` (`|p|^2 = 1 + eps`, `|eps| < 1e-4`) the normalisation
/// uses one Newton step of `1/sqrt` from 1, `1 - eps/2`, which leaves
/// `||p| (1 - eps/2) - 1| <= 3/8 eps^2 < 4e-9` and, applied again at the next
/// update, contracts any norm error quadratically; larger updates use the
/// exact square root. This keeps `sqrt` and a division off the Gauss-Seidel
/// dependency chain, where almost every update is tiny. (`predict`
/// normalises exactly once per substep.)
#[inline]
pub(super) fn rotate_body(q: &Quat, u: &Vec3) -> Quat {
    let p = q + mul_pure(q, &(u * 0.5));
    let eps = p.norm_squared() - 1.0;
    if eps.abs() < 1e-4 {
        p * (1.0 - 0.5 * eps)
    } else {
        p * (1.0 / p.norm())
    }
}

/// `conj(a) b` written out (the relative rotation of two frames).
#[inline]
pub(super) fn conj_mul(a: &Quat, b: &Quat) -> Quat {
    let (va, vb) = (a.imag(), b.imag());
    Quat::from_parts(a.w * b.w + va.dot(&vb), vb * a.w - va * b.w - va.cross(&vb))
}

/// Solve the symmetric 3x3 system `K x = b` with the adjugate,
/// `x = adj(K) b / det(K)`: one division, so little latency on the
/// Gauss-Seidel dependency chain (an `L D L^T` solve has three in series).
/// `k = [k00, k01, k02, k11, k12, k22]`. `None` unless `K` is positive
/// definite by Sylvester's criterion (`k00 > 0`, `k00 k11 - k01^2 > 0`,
/// `det > 0`), which `J W J^T + alpha~` is whenever a constraint has a
/// moving body.
#[inline]
pub(super) fn solve_spd3(k: [f64; 6], b: &Vec3) -> Option<Vec3> {
    let [k00, k01, k02, k11, k12, k22] = k;
    // Cofactors (symmetric).
    let c00 = k11 * k22 - k12 * k12;
    let c01 = k02 * k12 - k01 * k22;
    let c02 = k01 * k12 - k02 * k11;
    let c11 = k00 * k22 - k02 * k02;
    let c12 = k01 * k02 - k00 * k12;
    let c22 = k00 * k11 - k01 * k01;
    let det = k00 * c00 + k01 * c01 + k02 * c02;
    if !(k00 > 0.0 && c22 > 0.0 && det > 0.0) {
        return None;
    }
    let inv = 1.0 / det;
    Some(Vec3::new(
        (c00 * b.x + c01 * b.y + c02 * b.z) * inv,
        (c01 * b.x + c11 * b.y + c12 * b.z) * inv,
        (c02 * b.x + c12 * b.y + c22 * b.z) * inv,
    ))
}

/// Body-frame relative rotation by angle `|k| len` about the material axis `k/|k|`.
pub(super) fn rest_rotation(kappa: &Vec3, len: f64) -> Quat {
    let th = kappa.norm() * len;
    if th == 0.0 {
        return Quat::identity();
    }
    UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(*kappa), th).into_inner()
}

/// Discrete Darboux vector `(2/len) Im(conj(qa) qb)` with the real part made
/// non-negative (K&S 2016 sec. 4.2); returns `(Omega, w, v)`.
pub(super) fn darboux(qa: &Quat, qb: &Quat, len: f64) -> (Vec3, f64, Vec3) {
    let mut r = conj_mul(qa, qb);
    if r.w < 0.0 {
        r = -r;
    }
    let v = r.imag();
    (v * (2.0 / len), r.w, v)
}
