//! Analytic swept-tube SDF against brute force (dense sampling of the
//! centreline), its gradient against finite differences, unions and the
//! procedural vessels.

use std::f64::consts::PI;
use std::sync::Arc;
use surgbench_core::sdf::{CenterlineBuilder, Sdf, SdfUnion, SweptTube};
use surgbench_core::{Vec3, vessel};

use surgbench_core::rng::SplitMix64 as Rng;

/// A 3D centreline with lines and arcs in three planes.
fn wiggly() -> CenterlineBuilder {
    CenterlineBuilder::new(Vec3::new(0.001, -0.002, 0.0), Vec3::new(1.0, 0.2, 0.0))
        .line(0.01)
        .arc(0.008, PI / 2.0, Vec3::y())
        .arc(0.005, 2.0 * PI / 3.0, Vec3::z())
        .line(0.004)
        .arc(0.012, PI / 4.0, Vec3::new(0.3, -1.0, 0.2))
}

/// Dense centreline samples `(s, c(s))` every `h` metres.
fn samples(tube: &SweptTube, h: f64) -> Vec<(f64, Vec3)> {
    let n = (tube.length() / h).ceil() as usize;
    (0..=n)
        .map(|i| {
            let s = tube.length() * i as f64 / n as f64;
            (s, tube.point_at(s))
        })
        .collect()
}

