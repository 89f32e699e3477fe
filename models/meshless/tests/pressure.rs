//! Follower pressure loads: resultants against closed forms, forces as the
//! volume gradient on closed surfaces, the load stiffness against finite
//! differences, and the Lamé tube (plane strain) through the model.

mod common;

use common::{Rng, jittered_block, material};
use std::f64::consts::PI;
use surgbench_core::{Body, Fidelity, Model, Scene, TetMesh, TissueBody, Vec3, mesh};
use surgbench_meshless::{MeshlessTissue, PressureLoad};

/// Volume enclosed by closed, outward-oriented triangles (m^3):
/// `(1/6) sum a . (b x c)` (divergence theorem).
fn enclosed_volume(faces: &[[usize; 3]], x: &[Vec3]) -> f64 {
    faces.iter().map(|f| x[f[0]].dot(&x[f[1]].cross(&x[f[2]])) / 6.0).sum()
}

/// A jittered block with its nodes moved randomly by up to `amp` (m).
fn deformed_block(seed: u64, amp: f64) -> (TetMesh, Vec<Vec3>) {
    let m = jittered_block(Vec3::new(0.01, 0.008, 0.006), [4, 3, 3], 0.1, seed);
    let mut r = Rng(seed + 100);
    let x = m.nodes.iter().map(|p| p + r.vec() * amp).collect();
    (m, x)
}

#[test]
fn closed_surface_pressure_has_zero_resultant_and_moment() {
    let (m, x) = deformed_block(3, 5e-4);
    let p = 250.0;
    let load = PressureLoad::new(&mesh::boundary_faces(&m).into_iter().map(|f| (f, p)).collect::<Vec<_>>());
    let mut f = vec![Vec3::zeros(); x.len()];
    load.add_forces(&x, 1.0, &mut f);
    let total: Vec3 = f.iter().sum();
    let moment: Vec3 = x.iter().zip(&f).map(|(xi, fi)| xi.cross(fi)).sum();
    let scale = f.iter().map(|v| v.norm()).sum::<f64>();
    // Exact cancellation up to rounding: ~1e-16 times the summed magnitudes.
    assert!(
        total.norm() < 1e-13 * scale,
        "sum of pressure forces {total:?} N, sum |f| {scale:.3e} N"
    );
    // On a closed surface the forces are -p dV/dx and V is invariant under
    // rotations, so the moment sum x_i x f_i vanishes too, up to rounding.
    let l = 0.01;
    assert!(
        moment.norm() < 1e-13 * scale * l,
        "moment {moment:?} N m vs sum |f| L {:.3e}",
        scale * l
    );
}

#[test]
fn closed_surface_pressure_is_minus_p_grad_volume() {
    // On a closed surface the consistent nodal forces are -p dV/dx exactly
    // (Bonet & Wood Sec. 6.5): check by central differences of V.
    let (m, mut x) = deformed_block(5, 4e-4);
    let p = 80.0;
    let faces = mesh::boundary_faces(&m);
    let load = PressureLoad::new(&faces.iter().map(|&f| (f, p)).collect::<Vec<_>>());
    let mut f = vec![Vec3::zeros(); x.len()];
    load.add_forces(&x, 1.0, &mut f);
    let fmax = f.iter().map(|v| v.amax()).fold(0.0, f64::max);
    let h = 1e-7;
    let mut worst: f64 = 0.0;
    for i in (0..x.len()).step_by(3) {
        for k in 0..3 {
            x[i][k] += h;
            let vp = enclosed_volume(&faces, &x);
            x[i][k] -= 2.0 * h;
            let vm = enclosed_volume(&faces, &x);
            x[i][k] += h;
            let fd = -p * (vp - vm) / (2.0 * h);
            worst = worst.max((fd - f[i][k]).abs());
        }
    }
    // V is cubic in x: central differences carry O(h^2) = 1e-14 relative
    // truncation plus rounding V * 1e-16 / h ~ 1e-15 m^2 against gradients ~ 1e-5 m^2.
    assert!(
        worst < 1e-6 * fmax,
        "max |f + p dV/dx| {worst:.3e} N, max |f| {fmax:.3e} N"
    );
}

