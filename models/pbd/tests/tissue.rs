//! Physics tests of the tetrahedral XPBD tissue (`pbd-tissue`).

use surgbench_core::Setting;
use surgbench_core::mesh::{tet_volume_gradients, tet_volume_of as tet_volume};
use surgbench_core::{
    Body, BuildError, DeviceCommand, Fidelity, Iso3, Model, ModelFactory, Observation, Scene, SolidMaterial,
    TissueBody, Vec3,
};
use surgbench_pbd::{PbdTissue, PbdTissueFactory, StaticParams, project_volume};

mod common;
use common::Rng;

fn fid(iters: usize, sub: usize, dt: f64, damping: f64) -> Fidelity {
    let mut f = Fidelity {
        dt: Some(dt),
        iterations: Some(iters),
        ..Default::default()
    };
    f.extras.insert("substeps".into(), Setting::from(sub as f64));
    f.extras.insert("damping".into(), Setting::from(damping));
    f
}

/// A block of `cells` cubes of edge `h` (m), with nodes selected by
/// predicates fixed and driven by `disp`.
fn block_scene(
    cells: [usize; 3],
    h: f64,
    nu: f64,
    fixed: impl Fn(&Vec3) -> bool,
    driven: impl Fn(&Vec3) -> bool,
    disp: Vec3,
) -> Scene {
    let size = Vec3::new(cells[0] as f64, cells[1] as f64, cells[2] as f64) * h;
    let mesh = surgbench_core::mesh::block(size, cells);
    let fixed_nodes = (0..mesh.nodes.len()).filter(|&i| fixed(&mesh.nodes[i])).collect();
    let driven_nodes = (0..mesh.nodes.len())
        .filter(|&i| driven(&mesh.nodes[i]))
        .map(|i| (i, disp))
        .collect();
    let mut scene = Scene::empty("block");
    let material = SolidMaterial {
        youngs_modulus: 1e4,
        poisson_ratio: nu,
        density: 1000.0,
    };
    scene.bodies.push(Body::Tissue(TissueBody {
        fixed_nodes,
        driven_nodes,
        ..TissueBody::new(mesh, material)
    }));
    scene
}

fn run(scene: &Scene, f: &Fidelity, steps: usize, ramp: usize) -> (Observation, PbdTissue) {
    let mut m = PbdTissue::new(scene, f).expect("build");
    let dt = f.dt.unwrap();
    for k in 1..=steps {
        let cmd = DeviceCommand {
            load: (k as f64 / ramp as f64).min(1.0),
            ..Default::default()
        };
        m.step(dt, &cmd).unwrap_or_else(|e| panic!("step {k}: {e}"));
    }
    (m.observe(), m)
}

#[test]
fn volume_gradients_match_finite_differences() {
    let mut rng = Rng(7);
    for case in 0..20 {
        let p: [Vec3; 4] = std::array::from_fn(|_| rng.signed_vec());
        let g = tet_volume_gradients(&p);
        for i in 0..4 {
            for a in 0..3 {
                let h = 1e-6;
                let (mut pp, mut pm) = (p, p);
                pp[i][a] += h;
                pm[i][a] -= h;
                let fd = (tet_volume(&pp) - tet_volume(&pm)) / (2.0 * h);
                // V is affine in each node, so central differences are exact up
                // to roundoff: eps * |V| / h ~ 1e-10.
                assert!(
                    (fd - g[i][a]).abs() < 1e-9,
                    "case {case}: dV/dp{}[{a}] analytic {} vs FD {fd}",
                    i + 1,
                    g[i][a]
                );
            }
        }
    }
}

