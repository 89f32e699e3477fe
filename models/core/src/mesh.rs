//! Tetrahedral meshing shared by every tissue model and tissue scenario:
//! structured builders ([`block`], [`tube`], [`tube_sector`]), node sets by
//! predicate, boundary faces, mesh quality ([`quality`]), ASCII readers for
//! Gmsh v4 ([`read_gmsh_v4`]) and Medit ([`read_medit`]) files, and the
//! Truth Cube phantom loader ([`truth_cube::load`]).
//!
//! Units are SI (metres). Every builder returns positively oriented tets
//! (`(b - a) x (c - a) . (d - a) > 0`).
//!
//! Structured builders split each hexahedral cell into six tetrahedra along
//! its main diagonal (the Kuhn / Freudenthal subdivision). Neighbouring cells
//! then share face diagonals, so the mesh is conforming, also across the
//! periodic seam of a full tube.
//!
//! ```
//! use surgbench_core::{mesh, Vec3};
//! let m = mesh::block(Vec3::new(0.01, 0.01, 0.02), [2, 2, 4]);
//! assert_eq!(m.tets.len(), 6 * 2 * 2 * 4);
//! let bottom = mesh::nodes_on_plane(&m, 2, 0.0, 1e-9);
//! assert_eq!(bottom.len(), 9);
//! let q = mesh::quality(&m);
//! assert_eq!(q.inverted, 0);
//! assert!((q.volume - 0.01 * 0.01 * 0.02).abs() < 1e-15);
//! ```

use crate::Vec3;
use crate::scene::TetMesh;
use std::collections::HashMap;
use std::fmt;
use std::path::Path;

/// Signed volume of the tet `(a, b, c, d)` (m^3); positive when
/// `(b - a) x (c - a)` points towards `d`.
pub fn tet_volume(a: &Vec3, b: &Vec3, c: &Vec3, d: &Vec3) -> f64 {
    (b - a).cross(&(c - a)).dot(&(d - a)) / 6.0
}