#[test]
fn load_stiffness_matches_finite_differences_and_is_symmetric_when_closed() {
    let (m, x) = deformed_block(9, 5e-4);
    let p = 120.0;
    let all = mesh::boundary_faces(&m);
    // An open patch (faces on the bottom, z ~ 0) and the closed surface.
    let bottom: Vec<[usize; 3]> = all
        .iter()
        .copied()
        .filter(|f| f.iter().all(|&i| m.nodes[i].z < 1e-3))
        .collect();
    assert!(!bottom.is_empty());
    let mut r = Rng(21);
    let dx: Vec<Vec3> = x.iter().map(|_| r.vec()).collect();
    let y: Vec<Vec3> = x.iter().map(|_| r.vec()).collect();
    for (name, faces, closed) in [("open", &bottom, false), ("closed", &all, true)] {
        let load = PressureLoad::new(&faces.iter().map(|&f| (f, p)).collect::<Vec<_>>());
        let s = 0.7;
        let force = |x: &[Vec3]| {
            let mut f = vec![Vec3::zeros(); x.len()];
            load.add_forces(x, s, &mut f);
            f
        };
        let mut jdx = vec![Vec3::zeros(); x.len()];
        load.add_jacobian(&x, s, &dx, &mut jdx);
        // The force is quadratic in x: central differences are exact up to rounding.
        let h = 1e-6;
        let xp: Vec<Vec3> = x.iter().zip(&dx).map(|(a, d)| a + d * h).collect();
        let xm: Vec<Vec3> = x.iter().zip(&dx).map(|(a, d)| a - d * h).collect();
        let (fp, fm) = (force(&xp), force(&xm));
        let jmax = jdx.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let err = (0..x.len())
            .map(|i| ((fp[i] - fm[i]) / (2.0 * h) - jdx[i]).amax())
            .fold(0.0, f64::max);
        // Rounding: |f| 1e-16 / h ~ 1e-10 of |J dx| here; 1e-7 leaves margin.
        assert!(
            err < 1e-7 * jmax,
            "{name}: max |FD - J dx| {err:.3e}, max |J dx| {jmax:.3e}"
        );
        // J^T through the adjoint identity y . (J dx) = (J^T y) . dx.
        let mut jty = vec![Vec3::zeros(); x.len()];
        load.add_jacobian_transpose(&x, s, &y, &mut jty);
        let a: f64 = y.iter().zip(&jdx).map(|(u, v)| u.dot(v)).sum();
        let b: f64 = jty.iter().zip(&dx).map(|(u, v)| u.dot(v)).sum();
        assert!(
            (a - b).abs() < 1e-12 * (a.abs() + b.abs()),
            "{name}: y.Jdx = {a:.15e}, J^T y.dx = {b:.15e}"
        );
        // Symmetric stiffness = -(J + J^T)/2.
        let mut ks = vec![Vec3::zeros(); x.len()];
        load.add_sym_stiffness(&x, s, &dx, &mut ks);
        let mut jtdx = vec![Vec3::zeros(); x.len()];
        load.add_jacobian_transpose(&x, s, &dx, &mut jtdx);
        let serr = (0..x.len())
            .map(|i| (ks[i] + (jdx[i] + jtdx[i]) * 0.5).amax())
            .fold(0.0, f64::max);
        assert!(serr < 1e-12 * jmax, "{name}: |K_s dx + (J + J^T) dx / 2| = {serr:.3e}");
        // Skew part: zero on the closed surface (-p d2V/dx2), not on the open patch.
        let skew = (0..x.len()).map(|i| (jdx[i] - jtdx[i]).amax()).fold(0.0, f64::max);
        eprintln!("{name} surface: max |(J - J^T) dx| = {skew:.3e}, max |J dx| = {jmax:.3e}");
        if closed {
            assert!(
                skew < 1e-12 * jmax,
                "closed surface: skew part {skew:.3e} vs {jmax:.3e}"
            );
        } else {
            assert!(skew > 1e-3 * jmax, "open patch: expected a skew part, got {skew:.3e}");
        }
    }
}

/// Inner-wall faces of a full tube, radius `a`, height `l`, `n` facets around.
fn inner_wall(a: f64, l: f64, n: usize) -> (TetMesh, PressureLoad) {
    let m = mesh::tube(a, 2.0 * a, l, n, 2, 3);
    let inner: Vec<bool> = m.nodes.iter().map(|p| (p.xy().norm() - a).abs() < 1e-9 * a).collect();
    let faces: Vec<([usize; 3], f64)> = mesh::boundary_faces(&m)
        .into_iter()
        .filter(|f| f.iter().all(|&i| inner[i]))
        .map(|f| (f, 1.0))
        .collect();
    (m, PressureLoad::new(&faces))
}

