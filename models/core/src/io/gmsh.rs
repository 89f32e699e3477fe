//! Gmsh MSH 4.x ASCII tetrahedral meshes.

use super::tetfile::{MeshError, Tokens, finish_mesh, read_text};
use crate::Vec3;
use crate::mesh::TetMesh;
use std::collections::HashMap;
use std::path::Path;

/// Read an ASCII Gmsh MSH 4.x file (`$Nodes` and `$Elements` sections; other
/// sections are skipped). Only 4-node tetrahedra (element type 4) are kept;
/// lower-dimensional elements are ignored. Coordinates are taken as metres
/// (use [`crate::mesh::scaled`] for files in mm). Tets are re-oriented positive.
pub fn read_gmsh_v4(path: impl AsRef<Path>) -> Result<TetMesh, MeshError> {
    let path = path.as_ref();
    parse_gmsh_v4(&path.display().to_string(), &read_text(path)?)
}

/// Parse the text of an ASCII Gmsh MSH 4.x file; `file` labels errors.
pub fn parse_gmsh_v4(file: &str, text: &str) -> Result<TetMesh, MeshError> {
    let mut tk = Tokens::new(file, text, None);
    let mut tags: HashMap<usize, usize> = HashMap::new();
    let mut nodes: Vec<Vec3> = Vec::new();
    let mut raw_tets: Vec<([usize; 4], usize)> = Vec::new();
    let mut seen_format = false;
    while let Some((ln, t)) = tk.peek() {
        tk.pos += 1;
        match t {
            "$MeshFormat" => {
                read_format(&mut tk)?;
                seen_format = true;
            }
            "$Nodes" => read_nodes(&mut tk, ln, &mut tags, &mut nodes)?,
            "$Elements" => read_elements(&mut tk, ln, &mut raw_tets)?,
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
    let mut tets: Vec<([usize; 4], usize)> = Vec::new();
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

/// The body of `$MeshFormat`: version 4.x, ASCII.
fn read_format(tk: &mut Tokens) -> Result<(), MeshError> {
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
    Ok(())
}

/// The body of `$Nodes` (section header on line `ln`): node positions, and
/// each node's tag mapped to its index in `nodes`.
fn read_nodes(
    tk: &mut Tokens,
    ln: usize,
    tags: &mut HashMap<usize, usize>,
    nodes: &mut Vec<Vec3>,
) -> Result<(), MeshError> {
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
    Ok(())
}

/// Nodes per element of the Gmsh element types this reader can skip over
/// (or keep: type 4, the 4-node tetrahedron).
fn element_nodes(ty: usize) -> Option<usize> {
    Some(match ty {
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
        _ => return None,
    })
}

/// The body of `$Elements` (section header on line `ln`): the 4-node
/// tetrahedra as node tags, each with its line.
fn read_elements(tk: &mut Tokens, ln: usize, raw_tets: &mut Vec<([usize; 4], usize)>) -> Result<(), MeshError> {
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
        let nn = element_nodes(ty).ok_or_else(|| tk.err(tl, format!("element type {ty} is not supported")))?;
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
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::quality;

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
}