/// Kuhn subdivision of the unit cube: corner `k` has offset bits
/// `(k & 1, k >> 1 & 1, k >> 2 & 1)`; each tet walks from corner 0 to
/// corner 7 along one permutation of the axes.
const KUHN: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// Build tets from a structured `(ni+1) x (nj+1) x (nk+1)` lattice whose node
/// index is `node(i, j, k)`; orientation is fixed from the node positions.
fn lattice_tets(nodes: &[Vec3], cells: [usize; 3], node: impl Fn(usize, usize, usize) -> usize) -> Vec<[usize; 4]> {
    let mut tets = Vec::with_capacity(6 * cells[0] * cells[1] * cells[2]);
    for k in 0..cells[2] {
        for j in 0..cells[1] {
            for i in 0..cells[0] {
                let corner = |c: usize| node(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                for t in KUHN {
                    let mut tet = t.map(corner);
                    let [a, b, c, d] = tet.map(|n| nodes[n]);
                    if tet_volume(&a, &b, &c, &d) < 0.0 {
                        tet.swap(2, 3);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    tets
}

/// Axis-aligned box `[0, size.x] x [0, size.y] x [0, size.z]` (m) with
/// `cells[i]` hexahedral cells along axis `i`, six tets per cell.
///
/// Node `(i, j, k)` has index `i + (cells[0] + 1) * (j + (cells[1] + 1) * k)`.
/// A zero cell count is raised to one.
pub fn block(size: Vec3, cells: [usize; 3]) -> TetMesh {
    let c = cells.map(|n| n.max(1));
    let (nx, ny, nz) = (c[0] + 1, c[1] + 1, c[2] + 1);
    let mut nodes = Vec::with_capacity(nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                nodes.push(Vec3::new(
                    size.x * i as f64 / c[0] as f64,
                    size.y * j as f64 / c[1] as f64,
                    size.z * k as f64 / c[2] as f64,
                ));
            }
        }
    }
    let tets = lattice_tets(&nodes, c, |i, j, k| i + nx * (j + ny * k));
    TetMesh { nodes, tets }
}

/// Full thick-walled tube about the z axis: radii `inner..outer` (m),
/// `z` in `[0, height]`, with `n_theta >= 3` cells around, `n_r` through the
/// wall and `n_z` along the axis. The circles are approximated by polygons
/// with `n_theta` sides (nodes lie exactly on the circles).
pub fn tube(inner: f64, outer: f64, height: f64, n_theta: usize, n_r: usize, n_z: usize) -> TetMesh {
    cylindrical(
        inner,
        outer,
        height,
        std::f64::consts::TAU,
        n_theta.max(3),
        n_r,
        n_z,
        true,
    )
}

/// Sector `0 <= theta <= angle` (rad, from +x towards +y) of a thick-walled
/// tube about the z axis; see [`tube`]. With `angle = pi/2` and symmetry
/// conditions (`u_y = 0` on `y = 0`, `u_x = 0` on `x = 0`) it models the
/// full tube at a quarter of the cost.
pub fn tube_sector(inner: f64, outer: f64, height: f64, angle: f64, n_theta: usize, n_r: usize, n_z: usize) -> TetMesh {
    cylindrical(inner, outer, height, angle, n_theta.max(1), n_r, n_z, false)
}

fn cylindrical(
    inner: f64,
    outer: f64,
    height: f64,
    angle: f64,
    n_t: usize,
    n_r: usize,
    n_z: usize,
    periodic: bool,
) -> TetMesh {
    let (n_r, n_z) = (n_r.max(1), n_z.max(1));
    let nt_nodes = if periodic { n_t } else { n_t + 1 };
    let (nr_nodes, nz_nodes) = (n_r + 1, n_z + 1);
    let mut nodes = Vec::with_capacity(nt_nodes * nr_nodes * nz_nodes);
    for k in 0..nz_nodes {
        for j in 0..nt_nodes {
            for i in 0..nr_nodes {
                let r = inner + (outer - inner) * i as f64 / n_r as f64;
                let th = angle * j as f64 / n_t as f64;
                let z = height * k as f64 / n_z as f64;
                let (s, c) = th.sin_cos();
                // Exact zeros on the symmetry planes keep node sets crisp.
                let x = if (th - std::f64::consts::FRAC_PI_2).abs() < 1e-14 {
                    0.0
                } else {
                    r * c
                };
                let y = if th == 0.0 { 0.0 } else { r * s };
                nodes.push(Vec3::new(x, y, z));
            }
        }
    }
    let tets = lattice_tets(&nodes, [n_r, n_t, n_z], |i, j, k| {
        i + nr_nodes * ((j % nt_nodes) + nt_nodes * k)
    });
    TetMesh { nodes, tets }
}

/// A copy of `mesh` with every node moved by `offset` (m).
pub fn translated(mesh: &TetMesh, offset: Vec3) -> TetMesh {
    TetMesh {
        nodes: mesh.nodes.iter().map(|p| p + offset).collect(),
        tets: mesh.tets.clone(),
    }
}

/// A copy of `mesh` with coordinates multiplied by `factor` (e.g. `1e-3` for
/// a file written in millimetres).
pub fn scaled(mesh: &TetMesh, factor: f64) -> TetMesh {
    TetMesh {
        nodes: mesh.nodes.iter().map(|p| p * factor).collect(),
        tets: mesh.tets.clone(),
    }
}

/// Indices of the nodes whose rest position satisfies `pred`, ascending.
pub fn nodes_where(mesh: &TetMesh, pred: impl Fn(&Vec3) -> bool) -> Vec<usize> {
    (0..mesh.nodes.len()).filter(|&i| pred(&mesh.nodes[i])).collect()
}

/// Nodes with `|p[axis] - value| <= tol` (axis 0 = x, 1 = y, 2 = z).
pub fn nodes_on_plane(mesh: &TetMesh, axis: usize, value: f64, tol: f64) -> Vec<usize> {
    nodes_where(mesh, |p| (p[axis] - value).abs() <= tol)
}

/// Nodes at distance `radius` (within `tol`) from the z axis.
pub fn nodes_on_cylinder(mesh: &TetMesh, radius: f64, tol: f64) -> Vec<usize> {
    nodes_where(mesh, |p| (p.x.hypot(p.y) - radius).abs() <= tol)
}

/// Axis-aligned bounding box `(min, max)` of the nodes (m).
pub fn bounds(mesh: &TetMesh) -> (Vec3, Vec3) {
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for p in &mesh.nodes {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (lo, hi)
}

/// Boundary triangles (faces used by exactly one tet), each ordered so that
/// its normal `(b - a) x (c - a)` points out of the mesh (for positively
/// oriented tets). Sorted for determinism.
pub fn boundary_faces(mesh: &TetMesh) -> Vec<[usize; 3]> {
    // Faces of a positive tet (a,b,c,d) with outward normals.
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
    let mut count: HashMap<[usize; 3], (usize, [usize; 3])> = HashMap::new();
    for t in &mesh.tets {
        for f in FACES {
            let face = f.map(|i| t[i]);
            let mut key = face;
            key.sort_unstable();
            count.entry(key).and_modify(|e| e.0 += 1).or_insert((1, face));
        }
    }
    let mut out: Vec<[usize; 3]> = count.into_values().filter(|(n, _)| *n == 1).map(|(_, f)| f).collect();
    out.sort_unstable();
    out
}

/// Geometric quality of a tet mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshQuality {
    /// Smallest dihedral angle over all tets (degrees).
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle over all tets (degrees).
    pub max_dihedral_deg: f64,
    /// Smallest signed tet volume (m^3); negative means an inverted tet.
    pub min_volume: f64,
    /// Largest signed tet volume (m^3).
    pub max_volume: f64,
    /// Sum of signed volumes (m^3).
    pub volume: f64,
    /// Count of tets with non-positive volume.
    pub inverted: usize,
}

/// The six dihedral angles of a tet (radians), one per edge.
pub fn dihedral_angles(p: [Vec3; 4]) -> [f64; 6] {
    const EDGES: [[usize; 4]; 6] = [
        [0, 1, 2, 3],
        [0, 2, 1, 3],
        [0, 3, 1, 2],
        [1, 2, 0, 3],
        [1, 3, 0, 2],
        [2, 3, 0, 1],
    ];
    EDGES.map(|[i, j, k, l]| {
        let e = (p[j] - p[i]).normalize();
        let u = p[k] - p[i];
        let w = p[l] - p[i];
        let u = u - e * u.dot(&e);
        let w = w - e * w.dot(&e);
        (u.dot(&w) / (u.norm() * w.norm())).clamp(-1.0, 1.0).acos()
    })
}

/// Dihedral angles, volumes and inverted count of `mesh` at its rest nodes.
pub fn quality(mesh: &TetMesh) -> MeshQuality {
    quality_at(mesh, &mesh.nodes)
}

/// Like [`quality`] but at deformed node positions `x` (m).
pub fn quality_at(mesh: &TetMesh, x: &[Vec3]) -> MeshQuality {
    let mut q = MeshQuality {
        min_dihedral_deg: f64::INFINITY,
        max_dihedral_deg: f64::NEG_INFINITY,
        min_volume: f64::INFINITY,
        max_volume: f64::NEG_INFINITY,
        volume: 0.0,
        inverted: 0,
    };
    for t in &mesh.tets {
        let p = t.map(|i| x[i]);
        let v = tet_volume(&p[0], &p[1], &p[2], &p[3]);
        q.volume += v;
        q.min_volume = q.min_volume.min(v);
        q.max_volume = q.max_volume.max(v);
        if v <= 0.0 {
            q.inverted += 1;
        }
        for a in dihedral_angles(p) {
            q.min_dihedral_deg = q.min_dihedral_deg.min(a.to_degrees());
            q.max_dihedral_deg = q.max_dihedral_deg.max(a.to_degrees());
        }
    }
    q
}

/// Flip every negatively oriented tet so that all volumes are positive
/// (file formats do not agree on orientation). Returns how many were flipped.
pub fn orient_positive(mesh: &mut TetMesh) -> usize {
    let mut flipped = 0;
    for t in &mut mesh.tets {
        let [a, b, c, d] = t.map(|i| mesh.nodes[i]);
        if tet_volume(&a, &b, &c, &d) < 0.0 {
            t.swap(2, 3);
            flipped += 1;
        }
    }
    flipped
}

/// A mesh file could not be read: which file, which line (1-based; 0 when
/// the problem is not tied to a line) and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MeshError {
    /// File name (or the label given to a parser).
    pub file: String,
    /// 1-based line number, 0 for whole-file problems.
    pub line: usize,
    /// What is wrong.
    pub what: String,
}

impl fmt::Display for MeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.file, self.line, self.what)
    }
}

