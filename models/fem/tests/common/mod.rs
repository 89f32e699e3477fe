//! Shared test helpers: a seeded RNG and small meshes.
#![allow(dead_code)]

use surgbench_core::{SolidMaterial, Vec3};

/// The workspace's seeded generator (`signed()` in [-1, 1), `signed_vec()`);
/// not every test file that includes this module draws numbers.
#[allow(unused_imports)]
pub use surgbench_core::rng::SplitMix64 as SplitMix;

/// Soft-tissue-like material (SI).
pub fn tissue(nu: f64) -> SolidMaterial {
    SolidMaterial {
        youngs_modulus: 5e3,
        poisson_ratio: nu,
        density: 1000.0,
    }
}

/// Path of a committed reference file under `datasets/reference/`.
pub fn reference(rel: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../datasets/reference")
        .join(rel)
}

/// Read `key = number` from the `[parameters]` table of a meta.toml.
pub fn meta_param(rel: &str, key: &str) -> f64 {
    let path = reference(rel);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut in_params = false;
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.starts_with('[') {
            in_params = line == "[parameters]";
        } else if let Some((k, v)) = line.split_once('=')
            && in_params
            && k.trim() == key
        {
            return v
                .trim()
                .parse()
                .unwrap_or_else(|_| panic!("{}: `{key}` is not a number", path.display()));
        }
    }
    panic!("{}: no `{key}` in [parameters]", path.display())
}

/// Numeric rows of a CSV with one header line.
pub fn csv_rows(rel: &str) -> Vec<Vec<f64>> {
    let path = reference(rel);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|c| {
                    c.trim()
                        .parse()
                        .unwrap_or_else(|_| panic!("{}: bad number `{c}`", path.display()))
                })
                .collect()
        })
        .collect()
}

/// Truth-cube edge (m): Kerdok et al. 2003's 80 mm silicone cube.
pub const TRUTH_CUBE_EDGE: f64 = 0.08;

/// The truth-cube scene (comparisons builds the same) with `n` cells per
/// edge (level 0: `n = 4`): E = 15.3 kPa, nu = 0.499, bottom plate fixed,
/// top plate driven down by `strain` of the edge.
pub fn truth_cube_body(strain: f64, n: usize) -> surgbench_core::TissueBody {
    use surgbench_core::{TissueBody, mesh};
    let edge = TRUTH_CUBE_EDGE;
    let m = mesh::block(Vec3::new(edge, edge, edge), [n, n, n]);
    let tol = 1e-9 * edge;
    let mut b = TissueBody::new(
        m.clone(),
        SolidMaterial {
            youngs_modulus: 15.3e3,
            poisson_ratio: 0.499,
            density: 980.0,
        },
    );
    b.fixed_nodes = mesh::nodes_on_plane(&m, 2, 0.0, tol);
    b.driven_nodes = mesh::nodes_on_plane(&m, 2, edge, tol)
        .into_iter()
        .map(|i| (i, Vec3::new(0.0, 0.0, -strain * edge)))
        .collect();
    b
}

/// The truth-cube scenario's cosine load ramp at time `t` (s) over `ramp`
/// (s): `0.5 (1 - cos(pi t / ramp))`, then 1.
pub fn cosine_ramp(t: f64, ramp: f64) -> f64 {
    if t >= ramp {
        1.0
    } else {
        0.5 * (1.0 - (std::f64::consts::PI * t / ramp).cos())
    }
}
