//! Issue 16: every parser a user can feed must answer malformed input with
//! an error, never a panic. Property tests over each one: byte-level
//! mutations of a valid file (replace, insert, delete, truncate, duplicate a
//! span) and random bytes. `SURGBENCH_FUZZ_CASES` sets the cases per parser
//! (default 10,000, CI's count); a longer run on the stable toolchain:
//!
//! ```sh
//! SURGBENCH_FUZZ_CASES=1000000 cargo test --release --test issue_16_fuzz_parsers
//! ```

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::path::PathBuf;
use surgbench_comparisons::comparison::Comparison;
use surgbench_comparisons::references::{TipTrajectory, read_csv_columns};
use surgbench_core::Vec3;
use surgbench_core::haptic::Session;
use surgbench_core::io::{self, TriSurface, truth_cube};
use surgbench_reports::{ResultRow, read_results_csv, write_results_csv};

/// Cases per parser.
fn cases() -> u32 {
    std::env::var("SURGBENCH_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000)
}

/// One edit of a byte string.
#[derive(Debug, Clone)]
enum Edit {
    Replace(usize, u8),
    Insert(usize, u8),
    Delete(usize),
    Truncate(usize),
    /// Copy `len` bytes from one place to another (repeated lines, fields).
    Duplicate(usize, usize, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    // Bytes that matter to these formats more often than uniform ones.
    let byte = prop_oneof![
        any::<u8>(),
        prop::sample::select(b",\n\r#-.eE0123456789 \t\"$".to_vec()),
    ];
    prop_oneof![
        (any::<usize>(), byte.clone()).prop_map(|(i, b)| Edit::Replace(i, b)),
        (any::<usize>(), byte).prop_map(|(i, b)| Edit::Insert(i, b)),
        any::<usize>().prop_map(Edit::Delete),
        any::<usize>().prop_map(Edit::Truncate),
        (any::<usize>(), any::<usize>(), 1usize..64).prop_map(|(a, b, n)| Edit::Duplicate(a, b, n)),
    ]
}

fn apply(seed: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for e in edits {
        let n = v.len().max(1);
        match *e {
            Edit::Replace(i, b) if !v.is_empty() => v[i % n] = b,
            Edit::Insert(i, b) => v.insert(i % (v.len() + 1), b),
            Edit::Delete(i) if !v.is_empty() => {
                v.remove(i % n);
            }
            Edit::Truncate(i) => v.truncate(i % (v.len() + 1)),
            Edit::Duplicate(a, b, len) if !v.is_empty() => {
                let a = a % n;
                let span: Vec<u8> = v[a..(a + len).min(v.len())].to_vec();
                let at = b % (v.len() + 1);
                v.splice(at..at, span);
            }
            _ => {}
        }
    }
    v
}

/// Inputs: the seed mutated by 1-8 edits, or random bytes.
fn inputs(seed: Vec<u8>) -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        3 => prop::collection::vec(edit(), 1..8).prop_map(move |e| apply(&seed, &e)),
        1 => prop::collection::vec(any::<u8>(), 0..256),
    ]
}

/// Run `parse` on `cases()` inputs derived from `seed`; the seed itself must
/// parse (so the mutations start from a valid file) and nothing may panic.
fn fuzz(name: &str, seed: Vec<u8>, parse: impl Fn(&[u8]) -> bool) {
    assert!(parse(&seed), "{name}: the seed does not parse");
    let config = Config {
        cases: cases(),
        failure_persistence: None,
        ..Config::default()
    };
    let mut runner = TestRunner::new_with_rng(
        config,
        proptest::test_runner::TestRng::deterministic_rng(proptest::test_runner::RngAlgorithm::ChaCha),
    );
    runner
        .run(&inputs(seed), |bytes| {
            parse(&bytes);
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{name}: {e}"));
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// A scratch file for the parsers that read paths.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("surgbench-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A closed tetrahedron surface, outward normals.
fn tetra() -> TriSurface {
    TriSurface {
        vertices: vec![Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()],
        triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    }
}

#[test]
fn comparison_toml() {
    let seed = std::fs::read(repo("comparisons/standard.toml")).unwrap();
    fuzz("comparison TOML", seed, |b| Comparison::parse(&text(b)).is_ok());
}

#[test]
fn results_csv() {
    let path = scratch("results.csv");
    let row = ResultRow {
        comparison: "standard".into(),
        scenario: "cantilever-gravity".into(),
        model: "der".into(),
        ..Default::default()
    };
    write_results_csv(&path, &[row.clone(), row]).unwrap();
    let seed = std::fs::read(&path).unwrap();
    fuzz("results CSV", seed, |b| {
        std::fs::write(&path, b).unwrap();
        read_results_csv(&path).is_ok()
    });
}

#[test]
fn haptic_replay_csv() {
    let seed = std::fs::read(repo("datasets/vessels/branch-selection-45.csv")).unwrap();
    fuzz("haptic replay CSV", seed, |b| Session::parse("s.csv", &text(b)).is_ok());
}

#[test]
fn truth_cube_phantom_csv() {
    let seed = std::fs::read(repo("datasets/phantom/truth-cube/truth-cube-uniaxial.csv")).unwrap();
    fuzz("Truth Cube CSV", seed, |b| {
        truth_cube::parse("tc.csv", &text(b)).is_ok()
    });
}

#[test]
fn scikit_fem_reference_csv() {
    let path = scratch("reference.csv");
    let seed = std::fs::read(repo("datasets/reference/wall-punch/wall-punch.csv")).unwrap();
    fuzz("reference CSV", seed, |b| {
        std::fs::write(&path, b).unwrap();
        read_csv_columns(&path, &["depth_m", "force_n"]).is_ok()
    });
}

#[test]
fn cached_tip_trajectory_csv() {
    let path = scratch("tip_trajectory.csv");
    let seed = std::fs::read(repo("datasets/reference/flow-drift/tip_trajectory.csv")).unwrap();
    fuzz("tip trajectory CSV", seed, |b| {
        std::fs::write(&path, b).unwrap();
        TipTrajectory::load(&path).is_ok()
    });
}

#[test]
fn stl_ascii_and_binary() {
    let path = scratch("t.stl");
    tetra().write_stl_ascii(&path).unwrap();
    let ascii = std::fs::read(&path).unwrap();
    fuzz("ASCII STL", ascii, |b| io::parse_stl("t.stl", b).is_ok());
    fuzz("binary STL", tetra().to_stl_binary(), |b| {
        io::parse_stl("t.stl", b).is_ok()
    });
}

#[test]
fn obj() {
    let path = scratch("t.obj");
    tetra().write_obj(&path).unwrap();
    let seed = std::fs::read(&path).unwrap();
    fuzz("OBJ", seed, |b| io::parse_obj("t.obj", &text(b)).is_ok());
}

#[test]
fn gmsh_v4() {
    let seed = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 0 0 1\n1 0 0 0 1 1 1 0 0\n$EndEntities\n\
$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n\
$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 4\n$EndElements\n";
    fuzz("Gmsh v4", seed.as_bytes().to_vec(), |b| {
        io::parse_gmsh_v4("t.msh", &text(b)).is_ok()
    });
}

#[test]
fn medit() {
    let seed = "MeshVersionFormatted 2\nDimension 3\nVertices\n5\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n1 1 1 1\n\
Tetrahedra\n2\n1 2 3 4 0\n2 3 4 5 0\nEnd\n";
    fuzz("Medit", seed.as_bytes().to_vec(), |b| {
        io::parse_medit("t.mesh", &text(b)).is_ok()
    });
}
