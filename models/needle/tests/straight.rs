//! Straight insertion of a stiff needle into a gel block: the base force
//! against the closed form `f_cut + f_perlen d` while every coupling point
//! slides (seed Sec. 3.3: the friction bounds sum to `f_perlen d`), the
//! hold, and the retraction `-f_perlen d`.

mod common;

use surgbench_core::{Fidelity, ModelFactory};
use surgbench_needle::NeedleFactory;

const F_PERLEN: f64 = 20.0;
const F_CUT: f64 = 0.05;
const V: f64 = 0.01;

/// One sample per step: time, axial force the hand applies (N), inserted
/// length (m), points sliding forward and backward, coupling points.
struct Sample {
    t: f64,
    push: f64,
    d: f64,
    forward: f64,
    backward: f64,
    points: f64,
    /// Remeshed runs: coupling points left embedded for want of a valid
    /// operation, and the tissue's node count.
    refused: f64,
    nodes: f64,
    /// The smallest tet volume ratio `V / V0` so far.
    volume_ratio_min: f64,
    /// Share of tet blocks rebuilt per step so far, and tissue
    /// factorizations so far (the lazy Jacobian's counts).
    updated: f64,
    factorizations: f64,
}

/// Insert 12 mm at `V`, hold 0.3 s, retract 10 mm at `V`.
fn run(cells: [usize; 3], segments: usize) -> Vec<Sample> {
    run_threads(cells, segments, 2)
}

/// [`run`] with the tissue assembled on `threads` threads.
fn run_threads(cells: [usize; 3], segments: usize, threads: usize) -> Vec<Sample> {
    run_with(cells, segments, threads, 0.0)
}

/// [`run_threads`] with viscous shaft friction `eta` (N s/m^2).
fn run_with(cells: [usize; 3], segments: usize, threads: usize, eta: f64) -> Vec<Sample> {
    run_coupled(cells, segments, threads, eta, "embedded")
}

/// [`run_with`] with coupling points `coupling` (`embedded` or `remesh`).
fn run_coupled(cells: [usize; 3], segments: usize, threads: usize, eta: f64, coupling: &str) -> Vec<Sample> {
    run_lazy(cells, segments, threads, eta, coupling, 0.0)
}

/// [`run_coupled`] with the tissue's lazy Jacobian threshold (rad).
fn run_lazy(cells: [usize; 3], segments: usize, threads: usize, eta: f64, coupling: &str, lazy: f64) -> Vec<Sample> {
    let x1 = 12e-3 + 1e-3;
    let feed = [(0.0, 0.0), (x1 / V, x1), (x1 / V + 0.3, x1), (x1 / V + 1.3, x1 - 10e-3)];
    let mut scene = common::scene(&feed, cells, F_PERLEN, F_CUT);
    scene.needle.as_mut().expect("a needle scene").viscous_friction = eta;
    let f = Fidelity::parse_pairs(&[
        format!("segments={segments}"),
        format!("threads={threads}"),
        format!("coupling={coupling}"),
        format!("lazy_threshold={lazy}"),
    ])
    .unwrap();
    let mut m = NeedleFactory.build(&scene, &f).unwrap();
    let dt = m.dt();
    let n = (scene.duration / dt).round() as usize;
    let mut out = Vec::with_capacity(n);
    for i in 1..=n {
        let t = i as f64 * dt;
        m.step(dt, &scene.control.command_at(t)).unwrap();
        let o = m.observe();
        let d = m.diagnostics();
        out.push(Sample {
            t,
            // The observation's hand force is the needle's force on the hand.
            push: -o.hand_force.x,
            d: d["inserted_length_m"],
            forward: d["forward_points"],
            backward: d["backward_points"],
            points: d["coupling_points"],
            refused: d.get("remesh_refused").copied().unwrap_or(0.0),
            nodes: d.get("tissue_nodes").copied().unwrap_or(0.0),
            volume_ratio_min: d["tissue_volume_ratio_min"],
            updated: d["tets_updated_fraction"],
            factorizations: d["tissue_factorizations"],
        });
    }
    out
}

#[test]
fn base_force_follows_the_closed_form_while_sliding() {
    closed_form_while_sliding(&run([8, 4, 4], 40), "embedded");
}

#[test]
fn remeshed_base_force_follows_the_closed_form_while_sliding() {
    let s = run_coupled([8, 4, 4], 40, 2, 0.0, "remesh");
    closed_form_while_sliding(&s, "remesh");
    let last = s.last().unwrap();
    let most = s.iter().map(|x| x.nodes).fold(0.0, f64::max);
    println!(
        "remesh: {} refused, tissue nodes up to {most}, {} at the end",
        last.refused, last.nodes
    );
    // Every coupling point found a valid operation (it is a mesh node).
    assert_eq!(last.refused, 0.0);
    // No element inverts at this mesh level (measured: 0.78 at the worst
    // step). At level 1 the tip's node, stuck, squeezes the tet ahead of it
    // through zero (issue 18 note); this is what would show it here.
    assert!(last.volume_ratio_min > 0.0, "volume ratio {}", last.volume_ratio_min);
    // The block has 9 x 5 x 5 = 225 nodes; the channel added some (the
    // needle runs along a grid line, so many points snap grid nodes).
    assert!(most > 225.0);
}

