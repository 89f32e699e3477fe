//! Lamé thick-walled tube under internal pressure, plane strain (u_z = 0 on
//! both ends), quarter tube with symmetry conditions. Closed form
//! (Timoshenko and Goodier, Theory of Elasticity, Sec. 28):
//! `u(r) = p a^2 / (E (b^2 - a^2)) ((1+nu)(1-2nu) r + (1+nu) b^2 / r)`.
//! Parameters come from `datasets/reference/lame-tube/meta.toml`, shared with
//! the scikit-fem script.

mod common;
use common::{csv_rows, meta_param};
use surgbench_core::{SolidMaterial, TetMesh, Vec3, mesh};
use surgbench_fem::{Constraint, Law, Loads, StaticParams, pressure_loads, solve_static};

struct Tube {
    a: f64,
    b: f64,
    h: f64,
    e: f64,
    nu: f64,
    p: f64,
}

fn params() -> Tube {
    let m = "lame-tube/meta.toml";
    Tube {
        a: meta_param(m, "inner_radius"),
        b: meta_param(m, "outer_radius"),
        h: meta_param(m, "height"),
        e: meta_param(m, "youngs_modulus"),
        nu: meta_param(m, "poisson_ratio"),
        p: meta_param(m, "pressure"),
    }
}

fn exact(t: &Tube, r: f64) -> f64 {
    t.p * t.a * t.a / (t.e * (t.b * t.b - t.a * t.a))
        * ((1.0 + t.nu) * (1.0 - 2.0 * t.nu) * r + (1.0 + t.nu) * t.b * t.b / r)
}

/// Solve on a quarter tube with `k` refinement (n_r = 2k, n_theta = 4k);
/// returns the mesh and displacements.
fn solve(t: &Tube, n_r: usize, n_theta: usize, law: Law) -> (TetMesh, Vec<Vec3>) {
    let m = mesh::tube_sector(t.a, t.b, t.h, std::f64::consts::FRAC_PI_2, n_theta, n_r, 1);
    let mut cons = Vec::new();
    for i in mesh::nodes_on_plane(&m, 1, 0.0, 0.0) {
        cons.push(Constraint::axis(i, 1, 0.0));
    }
    for i in mesh::nodes_on_plane(&m, 0, 0.0, 0.0) {
        cons.push(Constraint::axis(i, 0, 0.0));
    }
    // One layer: every node is on an end face, so u_z = 0 everywhere.
    for i in 0..m.nodes.len() {
        cons.push(Constraint::axis(i, 2, 0.0));
    }
    let inner: Vec<[usize; 3]> = mesh::boundary_faces(&m)
        .into_iter()
        .filter(|f| {
            f.iter()
                .all(|&i| (m.nodes[i].x.hypot(m.nodes[i].y) - t.a).abs() < 1e-12)
        })
        .collect();
    let loads = Loads {
        body_force: None,
        nodal: pressure_loads(&m, &inner, t.p),
    };
    let mat = SolidMaterial {
        youngs_modulus: t.e,
        poisson_ratio: t.nu,
        density: 1000.0,
    };
    let info = solve_static(&m, &mat, law, &cons, &loads, &StaticParams::default()).unwrap();
    (m, info.displacements)
}

/// Largest nodal radial-displacement error relative to `u(a)`.
fn nodal_error(t: &Tube, m: &TetMesh, u: &[Vec3]) -> f64 {
    let mut worst: f64 = 0.0;
    for (p, d) in m.nodes.iter().zip(u) {
        let r = p.x.hypot(p.y);
        let ur = (p.x * d.x + p.y * d.y) / r;
        worst = worst.max((ur - exact(t, r)).abs());
    }
    worst / exact(t, t.a)
}

fn exact_field(t: &Tube, p: &Vec3) -> Vec3 {
    let r = p.x.hypot(p.y);
    Vec3::new(p.x, p.y, 0.0) * (exact(t, r) / r)
}

/// Gradient of `u = f(r) e_r` with `f = A r + B / r`: `f/r I2 + (f' - f/r) e_r e_r^T`.
fn exact_grad(t: &Tube, p: &Vec3) -> surgbench_fem::material::M3 {
    let r = p.x.hypot(p.y);
    let c = t.p * t.a * t.a / (t.e * (t.b * t.b - t.a * t.a));
    let (aa, bb) = (c * (1.0 + t.nu) * (1.0 - 2.0 * t.nu), c * (1.0 + t.nu) * t.b * t.b);
    let f = aa * r + bb / r;
    let fp = aa - bb / (r * r);
    let er = Vec3::new(p.x / r, p.y / r, 0.0);
    let mut g = er * er.transpose() * (fp - f / r);
    g[(0, 0)] += f / r;
    g[(1, 1)] += f / r;
    g
}

