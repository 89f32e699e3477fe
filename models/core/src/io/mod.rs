//! File formats: tetrahedral meshes (Gmsh MSH 4.x [`read_gmsh_v4`], Medit
//! [`read_medit`]), triangle surfaces (STL binary and ASCII, OBJ:
//! [`load_mesh`] into a [`TriSurface`]) and CSV tables ([`table`], [`truth_cube`]).
//!
//! Every reader names the file, the place (line, byte, triangle) and what is
//! wrong in its error. Coordinates are read as metres unless a scale is given.
//!
//! ```
//! use surgbench_core::io;
//! let text = "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\nTetrahedra\n1\n1 2 3 4 0\nEnd\n";
//! let m = io::parse_medit("t.mesh", text).unwrap();
//! assert_eq!((m.nodes.len(), m.tets.len()), (4, 1));
//! ```

pub mod gmsh;
pub mod medit;
pub mod obj;
pub mod stl;
pub mod surface;
pub mod table;
pub mod tetfile;
pub mod truth_cube;

pub use gmsh::{parse_gmsh_v4, read_gmsh_v4};
pub use medit::{parse_medit, read_medit};
pub use obj::parse_obj;
pub use stl::parse_stl;
pub use surface::{SurfaceError, TriSurface, load_mesh};
pub use tetfile::MeshError;
