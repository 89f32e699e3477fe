//! Triangle surfaces (a vessel lumen from STL or OBJ): the [`TriSurface`]
//! type, its closedness check and [`load_mesh`], which picks the reader
//! ([`super::stl`], [`super::obj`]) by file extension. Units are SI (metres).

use super::{obj, stl};
use crate::Vec3;
use std::collections::HashMap;
use std::fmt;
use std::path::Path;

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
pub struct SurfaceError {
    /// File (or `<memory>`).
    pub file: String,
    /// Where: `line 12`, `byte 84`, `triangle 5`, `edge 3-7`.
    pub location: String,
    /// What is wrong.
    pub what: String,
}

impl fmt::Display for SurfaceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.location.is_empty() {
            write!(f, "{}: {}", self.file, self.what)
        } else {
            write!(f, "{}: {}: {}", self.file, self.location, self.what)
        }
    }
}

impl std::error::Error for SurfaceError {}

pub(crate) fn merr(file: &str, location: impl Into<String>, what: impl Into<String>) -> SurfaceError {
    SurfaceError {
        file: file.to_string(),
        location: location.into(),
        what: what.into(),
    }
}

/// Builds a surface from triangle soups, merging bit-identical vertices.
#[derive(Default)]
pub(crate) struct Welder {
    map: HashMap<[u64; 3], usize>,
    pub(crate) surface: TriSurface,
}

impl Welder {
    pub(crate) fn vertex(&mut self, p: Vec3) -> usize {
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
    pub fn check_closed(&self) -> Result<(), SurfaceError> {
        self.check_closed_named("<memory>")
    }

    pub(crate) fn check_closed_named(&self, file: &str) -> Result<(), SurfaceError> {
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
}

/// Load a closed vessel surface from `.stl` (binary or ASCII) or `.obj`,
/// multiplying coordinates by `scale` (1 for metres, 1e-3 for millimetres),
/// and check it with [`TriSurface::check_closed`].
pub fn load_mesh(path: &Path, scale: f64) -> Result<TriSurface, SurfaceError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| merr(&file, "", e.to_string()))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let surface = match ext.as_str() {
        "stl" => stl::parse_stl(&file, &bytes)?,
        "obj" => {
            let text = std::str::from_utf8(&bytes)
                .map_err(|e| merr(&file, format!("byte {}", e.valid_up_to()), "not UTF-8 text"))?;
            obj::parse_obj(&file, text)?
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
