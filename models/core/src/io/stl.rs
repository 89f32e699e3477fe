//! STL triangle surfaces, binary and ASCII: reading ([`parse_stl`]) and
//! writing ([`TriSurface::write_stl_ascii`], [`TriSurface::to_stl_binary`]).

use super::surface::{SurfaceError, TriSurface, Welder, merr};
use crate::Vec3;
use std::path::Path;

impl TriSurface {
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
}

/// Parse STL bytes: binary when the size matches the facet count at byte
/// 80, ASCII when the text starts with `solid`. Vertices are welded by exact
/// coordinates. The surface is not checked for closure (see
/// [`TriSurface::check_closed`]).
pub fn parse_stl(file: &str, bytes: &[u8]) -> Result<TriSurface, SurfaceError> {
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

fn parse_stl_binary(file: &str, bytes: &[u8], n: usize) -> Result<TriSurface, SurfaceError> {
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

fn parse_stl_ascii(file: &str, text: &str) -> Result<TriSurface, SurfaceError> {
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
