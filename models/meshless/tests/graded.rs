//! Per-node support radii on a strongly graded mesh (edges over x40, like
//! the sphere-indentation block): the MLS gradient still reproduces affine
//! fields at every node, the forces and Hessian-vector products are still
//! the exact derivatives of the energy, the MLS surface map still
//! reproduces affine fields, the model builds and reruns bit for bit; on
//! the Kuhn blocks the local lengths are the global mean edge.
//!
//! These meshes used to be refused (`MAX_GRADING = 8`: one support radius
//! for every node left the coarse cells' nodes without a full
//! neighbourhood).

mod common;

use common::{Rng, forces, material, ramp, tissue_scene_with, total, volumes};
use surgbench_core::scene::SphereIndenter;
use surgbench_core::{Fidelity, Mat3, Model, ModelFactory, Scene, Settle, TetMesh, TissueBody, Vec3, mesh};
use surgbench_meshless::{MeshlessFactory, MeshlessTissue, MlsMap, PointElastic, StateCache, local_edge_lengths};

const E: f64 = 1e4;
/// Block half-width (m).
const W: f64 = 0.01;

/// Quarter block `[0, W]^2 x [-W, 0]` with `n` cells per edge graded towards
/// the corner at the origin the way the sphere-indentation block is: the
/// unit structured block with node `xi` moved to `(xi_x, xi_y, -xi_z)
/// rho(s) / s`, `s` its max-norm, `rho(s) = c s + (W - c) t^2`,
/// `t = max(0, 2 s - 1)`: uniform cubes of size `c / n` for `s <= 1/2`,
/// radially growing beyond.
fn graded_block(n: usize, c: f64) -> TetMesh {
    let mut m = mesh::block(Vec3::repeat(1.0), [n, n, n]);
    for p in &mut m.nodes {
        let s = p.x.max(p.y).max(p.z);
        let t = (2.0 * s - 1.0).max(0.0);
        let f = if s > 0.0 { (c * s + (W - c) * t * t) / s } else { 0.0 };
        *p = Vec3::new(p.x * f, p.y * f, -p.z * f);
    }
    mesh::orient_positive(&mut m);
    m
}

/// Shortest and longest tet edge (m).
fn edge_range(m: &TetMesh) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for t in &m.tets {
        for a in 0..4 {
            for b in a + 1..4 {
                let l = (m.nodes[t[b]] - m.nodes[t[a]]).norm();
                lo = lo.min(l);
                hi = hi.max(l);
            }
        }
    }
    (lo, hi)
}

/// The graded block (8 cells, inner cells of `W / 80`) and its point
/// discretisation at the model's radii (`h_i = 1.5 l_i`, raised where
/// flat; the model is built to read them).
fn setup(nu: f64, gamma: f64) -> (TetMesh, PointElastic) {
    let m = graded_block(8, 0.1 * W);
    let scene = tissue_scene_with(TissueBody::new(m.clone(), material(nu)), "graded");
    let h = MeshlessTissue::new(&scene, &Fidelity::default())
        .unwrap()
        .elastic()
        .radius
        .clone();
    let el = PointElastic::new(&m.nodes, &volumes(&m), &h, E, nu, gamma * E).unwrap();
    (m, el)
}

/// Displacements of `frac` of each node's local edge length, random
/// directions: the same strain level in fine and coarse cells.
fn perturbed(m: &TetMesh, frac: f64, seed: u64) -> Vec<Vec3> {
    let l = local_edge_lengths(m);
    let mut r = Rng(seed);
    m.nodes
        .iter()
        .zip(&l)
        .map(|(p, li)| p + r.vec() * (frac * li))
        .collect()
}

