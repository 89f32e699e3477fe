//! A layered block (`TissueBody::regions`), coupling points embedded or
//! made mesh nodes by tip remeshing: a stiffer membrane with a
//! larger cutting force across the needle's path. While every coupling
//! point slides, the base force is the closed form of the straight
//! insertion with the cutting force of the tissue the tip is cutting,
//! `f_cut(region) + f_perlen d`: the membrane's while the tip is in it, the
//! gel's before and after. At the membrane the tip first tents it (the tip
//! point sticks until the force reaches the membrane's bound), then
//! punctures: the spike the seed's capsule shows.

mod common;

use surgbench_core::{Body, Fidelity, ModelFactory, SolidMaterial, TissueRegion, Vec3};
use surgbench_needle::NeedleFactory;

const F_PERLEN: f64 = 20.0;
const F_CUT: f64 = 0.05;
/// The membrane's cutting force (N): six times the gel's.
const F_MEMBRANE: f64 = 0.3;
const V: f64 = 0.01;
/// The membrane: the cell layer `x` in [7.5, 10] mm of the 8 x 4 x 4 block.
const MEMBRANE: [f64; 2] = [7.5e-3, 10e-3];

struct Sample {
    push: f64,
    d: f64,
    sliding: bool,
    tip_x: f64,
    /// Where the tip cuts (rest x, m) and the cutting force there (N).
    cut_x: f64,
    cut: f64,
}

/// The insertion with coupling points `coupling` (`embedded` or `remesh`).
fn run(cells: [usize; 3], coupling: &str) -> Vec<Sample> {
    let x1 = 17e-3 + 1e-3;
    let feed = [(0.0, 0.0), (x1 / V, x1)];
    let mut scene = common::scene(&feed, cells, F_PERLEN, F_CUT);
    let Body::Tissue(t) = &mut scene.bodies[1] else {
        panic!("the test scene's second body is the block")
    };
    let membrane: Vec<usize> = (0..t.mesh.tets.len())
        .filter(|&e| {
            let c = t.mesh.tets[e].iter().map(|&i| t.mesh.nodes[i]).sum::<Vec3>() / 4.0;
            c.x > MEMBRANE[0] && c.x < MEMBRANE[1]
        })
        .collect();
    assert!(!membrane.is_empty());
    t.regions.push(TissueRegion {
        name: "membrane".into(),
        material: SolidMaterial {
            youngs_modulus: 4.0 * t.material.youngs_modulus,
            ..t.material
        },
        tets: membrane,
        cutting_force: Some(F_MEMBRANE),
    });
    scene.validate().unwrap();
    // Remeshed: splits only (no snaps, which move built nodes and so the
    // layer faces they sit on).
    let mut settings = vec!["segments=40".to_string(), format!("coupling={coupling}")];
    if coupling == "remesh" {
        settings.push("remesh_max_offset=0".into());
    }
    let f = Fidelity::parse_pairs(&settings).unwrap();
    let mut m = NeedleFactory.build(&scene, &f).unwrap();
    let dt = m.dt();
    let n = (scene.duration / dt).round() as usize;
    (1..=n)
        .map(|i| {
            m.step(dt, &scene.control.command_at(i as f64 * dt)).unwrap();
            let o = m.observe();
            let d = m.diagnostics();
            Sample {
                push: -o.hand_force.x,
                d: d["inserted_length_m"],
                sliding: d["coupling_points"] >= 2.0 && d["forward_points"] == d["coupling_points"],
                tip_x: o.rods[0].nodes.last().expect("a needle has nodes").x,
                cut_x: d.get("tip_rest_x_m").copied().unwrap_or(f64::NAN),
                cut: d.get("tip_cutting_force_n").copied().unwrap_or(f64::NAN),
            }
        })
        .collect()
}

#[test]
fn the_base_force_takes_the_cutting_force_of_the_layer_the_tip_cuts() {
    check(&run([8, 4, 4], "embedded"), "embedded");
}

