//! Vessels: procedural vessel trees with physiological sizes (analytic
//! swept tubes), Poiseuille blood flow, and triangle-mesh vessels loaded from
//! STL (binary or ASCII) and OBJ files. SI units (metres, m/s).
//!
//! Procedural vessels ([`aortic_arch`], [`coronary_tortuous`],
//! [`y_bifurcation`]) are a trunk [`SweptTube`] plus branch tubes that start
//! on the trunk's centreline, joined as a union of lumens. Sizes:
//! - aorta: inner diameter 25 mm, arch (centreline) radius 35 mm. Adult
//!   thoracic aortic diameters of 25-35 mm are reported by Hager et al.
//!   (2002), "Diameters of the thoracic aorta throughout life as measured
//!   with helical computed tomography", J Thorac Cardiovasc Surg 123:1060;
//!   arch heights/widths of a few centimetres by Redheuil et al. (2011),
//!   "Age-related changes in aortic arch geometry", J Am Coll Cardiol
//!   58:1262. Supra-aortic branches (brachiocephalic 12 mm, left common
//!   carotid 7.5 mm, left subclavian 9 mm diameter) are typical adult values
//!   of the same order as those CT studies, not a specific patient.
//! - coronary: lumen diameter 3 mm, as in proximal coronary segments
//!   (Dodge et al. (1992), "Lumen diameter of normal human coronary
//!   arteries", Circulation 86:232); bends of curvature radius down to 5 mm
//!   stand for a severely tortuous vessel.
//! - Y bifurcation: trunk 4 mm, branches 3 mm diameter at 45 and 70 degrees:
//!   a generic geometry for branch selection, not an anatomical site.
//!
//! ```
//! use surgbench_core::vessel;
//! use surgbench_core::sdf::Sdf;
//! let arch = vessel::aortic_arch();
//! let entry = arch.entry().translation.vector;
//! assert!(arch.distance(&entry) < -0.012); // on the axis, 12.5 mm from the wall
//! ```

use crate::scene::FlowField;
use crate::sdf::{CenterlineBuilder, Sdf, SweptTube};
use crate::{Iso3, Vec3};
use std::collections::HashMap;
use std::f64::consts::PI;
use std::fmt;
use std::path::Path;

// ---------------------------------------------------------------------------
// Procedural vessels.
// ---------------------------------------------------------------------------

/// A named branch of a vessel tree.
#[derive(Debug, Clone)]
pub struct Branch {
    /// Name, e.g. `left-subclavian`.
    pub name: String,
    /// Its lumen.
    pub tube: SweptTube,
}

/// A vessel tree: a trunk and branches whose centrelines start on the trunk's
/// centreline; the lumen is their union (`phi = min`).
#[derive(Debug, Clone)]
pub struct Vessel {
    /// Name.
    pub name: String,
    /// The main lumen; the wire enters at its start.
    pub trunk: SweptTube,
    /// Side branches.
    pub branches: Vec<Branch>,
}

impl Vessel {
    /// Base clamp pose at the trunk's entry: on the centreline, local +x
    /// along the lumen (the harness's rod convention).
    pub fn entry(&self) -> Iso3 {
        self.trunk.frame_at(0.0)
    }

    /// The branch called `name`.
    pub fn branch(&self, name: &str) -> Option<&Branch> {
        self.branches.iter().find(|b| b.name == name)
    }

    /// Which lumen `p` is deepest in: `None` for the trunk, `Some(i)` for
    /// branch `i`, with its signed distance (m).
    pub fn deepest(&self, p: &Vec3) -> (Option<usize>, f64) {
        let mut best = (None, self.trunk.distance(p));
        for (i, b) in self.branches.iter().enumerate() {
            let d = b.tube.distance(p);
            if d < best.1 {
                best = (Some(i), d);
            }
        }
        best
    }
}

