//! Issue 16: the mesh readers are part of the product. `run-one --mesh FILE`
//! builds `tissue-patch-test` on a user's Gmsh or Medit tet mesh and
//! `vessel-mesh-insertion` on a user's STL or OBJ lumen; every way of
//! getting it wrong is exit 2 with a sentence naming the file or the key,
//! and nothing is written.
//!
//! The example meshes shipped in `datasets/meshes/` are what
//! [`perturbed_cube`] and [`example_tube`] write (checked here byte for
//! byte); `SURGBENCH_WRITE_EXAMPLES=1 cargo test --test issue_16_user_mesh`
//! rewrites them.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;
use surgbench_core::io::TriSurface;
use surgbench_core::rng::SplitMix64;
use surgbench_core::sdf::CenterlineBuilder;
use surgbench_core::{TetMesh, Vec3, mesh};
use surgbench_reports::RunSummary;

mod common;
use common::output_within;

fn surgbench() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surgbench"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `run-one` with `args`, writing to `out`; a minute is far more than any
/// of these runs takes.
fn run_one(out: &Path, args: &[&str]) -> Output {
    let mut c = surgbench();
    c.arg("run-one").args(args).arg("--out").arg(out).arg("--quiet");
    output_within(c, Duration::from_secs(120), "run-one")
}

/// Exit 2, one `error:` line naming every one of `words`, `out` not created.
fn assert_usage(o: &Output, out: &Path, words: &[&str]) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    for w in words {
        assert!(e.contains(w), "`{w}` not in: {e}");
    }
    assert!(!e.contains("panicked"), "{e}");
    assert!(!out.exists(), "nothing may be written on a usage error");
}

/// A 10 mm cube of 4 x 4 x 4 cells (six tets each) whose 27 interior nodes
/// are moved by up to 15 % of a cell along each axis (seeded): an irregular
/// mesh, as a mesher would give, with every tet still positive.
fn perturbed_cube() -> TetMesh {
    let edge = 0.01;
    let mut m = mesh::block(Vec3::repeat(edge), [4, 4, 4]);
    let cell = edge / 4.0;
    let mut rng = SplitMix64(0x5eed_0016);
    for x in &mut m.nodes {
        let inside = (0..3).all(|a| x[a] > 1e-9 && x[a] < edge - 1e-9);
        if inside {
            *x += rng.signed_vec() * (0.15 * cell);
        }
    }
    for t in &m.tets {
        let v = mesh::tet_volume_of(&t.map(|i| m.nodes[i]));
        assert!(v > 0.0, "perturbation inverted a tet");
    }
    m
}

/// `m` in Gmsh MSH 4.1 ASCII: one volume entity, nodes tagged 1..n.
fn gmsh_text(m: &TetMesh) -> String {
    let (n, e) = (m.nodes.len(), m.tets.len());
    let mut s =
        String::from("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 0 0 1\n1 0 0 0 1 1 1 0 0\n$EndEntities\n");
    writeln!(s, "$Nodes\n1 {n} 1 {n}\n3 1 0 {n}").unwrap();
    for i in 1..=n {
        writeln!(s, "{i}").unwrap();
    }
    for x in &m.nodes {
        writeln!(s, "{} {} {}", x.x, x.y, x.z).unwrap();
    }
    writeln!(s, "$EndNodes\n$Elements\n1 {e} 1 {e}\n3 1 4 {e}").unwrap();
    for (k, t) in m.tets.iter().enumerate() {
        writeln!(s, "{} {} {} {} {}", k + 1, t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1).unwrap();
    }
    s.push_str("$EndElements\n");
    s
}

/// `m` in Medit `.mesh` format, coordinates multiplied by `factor`.
fn medit_text(m: &TetMesh, factor: f64) -> String {
    let mut s = format!("MeshVersionFormatted 2\nDimension 3\nVertices\n{}\n", m.nodes.len());
    for x in &m.nodes {
        writeln!(s, "{} {} {} 0", x.x * factor, x.y * factor, x.z * factor).unwrap();
    }
    writeln!(s, "Tetrahedra\n{}", m.tets.len()).unwrap();
    for t in &m.tets {
        writeln!(s, "{} {} {} {} 1", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1).unwrap();
    }
    s.push_str("End\n");
    s
}

