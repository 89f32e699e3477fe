//! Voxel SDF: second-order convergence of trilinear interpolation away from
//! the medial axis, the analytic gradient of the interpolant against finite
//! differences, the mesh path (parry3d) against the analytic tube and a
//! winding-number inside test, and the on-disk cache.

use std::f64::consts::PI;
use surgbench_core::Vec3;
use surgbench_core::io::TriSurface;
use surgbench_core::sdf::{CenterlineBuilder, MeshSdf, Sdf, SweptTube, VoxelSdf};

struct Rng(u64);
impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

const R: f64 = 2e-3; // lumen radius
const RB: f64 = 10e-3; // bend radius

/// A quarter torus: arc of bend radius 10 mm in the x-y plane, lumen 2 mm.
fn bend() -> SweptTube {
    CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .arc(RB, PI / 2.0, Vec3::y())
        .build_constant(R)
        .unwrap()
}

#[test]
fn trilinear_error_converges_at_second_order_away_from_the_medial_axis() {
    let tube = bend();
    // Box covering the arc: a whole number of cells at every spacing below.
    let lo = Vec3::new(-4e-3, -4e-3, -4e-3);
    let hi = Vec3::new(16e-3, 16e-3, 4e-3);
    let spacings = [1e-3, 0.5e-3, 0.25e-3, 0.125e-3];
    let rho_min = 0.5 * R;
    let mut errs = Vec::new();
    for &h in &spacings {
        let grid = VoxelSdf::from_sdf(&tube, lo, hi, h).unwrap();
        // Same seed and box: the same sample points at every spacing. Keep
        // points whose interpolation cell stays out of the medial axis (the
        // centreline) by rho_min: radial >= rho_min + sqrt(3) h_max; and on
        // the arc's interior (radial < 2 R keeps away from the torus axis).
        let keep = |p: &Vec3| {
            let pr = tube.project(p);
            pr.radial >= rho_min + 3f64.sqrt() * spacings[0]
                && pr.radial <= 2.0 * R
                && pr.s > 1e-3
                && pr.s < tube.length() - 1e-3
        };
        let e = grid.error_against(&tube, 2000, 0xabc, f64::INFINITY, keep);
        assert!(e.count == 2000, "only {} sample points kept", e.count);
        // Tensor-product linear interpolation: |f - I f| <= h^2/8 sum_k |f_kk|
        // and sum_k |f_kk| <= sum of |Hessian eigenvalues| = 1/rho + 1/(RB - rho)
        // for the distance to a circle of radius RB; rho >= rho_min over the cell.
        let bound = h * h / 8.0 * (1.0 / rho_min + 1.0 / (RB - 2.0 * R - 2.0 * spacings[0]));
        assert!(
            e.max <= bound,
            "h={h:e}: max error {:e} above the interpolation bound {bound:e}",
            e.max
        );
        println!("h = {h:e} m: max {:e} m, rms {:e} m, bound {bound:e} m", e.max, e.rms);
        errs.push(e);
    }
    for w in errs.windows(2).zip(spacings.windows(2)) {
        let (e, h) = w;
        let order_max = (e[0].max / e[1].max).ln() / (h[0] / h[1]).ln();
        let order_rms = (e[0].rms / e[1].rms).ln() / (h[0] / h[1]).ln();
        println!("observed order: max {order_max:.3}, rms {order_rms:.3}");
        // Second order in theory; measured 1.99-2.02 (rms) and 1.94-2.04
        // (max; the worst point changes with h, hence the looser 1.7).
        assert!(
            order_rms > 1.85,
            "rms order {order_rms:.3} between h={:e} and {:e}",
            h[0],
            h[1]
        );
        assert!(
            order_max > 1.7,
            "max order {order_max:.3} between h={:e} and {:e}",
            h[0],
            h[1]
        );
    }
}