impl Sdf for Vessel {
    fn distance(&self, p: &Vec3) -> f64 {
        self.deepest(p).1
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let mut best = self.trunk.distance_gradient(p);
        for b in &self.branches {
            let dg = b.tube.distance_gradient(p);
            if dg.0 < best.0 {
                best = dg;
            }
        }
        best
    }
    /// The Hessian of the lumen `p` is deepest in ([`Vessel::deepest`]),
    /// the same one [`Sdf::gradient`] uses.
    fn hessian(&self, p: &Vec3) -> crate::Mat3 {
        match self.deepest(p).0 {
            None => self.trunk.hessian(p),
            Some(i) => self.branches[i].tube.hessian(p),
        }
    }
}

/// Aortic lumen radius (m): inner diameter 25 mm.
pub const AORTA_RADIUS: f64 = 12.5e-3;
/// Aortic arch centreline radius (m).
pub const ARCH_RADIUS: f64 = 35e-3;
/// Length of the straight descending segment before the arch (m): the
/// thoracic descending aorta is about 20 cm long, and scenes that feed a
/// wire by moving its clamp along this straight need the room (the clamp
/// must stay inside the lumen for the whole push).
pub const ARCH_DESCENDING: f64 = 210e-3;
/// Length of the straight ascending segment after the arch (m).
pub const ARCH_ASCENDING: f64 = 50e-3;
/// Length of each supra-aortic branch (m).
pub const ARCH_BRANCH_LENGTH: f64 = 200e-3;

/// Aortic arch traversed as in a femoral approach: the trunk starts at the
/// origin heading up (+z) the descending aorta (210 mm), turns over the arch
/// (radius 35 mm, 180 degrees, towards -x), and runs down the ascending aorta
/// (50 mm, -z); lumen diameter 25 mm. The supra-aortic branches leave the top
/// of the arch upwards at 60, 90 and 120 degrees along it: `left-subclavian`
/// (9 mm, met first), `left-common-carotid` (7.5 mm), `brachiocephalic`
/// (12 mm), each [`ARCH_BRANCH_LENGTH`] long: long enough that a wire
/// pushed into one keeps going for the whole of `arch-insertion` instead of
/// meeting a closed end no real artery has. (With gravity along -z the
/// patient would be standing: scenes choose their gravity.)
pub fn aortic_arch() -> Vessel {
    let trunk = CenterlineBuilder::new(Vec3::zeros(), Vec3::z())
        .line(ARCH_DESCENDING)
        .arc(ARCH_RADIUS, PI, -Vec3::x())
        .line(ARCH_ASCENDING)
        .build_constant(AORTA_RADIUS)
        .expect("static arch geometry is valid");
    let center = Vec3::new(-ARCH_RADIUS, 0.0, ARCH_DESCENDING);
    let branch = |name: &str, phi_deg: f64, tilt_deg: f64, radius: f64| {
        let phi = phi_deg.to_radians();
        let start = center + Vec3::new(phi.cos(), 0.0, phi.sin()) * ARCH_RADIUS;
        let t = tilt_deg.to_radians();
        let dir = Vec3::new(t.sin(), 0.0, t.cos());
        Branch {
            name: name.to_string(),
            tube: CenterlineBuilder::new(start, dir)
                .line(ARCH_BRANCH_LENGTH)
                .build_constant(radius)
                .expect("static branch geometry is valid"),
        }
    };
    Vessel {
        name: "aortic-arch".into(),
        trunk,
        branches: vec![
            branch("left-subclavian", 60.0, 15.0, 4.5e-3),
            branch("left-common-carotid", 90.0, 0.0, 3.75e-3),
            branch("brachiocephalic", 120.0, -15.0, 6e-3),
        ],
    }
}

/// Coronary lumen radius (m): diameter 3 mm.
pub const CORONARY_RADIUS: f64 = 1.5e-3;
/// Straight entry (guide-catheter) segment of the coronary (m): long enough
/// that a clamp fed along it stays in the straight for `coronary-tortuous`.
pub const CORONARY_ENTRY: f64 = 60e-3;

