//! STL (binary and ASCII) and OBJ loading: round trips of a procedural tube
//! mesh, and clear errors on malformed, open, non-manifold and inside-out
//! meshes.

use std::path::PathBuf;
use surgbench_core::Vec3;
use surgbench_core::io::{TriSurface, load_mesh, parse_obj, parse_stl};
use surgbench_core::sdf::CenterlineBuilder;

fn tube_mesh() -> TriSurface {
    CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(0.01)
        .arc(0.01, 1.0, Vec3::y())
        .build_constant(2e-3)
        .unwrap()
        .to_mesh(12, 2e-3)
        .unwrap()
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("surgbench-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn round_trips_keep_topology_and_geometry() {
    let m = tube_mesh();
    m.check_closed().unwrap();
    let vol = m.signed_volume();
    // ASCII STL (written with {:e}: shortest round trip, so exact).
    let p = tmp("tube.stl");
    m.write_stl_ascii(&p).unwrap();
    let a = load_mesh(&p, 1.0).unwrap();
    assert_eq!(a.vertices.len(), m.vertices.len(), "welded vertex count");
    assert_eq!(a.triangles.len(), m.triangles.len());
    assert!(
        (a.signed_volume() - vol).abs() < 1e-15 * vol.abs().max(1.0),
        "{} vs {vol}",
        a.signed_volume()
    );
    // Binary STL (f32 coordinates: volume within f32 precision).
    let p = tmp("tube_bin.stl");
    std::fs::write(&p, m.to_stl_binary()).unwrap();
    let b = load_mesh(&p, 1.0).unwrap();
    assert_eq!(b.vertices.len(), m.vertices.len());
    assert!(
        ((b.signed_volume() - vol) / vol).abs() < 1e-6,
        "binary volume {} vs {vol}",
        b.signed_volume()
    );
    // OBJ, in millimetres, scaled back.
    let p = tmp("tube.obj");
    m.scaled(1e3).write_obj(&p).unwrap();
    let o = load_mesh(&p, 1e-3).unwrap();
    assert_eq!(o.triangles, m.triangles);
    assert!(((o.signed_volume() - vol) / vol).abs() < 1e-12);
}

#[test]
fn obj_accepts_common_statements() {
    let text = "# cube-ish tetra\no t\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\ns off\nf 1//1 3//1 2//1\nf 1/1/1 2 4\nf -4 4 3\nf 2 3 4\n";
    let s = parse_obj("t.obj", text).unwrap();
    assert_eq!(s.triangles.len(), 4);
    s.check_closed().unwrap();
    assert!((s.signed_volume() - 1.0 / 6.0).abs() < 1e-15);
}

#[test]
fn malformed_files_name_file_location_and_problem() {
    let e = parse_obj("bad.obj", "v 0 0 0\nv 1 x 0\n").unwrap_err();
    assert_eq!((e.file.as_str(), e.location.as_str()), ("bad.obj", "line 2"), "{e}");
    assert!(e.to_string().contains("`x` is not a finite number"), "{e}");
    let e = parse_obj("bad.obj", "v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap_err();
    assert!(
        e.to_string().contains("line 3") && e.to_string().contains("out of range"),
        "{e}"
    );
    let e = parse_obj("bad.obj", "v 0 0 0\nbogus 1\n").unwrap_err();
    assert!(
        e.to_string().contains("line 2") && e.to_string().contains("unknown OBJ statement"),
        "{e}"
    );

    let ascii = "solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 nan\n";
    let e = parse_stl("bad.stl", ascii.as_bytes()).unwrap_err();
    assert!(
        e.to_string().contains("bad.stl: line 5") && e.to_string().contains("`nan`"),
        "{e}"
    );
    let e = parse_stl(
        "bad.stl",
        b"solid x\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n  endloop\n",
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("line 5") && e.to_string().contains("1 vertices"),
        "{e}"
    );
    let e = parse_stl("bad.stl", b"solid x\n").unwrap_err();
    assert!(e.to_string().contains("missing `endsolid`"), "{e}");
    // Binary STL whose facet count disagrees with its size.
    let mut bin = tube_mesh().to_stl_binary();
    bin.truncate(bin.len() - 10);
    let e = parse_stl("bin.stl", &bin).unwrap_err();
    assert!(
        e.to_string().contains("byte 80") && e.to_string().contains("facets"),
        "{e}"
    );
    let e = load_mesh(&tmp("missing.stl"), 1.0).unwrap_err();
    assert!(e.to_string().contains("missing.stl"), "{e}");
    let p = tmp("x.ply");
    std::fs::write(&p, "ply").unwrap();
    assert!(
        load_mesh(&p, 1.0)
            .unwrap_err()
            .to_string()
            .contains("unknown mesh extension")
    );
}

#[test]
fn open_non_manifold_and_inside_out_meshes_are_rejected() {
    let m = tube_mesh();
    let mut open = m.clone();
    open.triangles.pop();
    let e = open.check_closed().unwrap_err();
    assert!(
        e.what.contains("boundary edge") && e.location.starts_with("edge "),
        "{e}"
    );

    // A third triangle on an existing edge.
    let mut nm = m.clone();
    let t = nm.triangles[0];
    nm.vertices.push(Vec3::new(1.0, 1.0, 1.0));
    nm.triangles.push([t[0], t[1], nm.vertices.len() - 1]);
    let e = nm.check_closed().unwrap_err();
    assert!(e.what.contains("non-manifold"), "{e}");

    let mut flipped = m.clone();
    for t in &mut flipped.triangles {
        t.swap(1, 2);
    }
    let e = flipped.check_closed().unwrap_err();
    assert!(e.what.contains("inside-out"), "{e}");

    // Written to disk, the loader reports the file name too.
    let p = tmp("flipped.obj");
    flipped.write_obj(&p).unwrap();
    let e = load_mesh(&p, 1.0).unwrap_err();
    assert!(
        e.to_string().contains("flipped.obj") && e.to_string().contains("inside-out"),
        "{e}"
    );

    let mut degenerate = m.clone();
    degenerate.triangles[3] = [1, 1, 2];
    assert!(degenerate.check_closed().unwrap_err().what.contains("degenerate"));
}