/// A user's lumen, not the built-in one: 3 mm radius, 40 mm straight
/// along +z from (0, 0, 0.1), a 60 degree bend of 25 mm radius towards +x,
/// 20 mm straight; 24 vertices per ring, rings 2 mm apart.
fn example_tube() -> TriSurface {
    CenterlineBuilder::new(Vec3::new(0.0, 0.0, 0.1), Vec3::z())
        .line(0.04)
        .arc(0.025, std::f64::consts::PI / 3.0, Vec3::x())
        .line(0.02)
        .build_constant(3e-3)
        .unwrap()
        .to_mesh(24, 2e-3)
        .unwrap()
}

fn shipped(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/meshes").join(name)
}

/// The shipped example meshes are what the generators here write.
#[test]
fn shipped_example_meshes_match_their_generators() {
    let files = [
        ("perturbed-cube.msh", gmsh_text(&perturbed_cube()).into_bytes()),
        ("bent-tube.stl", example_tube().to_stl_binary()),
    ];
    for (name, bytes) in files {
        if std::env::var_os("SURGBENCH_WRITE_EXAMPLES").is_some() {
            std::fs::create_dir_all(shipped("")).unwrap();
            std::fs::write(shipped(name), &bytes).unwrap();
        }
        let on_disk = std::fs::read(shipped(name)).unwrap_or_default();
        assert!(
            on_disk == bytes,
            "datasets/meshes/{name} differs from its generator; rewrite with SURGBENCH_WRITE_EXAMPLES=1"
        );
    }
}