impl std::error::Error for MeshError {}

/// Whitespace-separated tokens with their 1-based line numbers.
struct Tokens<'a> {
    file: &'a str,
    toks: Vec<(usize, &'a str)>,
    pos: usize,
    last_line: usize,
}

impl<'a> Tokens<'a> {
    fn new(file: &'a str, text: &'a str, comment: Option<char>) -> Self {
        let mut toks = Vec::new();
        for (ln, line) in text.lines().enumerate() {
            let line = match comment {
                Some(c) => line.split(c).next().unwrap_or(""),
                None => line,
            };
            toks.extend(line.split_whitespace().map(|t| (ln + 1, t)));
        }
        let last_line = text.lines().count();
        Self {
            file,
            toks,
            pos: 0,
            last_line,
        }
    }
    fn err(&self, line: usize, what: impl Into<String>) -> MeshError {
        MeshError {
            file: self.file.to_string(),
            line,
            what: what.into(),
        }
    }
    fn next(&mut self, expecting: &str) -> Result<(usize, &'a str), MeshError> {
        let t = self
            .toks
            .get(self.pos)
            .copied()
            .ok_or_else(|| self.err(self.last_line, format!("unexpected end of file, expecting {expecting}")))?;
        self.pos += 1;
        Ok(t)
    }
    fn peek(&self) -> Option<(usize, &'a str)> {
        self.toks.get(self.pos).copied()
    }
    fn usize(&mut self, what: &str) -> Result<usize, MeshError> {
        let (ln, t) = self.next(what)?;
        t.parse()
            .map_err(|_| self.err(ln, format!("expected {what} (non-negative integer), found `{t}`")))
    }
    fn f64(&mut self, what: &str) -> Result<f64, MeshError> {
        let (ln, t) = self.next(what)?;
        match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(ln, format!("expected {what} (finite number), found `{t}`"))),
        }
    }
    fn expect(&mut self, word: &str) -> Result<usize, MeshError> {
        let (ln, t) = self.next(word)?;
        if t.eq_ignore_ascii_case(word) {
            Ok(ln)
        } else {
            Err(self.err(ln, format!("expected `{word}`, found `{t}`")))
        }
    }
}