#[test]
fn lame_tube_converges_with_order_two() {
    let t = params();
    let mut rows = Vec::new();
    for k in [1usize, 2, 4, 8] {
        let (m, u) = solve(&t, 2 * k, 4 * k, Law::Linear);
        let (l2, h1) = surgbench_fem::error_norms(&m, &u, |p| exact_field(&t, p), |p| exact_grad(&t, p));
        rows.push((k, l2, h1, nodal_error(&t, &m, &u)));
    }
    let ord = |f: fn(&(usize, f64, f64, f64)) -> f64| -> Vec<f64> {
        rows.windows(2).map(|w| (f(&w[0]) / f(&w[1])).log2()).collect()
    };
    let (o2, o1, on) = (ord(|r| r.1), ord(|r| r.2), ord(|r| r.3));
    let msg =
        format!("(k, L2, H1, max nodal rel): {rows:?}\norders L2 {o2:?}\norders H1 {o1:?}\norders max-nodal {on:?}");
    eprintln!("{msg}");
    // Theory for P1 (with the O(h^2) polygonal boundary): 2 in L2, 1 in H1.
    // Measured on the last pair: see the message; band +-0.2.
    assert!((o2.last().unwrap() - 2.0).abs() < 0.2, "{msg}");
    assert!((o1.last().unwrap() - 1.0).abs() < 0.2, "{msg}");
    // The max nodal error converges more slowly (observed ~1.5: the inner
    // polygon's slightly re-entrant corners carry weak stress singularities);
    // it must still fall at every level and be under 1.5 % at k = 8 (measured 1.0 %).
    assert!(rows.windows(2).all(|w| w[1].3 < w[0].3) && rows[3].3 < 0.015, "{msg}");
}

#[test]
fn lame_tube_matches_scikit_fem_reference_and_corotational_agrees() {
    let t = params();
    let (m, u) = solve(&t, 16, 32, Law::Linear);
    let (_, uc) = solve(&t, 16, 32, Law::Corotational);
    // Nodes on the diagonal theta = pi/4 (n_theta = 32: node column 16) at mid height are
    // not present (one layer), so compare at nodes on theta = pi/4 and interpolate in r.
    let diag: Vec<(f64, f64, f64)> = {
        let mut v: Vec<(f64, f64, f64)> = m
            .nodes
            .iter()
            .zip(u.iter().zip(&uc))
            .filter(|(p, _)| (p.y.atan2(p.x) - std::f64::consts::FRAC_PI_4).abs() < 1e-9 && p.z == 0.0)
            .map(|(p, (d, dc))| {
                let r = p.x.hypot(p.y);
                (r, (p.x * d.x + p.y * d.y) / r, (p.x * dc.x + p.y * dc.y) / r)
            })
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v
    };
    assert_eq!(diag.len(), 17);
    let interp = |r: f64, col: usize| {
        let i = diag.partition_point(|q| q.0 < r).clamp(1, diag.len() - 1);
        let (a, b) = (diag[i - 1], diag[i]);
        let w = (r - a.0) / (b.0 - a.0);
        let (ya, yb) = if col == 1 { (a.1, b.1) } else { (a.2, b.2) };
        ya + w * (yb - ya)
    };
    let refs = csv_rows("lame-tube/lame-tube.csv");
    let scale = exact(&t, t.a);
    let mut worst_ref: f64 = 0.0;
    let mut worst_corot: f64 = 0.0;
    for row in &refs {
        let (r, ur_skfem, ur_exact) = (row[0], row[1], row[2]);
        assert!(
            (ur_exact - exact(&t, r)).abs() < 1e-9 * scale,
            "closed forms disagree at r={r}: {ur_exact} vs {}",
            exact(&t, r)
        );
        worst_ref = worst_ref.max((interp(r, 1) - ur_skfem).abs() / scale);
        worst_corot = worst_corot.max((interp(r, 2) - interp(r, 1)).abs() / scale);
    }
    eprintln!("vs scikit-fem P2: {worst_ref:.3e}; corotational vs linear: {worst_corot:.3e} (relative to u(a))");
    // Both discretize the same problem: the P1 max nodal error at this level is
    // 1.0e-2 of u(a) (convergence test, k = 8), the P2 reference's own error
    // 6.7e-4 (its provenance): bound 1.2e-2. Measured 7.2e-3.
    assert!(
        worst_ref < 1.2e-2,
        "P1 vs scikit-fem P2 relative difference {worst_ref:.3e}"
    );
    // Strain ~2%: geometric nonlinearity changes u by O(strain^2 + rotations) ~ 1e-3.
    assert!(worst_corot < 5e-3, "corotational vs linear {worst_corot:.3e}");
}