/// Tortuous coronary-like tube, diameter 3 mm: a 60 mm straight entry along
/// +x (where a guide catheter would sit), then five bends in alternating
/// planes with curvature radii 8, 5, 6, 5 and 10 mm, then 30 mm straight.
pub fn coronary_tortuous() -> Vessel {
    let trunk = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(CORONARY_ENTRY)
        .arc(8e-3, PI / 3.0, Vec3::y())
        .arc(5e-3, PI / 2.0, Vec3::z())
        .arc(6e-3, 2.0 * PI / 3.0, -Vec3::y())
        .arc(5e-3, PI / 2.0, -Vec3::z())
        .arc(10e-3, PI / 3.0, Vec3::y())
        .line(30e-3)
        .build_constant(CORONARY_RADIUS)
        .expect("static coronary geometry is valid");
    Vessel {
        name: "coronary-tortuous".into(),
        trunk,
        branches: Vec::new(),
    }
}

/// Trunk length of the Y bifurcation (m).
pub const Y_TRUNK: f64 = 40e-3;
/// Trunk lumen radius of the Y bifurcation (m).
pub const Y_TRUNK_RADIUS: f64 = 2e-3;
/// Branch lumen radius of the Y bifurcation (m).
pub const Y_BRANCH_RADIUS: f64 = 1.5e-3;

/// Y bifurcation in the x-y plane: trunk (4 mm diameter, 40 mm) along +x from
/// the origin, then `branch-45` leaving at 45 degrees towards +y and
/// `branch-70` at 70 degrees towards -y, both 3 mm diameter and 30 mm long,
/// starting at the trunk's end point.
pub fn y_bifurcation() -> Vessel {
    let trunk = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(Y_TRUNK)
        .build_constant(Y_TRUNK_RADIUS)
        .expect("static trunk geometry is valid");
    let end = Vec3::new(Y_TRUNK, 0.0, 0.0);
    let branch = |name: &str, deg: f64| {
        let a = deg.to_radians();
        Branch {
            name: name.to_string(),
            tube: CenterlineBuilder::new(end, Vec3::new(a.cos(), a.sin(), 0.0))
                .line(30e-3)
                .build_constant(Y_BRANCH_RADIUS)
                .expect("static branch geometry is valid"),
        }
    };
    Vessel {
        name: "y-bifurcation".into(),
        trunk,
        branches: vec![branch("branch-45", 45.0), branch("branch-70", -70.0)],
    }
}

/// Axial Poiseuille flow in a straight tube:
/// `v(r) = v_max (1 - r^2 / R^2)` along `axis` for `r < R`, zero outside
/// (the steady laminar solution for a pressure-driven Newtonian fluid in a
/// pipe; e.g. Batchelor, "An Introduction to Fluid Dynamics", section 4.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoiseuilleFlow {
    /// A point on the axis (m).
    pub origin: Vec3,
    /// Unit flow direction.
    pub axis: Vec3,
    /// Tube radius `R` (m).
    pub radius: f64,
    /// Centreline speed `v_max` (m/s); the mean speed is `v_max / 2`.
    pub v_max: f64,
}

impl FlowField for PoiseuilleFlow {
    fn velocity(&self, p: &Vec3) -> Vec3 {
        let d = p - self.origin;
        let r2 = (d - self.axis * d.dot(&self.axis)).norm_squared();
        let q = 1.0 - r2 / (self.radius * self.radius);
        if q > 0.0 {
            self.axis * (self.v_max * q)
        } else {
            Vec3::zeros()
        }
    }
}

// ---------------------------------------------------------------------------
// Triangle meshes and their loaders.
// ---------------------------------------------------------------------------

/// A triangle surface (m): vertices and triangles as vertex indices. A
/// vessel lumen mesh is closed with normals (counter-clockwise winding)
/// pointing out of the lumen.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriSurface {
    /// Vertex positions (m).
    pub vertices: Vec<Vec3>,
    /// Triangles (indices into `vertices`).
    pub triangles: Vec<[usize; 3]>,
}