#[test]
fn tube_inner_pressure_resultant_radial_load_is_p_2pi_a_l() {
    // Internal pressure p on the inner wall of a tube (radius a, length L):
    // zero net force, total outward radial load p 2 pi a L. With n flat
    // facets the faceted wall carries exactly p n a sin(2 pi / n) L (each
    // facet's area 2 a sin(pi/n) L, its nodes cos(pi/n) off its normal),
    // which tends to p 2 pi a L with relative error (2 pi / n)^2 / 6.
    let (a, l, p) = (0.01, 0.005, 40.0);
    let mut errs = Vec::new();
    for n in [12, 24, 48] {
        let (m, mut load) = inner_wall(a, l, n);
        load.pressure.iter_mut().for_each(|q| *q = p);
        let mut f = vec![Vec3::zeros(); m.nodes.len()];
        load.add_forces(&m.nodes, 1.0, &mut f);
        let net: Vec3 = f.iter().sum();
        let radial: f64 = m
            .nodes
            .iter()
            .zip(&f)
            .map(|(x, fi)| fi.dot(&Vec3::new(x.x, x.y, 0.0).normalize()))
            .sum();
        let faceted = p * n as f64 * a * (2.0 * PI / n as f64).sin() * l;
        let exact = p * 2.0 * PI * a * l;
        let rel = (radial - exact) / exact;
        eprintln!(
            "tube n={n}: radial load {radial:.10e} N, faceted closed form {faceted:.10e} N, p 2 pi a L {exact:.10e} N (rel {rel:+.3e}), net {net:?}"
        );
        // Rounding only: a few hundred additions of terms ~1e-3 N.
        assert!(
            (radial - faceted).abs() < 1e-12 * exact,
            "n={n}: radial {radial:.15e} vs faceted {faceted:.15e}"
        );
        // Net force cancels by symmetry of the closed polygon, to rounding.
        assert!(net.norm() < 1e-12 * exact, "n={n}: net force {net:?} N");
        errs.push(rel);
    }
    // Second order in the facet angle: (2 pi/n)^2/6 halves n -> quarter error.
    for w in errs.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!((order - 2.0).abs() < 0.05, "order {order:.3} from {errs:?}");
    }
}

/// Plane-strain Lamé quarter tube (as the harness's `lame-tube` builds it):
/// radii `a`, `b`, height `h`, `2^(level+1)` cells through the wall,
/// symmetry rollers on x = 0 and y = 0, both ends held in z, pressure `p`
/// on the inner wall ramped over `ramp` s.
fn lame_scene(level: usize, p: f64) -> (Scene, TetMesh) {
    let (a, b, h) = (0.01, 0.02, 0.005);
    let n_r = 2 << level;
    let n_z = ((h / ((b - a) / n_r as f64)).round() as usize).clamp(1, 4 * n_r);
    let m = mesh::tube_sector(a, b, h, PI / 2.0, 3 * n_r, n_r, n_z);
    let tol = 1e-9 * b;
    let mut axes = std::collections::BTreeMap::<usize, [bool; 3]>::new();
    for (axis, value, k) in [(1, 0.0, 1), (0, 0.0, 0), (2, 0.0, 2), (2, h, 2)] {
        for i in mesh::nodes_on_plane(&m, axis, value, tol) {
            axes.entry(i).or_insert([false; 3])[k] = true;
        }
    }
    let inner: Vec<bool> = m.nodes.iter().map(|q| (q.xy().norm() - a).abs() <= tol).collect();
    let mut body = TissueBody::new(m.clone(), material(0.3));
    body.partial_fixed = axes.into_iter().collect();
    body.pressure_faces = mesh::boundary_faces(&m)
        .into_iter()
        .filter(|f| f.iter().all(|&i| inner[i]))
        .map(|f| (f, p))
        .collect();
    let mut s = common::tissue_scene(m.clone(), material(0.3));
    s.bodies[0] = Body::Tissue(body);
    s.control = common::ramp(0.04);
    s.settle = Some(surgbench_core::Settle {
        velocity_tol: 1e-6,
        min_time: 0.04,
    });
    s.duration = 0.1;
    (s, m)
}

/// Lamé plane-strain radial displacement (Timoshenko & Goodier, Theory of
/// Elasticity, Sec. 28, plane strain): `u(r) = p a^2 / (E (b^2 - a^2))
/// ((1+nu)(1-2nu) r + (1+nu) b^2 / r)` (m).
fn lame_u(r: f64, p: f64) -> f64 {
    let (a, b, e, nu) = (0.01, 0.02, 1e4, 0.3);
    p * a * a / (e * (b * b - a * a)) * ((1.0 + nu) * (1.0 - 2.0 * nu) * r + (1.0 + nu) * b * b / r)
}