fn bbox(pts: &[(f64, Vec3)], pad: f64) -> (Vec3, Vec3) {
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for (_, p) in pts {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (lo - Vec3::repeat(pad), hi + Vec3::repeat(pad))
}

#[test]
fn constant_radius_tube_matches_brute_force_distance() {
    let r = 1.5e-3;
    let tube = wiggly().build_constant(r).unwrap();
    let h = 2e-6;
    let dense = samples(&tube, h);
    let (lo, hi) = bbox(&dense, 3.0 * r);
    let mut rng = Rng(0x5eed_0001);
    let mut worst = 0.0f64;
    for i in 0..400 {
        let p = rng.in_box(lo, hi);
        let brute = dense.iter().map(|(_, c)| (p - c).norm()).fold(f64::INFINITY, f64::min);
        let proj = tube.project(&p);
        let phi = tube.distance(&p);
        // The nearest of samples h apart is at most h/2 along the curve from
        // the true closest point: |p - c| grows by at most (h/2)^2 / (2 d)
        // (+ curvature terms, covered by the factor 2), so this bounds the
        // brute force's own error.
        let tol = 2.0 * (h / 2.0).powi(2) / (2.0 * proj.radial.max(1e-5)) + 1e-15;
        assert!(
            phi <= brute - r + 1e-15,
            "point {i} {p:?}: analytic phi {phi:e} exceeds the brute-force minimum {:e}",
            brute - r
        );
        assert!(
            (brute - r) - phi <= tol,
            "point {i} {p:?}: analytic phi {phi:e} vs brute force {:e} (tol {tol:e})",
            brute - r
        );
        worst = worst.max((brute - r - phi).abs());
    }
    println!("constant radius: max |phi - brute| = {worst:e} m over 400 points");
}

#[test]
fn varying_radius_tube_is_close_to_the_canal_surface() {
    // Radius 2 mm -> 1 mm over the centreline: slope ~ 2.9e-2.
    let tube0 = wiggly().build_constant(1e-3).unwrap();
    let len = tube0.length();
    let slope = 1e-3 / len;
    let tube = wiggly().build(&[(0.0, 2e-3), (len, 1e-3)]).unwrap();
    let h = 2e-6;
    let dense = samples(&tube, h);
    let mut rng = Rng(0x5eed_0002);
    let mut worst_rel = 0.0f64;
    let mut checked = 0;
    for i in 0..400 {
        // Near the centreline: a random point of the 2.5 mm cube around c(s).
        let c = tube.point_at(rng.unit() * len);
        let p = rng.in_box(c - Vec3::repeat(2.5e-3), c + Vec3::repeat(2.5e-3));
        // Canal surface of the swept spheres: min_s |p - c(s)| - r(s).
        let canal = dense
            .iter()
            .map(|(s, c)| (p - c).norm() - tube.radius_at(*s))
            .fold(f64::INFINITY, f64::min);
        let proj = tube.project(&p);
        if proj.radial > 2.5e-3 {
            continue; // keep within half the tightest bend radius (5 mm) of the centreline
        }
        let phi = tube.distance(&p);
        let sampling = 2.0 * (h / 2.0).powi(2) / (2.0 * proj.radial.max(1e-5)) + 1e-15;
        // Straight-line analysis: min_u sqrt(d^2 + u^2) - r' u = d sqrt(1 - r'^2)
        // ~ d (1 - r'^2 / 2). Near an arc of curvature kappa the metric along
        // the curve scales by (1 - kappa d) >= 1/2 for d <= 1/(2 kappa), which
        // at most doubles the gap: hence the factor 2.
        let bound = 2.0 * proj.radial * slope * slope / 2.0 + sampling;
        assert!(
            phi >= canal - sampling,
            "point {i}: phi {phi:e} below the canal distance {canal:e}"
        );
        assert!(
            phi - canal <= bound,
            "point {i} {p:?}: phi {phi:e} - canal {canal:e} = {:e} > bound {bound:e} (radial {:e})",
            phi - canal,
            proj.radial
        );
        checked += 1;
        if proj.radial > 1e-4 {
            worst_rel = worst_rel.max((phi - canal) / (proj.radial * slope * slope / 2.0));
        }
    }
    assert!(checked >= 200, "only {checked} points near the centreline");
    println!("varying radius: max (phi - canal) / (d r'^2/2) = {worst_rel:.3} over {checked} points");
}

#[test]
fn gradient_matches_finite_differences() {
    let len = wiggly().build_constant(1e-3).unwrap().length();
    for (name, tube) in [
        ("constant", wiggly().build_constant(1.5e-3).unwrap()),
        (
            "varying",
            wiggly()
                .build(&[(0.0, 2e-3), (0.5 * len, 1.6e-3), (len, 1e-3)])
                .unwrap(),
        ),
    ] {
        let dense = samples(&tube, 1e-4);
        let (lo, hi) = bbox(&dense, 3e-3);
        let mut rng = Rng(0x5eed_0003);
        let mut checked = 0;
        for i in 0..300 {
            let p = rng.in_box(lo, hi);
            let proj = tube.project(&p);
            if proj.radial < 2e-4 {
                continue; // the medial axis (centreline), where phi has a kink
            }
            let g = tube.gradient(&p);
            let step = 1e-8;
            let mut fd = Vec3::zeros();
            for k in 0..3 {
                let (mut a, mut b) = (p, p);
                a[k] += step;
                b[k] -= step;
                fd[k] = (tube.distance(&a) - tube.distance(&b)) / (2.0 * step);
            }
            // Central differences: truncation step^2 |phi'''| ~ step^2 / d^2 ~ 2.5e-9;
            // roundoff eps |phi| / step ~ 1e-11; skip points where the
            // stencil straddles a switch between pieces (phi is C1 but not C2
            // there, and the FD error is then O(step / d) ~ 5e-5).
            let err = (g - fd).norm();
            if err > 1e-6 {
                let other = (0..3).any(|k| {
                    let mut a = p;
                    a[k] += step;
                    tube.project(&a).piece != proj.piece
                });
                assert!(
                    other,
                    "{name} tube, point {i} {p:?}: gradient {g:?} vs finite differences {fd:?} ({err:e})"
                );
                continue;
            }
            if name == "constant" {
                assert!(
                    (g.norm() - 1.0).abs() < 1e-12,
                    "point {i}: |grad| = {} for a constant radius",
                    g.norm()
                );
            }
            checked += 1;
        }
        assert!(checked > 250, "{name}: only {checked} points checked");
    }
}

#[test]
fn union_takes_the_deepest_lumen_and_its_normal() {
    let a = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(0.02)
        .build_constant(2e-3)
        .unwrap();
    let b = CenterlineBuilder::new(Vec3::new(0.02, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0))
        .line(0.02)
        .build_constant(1e-3)
        .unwrap();
    let u = SdfUnion {
        parts: vec![Arc::new(a.clone()), Arc::new(b.clone())],
    };
    let mut rng = Rng(7);
    for i in 0..200 {
        let p = rng.in_box(Vec3::new(-0.005, -0.005, -0.005), Vec3::new(0.04, 0.02, 0.005));
        let (da, db) = (a.distance(&p), b.distance(&p));
        assert_eq!(u.distance(&p), da.min(db), "point {i}");
        let g = if da <= db { a.gradient(&p) } else { b.gradient(&p) };
        assert_eq!(u.gradient(&p), g, "point {i}");
    }
}

#[test]
fn frame_at_points_along_the_lumen() {
    let tube = wiggly().build_constant(1e-3).unwrap();
    for s in [0.0, 0.005, 0.012, tube.length()] {
        let f = tube.frame_at(s);
        let x = f.rotation * Vec3::x();
        assert!(
            (x - tube.tangent_at(s)).norm() < 1e-12,
            "s={s}: frame x {x:?} vs tangent {:?}",
            tube.tangent_at(s)
        );
        assert!((f.translation.vector - tube.point_at(s)).norm() < 1e-15);
    }
    // Tangent continuity (G1) at every joint.
    let mut s = 0.0;
    for p in tube.pieces() {
        s += p.length();
        let (a, b) = (tube.tangent_at(s - 1e-9), tube.tangent_at(s + 1e-9));
        assert!((a - b).norm() < 1e-6, "tangent jumps at s={s}: {a:?} -> {b:?}");
    }
}

#[test]
fn builder_rejects_bad_geometry() {
    let e = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(-1.0)
        .build_constant(1e-3)
        .unwrap_err();
    assert!(e.0.contains("line length"), "{e}");
    let e = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .arc(0.01, 1.0, Vec3::x())
        .build_constant(1e-3)
        .unwrap_err();
    assert!(e.0.contains("parallel"), "{e}");
    let e = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(0.01)
        .build(&[(0.0, 1e-3), (0.001, 2e-3)])
        .unwrap_err();
    assert!(e.0.contains("slope"), "{e}");
    let e = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(0.01)
        .build_constant(0.0)
        .unwrap_err();
    assert!(e.0.contains("r > 0"), "{e}");
}

#[test]
fn procedural_vessels_have_their_documented_sizes() {
    let arch = vessel::aortic_arch();
    // Trunk: 60 mm + pi 35 mm + 50 mm.
    let l = vessel::ARCH_DESCENDING + PI * vessel::ARCH_RADIUS + vessel::ARCH_ASCENDING;
    assert!(
        (arch.trunk.length() - l).abs() < 1e-12,
        "arch length {} vs {l}",
        arch.trunk.length()
    );
    // Top of the arch: 35 mm above the arch centre, radius 12.5 mm.
    let top = Vec3::new(-vessel::ARCH_RADIUS, 0.0, vessel::ARCH_DESCENDING + vessel::ARCH_RADIUS);
    assert!((arch.trunk.distance(&top) + vessel::AORTA_RADIUS).abs() < 1e-15);
    for (name, r) in [
        ("left-subclavian", 4.5e-3),
        ("left-common-carotid", 3.75e-3),
        ("brachiocephalic", 6e-3),
    ] {
        let b = arch.branch(name).unwrap();
        let p = b.tube.point_at(0.04);
        assert!(
            (arch.distance(&p) + r).abs() < 1e-12,
            "{name}: phi on its axis {} vs -{r}",
            arch.distance(&p)
        );
        assert_eq!(arch.deepest(&p).0.map(|i| arch.branches[i].name.as_str()), Some(name));
        // Leaves upwards, out of the top of the arch.
        assert!(b.tube.tangent_at(0.0).z > 0.9);
    }
    let entry = arch.entry();
    assert!(
        (entry.rotation * Vec3::x() - Vec3::z()).norm() < 1e-12,
        "arch entry heads up the descending aorta"
    );

    let cor = vessel::coronary_tortuous();
    assert!((cor.distance(&cor.trunk.point_at(0.06)) + 1.5e-3).abs() < 1e-15);
    let min_bend = cor
        .trunk
        .pieces()
        .iter()
        .filter_map(|p| match p {
            surgbench_core::sdf::Piece::Arc { radius, .. } => Some(*radius),
            _ => None,
        })
        .fold(f64::INFINITY, f64::min);
    assert_eq!(min_bend, 5e-3, "tightest coronary bend");

    let y = vessel::y_bifurcation();
    for (name, deg) in [("branch-45", 45.0f64), ("branch-70", -70.0)] {
        let t = y.branch(name).unwrap().tube.tangent_at(0.0);
        let ang = t.y.atan2(t.x).to_degrees();
        assert!((ang - deg).abs() < 1e-12, "{name} leaves at {ang} deg");
    }
}

#[test]
fn poiseuille_profile() {
    use surgbench_core::flow::FlowField;
    let f = surgbench_core::flow::PoiseuilleFlow {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 2e-3,
        v_max: 0.4,
    };
    assert_eq!(f.velocity(&Vec3::new(0.3, 0.0, 0.0)), Vec3::new(0.4, 0.0, 0.0));
    let v = f.velocity(&Vec3::new(0.0, 1e-3, 0.0));
    assert!((v.x - 0.3).abs() < 1e-15, "v(R/2) = {} vs 3/4 v_max", v.x);
    assert_eq!(f.velocity(&Vec3::new(0.0, 0.0, 2.5e-3)), Vec3::zeros());
}

#[test]
fn distance_gradient_equals_the_separate_queries_bit_for_bit() {
    use surgbench_core::sdf::{StraightTube, TransformedSdf, VoxelSdf};
    let arch = vessel::aortic_arch();
    let tube = wiggly().build(&[(0.0, 2e-3), (0.02, 1.5e-3)]).unwrap();
    let grid = VoxelSdf::from_sdf(&tube, Vec3::repeat(-0.01), Vec3::repeat(0.03), 1e-3).unwrap();
    let straight = StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::y(),
        radius: 1e-3,
    };
    let iso = surgbench_core::Iso3::new(Vec3::new(0.01, 0.0, -0.02), Vec3::new(0.3, -0.2, 0.5));
    let moved = TransformedSdf::new(Arc::new(arch.clone()), iso);
    let union = SdfUnion {
        parts: vec![Arc::new(tube.clone()), Arc::new(straight)],
    };
    let all: [(&str, &dyn Sdf); 6] = [
        ("arch", &arch),
        ("tube", &tube),
        ("grid", &grid),
        ("straight", &straight),
        ("moved", &moved),
        ("union", &union),
    ];
    let mut rng = Rng(11);
    for i in 0..300 {
        let p = rng.in_box(Vec3::new(-0.06, -0.02, -0.02), Vec3::new(0.04, 0.04, 0.12));
        for (name, s) in all {
            let (d, g) = s.distance_gradient(&p);
            assert_eq!(
                (d.to_bits(), g),
                (s.distance(&p).to_bits(), s.gradient(&p)),
                "{name}, point {i} {p:?}"
            );
        }
    }
}