fn read_text(path: &Path) -> Result<String, MeshError> {
    std::fs::read_to_string(path).map_err(|e| MeshError {
        file: path.display().to_string(),
        line: 0,
        what: format!("cannot read: {e}"),
    })
}

fn finish_mesh(file: &str, nodes: Vec<Vec3>, tets: Vec<([usize; 4], usize)>) -> Result<TetMesh, MeshError> {
    if tets.is_empty() {
        return Err(MeshError {
            file: file.to_string(),
            line: 0,
            what: "no tetrahedra (4-node elements) in the file".into(),
        });
    }
    let mut mesh = TetMesh {
        nodes,
        tets: tets.iter().map(|(t, _)| *t).collect(),
    };
    for (t, ln) in &tets {
        let [a, b, c, d] = t.map(|i| mesh.nodes[i]);
        if tet_volume(&a, &b, &c, &d) == 0.0 {
            return Err(MeshError {
                file: file.to_string(),
                line: *ln,
                what: format!("degenerate tetrahedron {t:?} (zero volume)"),
            });
        }
    }
    orient_positive(&mut mesh);
    Ok(mesh)
}

/// Read an ASCII Gmsh MSH 4.x file (`$Nodes` and `$Elements` sections; other
/// sections are skipped). Only 4-node tetrahedra (element type 4) are kept;
/// lower-dimensional elements are ignored. Coordinates are taken as metres
/// (use [`scaled`] for files in mm). Tets are re-oriented positive.
pub fn read_gmsh_v4(path: impl AsRef<Path>) -> Result<TetMesh, MeshError> {
    let path = path.as_ref();
    parse_gmsh_v4(&path.display().to_string(), &read_text(path)?)
}

/// Parse the text of an ASCII Gmsh MSH 4.x file; `file` labels errors.
pub fn parse_gmsh_v4(file: &str, text: &str) -> Result<TetMesh, MeshError> {
    let mut tk = Tokens::new(file, text, None);
    let mut tags: HashMap<usize, usize> = HashMap::new();
    let mut nodes: Vec<Vec3> = Vec::new();
    let mut tets: Vec<([usize; 4], usize)> = Vec::new();
    let mut raw_tets: Vec<([usize; 4], usize)> = Vec::new();
    let mut seen_format = false;
    while let Some((ln, t)) = tk.peek() {
        tk.pos += 1;
        match t {
            "$MeshFormat" => {
                let (vln, v) = tk.next("format version")?;
                let ver: f64 = v
                    .parse()
                    .map_err(|_| tk.err(vln, format!("bad format version `{v}`")))?;
                if !(4.0..5.0).contains(&ver) {
                    return Err(tk.err(vln, format!("MSH version {v} is not supported (need 4.x)")));
                }
                let ft = tk.usize("file type")?;
                if ft != 0 {
                    return Err(tk.err(vln, "binary MSH files are not supported (file type 1); save as ASCII"));
                }
                tk.usize("data size")?;
                tk.expect("$EndMeshFormat")?;
                seen_format = true;
            }
            "$Nodes" => {
                let blocks = tk.usize("numEntityBlocks")?;
                let total = tk.usize("numNodes")?;
                tk.usize("minNodeTag")?;
                tk.usize("maxNodeTag")?;
                nodes.reserve(total);
                for _ in 0..blocks {
                    let dim = tk.usize("entityDim")?;
                    tk.next("entityTag")?;
                    let parametric = tk.usize("parametric flag")?;
                    let n = tk.usize("numNodesInBlock")?;
                    let mut block_tags = Vec::with_capacity(n);
                    for _ in 0..n {
                        let (tl, _) = tk.peek().unwrap_or((ln, ""));
                        let tag = tk.usize("node tag")?;
                        if tags.contains_key(&tag) {
                            return Err(tk.err(tl, format!("duplicate node tag {tag}")));
                        }
                        block_tags.push(tag);
                    }
                    for tag in block_tags {
                        let p = Vec3::new(tk.f64("x")?, tk.f64("y")?, tk.f64("z")?);
                        if parametric == 1 {
                            for _ in 0..dim.min(3) {
                                tk.f64("parametric coordinate")?;
                            }
                        }
                        tags.insert(tag, nodes.len());
                        nodes.push(p);
                    }
                }
                if nodes.len() != total {
                    return Err(tk.err(
                        ln,
                        format!("$Nodes declares {total} nodes but its blocks hold {}", nodes.len()),
                    ));
                }
                tk.expect("$EndNodes")?;
            }
            "$Elements" => {
                let blocks = tk.usize("numEntityBlocks")?;
                tk.usize("numElements")?;
                tk.usize("minElementTag")?;
                tk.usize("maxElementTag")?;
                for _ in 0..blocks {
                    tk.usize("entityDim")?;
                    tk.next("entityTag")?;
                    let (tl, _) = tk.peek().unwrap_or((ln, ""));
                    let ty = tk.usize("elementType")?;
                    let n = tk.usize("numElementsInBlock")?;
                    let nn = match ty {
                        15 => 1,
                        1 => 2,
                        2 => 3,
                        3 => 4,
                        4 => 4,
                        5 => 8,
                        6 => 6,
                        7 => 5,
                        8 => 3,
                        9 => 6,
                        11 => 10,
                        _ => return Err(tk.err(tl, format!("element type {ty} is not supported"))),
                    };
                    for _ in 0..n {
                        let (el, _) = tk.peek().unwrap_or((ln, ""));
                        tk.usize("element tag")?;
                        let mut v = [0usize; 10];
                        for slot in v.iter_mut().take(nn) {
                            *slot = tk.usize("element node tag")?;
                        }
                        if ty == 4 {
                            raw_tets.push(([v[0], v[1], v[2], v[3]], el));
                        }
                    }
                }
                tk.expect("$EndElements")?;
            }
            s if s.starts_with('$') && !s.starts_with("$End") => {
                // Skip an unknown section up to its end marker.
                let end = format!("$End{}", &s[1..]);
                loop {
                    let (_, w) = tk.next(&end)?;
                    if w == end {
                        break;
                    }
                }
            }
            other => return Err(tk.err(ln, format!("unexpected `{other}` outside any section"))),
        }
    }
    if !seen_format {
        return Err(tk.err(1, "missing $MeshFormat section (is this a Gmsh file?)"));
    }
    for (t, el) in raw_tets {
        let mut idx = [0usize; 4];
        for (k, tag) in t.iter().enumerate() {
            idx[k] = *tags
                .get(tag)
                .ok_or_else(|| tk.err(el, format!("element refers to node tag {tag}, which is not in $Nodes")))?;
        }
        tets.push((idx, el));
    }
    finish_mesh(file, nodes, tets)
}