#[test]
fn single_tet_is_projected_back_to_its_rest_volume() {
    let mut rng = Rng(11);
    let rest: [Vec3; 4] = [Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()];
    let v0 = tet_volume(&rest);
    let mut p = rest.map(|q| q + rng.signed_vec() * 0.2);
    let w = [1.0, 0.5, 2.0, 1.0];
    let mut lambda = 0.0;
    let mut errs = vec![(tet_volume(&p) - v0).abs() / v0];
    for _ in 0..6 {
        project_volume(&mut p, w, v0, 0.0, &mut lambda);
        errs.push((tet_volume(&p) - v0).abs() / v0);
    }
    println!("single tet: |V - V0| / V0 per projection: {errs:?}");
    // Each projection is a Newton step along the gradient of a cubic: the
    // error falls at least quadratically and reaches roundoff.
    assert!(errs[1] < errs[0], "first projection did not reduce the error: {errs:?}");
    assert!(
        errs[2] < 10.0 * errs[1] * errs[1].max(1e-16) + 1e-15,
        "not quadratic: {errs:?}"
    );
    assert!(errs[6] < 1e-14, "not at rest volume after 6 projections: {errs:?}");
}

#[test]
fn squashed_nearly_incompressible_block_keeps_its_volume() {
    const ITERS: usize = 40;
    const SUB: usize = 20;
    let h = 5e-3;
    let top = 4.0 * h;
    let scene = block_scene(
        [4, 4, 4],
        h,
        0.499,
        |p| p.z == 0.0,
        |p| p.z == top,
        Vec3::new(0.0, 0.0, -0.2 * top),
    );
    let (o, m) = run(&scene, &fid(ITERS, SUB, 1e-3, 100.0), 300, 100);
    let t = &o.tissues[0];
    println!(
        "squashed block: volume error {:.3e}, inverted {}, hand force {:?}, residual {:.2e}, speed check {:.2e}",
        t.volume_error,
        t.inverted,
        o.hand_force,
        o.constraint_residual.unwrap(),
        o.energy.kinetic
    );
    assert_eq!(t.inverted, 0, "inverted tets");
    // The brief's 1% bound. Measured -0.90% at a converged residual: far above
    // the continuum 0.04% because one volume constraint per linear tet
    // over-constrains the motion (volumetric locking): the error saturates near
    // -0.8% as nu -> 1/2 (measured -1.65% at nu = 0.49, -0.80% at 0.4999) while
    // the hand force grows with lambda (1.4 N, 6.4 N, 56 N at 0.49/0.499/0.4999).
    assert!(t.volume_error.abs() < 0.01, "volume error {}", t.volume_error);
    // The squashed block pushes back up on the hand.
    assert!(o.hand_force.z > 0.0, "hand force {:?}", o.hand_force);
    assert!(m.constraint_projections() > 0);
}

/// Static sideways sag of a 1x1x4-cell column (2 cm) fixed at its base under
/// gravity along -x: mean x of the top nodes (m).
fn column_sag(iters: usize) -> (f64, f64) {
    let h = 5e-3;
    let scene = {
        let mut s = block_scene([1, 1, 4], h, 0.3, |p| p.z == 0.0, |_| false, Vec3::zeros());
        s.gravity = Vec3::new(-9.81, 0.0, 0.0);
        s
    };
    let (o, _) = run(&scene, &fid(iters, 10, 1e-3, 200.0), 400, 1);
    let t = &o.tissues[0];
    let tops: Vec<f64> = t
        .rest
        .iter()
        .zip(&t.nodes)
        .filter(|(r, _)| (r.z - 4.0 * h).abs() < 1e-12)
        .map(|(r, p)| p.x - r.x)
        .collect();
    (
        tops.iter().sum::<f64>() / tops.len() as f64,
        o.constraint_residual.unwrap(),
    )
}

#[test]
fn xpbd_tissue_stiffness_does_not_depend_on_iterations() {
    let (a, ra) = column_sag(20);
    let (b, rb) = column_sag(80);
    let rel = (a - b).abs() / b.abs();
    println!(
        "column sag: 20 it {a:.9e} m (residual {ra:.1e}), 80 it {b:.9e} m (residual {rb:.1e}), rel diff {rel:.2e}"
    );
    // Tolerance: the 20-iteration solve's residual (relative constraint
    // violation left per substep, measured below 1e-6) bounds the difference.
    assert!(ra < 1e-6, "20 iterations did not converge: residual {ra}");
    assert!(rel < 1e-4, "20 it {a} vs 80 it {b}: rel diff {rel}");
    assert!(a < 0.0, "the column must sag along gravity: {a}");
}