/// The checks of the straight insertion on the samples `s` of a run.
fn closed_form_while_sliding(s: &[Sample], what: &str) {
    let t_in = 13e-3 / V;
    let mut worst_in: f64 = 0.0;
    let mut worst_out: f64 = 0.0;
    let (mut sliding_in, mut sliding_out) = (0, 0);
    for x in s {
        // The closed form holds while every point slides the way the needle moves.
        if x.points >= 2.0 && x.forward == x.points && x.t < t_in {
            sliding_in += 1;
            let closed = F_CUT + F_PERLEN * x.d;
            worst_in = worst_in.max((x.push - closed).abs() / closed);
        }
        if x.points >= 2.0 && x.backward == x.points && x.t > t_in + 0.3 {
            sliding_out += 1;
            let closed = -F_PERLEN * x.d;
            worst_out = worst_out.max((x.push - closed).abs() / closed.abs());
        }
        // Holding and retracting, the hand force never exceeds what the
        // friction bounds (and, pushing, the uncut tip) can hold. Slack: the
        // LCP's check tolerance, and the friction of the length the needle
        // leaves in one step of 1 ms (the bounds use the step's starting d,
        // the sample its end).
        if x.t > t_in + 1.5e-3 {
            let bound = F_PERLEN * x.d + if x.push > 0.0 { F_CUT } else { 0.0 };
            assert!(
                x.push.abs() <= bound * (1.0 + 1e-3) + F_PERLEN * V * 1e-3,
                "t = {} s: {} N past {} N",
                x.t,
                x.push,
                bound
            );
        }
    }
    println!(
        "{what}: sliding steps {sliding_in} in, {sliding_out} out, worst insertion error {worst_in:.3e}, retraction {worst_out:.3e}"
    );
    // Most of the insertion slides (measured: 854 of 1,300 steps; the
    // others are stick episodes of the block's axial ringing).
    assert!(sliding_in > 500, "{sliding_in} sliding steps");
    // Issue 17's bound; measured 0.26 % (the needle's axial inertia and the
    // one-step linearization of its clamp reaction).
    assert!(worst_in < 0.02, "insertion error {worst_in}");
    // Retracting, the tissue first follows the needle back, releasing the
    // compression the insertion stored (~6 mm of the 10 mm stroke); then
    // every point slides back (measured: 413 steps, worst error 0.33 %).
    assert!(sliding_out > 100, "{sliding_out} steps sliding back");
    assert!(worst_out < 0.02, "retraction error {worst_out}");
}

/// The tissue's lazy Jacobian (`lazy_threshold`, rad): a tet's warped
/// stiffness is rebuilt only once its rotation has turned past the
/// threshold, and a step whose blocks all stayed keeps the factorization.
/// The forces are exact at every step; only the implicit step's matrix is
/// older, so the run tends to the full update as the threshold falls.
#[test]
fn lazy_jacobian_tends_to_the_full_update_and_keeps_the_closed_form() {
    let full = run_lazy([8, 4, 4], 40, 2, 0.0, "embedded", 0.0);
    let steps = full.len() as f64;
    let end = full.last().unwrap();
    assert_eq!(end.updated, 1.0, "every block every step");
    assert_eq!(end.factorizations, steps, "one factorization a step");
    // The force scale: the closed form at the deepest insertion.
    let scale = F_CUT + F_PERLEN * 12e-3;
    let (mut devs, mut last_updated, mut last_factorizations) = (Vec::new(), 1.0, steps);
    for lazy in [1e-4, 1e-3, 1e-2, 1e-1] {
        let s = run_lazy([8, 4, 4], 40, 2, 0.0, "embedded", lazy);
        let dev = s
            .iter()
            .zip(&full)
            .map(|(a, b)| (a.push - b.push).abs())
            .fold(0.0, f64::max)
            / scale;
        let end = s.last().unwrap();
        println!(
            "lazy {lazy}: updated {:.4}, factorizations {} of {steps}, worst force change {dev:.3e} of the scale",
            end.updated, end.factorizations
        );
        // A higher threshold keeps more blocks and factorizations.
        assert!(end.updated < last_updated, "lazy {lazy}: updated {}", end.updated);
        assert!(end.factorizations <= last_factorizations, "lazy {lazy}");
        (last_updated, last_factorizations) = (end.updated, end.factorizations);
        // The closed form holds as tightly as with the full update
        // (measured 0.26-0.27 % inserting, 0.32-0.33 % retracting at 1e-2 and 1e-1).
        if lazy >= 1e-2 {
            closed_form_while_sliding(&s, &format!("lazy {lazy}"));
        }
        devs.push(dev);
    }
    // The run tends to the full update as the threshold falls (measured
    // 7.6e-8, 5.6e-6, 8.3e-3 of the scale at 1e-4, 1e-3, 1e-2).
    assert!(devs[0] < devs[1] && devs[1] < devs[2], "{devs:?}");
    assert!(devs[0] < 1e-6, "{devs:?}");
}

