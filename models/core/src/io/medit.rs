//! Medit `.mesh` ASCII tetrahedral meshes.

use super::tetfile::{MeshError, Tokens, finish_mesh, read_text};
use crate::Vec3;
use crate::mesh::TetMesh;
use std::path::Path;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::quality;

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
}