/// A mesh could not be loaded or is not a closed, outward-oriented 2-manifold.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MeshError {
    /// File (or `<memory>`).
    pub file: String,
    /// Where: `line 12`, `byte 84`, `triangle 5`, `edge 3-7`.
    pub location: String,
    /// What is wrong.
    pub what: String,
}

impl fmt::Display for MeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.location.is_empty() {
            write!(f, "{}: {}", self.file, self.what)
        } else {
            write!(f, "{}: {}: {}", self.file, self.location, self.what)
        }
    }
}

impl std::error::Error for MeshError {}

fn merr(file: &str, location: impl Into<String>, what: impl Into<String>) -> MeshError {
    MeshError {
        file: file.to_string(),
        location: location.into(),
        what: what.into(),
    }
}

/// Builds a surface from triangle soups, merging bit-identical vertices.
#[derive(Default)]
struct Welder {
    map: HashMap<[u64; 3], usize>,
    surface: TriSurface,
}

impl Welder {
    fn vertex(&mut self, p: Vec3) -> usize {
        // -0.0 and 0.0 are the same point.
        let key = [p.x + 0.0, p.y + 0.0, p.z + 0.0].map(f64::to_bits);
        let n = self.surface.vertices.len();
        *self.map.entry(key).or_insert_with(|| {
            self.surface.vertices.push(p);
            n
        })
    }
}

impl TriSurface {
    /// Axis-aligned bounding box `(min, max)` of the vertices (m).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for v in &self.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        (lo, hi)
    }

    /// Signed enclosed volume `sum a . (b x c) / 6` (m^3): positive for a
    /// closed mesh with outward normals.
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i]);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// A copy with every vertex multiplied by `factor` (e.g. `1e-3` for a
    /// file in millimetres).
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            vertices: self.vertices.iter().map(|v| v * factor).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// Check the surface bounds a volume: indices in range, no degenerate
    /// triangle, every edge shared by exactly two triangles (no boundary =
    /// open, no more = non-manifold) traversed once in each direction
    /// (consistent orientation), and a positive signed volume (outward
    /// normals; negative = inside-out).
    pub fn check_closed(&self) -> Result<(), MeshError> {
        self.check_closed_named("<memory>")
    }

    fn check_closed_named(&self, file: &str) -> Result<(), MeshError> {
        if self.triangles.is_empty() {
            return Err(merr(file, "", "mesh has no triangles"));
        }
        let n = self.vertices.len();
        let mut directed: HashMap<(usize, usize), usize> = HashMap::new();
        for (ti, t) in self.triangles.iter().enumerate() {
            if let Some(&i) = t.iter().find(|&&i| i >= n) {
                return Err(merr(
                    file,
                    format!("triangle {ti}"),
                    format!("vertex index {i} out of range ({n} vertices)"),
                ));
            }
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                return Err(merr(
                    file,
                    format!("triangle {ti}"),
                    format!("degenerate: repeated vertex {t:?}"),
                ));
            }
            for k in 0..3 {
                let e = (t[k], t[(k + 1) % 3]);
                if let Some(&other) = directed.get(&e) {
                    return Err(merr(
                        file,
                        format!("edge {}-{}", e.0, e.1),
                        format!(
                            "traversed in the same direction by triangles {other} and {ti}: non-manifold or inconsistently oriented"
                        ),
                    ));
                }
                directed.insert(e, ti);
            }
        }
        let mut keys: Vec<_> = directed.keys().copied().collect();
        keys.sort_unstable();
        for (a, b) in keys {
            if !directed.contains_key(&(b, a)) {
                return Err(merr(
                    file,
                    format!("edge {a}-{b}"),
                    format!(
                        "boundary edge (only triangle {} uses it): the mesh is open",
                        directed[&(a, b)]
                    ),
                ));
            }
        }
        let v = self.signed_volume();
        if !(v > 0.0) {
            return Err(merr(
                file,
                "",
                format!(
                    "signed volume {v:.3e} m^3 is not positive: the mesh is inside-out (normals point into the lumen)"
                ),
            ));
        }
        Ok(())
    }

    /// Write as ASCII STL (one facet per triangle, normals from the winding).
    pub fn write_stl_ascii(&self, path: &Path) -> std::io::Result<()> {
        use std::io::Write;
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        writeln!(f, "solid surgbench")?;
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i]);
            let n = (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or_default();
            writeln!(f, "  facet normal {:e} {:e} {:e}\n    outer loop", n.x, n.y, n.z)?;
            for p in [a, b, c] {
                writeln!(f, "      vertex {:e} {:e} {:e}", p.x, p.y, p.z)?;
            }
            writeln!(f, "    endloop\n  endfacet")?;
        }
        writeln!(f, "endsolid surgbench")?;
        f.flush()
    }

    /// Binary STL bytes (80-byte header, u32 count, 50 bytes per facet).
    pub fn to_stl_binary(&self) -> Vec<u8> {
        let mut out = vec![0u8; 80];
        out[..9].copy_from_slice(b"surgbench");
        out.extend_from_slice(&(self.triangles.len() as u32).to_le_bytes());
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i]);
            let n = (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or_default();
            for p in [n, a, b, c] {
                for x in p.iter() {
                    out.extend_from_slice(&(*x as f32).to_le_bytes());
                }
            }
            out.extend_from_slice(&[0, 0]);
        }
        out
    }

    /// Write as OBJ (`v` and `f` lines, 1-based).
    pub fn write_obj(&self, path: &Path) -> std::io::Result<()> {
        use std::io::Write;
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        for v in &self.vertices {
            writeln!(f, "v {:e} {:e} {:e}", v.x, v.y, v.z)?;
        }
        for t in &self.triangles {
            writeln!(f, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
        }
        f.flush()
    }
}