/// Read an ASCII Medit `.mesh` file (`Vertices` and `Tetrahedra`; other
/// keywords with counted records are skipped; `#` starts a comment). Indices
/// are 1-based in the file. Coordinates are taken as metres.
pub fn read_medit(path: impl AsRef<Path>) -> Result<TetMesh, MeshError> {
    let path = path.as_ref();
    parse_medit(&path.display().to_string(), &read_text(path)?)
}

/// Parse the text of an ASCII Medit `.mesh` file; `file` labels errors.
pub fn parse_medit(file: &str, text: &str) -> Result<TetMesh, MeshError> {
    let mut tk = Tokens::new(file, text, Some('#'));
    let mut nodes: Vec<Vec3> = Vec::new();
    let mut tets = Vec::new();
    let mut seen_version = false;
    while let Some((ln, t)) = tk.peek() {
        tk.pos += 1;
        match t.to_ascii_lowercase().as_str() {
            "meshversionformatted" => {
                let v = tk.usize("mesh version")?;
                if v == 0 || v > 3 {
                    return Err(tk.err(ln, format!("unsupported MeshVersionFormatted {v}")));
                }
                seen_version = true;
            }
            "dimension" => {
                let dim = tk.usize("dimension")?;
                if dim != 3 {
                    return Err(tk.err(ln, format!("only Dimension 3 is supported, found {dim}")));
                }
            }
            "vertices" => {
                let n = tk.usize("vertex count")?;
                nodes.reserve(n);
                for _ in 0..n {
                    let p = Vec3::new(tk.f64("x")?, tk.f64("y")?, tk.f64("z")?);
                    tk.usize("vertex reference")?;
                    nodes.push(p);
                }
            }
            "tetrahedra" => {
                let n = tk.usize("tetrahedron count")?;
                for _ in 0..n {
                    let (el, _) = tk.peek().unwrap_or((ln, ""));
                    let mut v = [0usize; 4];
                    for slot in &mut v {
                        let i = tk.usize("vertex index")?;
                        if i == 0 || i > nodes.len() {
                            return Err(tk.err(
                                el,
                                format!(
                                    "tetrahedron refers to vertex {i}, but {} vertices were read (1-based)",
                                    nodes.len()
                                ),
                            ));
                        }
                        *slot = i - 1;
                    }
                    tk.usize("tetrahedron reference")?;
                    tets.push((v, el));
                }
            }
            "end" => break,
            kw => {
                // Known element keywords we skip: count, then per-record
                // vertex indices plus one reference.
                let per = match kw {
                    "edges" => 3,
                    "triangles" => 4,
                    "quadrilaterals" => 5,
                    "hexahedra" => 9,
                    "corners" | "requiredvertices" | "ridges" | "requirededges" => 1,
                    _ => return Err(tk.err(ln, format!("unknown keyword `{t}`"))),
                };
                let n = tk.usize("record count")?;
                for _ in 0..n * per {
                    tk.usize("index")?;
                }
            }
        }
    }
    if !seen_version {
        return Err(tk.err(1, "missing MeshVersionFormatted (is this a Medit file?)"));
    }
    finish_mesh(file, nodes, tets)
}