#[test]
fn hanging_block_loads_the_hand_with_its_weight() {
    // Held by its top face only: at rest the hand carries the full weight.
    let h = 5e-3;
    let top = 3.0 * h;
    let mut scene = block_scene([2, 2, 3], h, 0.3, |_| false, |p| p.z == top, Vec3::zeros());
    scene.gravity = Vec3::new(0.0, 0.0, -9.81);
    let (o, _) = run(&scene, &fid(20, 10, 1e-3, 200.0), 300, 1);
    let weight = 1000.0 * 2.0 * 2.0 * 3.0 * h * h * h * 9.81;
    let rel = (o.hand_force - Vec3::new(0.0, 0.0, -weight)).norm() / weight;
    println!(
        "hanging block: hand force {:?}, weight {weight:.4e} N, rel err {rel:.2e}",
        o.hand_force
    );
    // Equilibrium up to the settled speed (kinetic energy ~0) and the residual.
    assert!(rel < 1e-4, "hand force {:?} vs weight {weight}", o.hand_force);
}

#[test]
fn reruns_are_bit_identical() {
    let h = 5e-3;
    let scene = block_scene(
        [3, 3, 3],
        h,
        0.45,
        |p| p.z == 0.0,
        |p| p.z == 3.0 * h,
        Vec3::new(1e-3, 0.0, -2e-3),
    );
    let f = fid(5, 2, 1e-3, 10.0);
    let (a, _) = run(&scene, &f, 50, 20);
    let (b, _) = run(&scene, &f, 50, 20);
    assert_eq!(a, b, "two runs of the same scene differ");
}

#[test]
fn rigid_motion_of_the_scene_moves_the_answer_rigidly() {
    let h = 5e-3;
    let mut scene = block_scene(
        [2, 2, 3],
        h,
        0.45,
        |p| p.z == 0.0,
        |p| p.z == 3.0 * h,
        Vec3::new(1e-3, 0.0, -2e-3),
    );
    scene.gravity = Vec3::new(0.0, 0.0, -9.81);
    let iso = Iso3::new(Vec3::new(0.3, -0.2, 0.5), Vec3::new(0.4, -1.1, 0.7));
    let moved = scene.transformed(&iso);
    let f = fid(10, 2, 1e-3, 10.0);
    let (a, _) = run(&scene, &f, 50, 20);
    let (b, _) = run(&moved, &f, 50, 20);
    let mut worst: f64 = 0.0;
    for (p, q) in a.tissues[0].nodes.iter().zip(&b.tissues[0].nodes) {
        worst = worst.max((iso.transform_point(&(*p).into()).coords - q).norm());
    }
    let df = (iso.rotation * a.hand_force - b.hand_force).norm() / a.hand_force.norm();
    println!("rigid motion: worst node mismatch {worst:.3e} m, hand force rel {df:.2e}");
    // Roundoff of coordinates of size ~0.5 m (1e-16 relative) amplified by
    // the stiff solve; measured ~1e-16 m. Bound 1e-12 m on a 15 mm block.
    assert!(worst < 1e-12, "worst node mismatch {worst} m");
    assert!(df < 1e-6, "hand force mismatch {df}");
}

#[test]
fn results_are_bit_identical_for_any_thread_count() {
    // The blocks of one colour touch disjoint nodes (crate::color), so the
    // parallel colour-ordered Gauss-Seidel must not depend on the threads,
    // also with local activation (a subset of every block).
    let h = 5e-3;
    let scene = block_scene(
        [3, 3, 16],
        h,
        0.45,
        |p| p.x == 0.0,
        |p| p.x == 3.0 * h && (p.z - 8.0 * h).abs() < 1.1 * h,
        Vec3::new(-1e-3, 0.0, 0.0),
    );
    for hash_box in [0.0, 0.02] {
        let mut runs = Vec::new();
        for threads in [1.0, 2.0, 3.0] {
            let mut f = fid(5, 2, 1e-3, 10.0);
            f.extras.insert("threads".into(), Setting::from(threads));
            if hash_box > 0.0 {
                f.extras.insert("hash_box".into(), Setting::from(hash_box));
            }
            let (o, m) = run(&scene, &f, 40, 20);
            assert_eq!(m.settings().threads, threads as usize);
            runs.push((threads, o));
        }
        for (threads, o) in &runs[1..] {
            assert!(
                *o == runs[0].1,
                "hash_box {hash_box}: {threads} threads differ from 1 thread (max node diff {:e} m)",
                o.tissues[0]
                    .nodes
                    .iter()
                    .zip(&runs[0].1.tissues[0].nodes)
                    .map(|(a, b)| (a - b).norm())
                    .fold(0.0, f64::max)
            );
        }
        assert!(runs[0].1.tissues[0].nodes != runs[0].1.tissues[0].rest, "nothing moved");
    }
}