#[test]
fn the_test_mesh_is_strongly_graded_and_the_radii_follow_it() {
    let (m, el) = setup(0.3, 0.1);
    let (lo, hi) = edge_range(&m);
    let l = local_edge_lengths(&m);
    // The radii are the plain local ones, 1.5 l_i, except where raised.
    let scene = tissue_scene_with(TissueBody::new(m.clone(), material(0.3)), "graded");
    let raised = MeshlessTissue::new(&scene, &Fidelity::default())
        .unwrap()
        .raised_supports()
        .to_vec();
    for i in (0..el.len()).filter(|i| raised.binary_search(i).is_err()) {
        assert_eq!(el.radius[i], 1.5 * l[i], "node {i}");
    }
    // The old refusal was at x8; this mesh is far beyond it.
    assert!(hi > 30.0 * lo, "edges {lo:.3e}..{hi:.3e} m");
    let (hmin, hmax) = el
        .radius
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &h| (a.min(h), b.max(h)));
    assert!(hmax > 10.0 * hmin, "radii {hmin:.3e}..{hmax:.3e} m");
    // Nodes whose star lies in the uniform inner zone (cubes of c / n) see
    // exactly the uniform lattice's neighbourhood, at most its 26 nearest
    // lattice points (h = 1.5 x 1.26 cell < 2 cells): the fine cells are not
    // smoothed over, as by one radius large enough for the coarse cells.
    let fine = 0.1 * W / 8.0 * (3.0 + 2.0 * 2f64.sqrt() + 3f64.sqrt()) / 6.0;
    let uniform: Vec<usize> = (0..el.len()).filter(|&i| (l[i] / fine - 1.0).abs() < 1e-12).collect();
    assert!(uniform.len() > 50, "only {} nodes in the uniform zone", uniform.len());
    let worst = uniform.iter().map(|&i| el.neighbours(i).count()).max().unwrap();
    assert!(worst <= 26, "a uniform-zone node sees {worst} neighbours");
    let counts: Vec<usize> = (0..el.len()).map(|i| el.neighbours(i).count()).collect();
    eprintln!(
        "graded block: {} nodes ({} in the uniform zone, {} raised), edges x{:.1}, radii x{:.1}, neighbours {}..{}",
        el.len(),
        uniform.len(),
        raised.len(),
        hi / lo,
        hmax / hmin,
        counts.iter().min().unwrap(),
        counts.iter().max().unwrap()
    );
}

#[test]
fn affine_field_gives_exact_gradient_at_every_node_of_a_graded_mesh() {
    let (m, el) = setup(0.3, 0.1);
    let mut r = Rng(11);
    let f0 = Mat3::identity() + Mat3::from_fn(|_, _| 0.2 * r.next());
    let c = r.vec() * W;
    let x: Vec<Vec3> = m.nodes.iter().map(|p| f0 * p + c).collect();
    let mut worst: f64 = 0.0;
    for i in 0..x.len() {
        worst = worst.max((el.deformation_gradient(i, &x) - f0).amax());
    }
    // Exact in exact arithmetic. Rounding: x_j - x_i loses digits in
    // proportion to |x| / |X_ij| (W over the finest edge, x80), times
    // cond(A_i) ~ 10 and eps: ~1e-13 at worst; 1e-12 leaves margin.
    assert!(worst < 1e-12, "max |F_i - F0| = {worst:.3e} over {} nodes", x.len());
    eprintln!("graded patch test: max |F_i - F0| = {worst:.2e}");
    let (u, hg) = el.energy(&x);
    let exact = el.volume.iter().sum::<f64>() * el.stvk(&f0).0;
    // The hourglass penalty is zero on affine fields; u sums ~700 terms.
    assert!(hg.abs() < 1e-12 * u, "hourglass energy {hg:.3e} J, strain {u:.3e} J");
    assert!(
        (u - exact).abs() < 1e-10 * exact,
        "U = {u:.6e}, V psi(F0) = {exact:.6e}"
    );
}