/// The same with every coupling point a mesh node: the tets the remesher
/// makes take the region of the tet they were split from.
#[test]
fn remeshed_the_base_force_takes_the_cutting_force_of_the_layer_the_tip_cuts() {
    check(&run([8, 4, 4], "remesh"), "remesh");
}

/// The checks of the layered insertion on the samples `s` of a run.
fn check(s: &[Sample], what: &str) {
    if std::env::var("TRACE").is_ok() {
        for (i, x) in s.iter().enumerate().step_by(10) {
            println!(
                "{i} tip {:.3} mm cut at {:.3} mm ({} N) d {:.3} mm push {:.4} N sliding {}",
                x.tip_x * 1e3,
                x.cut_x * 1e3,
                x.cut,
                x.d * 1e3,
                x.push,
                x.sliding
            );
        }
    }
    // The tip cuts at the membrane's force exactly while it cuts the
    // membrane's tets (rest x in the layer; round-off slack at its faces).
    let eps = 1e-9;
    for x in s.iter().filter(|x| x.cut.is_finite()) {
        let inside = x.cut_x > MEMBRANE[0] + eps && x.cut_x < MEMBRANE[1] - eps;
        let outside = x.cut_x < MEMBRANE[0] - eps || x.cut_x > MEMBRANE[1] + eps;
        assert!(
            (!inside || x.cut == F_MEMBRANE) && (!outside || x.cut == F_CUT),
            "cutting at rest x = {} m with {} N",
            x.cut_x,
            x.cut
        );
    }
    // While every point slides, the base force is the closed form with the
    // cutting force where the tip cut at the start of the step (the sample
    // before). Skipped: the 10 steps after the tip changes layer, while the
    // gel the puncture released springs back (measured: up to 3.8 % off for
    // 6 steps after the exit; the closed form is quasi-static).
    let (mut at_gel, mut at_membrane, mut worst, mut skipped) = (0, 0, 0.0f64, 0);
    let mut misses = Vec::new();
    let mut last_change = 0;
    for i in 1..s.len() {
        if s[i].cut != s[i - 1].cut {
            last_change = i;
        }
        let x = &s[i];
        if !(x.sliding && x.d > 1e-3) {
            continue;
        }
        if i - last_change <= 10 && last_change > 0 {
            skipped += 1;
            continue;
        }
        let cut = s[i - 1].cut;
        let closed = cut + F_PERLEN * x.d;
        let e = (x.push - closed).abs() / closed;
        if e < 0.02 {
            // Issue 17's 2 % bound of the straight insertion.
            worst = worst.max(e);
            if cut == F_MEMBRANE {
                at_membrane += 1;
            } else {
                at_gel += 1;
            }
        } else {
            misses.push((i, e));
        }
    }
    let peak = s.iter().map(|x| x.push).fold(f64::MIN, f64::max);
    println!(
        "{what}: sliding steps at the closed form: {at_gel} in gel, {at_membrane} in the membrane, worst {worst:.2e}; {skipped} skipped; misses {misses:?}; peak {peak} N"
    );
    // The tip enters the membrane once and leaves it once: no flip-flop of
    // the cutting force at a layer face.
    let changes = s
        .windows(2)
        .filter(|w| w[0].cut.is_finite() && w[1].cut != w[0].cut)
        .count();
    assert_eq!(changes, 2, "the tip changed layer {changes} times");
    assert!(
        at_gel > 300 && at_membrane > 100,
        "gel {at_gel}, membrane {at_membrane}"
    );
    assert!(misses.is_empty());
    // The puncture: the force peaks at the membrane's bound, above what the
    // gel alone gives at the full depth; and drops once the tip is through.
    assert!(peak > F_MEMBRANE + F_PERLEN * 9e-3, "peak {peak} N");
    let last = s.last().unwrap();
    assert!(last.cut == F_CUT && last.push < peak - 0.5 * (F_MEMBRANE - F_CUT));
}