/// A 3x3-node tool patch pushed 1.5 mm into the x = 3 cm face of a
/// 6x6x24-cell slab (3 x 3 x 12 cm, the x = 0 face fixed like a vessel wall on
/// its surroundings) at mid height z = 6 cm; returns (rms and max node error in the tool's core
/// box against the full solve, max displacement, projections full/local,
/// hand force relative difference).
fn local_vs_full(hash_box: f64, core: (f64, f64)) -> (f64, f64, f64, f64, f64) {
    let h = 5e-3;
    let (lx, lz) = (6.0 * h, 24.0 * h);
    let patch = move |p: &Vec3| p.x == lx && (p.z - lz / 2.0).abs() < 1.1 * h && (p.y - 3.0 * h).abs() < 1.1 * h;
    let scene = block_scene(
        [6, 6, 24],
        h,
        0.45,
        move |p| p.x == 0.0,
        patch,
        Vec3::new(-1.5e-3, 0.0, 0.0),
    );
    let steps = 120;
    // Converged solves (residual printed), so the difference is the localisation.
    let full_f = fid(20, 2, 1e-3, 100.0);
    let mut local_f = full_f.clone();
    local_f.extras.insert("hash_box".into(), Setting::from(hash_box));
    let (full, mf) = run(&scene, &full_f, steps, 40);
    let (local, ml) = run(&scene, &local_f, steps, 40);
    let rest = &full.tissues[0].rest;
    let (uf, ul) = (&full.tissues[0].nodes, &local.tissues[0].nodes);
    let umax = uf.iter().zip(rest).map(|(p, r)| (p - r).norm()).fold(0.0, f64::max);
    let (mut se, mut cnt, mut emax): (f64, usize, f64) = (0.0, 0, 0.0);
    for i in 0..rest.len() {
        if rest[i].z >= core.0 - 1e-12 && rest[i].z <= core.1 + 1e-12 {
            let e = (uf[i] - ul[i]).norm();
            se += e * e;
            cnt += 1;
            emax = emax.max(e);
        }
    }
    let rms = (se / cnt as f64).sqrt();
    let work = mf.constraint_projections() as f64 / ml.constraint_projections() as f64;
    let hf = (full.hand_force - local.hand_force).norm() / full.hand_force.norm();
    let (ne, nt) = ml.active_counts();
    let (fe, ft) = mf.active_counts();
    println!(
        "hash_box {hash_box} m: active {ne} edges + {nt} tets of {fe} + {ft}; projections full/local {work:.2}; \
         core-box error rms {rms:.3e} m, max {emax:.3e} m (max displacement {umax:.3e} m); hand force rel diff {hf:.3e}; \
         residuals full {:.1e} local {:.1e}",
        full.constraint_residual.unwrap(),
        local.constraint_residual.unwrap()
    );
    assert!(nt > 0 && nt < ft, "active tets {nt} of {ft}");
    (rms, emax, umax, work, hf)
}

#[test]
fn local_hash_activation_approaches_the_full_solve_as_the_box_grows() {
    // Boxes centred on the tool (z = 6 cm): d = 2.4 cm (core 4.8-7.2 cm) and
    // d = 4 cm (core 4-8 cm). Holding the nodes where the active tets meet
    // the others stiffens the local problem (the 2.4 cm box, whose region
    // ends 1.4 cm below the pushed face, doubles the hand force: 117 %; the
    // 4 cm box spans the slab's thickness: 7 %); a larger box holds them
    // farther from the tool.
    let small = local_vs_full(0.024, (0.048, 0.072));
    let large = local_vs_full(0.04, (0.04, 0.08));
    // Work saved follows the active fraction: (d + 2 d/3) / 12 cm of the tets.
    assert!(
        small.3 > large.3 && large.3 > 1.2,
        "work ratios small box {} large box {}",
        small.3,
        large.3
    );
    // Localisation error falls as the box grows (measured, printed above).
    assert!(
        large.0 < small.0,
        "rms error did not fall with the box: small {} large {}",
        small.0,
        large.0
    );
    assert!(
        large.4 < small.4,
        "hand force error did not fall with the box: small {} large {}",
        small.4,
        large.4
    );
}