#[test]
fn forces_are_minus_the_energy_gradient_on_a_graded_mesh() {
    let (m, el) = setup(0.3, 0.1);
    let x = perturbed(&m, 0.1, 23);
    let f = forces(&el, &x);
    let l = local_edge_lengths(&m);
    let mut worst_rel: f64 = 0.0;
    // Every other node (fine, transition and coarse ones all sampled).
    for i in (0..x.len()).step_by(2) {
        // Per-node step and scale: forces on fine nodes are ~(l_fine /
        // l_coarse)^2 smaller, so a global scale would hide their errors.
        let li = l[i];
        let eps = 1e-4 * li;
        let fi_scale = E * li * li * 1e-3;
        for a in 0..3 {
            let mut xp = x.clone();
            xp[i][a] += eps;
            let mut xm = x.clone();
            xm[i][a] -= eps;
            let fd = -(total(&el, &xp) - total(&el, &xm)) / (2.0 * eps);
            worst_rel = worst_rel.max((fd - f[i][a]).abs() / fi_scale.max(f[i][a].abs()));
        }
    }
    // Central differences: O(eps^2) ~ 1e-8 truncation, plus rounding of the
    // total energy U * 1e-16 / eps; U (~1e-4 J) is dominated by the coarse
    // cells, so at a fine node (l ~ 1.6e-4 m) this is 1e-20 / 1.6e-8 = 6e-13 N
    // against E l^2 1e-3 = 2.5e-7 N: ~3e-6. 1e-4 leaves margin and still
    // catches a wrong term (O(1)).
    assert!(
        worst_rel < 1e-4,
        "max |f + dU/dx| relative to the node's force scale: {worst_rel:.3e}"
    );
    eprintln!("graded forces vs FD of energy: {worst_rel:.2e}");
}

#[test]
fn hessian_products_are_minus_the_force_derivative_on_a_graded_mesh() {
    let (m, el) = setup(0.3, 0.1);
    let x = perturbed(&m, 0.1, 5);
    // Direction scaled like the positions: each node moves by its own cell size.
    let l = local_edge_lengths(&m);
    let mut r = Rng(6);
    let dir: Vec<Vec3> = l.iter().map(|li| r.vec() * *li).collect();
    let mut c = StateCache::default();
    el.prepare(&x, &mut c);
    let mut hv = vec![Vec3::zeros(); x.len()];
    el.add_hess_vec(&c, &dir, &mut hv);
    let eps = 1e-6;
    let xp: Vec<Vec3> = x.iter().zip(&dir).map(|(p, d)| p + d * eps).collect();
    let xm: Vec<Vec3> = x.iter().zip(&dir).map(|(p, d)| p - d * eps).collect();
    let (fp, fm) = (forces(&el, &xp), forces(&el, &xm));
    let mut worst_rel: f64 = 0.0;
    for i in 0..x.len() {
        // Node i's scale: H dx there is ~ E l_i^2 (dx / l) = E l_i^2.
        let scale = E * l[i] * l[i];
        let err = (-(fp[i] - fm[i]) / (2.0 * eps) - hv[i]).amax();
        worst_rel = worst_rel.max(err / scale);
    }
    // Central differences of forces: O(eps^2) ~ 1e-12 truncation plus
    // f * 1e-16 / eps ~ 1e-10 rounding, relative to each node's scale.
    assert!(worst_rel < 1e-7, "max |H v + df/dx v| / (E l_i^2) = {worst_rel:.3e}");
    eprintln!("graded Hessian product vs FD of forces: {worst_rel:.2e}");
}

#[test]
fn mls_map_with_per_target_radii_reproduces_affine_fields_on_a_graded_mesh() {
    let m = graded_block(8, 0.1 * W);
    let l = local_edge_lengths(&m);
    let mut surf: Vec<usize> = mesh::boundary_faces(&m).iter().flatten().copied().collect();
    surf.sort_unstable();
    surf.dedup();
    let targets: Vec<Vec3> = surf.iter().map(|&i| m.nodes[i]).collect();
    let radii: Vec<f64> = surf.iter().map(|&i| 2.0 * l[i]).collect();
    let map = MlsMap::new(&m.nodes, &targets, &radii).unwrap();
    let mut r = Rng(8);
    let a = Mat3::identity() + Mat3::from_fn(|_, _| 0.3 * r.next());
    let c = r.vec() * W;
    let x: Vec<Vec3> = m.nodes.iter().map(|p| a * p + c).collect();
    let y = map.map(&x);
    let worst = targets
        .iter()
        .zip(&y)
        .map(|(t, yi)| (a * t + c - yi).norm())
        .fold(0.0, f64::max);
    // Exact in exact arithmetic; rounding of ~30 shape functions times |x| ~ W.
    assert!(worst < 1e-14, "max MLS error on an affine field {worst:.3e} m");
    for t in 0..map.len() {
        let s: f64 = map.shape_functions(t).map(|(_, p)| p).sum();
        // Partition of unity; rounding of a few hundred terms at most.
        assert!(
            (s - 1.0).abs() < 1e-12,
            "partition of unity at surface particle {t}: {s}"
        );
    }
}

