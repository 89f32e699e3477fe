//! Geometry from a user's file (`run-one --mesh FILE`): a tetrahedral tissue
//! mesh (Gmsh MSH 4.x `.msh`, Medit `.mesh`) or a closed vessel surface
//! (STL `.stl`, binary or ASCII; Wavefront `.obj`), read by the core readers
//! and handed to the scenarios that declare they take one
//! ([`crate::scenario::ScenarioInfo::mesh`]). Units: the file's numbers times
//! `scale` are metres.

use crate::scenario::UsageError;
use std::path::{Path, PathBuf};
use surgbench_core::TetMesh;
use surgbench_core::io::{self, TriSurface};

/// What kind of geometry a scenario takes from a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshKind {
    /// A tetrahedral tissue mesh (`.msh`, `.mesh`).
    Tets,
    /// A closed triangle surface bounding a vessel lumen (`.stl`, `.obj`).
    Surface,
}

impl MeshKind {
    /// What a person is told the scenario takes.
    pub fn describe(self) -> &'static str {
        match self {
            MeshKind::Tets => "a tetrahedral mesh (.msh Gmsh 4.x, .mesh Medit)",
            MeshKind::Surface => "a closed vessel surface (.stl, .obj)",
        }
    }
}

/// The geometry read from a file.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// Tetrahedra (m), positively oriented by the reader.
    Tets(TetMesh),
    /// A closed, outward-oriented surface (m).
    Surface(TriSurface),
}

/// A mesh loaded from a user's file: the path as given and its geometry.
#[derive(Debug, Clone, PartialEq)]
pub struct UserMesh {
    /// The file as the user named it (shown in messages and `summary.json`).
    pub path: PathBuf,
    /// The factor applied to the file's coordinates to give metres.
    pub scale: f64,
    /// What was read.
    pub geometry: Geometry,
}

impl UserMesh {
    /// Read `path` by its extension, coordinates times `scale` (1 for a file
    /// in metres, 1e-3 for millimetres). Any problem (missing file, unknown
    /// extension, a parse error with its line, an open or inside-out
    /// surface, a degenerate tet) is a [`UsageError`] naming the file.
    pub fn load(path: &Path, scale: f64) -> Result<Self, UsageError> {
        if !(scale > 0.0 && scale.is_finite()) {
            return Err(UsageError(format!("--mesh-scale must be a number > 0, got {scale}")));
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let bad = |e: &dyn std::fmt::Display| UsageError(format!("--mesh: {e}"));
        let geometry = match ext.as_str() {
            "msh" => Geometry::Tets(scaled(io::read_gmsh_v4(path).map_err(|e| bad(&e))?, scale)),
            "mesh" => Geometry::Tets(scaled(io::read_medit(path).map_err(|e| bad(&e))?, scale)),
            "stl" | "obj" => Geometry::Surface(io::load_mesh(path, scale).map_err(|e| bad(&e))?),
            other => {
                return Err(UsageError(format!(
                    "--mesh {}: unknown extension `{other}`; surgbench reads .msh (Gmsh 4.x) and .mesh (Medit) tetrahedra, .stl and .obj surfaces",
                    path.display()
                )));
            }
        };
        Ok(Self {
            path: path.to_path_buf(),
            scale,
            geometry,
        })
    }

    /// The kind of geometry read.
    pub fn kind(&self) -> MeshKind {
        match self.geometry {
            Geometry::Tets(_) => MeshKind::Tets,
            Geometry::Surface(_) => MeshKind::Surface,
        }
    }

    /// The tetrahedra, if this is a tet mesh.
    pub fn tets(&self) -> Option<&TetMesh> {
        match &self.geometry {
            Geometry::Tets(m) => Some(m),
            Geometry::Surface(_) => None,
        }
    }

    /// The surface, if this is a surface mesh.
    pub fn surface(&self) -> Option<&TriSurface> {
        match &self.geometry {
            Geometry::Surface(s) => Some(s),
            Geometry::Tets(_) => None,
        }
    }

    /// A one-line description: file, kind and size.
    pub fn describe(&self) -> String {
        match &self.geometry {
            Geometry::Tets(m) => format!(
                "{} ({} nodes, {} tets)",
                self.path.display(),
                m.nodes.len(),
                m.tets.len()
            ),
            Geometry::Surface(s) => format!(
                "{} ({} vertices, {} triangles)",
                self.path.display(),
                s.vertices.len(),
                s.triangles.len()
            ),
        }
    }
}

fn scaled(m: TetMesh, scale: f64) -> TetMesh {
    if scale == 1.0 {
        m
    } else {
        surgbench_core::mesh::scaled(&m, scale)
    }
}

/// Checks that `scenario` (which takes `takes`, if anything) can use `mesh`.
pub fn check_kind(scenario: &str, takes: Option<MeshKind>, mesh: &UserMesh) -> Result<(), UsageError> {
    match takes {
        None => Err(UsageError(format!(
            "scenario `{scenario}` builds its own geometry and takes no --mesh (`surgbench list` marks the scenarios that do)"
        ))),
        Some(k) if k != mesh.kind() => Err(UsageError(format!(
            "scenario `{scenario}` takes {}, but {} is {}",
            k.describe(),
            mesh.path.display(),
            mesh.kind().describe()
        ))),
        Some(_) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The extension picks the reader; an unknown one, a missing file and a
    /// bad scale are usage errors naming what is wrong.
    #[test]
    fn loads_by_extension_and_names_errors() {
        let dir = tempfile::tempdir().unwrap();
        let medit = dir.path().join("t.mesh");
        std::fs::write(
            &medit,
            "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\nTetrahedra\n1\n1 2 3 4 0\nEnd\n",
        )
        .unwrap();
        let m = UserMesh::load(&medit, 1e-3).unwrap();
        assert_eq!(m.kind(), MeshKind::Tets);
        // Scaled to metres: the unit tet in millimetres.
        assert_eq!(m.tets().unwrap().nodes[1].x, 1e-3);
        let e = UserMesh::load(&dir.path().join("t.vtk"), 1.0).unwrap_err();
        assert!(e.0.contains("unknown extension `vtk`"), "{e}");
        let e = UserMesh::load(&dir.path().join("missing.stl"), 1.0).unwrap_err();
        assert!(e.0.contains("missing.stl"), "{e}");
        let e = UserMesh::load(&medit, 0.0).unwrap_err();
        assert!(e.0.contains("--mesh-scale"), "{e}");
        assert!(check_kind("x", Some(MeshKind::Surface), &m).is_err());
        assert!(check_kind("x", None, &m).is_err());
        assert!(check_kind("x", Some(MeshKind::Tets), &m).is_ok());
    }
}
