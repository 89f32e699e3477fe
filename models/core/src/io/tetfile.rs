//! What the tetrahedral-mesh readers ([`super::gmsh`], [`super::medit`])
//! share: the error type, a line-numbered tokenizer and the final checks
//! (no degenerate tet, positive orientation).

use crate::Vec3;
use crate::mesh::{TetMesh, orient_positive, tet_volume};
use std::fmt;
use std::path::Path;

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
pub(crate) struct Tokens<'a> {
    file: &'a str,
    toks: Vec<(usize, &'a str)>,
    pub(crate) pos: usize,
    last_line: usize,
}

impl<'a> Tokens<'a> {
    pub(crate) fn new(file: &'a str, text: &'a str, comment: Option<char>) -> Self {
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
    pub(crate) fn err(&self, line: usize, what: impl Into<String>) -> MeshError {
        MeshError {
            file: self.file.to_string(),
            line,
            what: what.into(),
        }
    }
    pub(crate) fn next(&mut self, expecting: &str) -> Result<(usize, &'a str), MeshError> {
        let t = self
            .toks
            .get(self.pos)
            .copied()
            .ok_or_else(|| self.err(self.last_line, format!("unexpected end of file, expecting {expecting}")))?;
        self.pos += 1;
        Ok(t)
    }
    pub(crate) fn peek(&self) -> Option<(usize, &'a str)> {
        self.toks.get(self.pos).copied()
    }
    pub(crate) fn usize(&mut self, what: &str) -> Result<usize, MeshError> {
        let (ln, t) = self.next(what)?;
        t.parse()
            .map_err(|_| self.err(ln, format!("expected {what} (non-negative integer), found `{t}`")))
    }
    pub(crate) fn f64(&mut self, what: &str) -> Result<f64, MeshError> {
        let (ln, t) = self.next(what)?;
        match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(ln, format!("expected {what} (finite number), found `{t}`"))),
        }
    }
    pub(crate) fn expect(&mut self, word: &str) -> Result<usize, MeshError> {
        let (ln, t) = self.next(word)?;
        if t.eq_ignore_ascii_case(word) {
            Ok(ln)
        } else {
            Err(self.err(ln, format!("expected `{word}`, found `{t}`")))
        }
    }
}

pub(crate) fn read_text(path: &Path) -> Result<String, MeshError> {
    std::fs::read_to_string(path).map_err(|e| MeshError {
        file: path.display().to_string(),
        line: 0,
        what: format!("cannot read: {e}"),
    })
}

pub(crate) fn finish_mesh(file: &str, nodes: Vec<Vec3>, tets: Vec<([usize; 4], usize)>) -> Result<TetMesh, MeshError> {
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
