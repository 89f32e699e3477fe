//! Scoring of `needle-bevel` and `needle-double-bend` through the runner,
//! with a kinematic needle whose tip follows arcs of known curvature and a
//! cached reference written for the test.

mod common;
use common::params;
use common::vessel::{Kinematic, TestFactory, run};

use surgbench_comparisons::scenario::{Declared, Scenario};
use surgbench_comparisons::scenarios::needle::{BevelParams, DoubleBendParams, NEEDLE_BEVEL, NEEDLE_DOUBLE_BEND};
use surgbench_core::{Capability, Vec3};

const CAPS: &[Capability] = &[
    Capability::Rod,
    Capability::Tissue,
    Capability::NeedleTissue,
    Capability::Insertion,
    Capability::Twist,
];

/// Default tip gap, insertion speed (m, m/s) and turn depth of the scenes.
const GAP: f64 = 1e-3;
const SPEED: f64 = 0.01;
const TURN_DEPTH: f64 = 0.0075;

/// Lateral offset (m, along +z) at depth `x` of an arc of radius `r`
/// leaving the entry along +x: bends towards +z for `r > 0`.
fn arc(r: f64, x: f64) -> f64 {
    r - r.signum() * (r * r - x * x).sqrt()
}

/// A kinematic needle whose tip is at depth `x = -GAP + s - l0` (s the
/// wire's length from its clamp) and `z = lateral(x)` once inside.
fn follower(lateral: fn(f64) -> f64) -> TestFactory {
    TestFactory {
        caps: CAPS,
        build: Box::new(move |_| {
            Box::new(Kinematic::along(
                move |s| {
                    let x = s - GAP - 0.01;
                    Vec3::new(x, 0.0, if x > 0.0 { lateral(x) } else { 0.0 })
                },
                0.01,
                20,
            ))
        }),
    }
}

/// The scene `s` with a reference trajectory whose tip follows `lateral`
/// (written every ms to a temporary datasets folder, kept alive by the
/// returned guard).
fn with_reference<P: surgbench_comparisons::scenario::ParamSet + 'static>(
    s: &Declared<P>,
    lateral: fn(f64) -> f64,
) -> (&'static Declared<P>, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let refdir = dir.path().join("reference").join(s.info.id);
    std::fs::create_dir_all(&refdir).unwrap();
    let mut csv = String::from("# test reference\nt,x,y,z\n");
    for k in 0..=1600 {
        let t = k as f64 * 1e-3;
        let x = -GAP + SPEED * t;
        let z = if x > 0.0 { lateral(x) } else { 0.0 };
        csv.push_str(&format!("{t:?},{x:?},0.0,{z:?}\n"));
    }
    std::fs::write(refdir.join("tip_trajectory.csv"), csv).unwrap();
    let leaked: &'static str = Box::leak(dir.path().display().to_string().into_boxed_str());
    let s: &'static Declared<P> = Box::leak(Box::new(Declared {
        datasets: Some(leaked),
        info: s.info,
        build: s.build,
    }));
    (s, dir)
}