/// Load a closed vessel surface from `.stl` (binary or ASCII) or `.obj`,
/// multiplying coordinates by `scale` (1 for metres, 1e-3 for millimetres),
/// and check it with [`TriSurface::check_closed`].
pub fn load_mesh(path: &Path, scale: f64) -> Result<TriSurface, MeshError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| merr(&file, "", e.to_string()))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let surface = match ext.as_str() {
        "stl" => parse_stl(&file, &bytes)?,
        "obj" => {
            let text = std::str::from_utf8(&bytes)
                .map_err(|e| merr(&file, format!("byte {}", e.valid_up_to()), "not UTF-8 text"))?;
            parse_obj(&file, text)?
        }
        other => {
            return Err(merr(
                &file,
                "",
                format!("unknown mesh extension `{other}` (expected stl or obj)"),
            ));
        }
    };
    if !(scale > 0.0 && scale.is_finite()) {
        return Err(merr(&file, "", format!("scale must be > 0, got {scale}")));
    }
    let surface = surface.scaled(scale);
    surface.check_closed_named(&file)?;
    Ok(surface)
}

/// Parse STL bytes: binary when the size matches the facet count at byte
/// 80, ASCII when the text starts with `solid`. Vertices are welded by exact
/// coordinates. The surface is not checked for closure (see
/// [`TriSurface::check_closed`]).
pub fn parse_stl(file: &str, bytes: &[u8]) -> Result<TriSurface, MeshError> {
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes(bytes[80..84].try_into().expect("4 bytes")) as usize;
        if bytes.len() as u64 == 84 + 50 * n as u64 {
            return parse_stl_binary(file, bytes, n);
        }
    }
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(512)]).to_string();
    if head.trim_start().starts_with("solid") {
        let text = std::str::from_utf8(bytes)
            .map_err(|e| merr(file, format!("byte {}", e.valid_up_to()), "ASCII STL is not valid text"))?;
        return parse_stl_ascii(file, text);
    }
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes(bytes[80..84].try_into().expect("4 bytes")) as u64;
        return Err(merr(
            file,
            "byte 80",
            format!(
                "binary STL header says {n} facets ({} bytes) but the file has {} bytes",
                84 + 50 * n,
                bytes.len()
            ),
        ));
    }
    Err(merr(
        file,
        "",
        format!(
            "too short for binary STL ({} bytes) and does not start with `solid`",
            bytes.len()
        ),
    ))
}