#[test]
fn bad_input_is_rejected_not_panicked() {
    let h = 5e-3;
    let scene = block_scene([1, 1, 1], h, 0.3, |p| p.z == 0.0, |_| false, Vec3::zeros());
    let mut f = fid(10, 1, 1e-3, 0.0);
    f.extras.insert("hashbox".into(), Setting::from(0.1));
    assert!(matches!(
        PbdTissueFactory.build(&scene, &f),
        Err(BuildError::BadParameter { .. })
    ));
    let mut f = fid(10, 1, 1e-3, 0.0);
    f.extras.insert("hash_box".into(), Setting::from(0.01));
    // Local activation needs a tool (driven nodes): none here.
    assert!(matches!(
        PbdTissueFactory.build(&scene, &f),
        Err(BuildError::BadParameter { .. })
    ));
    for threads in [0.0, 1.5, -2.0] {
        let mut f = fid(10, 1, 1e-3, 0.0);
        f.extras.insert("threads".into(), Setting::from(threads));
        assert!(
            matches!(PbdTissueFactory.build(&scene, &f), Err(BuildError::BadParameter { .. })),
            "threads = {threads} accepted"
        );
    }
    let neg = block_scene([1, 1, 1], h, -0.2, |p| p.z == 0.0, |_| false, Vec3::zeros());
    assert!(PbdTissueFactory.check(&neg).is_err());
    assert!(PbdTissueFactory.check(&Scene::empty("none")).is_err());
}

/// A 2x2x2-cell block (1 cm) on a fixed base with its top face driven down
/// by `d` (m), settled: (hand force, multiplier hand force, constraint energy).
fn compressed_block(d: f64, iters: usize) -> (Vec3, Vec3, f64) {
    let (o, m) = compressed_model(d, iters, 10, 300);
    (o.hand_force, m.multiplier_hand_force(), o.energy.elastic)
}

#[test]
fn hand_force_is_the_derivative_of_the_energy_in_the_driven_displacement() {
    // At static equilibrium of the free nodes the reaction on the driven
    // nodes is -dU/dx_driven, so along the drive f.z = dU/dd (the top moves
    // along -z): compared with a central difference of the settled energy.
    let d = 2e-4;
    let dd = 2e-6;
    let (f, fl, _) = compressed_block(d, 40);
    let (_, _, up) = compressed_block(d + dd, 40);
    let (_, _, dn) = compressed_block(d - dd, 40);
    let du = (up - dn) / (2.0 * dd);
    let rel = (f.z - du).abs() / du.abs();
    let rel_lambda = (fl - f).norm() / f.norm();
    println!(
        "compressed block: hand force {f:?}, multiplier force {fl:?} (rel diff {rel_lambda:.2e}), \
         dU/dd {du:.6e} N, rel err {rel:.2e}"
    );
    assert!(f.z > 0.0, "the compressed block must push the hand back up: {f:?}");
    // Central difference O((dd/d)^2) = 1e-4 of the nonlinear (geometric)
    // part plus the settling error; measured 1.5e-6.
    assert!(rel < 1e-3, "f.z {} vs dU/dd {du}: rel {rel}", f.z);
    // At convergence lambda / h^2 = -C / alpha (Macklin et al. 2016, eq. 18):
    // the two estimates agree up to the solve's residual (measured 1e-16).
    assert!(rel_lambda < 1e-3, "multiplier force {fl:?} vs energy force {f:?}");
}