#[test]
fn interpolant_gradient_matches_finite_differences() {
    let tube = bend();
    let h = 0.5e-3;
    let grid = VoxelSdf::from_sdf(&tube, Vec3::new(-4e-3, -4e-3, -4e-3), Vec3::new(16e-3, 16e-3, 4e-3), h).unwrap();
    let mut rng = Rng(0x9ad);
    for i in 0..500 {
        // A random cell, a random point inside it away from its faces (the
        // interpolant's gradient jumps across faces).
        let c = [0, 1, 2].map(|a| (rng.unit() * (grid.dims[a] - 1) as f64).floor());
        let f = [0, 1, 2].map(|_| 0.1 + 0.8 * rng.unit());
        let p = grid.origin + Vec3::new(c[0] + f[0], c[1] + f[1], c[2] + f[2]) * h;
        let g = grid.gradient(&p);
        let step = 1e-3 * h;
        let mut fd = Vec3::zeros();
        for k in 0..3 {
            let (mut a, mut b) = (p, p);
            a[k] += step;
            b[k] -= step;
            fd[k] = (grid.distance(&a) - grid.distance(&b)) / (2.0 * step);
        }
        // The interpolant is linear along each axis inside a cell, so central
        // differences are exact up to roundoff eps |phi| / step ~ 1e-11.
        assert!(
            (g - fd).norm() < 1e-8,
            "point {i} {p:?}: gradient {g:?} vs finite differences {fd:?}"
        );
    }
    // Outside the box the field grows with the distance to the box.
    let out = grid.max_corner() + Vec3::new(1e-3, 0.0, 0.0);
    let inside = grid.max_corner();
    assert!((grid.distance(&out) - grid.distance(&inside) - 1e-3).abs() < 1e-15);
    assert_eq!(grid.gradient(&out), Vec3::x());
}

/// The grid's Hessian (differences of the interpolant's gradient over one
/// spacing) approaches the tube's analytic Hessian near the wall, at about
/// first order in the spacing, and never shows the spikes that differences
/// across one cell face over 1e-6 m would (entries of order jump / 1e-6 m).
#[test]
fn grid_hessian_approaches_the_analytic_one_at_first_order() {
    let tube = bend();
    let (lo, hi) = (Vec3::new(-4e-3, -4e-3, -4e-3), Vec3::new(16e-3, 16e-3, 4e-3));
    let mut worst = Vec::new();
    for h in [0.5e-3, 0.25e-3, 0.125e-3] {
        let grid = VoxelSdf::from_sdf(&tube, lo, hi, h).unwrap();
        let mut rng = Rng(0x4e55);
        let (mut e2, mut n) = (0.0, 0);
        while n < 400 {
            let p = lo + Vec3::new(rng.unit() * 20e-3, rng.unit() * 20e-3, rng.unit() * 8e-3);
            // Inside the lumen, between a quarter of the radius from the axis and the wall less
            // two cells (the analytic Hessian is singular on the axis),
            // away from the arc's ends (the caps).
            let pr = tube.project(&p);
            let d = tube.distance(&p);
            if !(d < -2.0 * h && d > -0.75 * R && pr.s > 2e-3 && pr.s < tube.length() - 2e-3) {
                continue;
            }
            let e = (grid.hessian(&p) - tube.hessian(&p)).norm();
            e2 += e * e;
            n += 1;
        }
        worst.push((e2 / n as f64).sqrt() * R);
    }
    // Measured 0.86, 0.24, 0.093: orders 1.8 and 1.4.
    eprintln!("RMS Hessian error x R at h = 0.5, 0.25, 0.125 mm: {worst:?}");
    for w in worst.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!(order > 0.7, "order {order} from {worst:?}");
    }
    assert!(worst[2] < 0.2, "{worst:?}");
}

/// Generalized winding number of a closed surface around `p` (van Oosterom
/// & Strackee 1983 solid angle of a triangle): 1 inside, 0 outside.
fn winding(m: &TriSurface, p: &Vec3) -> f64 {
    let mut w = 0.0;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.vertices[i] - p);
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let num = a.dot(&b.cross(&c));
        let den = la * lb * lc + a.dot(&b) * lc + b.dot(&c) * la + c.dot(&a) * lb;
        w += 2.0 * num.atan2(den);
    }
    w / (4.0 * PI)
}