#[test]
fn reruns_are_bit_identical_at_1_and_2_threads() {
    for coupling in ["embedded", "remesh"] {
        let a = run_coupled([4, 2, 2], 20, 1, 0.0, coupling);
        let b = run_coupled([4, 2, 2], 20, 2, 0.0, coupling);
        let c = run_coupled([4, 2, 2], 20, 2, 0.0, coupling);
        assert_eq!(a.len(), b.len());
        let same = |x: &Sample, y: &Sample| x.push.to_bits() == y.push.to_bits() && x.d.to_bits() == y.d.to_bits();
        assert!(b.iter().zip(&c).all(|(x, y)| same(x, y)), "{coupling}: rerun");
        assert!(a.iter().zip(&b).all(|(x, y)| same(x, y)), "{coupling}: 1 vs 2 threads");
    }
    // A block whose factor is supernodal, with a lazy Jacobian: the kept
    // Delassus columns and the two-way parallel sweeps of the factor are
    // in play (the small block's factor is simplicial).
    let a = run_lazy([12, 6, 6], 20, 1, 0.0, "embedded", 0.1);
    let b = run_lazy([12, 6, 6], 20, 2, 0.0, "embedded", 0.1);
    let same = |x: &Sample, y: &Sample| x.push.to_bits() == y.push.to_bits() && x.d.to_bits() == y.d.to_bits();
    assert!(a.iter().zip(&b).all(|(x, y)| same(x, y)), "supernodal: 1 vs 2 threads");
}

#[test]
fn viscous_friction_adds_at_most_eta_v_d_while_sliding() {
    // eta v = 10 N/m at 10 mm/s: half the Coulomb friction per length.
    let eta = 1000.0;
    let s = run_with([8, 4, 4], 40, 2, eta);
    let t_in = 13e-3 / V;
    let (mut share_sum, mut sliding) = (0.0, 0);
    for x in s
        .iter()
        .filter(|x| x.t < t_in && x.d >= 2e-3 && x.points >= 2.0 && x.forward == x.points)
    {
        // Sliding forward, the shaft moves through the tissue at a speed in
        // [0, v]: the soft gel moves on with the needle (its compression
        // grows with the force), so the closed form with the tissue at rest,
        // f_cut + (f_perlen + eta v) d, is the upper bound and f_cut +
        // f_perlen d the lower. Slack: the 2 % of issue 17's bound.
        let (coulomb, viscous) = (F_CUT + F_PERLEN * x.d, eta * V * x.d);
        assert!(
            x.push >= coulomb * 0.98 && x.push <= (coulomb + viscous) * 1.02,
            "t = {} s: push {} N outside [{coulomb}, {}] N",
            x.t,
            x.push,
            coulomb + viscous
        );
        share_sum += (x.push - coulomb) / viscous;
        sliding += 1;
    }
    let share = share_sum / sliding as f64;
    println!("viscous: {sliding} sliding steps, mean viscous share {share:.3} of eta v d");
    assert!(sliding > 500, "{sliding} sliding steps");
    // Measured: the mean share is 0.73 (the shaft slides at 0.64 v to 0.79 v
    // as d grows): the viscous term acts, at the tissue's relative speed.
    assert!(share > 0.0, "no viscous force: share {share}");
}

#[test]
fn remeshing_is_taken_back_when_the_needle_leaves_and_refused_without_it() {
    // In 6 mm (tip 5 mm deep), out to 3 mm before the block.
    let feed = [(0.0, 0.0), (0.6, 6e-3), (1.4, -2e-3)];
    let scene = common::scene(&feed, [8, 4, 4], F_PERLEN, F_CUT);
    let f = Fidelity::parse_pairs(&["segments=40".to_string(), "coupling=remesh".to_string()]).unwrap();
    let mut m = NeedleFactory.build(&scene, &f).unwrap();
    let dt = m.dt();
    let (mut most_nodes, mut deepest) = (0.0_f64, 0.0_f64);
    for i in 1..=(scene.duration / dt).round() as usize {
        m.step(dt, &scene.control.command_at(i as f64 * dt)).unwrap();
        let d = m.diagnostics();
        most_nodes = most_nodes.max(d["tissue_nodes"]);
        deepest = deepest.max(d["remesh_depth"]);
    }
    let d = m.diagnostics();
    // 9 x 5 x 5 nodes; the channel had nodes of its own, all taken back.
    assert!(deepest >= 3.0, "entry, shaft and tip nodes: {deepest} operations deep");
    assert!(most_nodes > 225.0);
    assert_eq!(d["remesh_depth"], 0.0);
    assert_eq!(d["tissue_nodes"], 225.0);
    assert_eq!(d["coupling_points"], 0.0);
    let bad = Fidelity::parse_pairs(&["remesh_max_offset=0.2".to_string()]).unwrap();
    let err = NeedleFactory.build(&scene, &bad).err().expect("refused").to_string();
    assert!(err.contains("coupling=remesh only"), "{err}");
}