#[test]
fn the_bevel_scorer_recovers_an_arcs_curvature_against_the_reference() {
    // The model on an arc of radius 60 mm, the reference on one of 50 mm.
    let (s, _dir): (&Declared<BevelParams>, _) = with_reference(&NEEDLE_BEVEL, |x| arc(0.05, x));
    let p = params(s, &[]);
    let sum = run(s, &p, &follower(|x| arc(0.06, x)));
    assert_eq!(sum.status, "ok", "{}", sum.reason);
    let e = &sum.errors;
    assert_eq!(e["reference_available"], 1.0);
    // Points on an exact circle: the algebraic fit is exact to rounding.
    assert!((e["curvature_per_m"] - 1.0 / 0.06).abs() < 1e-6, "{e:?}");
    assert!((e["reference_curvature_per_m"] - 1.0 / 0.05).abs() < 1e-6, "{e:?}");
    assert!(
        (e["curvature_error_rel"] - (0.05 / 0.06 - 1.0f64).abs()).abs() < 1e-6,
        "{e:?}"
    );
    assert!(e["arc_fit_residual_rel"] < 1e-9, "{e:?}");
    assert_eq!(e["out_of_plane_m"], 0.0);
    // Both tips at x = 15 mm at the end (the feed's 16 mm less the gap):
    // the largest distance is there, between the two arcs.
    let x = 0.015;
    let gap = arc(0.05, x) - arc(0.06, x);
    assert!(
        (e["tip_path_error_m"] - gap).abs() < 1e-9,
        "{} vs {gap}",
        e["tip_path_error_m"]
    );
    assert!((e["tip_deflection_m"] - arc(0.06, x)).abs() < 1e-9);
    // The path the run writes to tip_path.csv: every sample in the bend
    // plane (z here), and from 2 mm deep (the scored window) the fitted
    // arc's offset, which on an exact circle is the path's own.
    let path = &sum.plane_path;
    assert!(path.len() > 100, "{} samples", path.len());
    for q in path {
        assert!(
            (q.s - if q.x > 0.0 { arc(0.06, q.x) } else { 0.0 }).abs() < 1e-12,
            "{q:?}"
        );
        if q.x >= 2e-3 {
            assert!((q.fit - q.s).abs() < 1e-9, "{q:?}");
        } else {
            assert!(q.fit.is_nan(), "{q:?}");
        }
    }
}

/// An S-curve: an arc of radius 50 mm towards +z, then from `JOIN` one of
/// the same radius towards -z, tangent at the join.
const JOIN: f64 = TURN_DEPTH + 1.5e-3;

fn s_curve(x: f64) -> f64 {
    let r = 0.05f64;
    if x <= JOIN {
        return arc(r, x);
    }
    let s0 = arc(r, JOIN);
    let slope = JOIN / (r * r - JOIN * JOIN).sqrt();
    let norm = slope.hypot(1.0);
    let (cx, cz) = (JOIN + r * slope / norm, s0 - r / norm);
    cz + (r * r - (x - cx).powi(2)).sqrt()
}

#[test]
fn the_double_bend_scorer_finds_both_arcs_and_the_inflection() {
    let (s, _dir): (&Declared<DoubleBendParams>, _) = with_reference(&NEEDLE_DOUBLE_BEND, s_curve);
    let p = params(s, &[]);
    let sum = run(s, &p, &follower(s_curve));
    assert_eq!(sum.status, "ok", "{}", sum.reason);
    let e = &sum.errors;
    // Arc 1 is scored up to the turn's start (7.5 mm), arc 2 from 2 mm of
    // feed past the turn's end (10 mm): each wholly on one arc.
    assert!((e["curvature_1_per_m"] - 20.0).abs() < 1e-6, "{e:?}");
    assert!((e["curvature_2_per_m"] + 20.0).abs() < 1e-6, "{e:?}");
    // The local parabola fits on a 0.25 mm grid straddle the join.
    assert!((e["inflection_x_m"] - JOIN).abs() < 0.1e-3, "{e:?}");
    // The run is the reference (the feed's rounding apart): every error is
    // zero to rounding.
    assert!(e["curvature_error_rel"] < 1e-9, "{e:?}");
    // The two paths' x differ in the last bits (the feed is interpolated
    // between other keys), so a sample 10 um from a 2 mm window's edge can
    // fall in or out of it and move the fitted zero crossing: measured
    // 5e-6 m, a fiftieth of the 0.25 mm search grid.
    assert!(e["inflection_error_m"] < 1e-5, "{e:?}");
    assert!(e["tip_path_error_m"] < 1e-12, "{e:?}");
}

#[test]
fn the_steering_scenes_reject_a_turn_that_leaves_no_second_arc() {
    let s: &dyn Scenario = &NEEDLE_DOUBLE_BEND;
    let p = params(s, &[("turn_depth", 0.013)]);
    let e = s.instantiate(&p).err().expect("no room for the second arc");
    assert!(e.0.contains("turn_depth"), "{}", e.0);
}