/// The Truth Cube phantom (Kerdok et al. 2003, Medical Image Analysis
/// 7(3):283-291): bead positions of a silicone cube under uniaxial
/// compression, as redistributed with OpenSurgSim (Apache-2.0).
pub mod truth_cube {
    use crate::Vec3;
    use std::path::Path;

    /// Nominal compressive strains of the four states in the file.
    pub const NOMINAL_STRAINS: [f64; 4] = [0.0, 0.05, 0.125, 0.1825];

    /// One bead: grid indices (1..=7) and its position in each state (m).
    #[derive(Debug, Clone, PartialEq)]
    pub struct Bead {
        /// Grid indices `(i, j, k)`, 1-based as in the file.
        pub index: [u8; 3],
        /// Position at nominal strain 0, 5, 12.5 and 18.25 % (m).
        pub positions: [Vec3; 4],
    }

    /// All beads of the uniaxial test.
    #[derive(Debug, Clone, PartialEq)]
    pub struct TruthCube {
        /// Beads in file order.
        pub beads: Vec<Bead>,
    }

    const COLUMNS: [&str; 15] = [
        "i", "j", "k", "x0", "y0", "z0", "x1", "y1", "z1", "x2", "y2", "z2", "x3", "y3", "z3",
    ];

    /// Load the CSV (`truth-cube-uniaxial.csv`): free-text lines, then a
    /// header row naming `i,j,k,x0,y0,z0,...,x3,y3,z3`, then one row per bead
    /// in millimetres. Positions are converted to metres. Errors name the
    /// file, the line and the missing column or bad value.
    pub fn load(path: impl AsRef<Path>) -> Result<TruthCube, String> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        parse(&path.display().to_string(), &text)
    }

    /// Parse the CSV text; `file` labels errors. See [`load`].
    pub fn parse(file: &str, text: &str) -> Result<TruthCube, String> {
        let lines: Vec<&str> = text.lines().collect();
        let header_at = lines
            .iter()
            .position(|l| l.split(',').next().map(str::trim) == Some("i"))
            .ok_or_else(|| format!("{file}: no header row starting with column `i`"))?;
        let header: Vec<&str> = lines[header_at].split(',').map(str::trim).collect();
        let mut col = [0usize; 15];
        for (c, name) in COLUMNS.iter().enumerate() {
            col[c] = header
                .iter()
                .position(|h| h == name)
                .ok_or_else(|| format!("{file}:{}: missing column `{name}`", header_at + 1))?;
        }
        let mut beads = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for (ln, line) in lines.iter().enumerate().skip(header_at + 1) {
            if line.trim().trim_matches(',').is_empty() {
                continue;
            }
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            let get = |c: usize| -> Result<f64, String> {
                let s = cells
                    .get(col[c])
                    .ok_or_else(|| format!("{file}:{}: row has no column `{}`", ln + 1, COLUMNS[c]))?;
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| format!("{file}:{}: column `{}` is not a number: `{s}`", ln + 1, COLUMNS[c]))
            };
            let mut index = [0u8; 3];
            for a in 0..3 {
                let v = get(a)?;
                if !(1.0..=7.0).contains(&v) || v.fract() != 0.0 {
                    return Err(format!(
                        "{file}:{}: bead index `{}` = {v} is not in 1..=7",
                        ln + 1,
                        COLUMNS[a]
                    ));
                }
                index[a] = v as u8;
            }
            let mut positions = [Vec3::zeros(); 4];
            for (s, p) in positions.iter_mut().enumerate() {
                *p = Vec3::new(get(3 + 3 * s)?, get(4 + 3 * s)?, get(5 + 3 * s)?) * 1e-3;
            }
            // The redistributed file repeats a few trailing rows; keep the
            // first occurrence of each bead.
            if seen.insert(index) {
                beads.push(Bead { index, positions });
            }
        }
        if beads.is_empty() {
            return Err(format!("{file}: no bead rows after the header"));
        }
        Ok(TruthCube { beads })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_volume_orientation_and_node_sets() {
        let size = Vec3::new(0.02, 0.03, 0.05);
        let m = block(size, [3, 4, 5]);
        assert_eq!(m.nodes.len(), 4 * 5 * 6);
        assert_eq!(m.tets.len(), 6 * 3 * 4 * 5);
        m.validate().unwrap();
        let q = quality(&m);
        assert_eq!(q.inverted, 0, "{q:?}");
        // Volumes sum to the box volume up to round-off (1e-12 relative).
        let v = size.x * size.y * size.z;
        assert!((q.volume - v).abs() < 1e-12 * v, "volume {} vs {v}", q.volume);
        assert_eq!(nodes_on_plane(&m, 2, 0.0, 1e-12).len(), 4 * 5);
        assert_eq!(nodes_on_plane(&m, 0, 0.02, 1e-12).len(), 5 * 6);
        // Boundary: 2 triangles per cell face on each of the six sides.
        let nf = boundary_faces(&m).len();
        assert_eq!(nf, 2 * 2 * (3 * 4 + 4 * 5 + 3 * 5), "boundary faces {nf}");
    }

    #[test]
    fn boundary_faces_point_outwards() {
        // Divergence theorem: sum over boundary of (x . n) dA = 3 V.
        let m = tube(0.01, 0.02, 0.03, 12, 3, 2);
        let q = quality(&m);
        let mut flux = 0.0;
        for f in boundary_faces(&m) {
            let [a, b, c] = f.map(|i| m.nodes[i]);
            let an = (b - a).cross(&(c - a)) / 2.0;
            flux += ((a + b + c) / 3.0).dot(&an);
        }
        assert!(
            (flux - 3.0 * q.volume).abs() < 1e-12 * q.volume.abs() * 3.0,
            "flux {flux} vs 3V {}",
            3.0 * q.volume
        );
    }

    #[test]
    fn tube_is_closed_and_converges_to_annulus_volume() {
        let (a, b, h) = (0.01, 0.02, 0.05);
        let m = tube(a, b, h, 64, 4, 3);
        m.validate().unwrap();
        let q = quality(&m);
        assert_eq!(q.inverted, 0);
        // Polygon area n/2 sin(2 pi/n) (b^2 - a^2): exact for the faceted tube.
        let n = 64.0;
        let exact = n / 2.0 * (std::f64::consts::TAU / n).sin() * (b * b - a * a) * h;
        assert!((q.volume - exact).abs() < 1e-12 * exact, "{} vs {exact}", q.volume);
        // Periodic: no boundary faces on a seam, so only inner, outer, ends.
        let nf = boundary_faces(&m).len();
        assert_eq!(nf, 2 * (64 * 3 * 2 + 64 * 4 * 2), "boundary faces {nf}");
        assert_eq!(nodes_on_cylinder(&m, a, 1e-12).len(), 64 * 4);
    }

    #[test]
    fn tube_sector_planes_and_quality() {
        let m = tube_sector(0.01, 0.02, 0.01, std::f64::consts::FRAC_PI_2, 8, 4, 1);
        m.validate().unwrap();
        assert_eq!(nodes_on_plane(&m, 1, 0.0, 0.0).len(), 5 * 2);
        assert_eq!(nodes_on_plane(&m, 0, 0.0, 0.0).len(), 5 * 2);
        let q = quality(&m);
        assert!(q.min_dihedral_deg > 10.0 && q.max_dihedral_deg < 170.0, "{q:?}");
    }

    #[test]
    fn dihedral_angles_of_regular_tet() {
        let p = [
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
        ];
        // Regular tet: every dihedral angle is acos(1/3) = 70.5288 deg.
        for a in dihedral_angles(p) {
            assert!((a - (1.0f64 / 3.0).acos()).abs() < 1e-12, "{a}");
        }
        // Kuhn cube tets: angles are 45, 60, 90 degrees.
        let q = quality(&block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]));
        assert!(
            (q.min_dihedral_deg - 45.0).abs() < 1e-9 && (q.max_dihedral_deg - 90.0).abs() < 1e-9,
            "{q:?}"
        );
    }

    const GMSH: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 0 0 1\n1 0 0 0 1 1 1 0 0\n$EndEntities\n\
