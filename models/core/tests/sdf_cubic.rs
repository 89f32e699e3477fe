//! Tricubic voxel SDF ([`CubicVoxelSdf`]): third-order convergence away from
//! the medial axis, a gradient continuous across cell faces (where the
//! trilinear one jumps), and analytic derivatives against differences.

use std::f64::consts::PI;
use surgbench_core::Vec3;
use surgbench_core::rng::SplitMix64;
use surgbench_core::sdf::{CenterlineBuilder, CubicVoxelSdf, Sdf, SweptTube, VoxelSdf};

const R: f64 = 2e-3; // lumen radius
const RB: f64 = 10e-3; // bend radius

/// A quarter torus: bend radius 10 mm in the x-y plane, lumen 2 mm.
fn bend() -> SweptTube {
    CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .arc(RB, PI / 2.0, Vec3::y())
        .build_constant(R)
        .unwrap()
}

fn grid(tube: &SweptTube, h: f64) -> VoxelSdf {
    // A box 4 mm clear of every sample, so no stencil is clamped at a face.
    VoxelSdf::from_sdf(tube, Vec3::new(-8e-3, -8e-3, -8e-3), Vec3::new(20e-3, 20e-3, 8e-3), h).unwrap()
}

/// Points whose 4-sample stencil stays off the centreline (the medial axis,
/// where the distance has a kink), off the arc's ends (4 mm) and off the
/// grid's faces.
fn samples(tube: &SweptTube, n: usize) -> Vec<Vec3> {
    let mut rng = SplitMix64(0xc0b1c);
    let mut out = Vec::new();
    while out.len() < n {
        let p = rng.in_box(Vec3::new(-4e-3, -4e-3, -4e-3), Vec3::new(16e-3, 16e-3, 4e-3));
        let pr = tube.project(&p);
        // The 4-sample stencil spans +-2 h (h <= 1 mm): radial >= 3 mm keeps
        // it 1 mm off the axis; <= 2 R stays off the torus axis (10 mm).
        if pr.radial >= 3e-3 && pr.radial <= 2.0 * R && pr.s > 4e-3 && pr.s < tube.length() - 4e-3 {
            out.push(p);
        }
    }
    out
}

#[test]
fn cubic_error_converges_at_third_order_away_from_the_medial_axis() {
    let tube = bend();
    let pts = samples(&tube, 1000);
    let mut rms = Vec::new();
    for h in [1e-3, 0.5e-3, 0.25e-3] {
        let c = CubicVoxelSdf::new(grid(&tube, h));
        let e2: f64 = pts.iter().map(|p| (c.distance(p) - tube.distance(p)).powi(2)).sum();
        rms.push((e2 / pts.len() as f64).sqrt());
    }
    let orders: Vec<f64> = rms.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    eprintln!("rms error {rms:?}, orders {orders:?}");
    // Cubic convolution errs by O(h^3) on a smooth field (Keys 1981);
    // measured 3.22 and 3.10 (rms 1.2e-6, 1.3e-7, 1.5e-8 m at 1, 0.5, 0.25 mm).
    for o in &orders {
        assert!(*o > 2.5, "orders {orders:?} from rms {rms:?}");
    }
}

#[test]
fn cubic_gradient_is_continuous_across_cell_faces_and_trilinear_is_not() {
    let tube = bend();
    let h = 0.5e-3;
    let g = grid(&tube, h);
    let cubic = CubicVoxelSdf::new(g.clone());
    let (mut cubic_jump, mut linear_jump) = (0.0f64, 0.0f64);
    for p in samples(&tube, 300) {
        // Move p onto the nearest x face of its cell and look both sides.
        let i = ((p.x - g.origin.x) / h).round();
        let face = Vec3::new(g.origin.x + i * h, p.y, p.z);
        let eps = Vec3::new(1e-9, 0.0, 0.0);
        cubic_jump = cubic_jump.max((cubic.gradient(&(face + eps)) - cubic.gradient(&(face - eps))).norm());
        linear_jump = linear_jump.max((g.gradient(&(face + eps)) - g.gradient(&(face - eps))).norm());
    }
    eprintln!("largest gradient jump across an x face: cubic {cubic_jump:e}, trilinear {linear_jump:e}");
    // C1: only the change over 2e-9 m, |Hess| 2e-9 ~ 1e-6 at |Hess| ~ 1/h.
    assert!(cubic_jump < 1e-5, "cubic jump {cubic_jump}");
    // The trilinear gradient jumps by ~h |Hess phi| ~ 0.5 mm / 1 mm.
    assert!(linear_jump > 1e-2, "trilinear jump {linear_jump}");
}

#[test]
fn cubic_derivatives_match_differences() {
    let tube = bend();
    let h = 0.5e-3;
    let c = CubicVoxelSdf::new(grid(&tube, h));
    for p in samples(&tube, 300) {
        let (g, hess) = (c.gradient(&p), c.hessian(&p));
        let s = 1e-4 * h;
        for k in 0..3 {
            let (mut a, mut b) = (p, p);
            a[k] += s;
            b[k] -= s;
            let dg = (c.distance(&a) - c.distance(&b)) / (2.0 * s);
            let dh = (c.gradient(&a) - c.gradient(&b)) / (2.0 * s);
            // Central differences of a cubic: error s^2/6 |f'''| with
            // |f'''| <~ |phi| / h^3, i.e. ~1e-8 relative; roundoff
            // eps |phi| / s ~ 1e-10. A cell face inside the stencil adds
            // the jump of the second derivative times s: bounded by 1e-4 h.
            assert!((g[k] - dg).abs() < 1e-6, "{p:?} d/dx{k}: {} vs {dg}", g[k]);
            assert!(
                (hess.column(k) - dh).norm() < 1e-2 / h,
                "{p:?} column {k}: {:?} vs {dh:?}",
                hess.column(k)
            );
        }
        assert_eq!(hess, hess.transpose());
    }
}