/// The compressed block of [`compressed_block`] stepped `steps` steps
/// (ramp over 100) at `iters` iterations and `sub` substeps.
fn compressed_model(d: f64, iters: usize, sub: usize, steps: usize) -> (Observation, PbdTissue) {
    let h = 5e-3;
    let top = 2.0 * h;
    let scene = block_scene(
        [2, 2, 2],
        h,
        0.3,
        |p| p.z == 0.0,
        |p| p.z == top,
        Vec3::new(0.0, 0.0, -d),
    );
    run(&scene, &fid(iters, sub, 1e-3, 200.0), steps, 100)
}

#[test]
fn static_equilibrium_is_the_converged_xpbd_answer_from_any_start() {
    let d = 2e-4;
    let p = StaticParams::default();
    let (o_conv, m_conv) = compressed_model(d, 40, 10, 300);
    // One iteration, one substep, stopped right after the ramp: far from
    // converged and not settled.
    let (o_raw, m_raw) = compressed_model(d, 1, 1, 100);
    let a = m_conv.static_equilibrium(&p).expect("compliant block");
    let b = m_raw.static_equilibrium(&p).expect("compliant block");
    let f = a.hand_force;
    println!(
        "static: {f:?} ({} GN, {} CG, rel res {:.1e}) and {:?} ({} GN, {} CG, rel res {:.1e}); \
         settled 40-it XPBD {:?}, 1-it XPBD {:?} (fraction {:.3})",
        a.newton_iterations,
        a.cg_iterations,
        a.rel_residual,
        b.hand_force,
        b.newton_iterations,
        b.cg_iterations,
        b.rel_residual,
        o_conv.hand_force,
        o_raw.hand_force,
        o_raw.hand_force.dot(&f) / f.norm_squared()
    );
    assert!(
        a.converged && b.converged,
        "static solves did not converge: {a:?} {b:?}"
    );
    // Same minimum from two starts: the gradient test (1e-9 of the load)
    // bounds the force difference through the stiffness; measured 7e-10.
    let rel_start = (a.hand_force - b.hand_force).norm() / f.norm();
    assert!(
        rel_start < 1e-7,
        "static force depends on the start: {f:?} vs {:?}",
        b.hand_force
    );
    // A converged, settled XPBD run rests there too (the 40-iteration solve's
    // residual and the settling speed; measured 2.7e-6).
    let rel_xpbd = (o_conv.hand_force - f).norm() / f.norm();
    assert!(rel_xpbd < 1e-4, "settled XPBD {:?} vs static {f:?}", o_conv.hand_force);
    // The unconverged run is measurably off, so the diagnostic separates them.
    let rel_raw = (o_raw.hand_force - f).norm() / f.norm();
    assert!(
        rel_raw > 1e-2,
        "1-iteration run unexpectedly converged: {:?}",
        o_raw.hand_force
    );
    let diag = m_raw.diagnostics();
    assert_eq!(diag.get("static_converged"), Some(&1.0), "{diag:?}");
    assert!((diag["static_hand_force_n"] - b.hand_force.norm()).abs() <= 1e-12 * f.norm());
}

#[test]
fn static_hand_force_is_the_derivative_of_the_minimum_energy() {
    // Envelope theorem: at the minimum over the free nodes, dU*/dd equals the
    // reaction along the drive (the top moves along -z, so f.z = dU*/dd),
    // independent of any XPBD run (each start is 1 iteration, unsettled).
    let (d, dd) = (2e-4, 2e-6);
    let p = StaticParams::default();
    let solve = |d: f64| {
        compressed_model(d, 1, 1, 100)
            .1
            .static_equilibrium(&p)
            .expect("compliant")
    };
    let (s, up, dn) = (solve(d), solve(d + dd), solve(d - dd));
    let du = (up.elastic_energy - dn.elastic_energy) / (2.0 * dd);
    let rel = (s.hand_force.z - du).abs() / du;
    println!("static hand force {:?}, dU*/dd {du:.9e} N, rel {rel:.2e}", s.hand_force);
    assert!(s.converged && up.converged && dn.converged);
    // Central difference: O((dd/d)^2) = 1e-4 of the geometric nonlinearity
    // (much less in practice), plus roundoff of U ~ 1e-16 U / dd; measured 1.4e-8.
    assert!(rel < 1e-5, "f.z {} vs dU*/dd {du}: rel {rel}", s.hand_force.z);
}