$Nodes\n1 5 1 5\n3 1 0 5\n1\n2\n3\n4\n5\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n$EndNodes\n\
$Elements\n2 3 1 3\n2 1 2 1\n1 1 2 3\n3 1 4 2\n2 1 3 2 4\n3 2 4 3 5\n$EndElements\n";

    #[test]
    fn gmsh_reads_tets_and_orients_them() {
        let m = parse_gmsh_v4("t.msh", GMSH).unwrap();
        assert_eq!(m.nodes.len(), 5);
        assert_eq!(m.tets.len(), 2);
        let q = quality(&m);
        assert_eq!(q.inverted, 0);
        // Tet (0,2,1,3) was negative in the file and is flipped.
        assert!((q.volume - (1.0 / 6.0 + 1.0 / 3.0)).abs() < 1e-15, "{q:?}");
    }

    #[test]
    fn gmsh_errors_name_file_line_and_problem() {
        let bad_tag = GMSH.replace("3 2 4 3 5", "3 2 4 3 9");
        let e = parse_gmsh_v4("t.msh", &bad_tag).unwrap_err();
        assert_eq!((e.file.as_str(), e.line), ("t.msh", 28), "{e}");
        assert!(e.what.contains("node tag 9"), "{e}");
        let bad_num = GMSH.replace("1 1 1\n$EndNodes", "1 x 1\n$EndNodes");
        let e = parse_gmsh_v4("t.msh", &bad_num).unwrap_err();
        assert_eq!(e.line, 20, "{e}");
        assert!(e.what.contains("`x`"), "{e}");
        let v2 = GMSH.replace("4.1 0 8", "2.2 0 8");
        let e = parse_gmsh_v4("t.msh", &v2).unwrap_err();
        assert!(e.line == 2 && e.what.contains("2.2"), "{e}");
        let cut = &GMSH[..GMSH.find("$EndElements").unwrap() - 5];
        let e = parse_gmsh_v4("t.msh", cut).unwrap_err();
        assert!(e.what.contains("end of file"), "{e}");
        let e = read_gmsh_v4("/nonexistent/x.msh").unwrap_err();
        assert!(e.file.contains("x.msh") && e.what.contains("cannot read"), "{e}");
    }

    const MEDIT: &str = "MeshVersionFormatted 2\n# comment\nDimension 3\nVertices\n5\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n1 1 1 1\n\
Triangles\n1\n1 2 3 0\nTetrahedra\n2\n1 2 3 4 0\n2 4 3 5 0\nEnd\n";

    #[test]
    fn medit_reads_tets() {
        let m = parse_medit("t.mesh", MEDIT).unwrap();
        assert_eq!((m.nodes.len(), m.tets.len()), (5, 2));
        assert_eq!(quality(&m).inverted, 0);
    }

    #[test]
    fn medit_errors_name_file_line_and_problem() {
        let e = parse_medit("t.mesh", &MEDIT.replace("2 4 3 5 0", "2 4 3 6 0")).unwrap_err();
        assert_eq!(e.line, 17, "{e}");
        assert!(e.what.contains("vertex 6"), "{e}");
        let e = parse_medit("t.mesh", &MEDIT.replace("Dimension 3", "Dimension 2")).unwrap_err();
        assert!(e.line == 3 && e.what.contains("Dimension"), "{e}");
        let e = parse_medit("t.mesh", &MEDIT.replace("Triangles", "Pyramids")).unwrap_err();
        assert!(e.line == 11 && e.what.contains("Pyramids"), "{e}");
        let e = parse_medit(
            "t.mesh",
            "MeshVersionFormatted 2\nDimension 3\nVertices\n1\n0 0 0 1\nEnd\n",
        )
        .unwrap_err();
        assert!(e.what.contains("no tetrahedra"), "{e}");
    }

    #[test]
    fn truth_cube_loads_in_metres_and_names_missing_columns() {
        let text = "Truth Cube,,\nAll positions in mm,,\ni,j,k,x0,y0,z0,x1,y1,z1,x2,y2,z2,x3,y3,z3\n\
1,1,1,-29.69,-28.86,12.62,-30.33,-29.38,12.96,-31.04,-30.09,13.65,-31.85,-31.08,14.38\n";
        let c = truth_cube::parse("c.csv", text).unwrap();
        assert_eq!(c.beads.len(), 1);
        assert_eq!(c.beads[0].index, [1, 1, 1]);
        assert!((c.beads[0].positions[3].z - 0.01438).abs() < 1e-15);
        let e = truth_cube::parse("c.csv", &text.replace(",y2,", ",yy,")).unwrap_err();
        assert!(e.contains("c.csv:3") && e.contains("`y2`"), "{e}");
        let e = truth_cube::parse("c.csv", &text.replace("-31.04", "abc")).unwrap_err();
        assert!(e.contains("c.csv:4") && e.contains("`x2`"), "{e}");
    }

    #[test]
    fn truth_cube_dataset_has_343_beads_compressed_along_z() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../datasets/phantom/truth-cube/truth-cube-uniaxial.csv"
        );
        let c = truth_cube::load(path).unwrap();
        assert_eq!(c.beads.len(), 343);
        // Bead z extent shrinks with each compression level (uniaxial along z).
        let extent = |s: usize| {
            let z = c.beads.iter().map(|b| b.positions[s].z);
            z.clone().fold(f64::NEG_INFINITY, f64::max) - z.fold(f64::INFINITY, f64::min)
        };
        let e: Vec<f64> = (0..4).map(extent).collect();
        assert!(
            e.windows(2).all(|w| w[1] < w[0]) && e[0] > 0.055 && e[0] < 0.065,
            "z extents (m) {e:?}"
        );
    }
}
