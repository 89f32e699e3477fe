//! Wavefront OBJ triangle surfaces: reading ([`parse_obj`]) and writing
//! ([`TriSurface::write_obj`]).

use super::surface::{SurfaceError, TriSurface, merr};
use crate::Vec3;
use std::path::Path;

impl TriSurface {
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

/// Parse OBJ text: `v x y z` vertices and `f` faces (indices 1-based or
/// negative-relative, `i/t/n` forms accepted, polygons fan-triangulated);
/// normals, texture coordinates, groups, materials and comments are ignored.
pub fn parse_obj(file: &str, text: &str) -> Result<TriSurface, SurfaceError> {
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
