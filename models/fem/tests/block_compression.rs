//! Block compression against the scikit-fem P2 reference
//! (`datasets/reference/block-compression`): linear elasticity, clamped base,
//! bonded plate on top. Checks the P1 force converges towards the reference
//! and that the large-strain laws agree with it at small strain.

mod common;
use common::{csv_rows, meta_param};
use surgbench_core::{SolidMaterial, Vec3, mesh};
use surgbench_fem::{Constraint, Law, Loads, StaticParams, solve_static};

fn plate_force(n: usize, law: Law, strain: f64, steps: usize) -> f64 {
    let meta = "block-compression/meta.toml";
    let l = meta_param(meta, "edge");
    let mat = SolidMaterial {
        youngs_modulus: meta_param(meta, "youngs_modulus"),
        poisson_ratio: meta_param(meta, "poisson_ratio"),
        density: 1000.0,
    };
    let m = mesh::block(Vec3::new(l, l, l), [n, n, n]);
    let mut cons: Vec<Constraint> = mesh::nodes_on_plane(&m, 2, 0.0, 1e-12)
        .into_iter()
        .map(Constraint::fixed)
        .collect();
    let top = mesh::nodes_on_plane(&m, 2, l, 1e-12);
    cons.extend(
        top.iter()
            .map(|&i| Constraint::displaced(i, Vec3::new(0.0, 0.0, -strain * l))),
    );
    let params = StaticParams {
        load_steps: steps,
        ..Default::default()
    };
    let info = solve_static(&m, &mat, law, &cons, &Loads::default(), &params).unwrap();
    // Force the plate applies on the body, downwards: report it positive.
    -top.iter().map(|&i| info.reactions[i].z).sum::<f64>()
}

#[test]
fn p1_force_converges_to_scikit_fem_reference() {
    let rows = csv_rows("block-compression/block-compression.csv");
    let (s, f_ref) = (rows[1][0], rows[1][2]);
    let errs: Vec<(usize, f64)> = [4usize, 8, 12]
        .iter()
        .map(|&n| (n, plate_force(n, Law::Linear, s, 1) / f_ref - 1.0))
        .collect();
    eprintln!("strain {s}: relative force error vs P2 reference per cells-per-edge: {errs:?}");
    // P1 is too stiff, error falls with h; the corner singularities of the
    // bonded edges slow it (measured 0.041, 0.015, 0.008): bound 2 % at n = 12.
    assert!(errs.windows(2).all(|w| w[1].1.abs() < w[0].1.abs()), "{errs:?}");
    assert!(errs[2].1.abs() < 0.02, "{errs:?}");
}

#[test]
fn large_strain_laws_match_linear_at_small_strain_and_differ_at_20_percent() {
    let n = 4;
    for law in [Law::Corotational, Law::NeoHookean] {
        let small = plate_force(n, law, 1e-3, 1) / plate_force(n, Law::Linear, 1e-3, 1) - 1.0;
        let large = plate_force(n, law, 0.2, 4) / plate_force(n, Law::Linear, 0.2, 1) - 1.0;
        eprintln!("{law:?}: force / linear - 1 at 0.1 % strain {small:.3e}, at 20 % strain {large:.3e}");
        // Geometric nonlinearity is O(strain): 1e-3 strain -> ~1e-3 relative.
        assert!(small.abs() < 3e-3, "{law:?} at 0.1%: {small:.3e}");
        // At 20 % the laws differ from linear by more than 1 % (measured:
        // corotational -1.5 %, neo-Hookean +21 %): why the reference says "small strain".
        assert!(large.abs() > 0.01, "{law:?} at 20%: {large:.3e}");
    }
}