/// RMS radial error over all nodes relative to `u(a)`, after the ramp.
fn lame_error(level: usize, p: f64, fid: &Fidelity) -> (f64, MeshlessTissue) {
    let (s, m) = lame_scene(level, p);
    let mut model = MeshlessTissue::new(&s, fid).unwrap();
    for k in 1..=5 {
        let st = model.step(0.01, &s.control.command_at(k as f64 * 0.01)).unwrap();
        assert!(st.converged, "level {level} step {k}: {st:?}");
    }
    let x = model.positions();
    let mut e2 = 0.0;
    for (x0, x) in m.nodes.iter().zip(x) {
        let rr = x0.xy().norm();
        let er = Vec3::new(x0.x / rr, x0.y / rr, 0.0);
        let d = (x - x0).dot(&er) - lame_u(rr, p);
        e2 += d * d;
    }
    ((e2 / m.nodes.len() as f64).sqrt() / lame_u(0.01, p), model)
}

#[test]
fn lame_tube_matches_the_closed_form_at_second_order() {
    // Quasi-static (the scene settles), pressure 10 Pa: u(a)/a = 1.9e-3, so
    // the follower load and StVK depart from the linear closed form by
    // O(1e-3) relative, under the discretisation error of these levels.
    let p = 10.0;
    let mut errs = Vec::new();
    for level in 0..3 {
        let (e, model) = lame_error(level, p, &Fidelity::default());
        eprintln!(
            "lame level {level}: {} nodes, rms radial error / u(a) = {e:.4e}",
            model.positions().len()
        );
        errs.push(e);
    }
    // Measured 1.775e-1, 5.41e-2, 1.43e-2 (levels 0-2; the harness gives the
    // same, and 3.9e-3 at level 3): observed orders 1.71 and 1.92 in the
    // cell size. Bounds: 20% at level 0, 2% at level 2, and order > 1.5
    // on each refinement (the scheme is second order in the interior; the
    // nodal integration at the boundaries costs a little on coarse meshes).
    assert!(errs[0] < 0.2 && errs[2] < 0.02, "errors {errs:?}");
    // Same inputs, bit-identical positions (the follower path included).
    let (_, a) = lame_error(0, p, &Fidelity::default());
    let (_, b) = lame_error(0, p, &Fidelity::default());
    assert_eq!(a.positions(), b.positions(), "lame level 0: reruns differ");
    for w in errs.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!(order > 1.5, "order {order:.2} from {errs:?}");
    }
}

#[test]
fn mls_mapping_error_on_the_lame_field_converges_at_second_order() {
    // The error the MLS surface mapping adds on its own: the exact Lamé
    // displacement placed on the nodes, mapped to the surface particles and
    // compared with the exact surface (MLS radius 2 mean edges, default).
    let p = 10.0;
    let u = |x: &Vec3| {
        let r = x.xy().norm();
        Vec3::new(x.x / r, x.y / r, 0.0) * lame_u(r, p)
    };
    let ua = lame_u(0.01, p);
    let (mut exact, mut sim) = (Vec::new(), Vec::new());
    for level in 0..3 {
        let (err, model) = lame_error(level, p, &Fidelity::default());
        let e = model.mls_mapping_error_of(u);
        let s = model.surface_mapping_errors();
        // An affine field is reproduced exactly (linear basis).
        let aff = model.mls_mapping_error_of(|x| Vec3::new(1e-3 * x.y + 2e-4, -3e-3 * x.z, 5e-4 * x.x));
        eprintln!(
            "lame level {level}: MLS error of the exact field rms {:.3e} max {:.3e} (of u(a): {:.3e}, {:.3e}); \
             on the simulated state rms {:.3e} max {:.3e} m; affine field max {:.1e} m; solution rms error {err:.3e}",
            e.rms,
            e.max,
            e.rms / ua,
            e.max / ua,
            s.rms,
            s.max,
            aff.max
        );
        // Rounding of ~50 shape functions times positions ~1e-2 m.
        assert!(
            aff.max < 1e-15,
            "level {level}: affine field mapped with error {:.3e} m",
            aff.max
        );
        exact.push(e.rms / ua);
        sim.push(s.rms / ua);
    }
    for w in exact.windows(2) {
        let order = (w[0] / w[1]).log2();
        // Linear-basis MLS is O(R^2) for smooth fields (Belytschko et al. 1996);
        // measured rms 4.00e-2, 1.11e-2, 2.78e-3 of u(a): orders 1.85, 2.00.
        assert!(order > 1.7, "MLS mapping error order {order:.2} from {exact:?}");
    }
    // At level 2 the mapping adds 0.28% of u(a) (rms), a fifth of the
    // solution's own error (1.4%); bound 1%.
    assert!(exact[2] < 0.01, "MLS mapping error / u(a) {exact:?}");
    // On the simulated state the particle-to-node distance also carries the
    // solution's roughness: measured about twice the exact-field value.
    let sim: Vec<String> = sim.iter().map(|v| format!("{v:.3e}")).collect();
    eprintln!("MLS particle-to-node distance on the simulated state / u(a): {sim:?}");
}