#[test]
fn mesh_sdf_agrees_with_the_analytic_tube_and_winding_numbers() {
    let tube = bend();
    let around = 48;
    let mesh = tube.to_mesh(around, 0.5e-3).unwrap();
    mesh.check_closed().unwrap();
    let exact = MeshSdf::new(&mesh).unwrap();
    let mut rng = Rng(0x3e5);
    let mut worst = 0.0f64;
    let mut n = 0;
    for i in 0..400 {
        let s = 1e-3 + rng.unit() * (tube.length() - 2e-3);
        let c = tube.point_at(s);
        let p = c + Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * (3.0 * R);
        let pr = tube.project(&p);
        if pr.s < 1e-3 || pr.s > tube.length() - 1e-3 {
            continue; // the mesh has flat caps, the SDF hemispherical ones
        }
        let d_mesh = exact.distance(&p);
        let wn = winding(&mesh, &p);
        assert!(
            (wn - if d_mesh < 0.0 { 1.0 } else { 0.0 }).abs() < 1e-6,
            "point {i} {p:?}: parry sign {d_mesh:e} disagrees with winding number {wn}"
        );
        // Polygon of `around` sides inscribed in the circle: sagitta
        // R (1 - cos(pi/around)); rings 0.5 mm apart on a 10 mm bend: chord
        // sagitta (0.5 mm)^2 / (8 * 8 mm) on the inner side. Distances differ
        // by at most the sum.
        let tol = R * (1.0 - (PI / around as f64).cos()) + (0.5e-3f64).powi(2) / (8.0 * (RB - R)) + 1e-12;
        let d = (d_mesh - tube.distance(&p)).abs();
        assert!(
            d <= tol,
            "point {i} {p:?}: mesh {d_mesh:e} vs analytic {:e} (tol {tol:e})",
            tube.distance(&p)
        );
        worst = worst.max(d);
        n += 1;
    }
    assert!(n > 300);
    println!("mesh vs analytic: max |diff| = {worst:e} m over {n} points");
}

#[test]
fn voxel_from_mesh_error_report() {
    let tube = bend();
    let mesh = tube.to_mesh(32, 1e-3).unwrap();
    let exact = MeshSdf::new(&mesh).unwrap();
    let mut prev = f64::INFINITY;
    for h in [0.8e-3, 0.4e-3, 0.2e-3] {
        let grid = VoxelSdf::from_mesh(&mesh, h, 1e-3).unwrap();
        let e = grid.error_against(&exact, 1000, 0x77, R, |_| true);
        // phi is 1-Lipschitz and the interpolant is a convex combination of
        // corner values, each within |p - c_i| of phi(p); by Jensen
        // sum w_i |p - c_i| <= h sqrt(sum_k t_k (1 - t_k)) <= sqrt(3) h / 2. (The mesh
        // SDF has kinks on bisector planes of the polygon's edges, so no
        // second-order bound; measured rms order ~1.7, max ~1.5.)
        let lip = 3f64.sqrt() * h / 2.0;
        println!(
            "mesh grid h = {h:e}: max {:e} m, rms {:e} m ({} points within {R:e} m of the wall)",
            e.max, e.rms, e.count
        );
        assert!(e.max <= lip, "h={h:e}: max error {:e} > Lipschitz bound {lip:e}", e.max);
        assert!(
            e.rms < prev,
            "rms error did not shrink at h={h:e}: {:e} after {prev:e}",
            e.rms
        );
        prev = e.rms;
    }
}

#[test]
fn voxel_cache_round_trip_and_bad_files() {
    let tube = bend();
    let grid = VoxelSdf::from_sdf(
        &tube,
        Vec3::new(-3e-3, -3e-3, -3e-3),
        Vec3::new(13e-3, 13e-3, 3e-3),
        1e-3,
    )
    .unwrap();
    let dir = std::env::temp_dir().join(format!("surgbench-voxel-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bend.vsdf");
    grid.write(&path).unwrap();
    let back = VoxelSdf::read(&path).unwrap();
    assert_eq!(back, grid, "cache round trip must be bit-identical");

    let mut bytes = std::fs::read(&path).unwrap();
    bytes.truncate(bytes.len() - 8);
    let bad = dir.join("truncated.vsdf");
    std::fs::write(&bad, &bytes).unwrap();
    let e = VoxelSdf::read(&bad).unwrap_err().0;
    assert!(e.contains("truncated.vsdf") && e.contains("expected"), "{e}");
    std::fs::write(&bad, b"hello").unwrap();
    let e = VoxelSdf::read(&bad).unwrap_err().0;
    assert!(e.contains("bad header"), "{e}");
    std::fs::remove_dir_all(&dir).ok();

    assert!(VoxelSdf::from_sdf(&tube, Vec3::zeros(), Vec3::zeros(), 1e-3).is_err());
    assert!(VoxelSdf::from_sdf(&tube, Vec3::zeros(), Vec3::repeat(1.0), 0.0).is_err());
}