fn parse_stl_binary(file: &str, bytes: &[u8], n: usize) -> Result<TriSurface, MeshError> {
    let mut w = Welder::default();
    for t in 0..n {
        let base = 84 + 50 * t;
        let mut tri = [0usize; 3];
        for (k, slot) in tri.iter_mut().enumerate() {
            let off = base + 12 + 12 * k;
            let c =
                |j: usize| f32::from_le_bytes(bytes[off + 4 * j..off + 4 * j + 4].try_into().expect("4 bytes")) as f64;
            let p = Vec3::new(c(0), c(1), c(2));
            if !p.iter().all(|x| x.is_finite()) {
                return Err(merr(
                    file,
                    format!("byte {off}"),
                    format!("facet {t} vertex {k} is not finite: {p:?}"),
                ));
            }
            *slot = w.vertex(p);
        }
        w.surface.triangles.push(tri);
    }
    Ok(w.surface)
}

fn parse_stl_ascii(file: &str, text: &str) -> Result<TriSurface, MeshError> {
    let mut w = Welder::default();
    let mut pending: Vec<usize> = Vec::new();
    let mut in_loop = false;
    let mut saw_end = false;
    for (ln, line) in text.lines().enumerate() {
        let at = || format!("line {}", ln + 1);
        let mut tok = line.split_whitespace();
        let Some(kw) = tok.next() else { continue };
        match kw {
            "solid" if ln == 0 || w.surface.triangles.is_empty() => {}
            "facet" | "endfacet" => {
                if in_loop {
                    return Err(merr(file, at(), format!("`{kw}` inside an unclosed `outer loop`")));
                }
            }
            "outer" => {
                if tok.next() != Some("loop") {
                    return Err(merr(file, at(), "expected `outer loop`"));
                }
                in_loop = true;
                pending.clear();
            }
            "vertex" => {
                if !in_loop {
                    return Err(merr(file, at(), "`vertex` outside `outer loop`"));
                }
                let mut c = [0.0; 3];
                for (k, x) in c.iter_mut().enumerate() {
                    let s = tok
                        .next()
                        .ok_or_else(|| merr(file, at(), format!("vertex has {k} coordinates, expected 3")))?;
                    *x = s
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| merr(file, at(), format!("`{s}` is not a finite number")))?;
                }
                pending.push(w.vertex(Vec3::new(c[0], c[1], c[2])));
            }
            "endloop" => {
                if pending.len() != 3 {
                    return Err(merr(
                        file,
                        at(),
                        format!("facet has {} vertices, expected 3", pending.len()),
                    ));
                }
                w.surface.triangles.push([pending[0], pending[1], pending[2]]);
                in_loop = false;
            }
            "endsolid" => {
                saw_end = true;
                break;
            }
            other => return Err(merr(file, at(), format!("unexpected keyword `{other}`"))),
        }
    }
    if in_loop {
        return Err(merr(file, "end of file", "unterminated `outer loop`"));
    }
    if !saw_end {
        return Err(merr(file, "end of file", "missing `endsolid`"));
    }
    Ok(w.surface)
}