/// Linear tets pass the patch test on an irregular user mesh, read from
/// Gmsh and from Medit (the latter in millimetres, scaled by --mesh-scale),
/// and both give the same numbers; `summary.json` names the file.
#[test]
fn fem_passes_the_patch_test_on_a_user_mesh_from_either_format() {
    let tmp = tempfile::tempdir().unwrap();
    let m = perturbed_cube();
    let msh = tmp.path().join("cube.msh");
    let medit = tmp.path().join("cube-mm.mesh");
    std::fs::write(&msh, gmsh_text(&m)).unwrap();
    std::fs::write(&medit, medit_text(&m, 1e3)).unwrap();
    let common = ["--scenario", "tissue-patch-test", "--model", "fem"];
    let mut errors = Vec::new();
    for (file, extra) in [(&msh, vec![]), (&medit, vec!["--mesh-scale", "1e-3"])] {
        let out = tmp.path().join(file.file_stem().unwrap());
        let mut args: Vec<&str> = common.to_vec();
        args.extend(["--mesh", file.to_str().unwrap()]);
        args.extend(extra);
        let o = run_one(&out, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        let s = RunSummary::read(&out.join("summary.json")).unwrap();
        assert_eq!(s.mesh.as_deref(), Some(file.to_str().unwrap()));
        assert_eq!(s.status, surgbench_reports::Status::Ok, "{}", s.reason);
        assert_eq!(s.errors["interior_nodes"], 27.0);
        let e = s.errors["patch_error_rel"];
        // Linear tets reproduce the affine field exactly: what is left is
        // the quasi-static Newton solve's tolerance and roundoff.
        assert!(e < 1e-8, "{}: patch_error_rel {e}", file.display());
        errors.push(e);
    }
    // Millimetres scaled to metres: the same mesh up to the rounding of
    // x * 1e3 * 1e-3, so the same answer to far below the 1e-8 above.
    assert!((errors[0] - errors[1]).abs() < 1e-10, "{errors:?}");
}

/// A wire pushed into a user's STL lumen along its entry straight: the run
/// completes, the wire stays inside (no penetration past a hair), and the
/// tip advanced by the feed.
#[test]
fn a_wire_runs_in_a_user_stl_vessel() {
    let tmp = tempfile::tempdir().unwrap();
    let stl = tmp.path().join("tube.stl");
    std::fs::write(&stl, example_tube().to_stl_binary()).unwrap();
    let out = tmp.path().join("wire");
    let o = run_one(
        &out,
        &[
            "--scenario",
            "vessel-mesh-insertion",
            "--model",
            "pbd-rod",
            "--mesh",
            stl.to_str().unwrap(),
            "--param",
            "entry_x=0",
            "--param",
            "entry_z=0.105",
            "--param",
            "entry_dir_x=0",
            "--param",
            "entry_dir_z=1",
            "--param",
            "initial_length=0.032",
            "--param",
            "duration=0.5",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let s = RunSummary::read(&out.join("summary.json")).unwrap();
    assert_eq!(s.status, surgbench_reports::Status::Ok, "{}", s.reason);
    // The tip starts 3 mm short of the bend and is fed 10 mm: it moves
    // (at least half the feed) and its surface stays within 5 % of the
    // wire radius of the wall (the voxel field's own error is ~1e-5 m).
    assert!(s.errors["tip_displacement_m"] > 5e-3, "{:?}", s.errors);
    assert!(s.errors["penetration_rel"] < 0.05, "{:?}", s.errors);
    assert!(
        !s.errors.contains_key("tip_progress_m"),
        "no centreline is known for a user's mesh"
    );
}

/// Every misuse is exit 2 naming the problem, with nothing written.
#[test]
fn mesh_misuse_is_a_usage_error() {
    let tmp = tempfile::tempdir().unwrap();
    let msh = tmp.path().join("cube.msh");
    std::fs::write(&msh, gmsh_text(&perturbed_cube())).unwrap();
    let stl = tmp.path().join("tube.stl");
    std::fs::write(&stl, example_tube().to_stl_binary()).unwrap();
    let broken = tmp.path().join("broken.msh");
    std::fs::write(&broken, gmsh_text(&perturbed_cube()).replace("$EndNodes", "$EndNodez")).unwrap();
    let out = tmp.path().join("never");
    let (msh, stl, broken) = (msh.to_str().unwrap(), stl.to_str().unwrap(), broken.to_str().unwrap());
    let patch = ["--scenario", "tissue-patch-test", "--model", "fem", "--mesh"];
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["--scenario", "cantilever-gravity", "--model", "der", "--mesh", msh],
            vec!["cantilever-gravity", "takes no --mesh"],
        ),
        ([&patch[..], &[stl]].concat(), vec!["tetrahedral mesh", "tube.stl"]),
        (
            [&patch[..], &[msh, "--fidelity", "mesh_level=1"]].concat(),
            vec!["mesh_level", "cube.msh"],
        ),
        ([&patch[..], &[msh, "--param", "edge=0.02"]].concat(), vec!["`edge`"]),
        ([&patch[..], &[broken]].concat(), vec!["broken.msh"]),
        ([&patch[..], &["cube.vtk"]].concat(), vec!["unknown extension `vtk`"]),
        ([&patch[..], &[msh, "--mesh-scale", "0"]].concat(), vec!["--mesh-scale"]),
        (
            vec![
                "--scenario",
                "vessel-mesh-insertion",
                "--model",
                "pbd-rod",
                "--mesh",
                stl,
            ],
            vec!["entry point", "tube.stl", "entry_x"],
        ),
    ];
    for (args, words) in cases {
        let o = run_one(&out, &args);
        assert_usage(&o, &out, &words);
    }
    // --mesh-scale needs --mesh (clap's own usage error, exit 2).
    let o = run_one(
        &out,
        &["--scenario", "tissue-patch-test", "--model", "fem", "--mesh-scale", "2"],
    );
    assert_usage(&o, &out, &["--mesh"]);
}