#[test]
fn kuhn_blocks_keep_the_global_radius() {
    // All Kuhn tets of cubic cells are congruent, so every node's local
    // length is the global mean edge (rounding of six-term sums), and the
    // floor (1.05 sqrt 3 a < 1.5 x 1.26 a) does not act: every radius is
    // the old single one.
    let m = mesh::block(Vec3::new(0.03, 0.03, 0.03), [5, 5, 5]);
    let scene = tissue_scene_with(TissueBody::new(m, material(0.3)), "kuhn");
    let t = MeshlessTissue::new(&scene, &Fidelity::default()).unwrap();
    let worst = t
        .local_edge()
        .iter()
        .map(|l| (l / t.mean_edge() - 1.0).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-14, "max |l_i / mean edge - 1| = {worst:.3e}");
    let h = 1.5 * t.mean_edge();
    let worst = t
        .elastic()
        .radius
        .iter()
        .map(|r| (r / h - 1.0).abs())
        .fold(0.0, f64::max);
    // Same rounding as above.
    assert!(worst < 1e-14, "max |h_i / (1.5 mean edge) - 1| = {worst:.3e}");
}

/// The graded quarter block with a sphere (R = W / 4) pressed `W / 400` into
/// its corner over four quasi-static steps: the sphere-indentation set-up
/// at test size.
fn indentation_scene() -> Scene {
    let m = graded_block(6, 0.1 * W);
    let tol = 1e-9 * W;
    let mut body = TissueBody::new(m.clone(), material(0.3));
    body.fixed_nodes = mesh::nodes_on_plane(&m, 2, -W, tol);
    body.partial_fixed = mesh::nodes_where(&m, |x| x.x.abs() <= tol || x.y.abs() <= tol)
        .into_iter()
        .filter(|i| !body.fixed_nodes.contains(i))
        .map(|i| {
            let p = m.nodes[i];
            (i, [p.x.abs() <= tol, p.y.abs() <= tol, false])
        })
        .collect();
    let r = 0.25 * W;
    body.indenter = Some(SphereIndenter {
        centre: Vec3::new(0.0, 0.0, r),
        radius: r,
        travel: Vec3::new(0.0, 0.0, -W / 400.0),
    });
    let mut s = tissue_scene_with(body, "meshless-graded-indentation");
    s.control = ramp(0.004);
    s.settle = Some(Settle {
        velocity_tol: 1e-6,
        min_time: 0.004,
    });
    s.duration = 0.004;
    s
}

#[test]
fn graded_indentation_is_accepted_and_reruns_bit_identically() {
    let scene = indentation_scene();
    assert!(
        MeshlessFactory.check(&scene).is_ok(),
        "graded meshes are no longer refused"
    );
    let run = || {
        let mut m = MeshlessTissue::new(&scene, &Fidelity::default()).unwrap();
        for k in 1..=4 {
            let st = m.step(1e-3, &scene.control.command_at(k as f64 * 1e-3)).unwrap();
            assert!(st.converged, "step {k}: Newton residual {:.3e}", st.residual);
        }
        m.observe()
    };
    let (a, b) = (run(), run());
    // The body pushes the sphere up (+z).
    assert!(a.hand_force.z > 0.0, "sphere force {:?}", a.hand_force);
    assert_eq!(a, b, "reruns differ");
}