/// Parse OBJ text: `v x y z` vertices and `f` faces (indices 1-based or
/// negative-relative, `i/t/n` forms accepted, polygons fan-triangulated);
/// normals, texture coordinates, groups, materials and comments are ignored.
pub fn parse_obj(file: &str, text: &str) -> Result<TriSurface, MeshError> {
    let mut s = TriSurface::default();
    for (ln, line) in text.lines().enumerate() {
        let at = || format!("line {}", ln + 1);
        let line = line.split('#').next().unwrap_or("");
        let mut tok = line.split_whitespace();
        match tok.next() {
            None => {}
            Some("v") => {
                let mut c = [0.0; 3];
                for (k, x) in c.iter_mut().enumerate() {
                    let t = tok
                        .next()
                        .ok_or_else(|| merr(file, at(), format!("`v` has {k} coordinates, expected 3")))?;
                    *x = t
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| merr(file, at(), format!("`{t}` is not a finite number")))?;
                }
                s.vertices.push(Vec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let mut idx = Vec::new();
                for t in tok {
                    let first = t.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| merr(file, at(), format!("face index `{t}` is not an integer")))?;
                    let n = s.vertices.len() as i64;
                    let j = if i > 0 { i - 1 } else { n + i };
                    if i == 0 || j < 0 || j >= n {
                        return Err(merr(
                            file,
                            at(),
                            format!("face index {i} out of range ({n} vertices so far)"),
                        ));
                    }
                    idx.push(j as usize);
                }
                if idx.len() < 3 {
                    return Err(merr(
                        file,
                        at(),
                        format!("face has {} vertices, expected at least 3", idx.len()),
                    ));
                }
                for k in 1..idx.len() - 1 {
                    s.triangles.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            Some("vn" | "vt" | "vp" | "o" | "g" | "s" | "usemtl" | "mtllib" | "l") => {}
            Some(other) => return Err(merr(file, at(), format!("unknown OBJ statement `{other}`"))),
        }
    }
    Ok(s)
}

#[cfg(test)]
mod hessian_tests {
    use super::*;
    use crate::Mat3;

    /// The vessels' Hessian (the deepest lumen's) against central
    /// differences of their gradient, at seeded points near the trunk and
    /// branches whose difference stencil stays in one lumen and on one piece
    /// of its centreline (no kink of the gradient inside it).
    #[test]
    fn vessel_hessian_matches_differences_of_the_gradient() {
        // Step and the smallest distance from a centreline kept (m); the
        // relative truncation error of central differences is about
        // (h / rho)^2 = 4e-6 (see the sdf tests); rounding adds ~1e-10.
        let (h, rho_min) = (1e-6, 5e-4);
        let tol = (h / rho_min) * (h / rho_min);
        for (vessel, seed) in [(y_bifurcation(), 7u64), (coronary_tortuous(), 8)] {
            let tubes: Vec<&SweptTube> = std::iter::once(&vessel.trunk)
                .chain(vessel.branches.iter().map(|b| &b.tube))
                .collect();
            // Which lumen and which piece of its centreline `p` belongs to.
            let key = |p: &Vec3| {
                let (lumen, _) = vessel.deepest(p);
                let tube = tubes[lumen.map_or(0, |i| i + 1)];
                let pr = tube.project(p);
                let end = pr.s <= 0.0 || pr.s >= tube.length();
                (lumen, pr.piece, end, pr.radial >= rho_min)
            };
            let mut rng = crate::rng::SplitMix64(seed);
            let (mut worst, mut n) = (0.0f64, 0usize);
            while n < 300 {
                let tube = tubes[(rng.unit() * tubes.len() as f64) as usize];
                let c = tube.point_at(rng.unit() * tube.length());
                let p = c + Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 4e-3;
                let k0 = key(&p);
                let mut fd = Mat3::zeros();
                let mut smooth = k0.3;
                for k in 0..3 {
                    let (mut a, mut b) = (p, p);
                    a[k] += h;
                    b[k] -= h;
                    smooth &= key(&a) == k0 && key(&b) == k0;
                    fd.set_column(k, &((vessel.gradient(&a) - vessel.gradient(&b)) / (a[k] - b[k])));
                }
                if !smooth {
                    continue;
                }
                let got = vessel.hessian(&p);
                let err = (got - fd).norm() / got.norm();
                assert!(
                    err < tol,
                    "{}: hessian at {p:?} {got} vs differences {fd} (rel {err:e}, tol {tol:e})",
                    vessel.name
                );
                worst = worst.max(err);
                n += 1;
            }
            eprintln!("{}: worst rel err {worst:.2e} over {n} points", vessel.name);
        }
    }
}
