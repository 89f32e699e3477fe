//! Needle-tip remeshing in material coordinates: the local operations of
//! the needle seed's Algorithm 2 (Chentanez et al. 2009, Sec. 3.4), chosen
//! by element quality, on an undo stack.
//!
//! For the tip's new material point `u`, the candidates are, in the tet `T`
//! that holds `u`:
//!
//! * **snap**: move the node of `T` nearest to `u` onto `u`;
//! * **edge split** (six), **face split** (four), **tet split** (one):
//!   a new node at `u`, and every tet that contains the split simplex `S`
//!   replaced by the tets that put `u` in place of one vertex of `S`;
//! * the same after taking back the operation on top of the stack (the
//!   seed's composite undo-then-apply: the tip node moves with the tip
//!   instead of leaving a node behind).
//!
//! Every candidate puts a mesh node exactly at `u`, so the coupling point
//! lies on the needle's path. Each is scored by its **quality vector**: the
//! quality `6 sqrt(2) V / l_rms^3` (1 for a regular tet, 0 for a flat one;
//! `V` the signed volume, `l_rms` the rms edge length) of every tet it
//! changes, sorted worst first; the lexicographically largest vector wins.
//!
//! Candidates are discarded when they
//!
//! * invert or flatten a tet (any changed quality `<= 0`);
//! * change the boundary: a changed boundary face must keep `u` in its
//!   plane, which an interior `u` never is; a `u` on the surface (the skin
//!   puncture) may split a boundary face or edge, or slide a boundary node
//!   within its flat surface;
//! * break the needle's connectivity: a node an operation on the stack put
//!   on the needle is never snapped away.
//!
//! A split preserves total volume: for any point `m`,
//! `V(a,b,c,d) = V(m,b,c,d) + V(a,m,c,d) + V(a,b,m,d) + V(a,b,c,m)`; the
//! terms that the split does not keep belong to faces around `S` and cancel
//! around a closed star, and on an open (boundary) star they vanish because
//! `m` is in the boundary face's plane. A snap keeps the star's outline, so
//! it keeps the volume too. The tests check both to round-off.
//!
//! Operations are recorded with everything they replaced, so taking one
//! back restores nodes, rest positions and element slots bit for bit:
//! withdrawing the needle completely gives back the mesh it started from.
//! Tets keep their slots where they can (an operation writes its first new
//! tets into the slots it frees and appends the rest), so the tissue
//! model's per-tet arrays change only where the mesh did.
//!
//! Units are SI (m).

use crate::coupling::barycentric;
use std::cmp::Ordering;
use std::fmt;
use surgbench_core::Vec3;
use surgbench_core::mesh::{TetMesh, tet_volume};

/// What an operation does to the tet that holds the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpKind {
    /// Move the nearest node of the tet onto the target.
    Snap,
    /// A new node at the target, splitting an edge's star.
    EdgeSplit,
    /// A new node at the target, splitting the one or two tets of a face.
    FaceSplit,
    /// A new node at the target, splitting the tet into four.
    TetSplit,
}

impl OpKind {
    /// Short lower-case name (diagnostics, reports).
    pub fn name(self) -> &'static str {
        match self {
            Self::Snap => "snap",
            Self::EdgeSplit => "edge",
            Self::FaceSplit => "face",
            Self::TetSplit => "tet",
        }
    }
}

/// Which candidates [`Remesher::place`] considers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// Only operations on the current mesh: the node on top of the stack
    /// stays where it is (a new coupling point behind the tip).
    New,
    /// Operations on the current mesh and, after taking back the top
    /// operation, on the mesh before it (the seed's choice).
    NewOrMove,
    /// Only after taking back the top operation: the top node follows the
    /// target (the tip while it retracts).
    Move,
}

/// Why a target could not be placed.
#[derive(Debug, Clone, PartialEq)]
pub enum RemeshError {
    /// No tet holds the target (m).
    Outside(Vec3),
    /// Every candidate inverts a tet, changes the boundary or moves a
    /// needle node.
    NoValidOperation(Vec3),
    /// [`Place::Move`] with nothing on the stack.
    NothingToMove,
}

impl fmt::Display for RemeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Outside(u) => write!(f, "no tet of the mesh holds the point ({}, {}, {}) m", u.x, u.y, u.z),
            Self::NoValidOperation(u) => write!(
                f,
                "no remeshing operation places a node at ({}, {}, {}) m without inverting a tet, changing the boundary or moving a needle node",
                u.x, u.y, u.z
            ),
            Self::NothingToMove => write!(f, "no operation on the stack to move"),
        }
    }
}

impl std::error::Error for RemeshError {}

/// One operation as applied: enough to apply it again or take it back
/// exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct Op {
    /// What it did.
    pub kind: OpKind,
    /// The node it put at the target: the snapped node or the new one.
    pub node: usize,
    /// The target (m, material coordinates).
    pub target: Vec3,
    /// Snap: the node's rest position before (m).
    moved_from: Option<Vec3>,
    /// Slots of the tets it replaced, with their nodes before.
    replaced: Vec<(usize, [usize; 4])>,
    /// The tets it writes: the first `replaced.len()` into the replaced
    /// slots, in order, the rest appended.
    written: Vec<[usize; 4]>,
}

impl Op {
    /// Slots of the tets this operation wrote, given the tet count before it.
    pub fn written_slots(&self, tets_before: usize) -> Vec<usize> {
        let reused = self.replaced.len().min(self.written.len());
        let mut s: Vec<usize> = self.replaced[..reused].iter().map(|r| r.0).collect();
        s.extend(tets_before..tets_before + self.written.len() - reused);
        s
    }
}

/// A scored candidate of [`Remesher::candidates`].
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// The operation (not applied yet).
    pub op: Op,
    /// Whether the top operation is taken back first (composite).
    pub moves_top: bool,
    /// Quality of every tet it changes, worst first.
    pub quality: Vec<f64>,
}

/// What [`Remesher::place`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placed {
    /// The node now at the target.
    pub node: usize,
    /// The operation applied.
    pub kind: OpKind,
    /// Whether the top operation was taken back first (the top node moved).
    pub moved_top: bool,
    /// The worst quality among the tets it changed.
    pub worst_quality: f64,
    /// How many tets it changed.
    pub changed_tets: usize,
}

/// Quality of the tet `p`: `6 sqrt(2) V / l_rms^3`, 1 for a regular tet,
/// negative when inverted.
pub fn tet_quality(p: &[Vec3; 4]) -> f64 {
    let v = tet_volume(&p[0], &p[1], &p[2], &p[3]);
    let l_rms = rms_edge(p);
    6.0 * std::f64::consts::SQRT_2 * v / (l_rms * l_rms * l_rms)
}

/// Root mean square of the six edge lengths of the tet `p` (m).
fn rms_edge(p: &[Vec3; 4]) -> f64 {
    let mut l2 = 0.0;
    for i in 0..4 {
        for j in i + 1..4 {
            l2 += (p[j] - p[i]).norm_squared();
        }
    }
    (l2 / 6.0).sqrt()
}

/// Lexicographic order of quality vectors sorted worst first: the first
/// differing entry decides; when one is a prefix of the other, the one
/// that changes fewer tets is better. `Greater` means `a` is better.
pub fn compare_quality(a: &[f64], b: &[f64]) -> Ordering {
    for (x, y) in a.iter().zip(b) {
        match x.total_cmp(y) {
            Ordering::Equal => continue,
            o => return o,
        }
    }
    b.len().cmp(&a.len())
}

/// A tet mesh in material coordinates that the needle tip remeshes (see
/// the module docs), with the undo stack of its operations.
#[derive(Debug, Clone)]
pub struct Remesher {
    nodes: Vec<Vec3>,
    tets: Vec<[usize; 4]>,
    /// Tets of each node, sorted by slot.
    node_tets: Vec<Vec<usize>>,
    /// Nodes an operation on the stack put on the needle.
    on_needle: Vec<bool>,
    /// Nodes the scene holds (fixed or driven): never snapped.
    pinned: Vec<bool>,
    stack: Vec<Op>,
    /// How far (in rms edge lengths of the tet holding the target) a snap
    /// may move a node, or an edge or face split put its node off the
    /// split simplex; infinite (the seed's rule) unless set.
    max_offset: f64,
}

/// Relative tolerance of "the target lies in a boundary face's plane",
/// in units of the face's rms edge length: round-off of a point computed
/// on the face, far below any geometric offset the mesh resolves.
const PLANE_TOL: f64 = 1e-9;

impl Remesher {
    /// Start from `mesh` (positively oriented tets, rest positions in m).
    pub fn new(mesh: &TetMesh) -> Self {
        let mut node_tets = vec![Vec::new(); mesh.nodes.len()];
        for (e, t) in mesh.tets.iter().enumerate() {
            for &i in t {
                node_tets[i].push(e);
            }
        }
        Self {
            nodes: mesh.nodes.clone(),
            tets: mesh.tets.clone(),
            node_tets,
            on_needle: vec![false; mesh.nodes.len()],
            pinned: vec![false; mesh.nodes.len()],
            stack: Vec::new(),
            max_offset: f64::INFINITY,
        }
    }

    /// Limit how far a snap moves a node, and how far an edge or face
    /// split puts its node off the split edge or face, to `fraction` of the
    /// rms edge length of the tet holding the target (a tet split is always
    /// a candidate). Either changes the finite element field around it (a
    /// split on its own simplex does not): the limit bounds that change.
    pub fn set_max_offset(&mut self, fraction: f64) {
        self.max_offset = fraction;
    }

    /// Never snap `nodes` (the scene's fixed and driven nodes: moving their
    /// rest position would move what holds the tissue).
    pub fn pin(&mut self, nodes: impl IntoIterator<Item = usize>) {
        for i in nodes {
            self.pinned[i] = true;
        }
    }

    /// Rest positions (m).
    pub fn nodes(&self) -> &[Vec3] {
        &self.nodes
    }

    /// Elements by slot.
    pub fn tets(&self) -> &[[usize; 4]] {
        &self.tets
    }

    /// The current mesh (a copy).
    pub fn mesh(&self) -> TetMesh {
        TetMesh {
            nodes: self.nodes.clone(),
            tets: self.tets.clone(),
        }
    }

    /// The operations applied, oldest first.
    pub fn stack(&self) -> &[Op] {
        &self.stack
    }

    /// The tets around `node`, by slot.
    pub fn tets_of(&self, node: usize) -> &[usize] {
        &self.node_tets[node]
    }

    /// Whether an operation on the stack put `node` on the needle.
    pub fn on_needle(&self, node: usize) -> bool {
        self.on_needle[node]
    }

    /// Tets that contain every node of `s`, by slot.
    fn star(&self, s: &[usize]) -> Vec<usize> {
        self.node_tets[s[0]]
            .iter()
            .copied()
            .filter(|&e| s[1..].iter().all(|i| self.tets[e].contains(i)))
            .collect()
    }

    /// The tet holding `u` and its barycentric weights: among the tets
    /// around `near` (and their neighbours) first, then all; on a shared
    /// face the tet whose smallest weight is largest, lowest slot on ties.
    pub fn locate(&self, u: &Vec3, near: Option<usize>) -> Option<(usize, [f64; 4])> {
        const SLACK: f64 = 1e-12;
        let score = |e: usize| {
            let p = self.tets[e].map(|i| self.nodes[i]);
            barycentric(p, u).map(|w| (w.iter().copied().fold(f64::INFINITY, f64::min), w))
        };
        let best_of = |it: &mut dyn Iterator<Item = usize>| {
            let mut best: Option<(f64, usize, [f64; 4])> = None;
            for e in it {
                if let Some((lo, w)) = score(e) {
                    let better = match best {
                        None => true,
                        Some((b, be, _)) => lo > b || (lo == b && e < be),
                    };
                    if lo >= -SLACK && better {
                        best = Some((lo, e, w));
                    }
                }
            }
            best
        };
        if let Some(n) = near.filter(|&n| n < self.nodes.len()) {
            let mut ring: Vec<usize> = self.node_tets[n]
                .iter()
                .flat_map(|&e| self.tets[e].iter().flat_map(|&i| self.node_tets[i].iter().copied()))
                .collect();
            ring.sort_unstable();
            ring.dedup();
            // Only a strictly interior hit is trusted from the ring: on a
            // shared face the best tet might lie outside it.
            if let Some((lo, e, w)) = best_of(&mut ring.into_iter())
                && lo > SLACK
            {
                return Some((e, w));
            }
        }
        best_of(&mut (0..self.tets.len())).map(|(_, e, w)| (e, w))
    }

    /// Position of node `i` if `op` were applied.
    fn pos_with(&self, op: &Op, i: usize) -> Vec3 {
        if i == op.node { op.target } else { self.nodes[i] }
    }

    /// The quality vector of `op` (worst first), or `None` if it inverts a
    /// tet or changes the boundary.
    fn score(&self, op: &Op, s: &[usize]) -> Option<Vec<f64>> {
        // Boundary: a face of a replaced tet that contains all of `s` is
        // split (or, for a snap, moved); if it is a boundary face the
        // target must stay in its plane.
        for &(_, t) in &op.replaced {
            for skip in 0..4 {
                let face: Vec<usize> = (0..4).filter(|&k| k != skip).map(|k| t[k]).collect();
                if !s.iter().all(|i| face.contains(i)) || self.star(&face).len() != 1 {
                    continue;
                }
                let [a, b, c] = [self.nodes[face[0]], self.nodes[face[1]], self.nodes[face[2]]];
                let n = (b - a).cross(&(c - a));
                let scale = ((b - a).norm_squared() + (c - b).norm_squared() + (a - c).norm_squared()) / 3.0;
                let dist = n.normalize().dot(&(op.target - a));
                if dist.abs() > PLANE_TOL * scale.sqrt() {
                    return None;
                }
            }
        }
        let mut q = Vec::with_capacity(op.written.len());
        for t in &op.written {
            let p = t.map(|i| self.pos_with(op, i));
            let qt = tet_quality(&p);
            if !(qt > 0.0) {
                return None;
            }
            q.push(qt);
        }
        q.sort_by(f64::total_cmp);
        Some(q)
    }

    /// The operation splitting the simplex `s` at `u` (a new node).
    fn split(&self, kind: OpKind, s: &[usize], u: Vec3) -> Op {
        let m = self.nodes.len();
        let star = self.star(s);
        let mut written = Vec::with_capacity(star.len() * s.len());
        for &e in &star {
            for &v in s {
                written.push(self.tets[e].map(|i| if i == v { m } else { i }));
            }
        }
        Op {
            kind,
            node: m,
            target: u,
            moved_from: None,
            replaced: star.iter().map(|&e| (e, self.tets[e])).collect(),
            written,
        }
    }

    /// Every valid candidate for `u` on the current mesh, scored, in a fixed
    /// order: snap, the six edges, the four faces, the tet.
    fn candidates_here(&self, u: Vec3, near: Option<usize>) -> Result<Vec<(Op, Vec<f64>)>, RemeshError> {
        let (e, _) = self.locate(&u, near).ok_or(RemeshError::Outside(u))?;
        let t = self.tets[e];
        let mut out = Vec::new();
        let nearest = *t
            .iter()
            .min_by(|&&a, &&b| {
                (self.nodes[a] - u)
                    .norm_squared()
                    .total_cmp(&(self.nodes[b] - u).norm_squared())
            })
            .expect("a tet has four nodes");
        let reach = self.max_offset * rms_edge(&t.map(|i| self.nodes[i]));
        if !self.on_needle[nearest]
            && !self.pinned.get(nearest).copied().unwrap_or(false)
            && (self.nodes[nearest] - u).norm() <= reach
        {
            let star = self.node_tets[nearest].clone();
            let op = Op {
                kind: OpKind::Snap,
                node: nearest,
                target: u,
                moved_from: Some(self.nodes[nearest]),
                replaced: star.iter().map(|&e| (e, self.tets[e])).collect(),
                written: star.iter().map(|&e| self.tets[e]).collect(),
            };
            if let Some(q) = self.score(&op, &[nearest]) {
                out.push((op, q));
            }
        }
        const EDGES: [[usize; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];
        const FACES: [[usize; 3]; 4] = [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]];
        for s in EDGES {
            let (a, b) = (self.nodes[t[s[0]]], self.nodes[t[s[1]]]);
            let e = (b - a).normalize();
            let off = (u - a) - e * e.dot(&(u - a));
            if off.norm() > reach {
                continue;
            }
            let s = s.map(|k| t[k]);
            let op = self.split(OpKind::EdgeSplit, &s, u);
            if let Some(q) = self.score(&op, &s) {
                out.push((op, q));
            }
        }
        for s in FACES {
            let [a, b, c] = s.map(|k| self.nodes[t[k]]);
            if (b - a).cross(&(c - a)).normalize().dot(&(u - a)).abs() > reach {
                continue;
            }
            let s = s.map(|k| t[k]);
            let op = self.split(OpKind::FaceSplit, &s, u);
            if let Some(q) = self.score(&op, &s) {
                out.push((op, q));
            }
        }
        let op = self.split(OpKind::TetSplit, &t, u);
        if let Some(q) = self.score(&op, &t) {
            out.push((op, q));
        }
        Ok(out)
    }

    /// Every valid candidate for placing a node at `u` (m, material
    /// coordinates) that `mode` allows, each with its quality vector, in
    /// the order [`Remesher::place`] breaks ties by (current mesh first).
    pub fn candidates(&mut self, u: Vec3, mode: Place) -> Result<Vec<Candidate>, RemeshError> {
        let near = self.stack.last().map(|o| o.node);
        let mut out = Vec::new();
        let mut outside = None;
        if mode != Place::Move {
            match self.candidates_here(u, near) {
                Ok(c) => out.extend(c.into_iter().map(|(op, quality)| Candidate {
                    op,
                    moves_top: false,
                    quality,
                })),
                Err(e) => outside = Some(e),
            }
        }
        if mode != Place::New {
            match self.stack.pop() {
                None if mode == Place::Move => return Err(RemeshError::NothingToMove),
                None => {}
                Some(top) => {
                    self.revert(&top);
                    // The tets the top operation restores count as changed
                    // too, unless the new operation replaces them again.
                    let hint = top.replaced.first().map(|r| r.1[0]);
                    let found = self.candidates_here(u, hint);
                    if let Ok(c) = &found {
                        for (op, mut q) in c.iter().cloned() {
                            for &(slot, t) in &top.replaced {
                                if !op.replaced.iter().any(|r| r.0 == slot) {
                                    q.push(tet_quality(&t.map(|i| self.nodes[i])));
                                }
                            }
                            q.sort_by(f64::total_cmp);
                            out.push(Candidate {
                                op,
                                moves_top: true,
                                quality: q,
                            });
                        }
                    }
                    self.apply(&top);
                    self.stack.push(top);
                    if let (Err(e), true) = (found, mode == Place::Move) {
                        return Err(e);
                    }
                }
            }
        }
        if out.is_empty()
            && let Some(e) = outside
        {
            return Err(e);
        }
        Ok(out)
    }

    /// Put a mesh node at `u` (m, material coordinates) by the best valid
    /// candidate (the lexicographically largest quality vector; earlier
    /// candidate on exact ties) and push it on the stack.
    pub fn place(&mut self, u: Vec3, mode: Place) -> Result<Placed, RemeshError> {
        let cands = self.candidates(u, mode)?;
        let best = cands
            .into_iter()
            .reduce(|a, b| {
                if compare_quality(&b.quality, &a.quality) == Ordering::Greater {
                    b
                } else {
                    a
                }
            })
            .ok_or(RemeshError::NoValidOperation(u))?;
        Ok(self.apply_candidate(best))
    }

    /// Apply a candidate of [`Remesher::candidates`] (taken on the mesh as
    /// it is now) and push it on the stack.
    pub fn apply_candidate(&mut self, c: Candidate) -> Placed {
        if c.moves_top {
            let top = self.stack.pop().expect("a candidate that moves the top has a top");
            self.revert(&top);
        }
        self.apply(&c.op);
        let placed = Placed {
            node: c.op.node,
            kind: c.op.kind,
            moved_top: c.moves_top,
            worst_quality: c.quality.first().copied().unwrap_or(f64::NAN),
            changed_tets: c.quality.len(),
        };
        self.stack.push(c.op);
        placed
    }

    /// Take back the operation on top of the stack; `None` if it is empty.
    pub fn pop(&mut self) -> Option<Op> {
        let op = self.stack.pop()?;
        self.revert(&op);
        Some(op)
    }

    fn detach(&mut self, slot: usize) {
        for i in self.tets[slot] {
            let list = &mut self.node_tets[i];
            if let Ok(k) = list.binary_search(&slot) {
                list.remove(k);
            }
        }
    }

    fn attach(&mut self, slot: usize) {
        for i in self.tets[slot] {
            let list = &mut self.node_tets[i];
            if let Err(k) = list.binary_search(&slot) {
                list.insert(k, slot);
            }
        }
    }

    fn apply(&mut self, op: &Op) {
        match op.moved_from {
            Some(_) => self.nodes[op.node] = op.target,
            None => {
                debug_assert_eq!(op.node, self.nodes.len());
                self.nodes.push(op.target);
                self.node_tets.push(Vec::new());
                self.on_needle.push(false);
            }
        }
        self.on_needle[op.node] = true;
        for &(slot, _) in &op.replaced {
            self.detach(slot);
        }
        for (k, t) in op.written.iter().enumerate() {
            let slot = match op.replaced.get(k) {
                Some(&(slot, _)) => slot,
                None => {
                    self.tets.push(*t);
                    self.tets.len() - 1
                }
            };
            self.tets[slot] = *t;
            self.attach(slot);
        }
    }

    fn revert(&mut self, op: &Op) {
        let reused = op.replaced.len().min(op.written.len());
        for _ in reused..op.written.len() {
            let slot = self.tets.len() - 1;
            self.detach(slot);
            self.tets.pop();
        }
        for &(slot, old) in op.replaced[..reused].iter() {
            self.detach(slot);
            self.tets[slot] = old;
            self.attach(slot);
        }
        match op.moved_from {
            Some(old) => {
                self.nodes[op.node] = old;
                self.on_needle[op.node] = false;
            }
            None => {
                debug_assert_eq!(op.node + 1, self.nodes.len());
                debug_assert!(self.node_tets[op.node].is_empty());
                self.nodes.pop();
                self.node_tets.pop();
                self.on_needle.pop();
            }
        }
    }
}

/// Nodal fields carried from a mesh to its remeshed successor: a node
/// of `new_rest` that the old mesh had at the same index and rest position
/// (bit for bit) keeps its values; a new or moved one gets the linear
/// interpolation, in the old rest tet that holds its rest position, of the
/// old values (the finite element's own field, so a split leaves the
/// deformation, and with it the elastic energy, unchanged). `fields`: one
/// slice per field over the old nodes. Fails if a rest position lies
/// outside the old mesh.
pub fn carry_over(
    old_rest: &[Vec3],
    old_tets: &[[usize; 4]],
    new_rest: &[Vec3],
    fields: &[&[Vec3]],
) -> Result<Vec<Vec<Vec3>>, RemeshError> {
    let mut out: Vec<Vec<Vec3>> = fields.iter().map(|_| Vec::with_capacity(new_rest.len())).collect();
    for (i, p) in new_rest.iter().enumerate() {
        if old_rest.get(i) == Some(p) {
            for (o, f) in out.iter_mut().zip(fields) {
                o.push(f[i]);
            }
            continue;
        }
        let at = crate::coupling::locate(old_tets, old_rest, p).ok_or(RemeshError::Outside(*p))?;
        let t = old_tets[at.tet];
        for (o, f) in out.iter_mut().zip(fields) {
            o.push((0..4).map(|k| f[t[k]] * at.w[k]).sum());
        }
    }
    Ok(out)
}

/// What [`Channel::tip_to`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ChannelStep {
    /// The operation that put the tip node at the tip, if one was needed.
    pub placed: Option<Placed>,
    /// Operations taken back (the tip retracted past coupling nodes).
    pub popped: usize,
}

/// The coupling nodes along a needle's channel, driven by the tip: the
/// bookkeeping around Algorithm 2 that the needle model does each step.
///
/// With `s` the spacing (the needle's edge length), the nodes for a tip
/// `a` past the puncture (`m s < a <= (m + 1) s`) are the **shaft nodes**
/// at `0, s, ..., (m - 1) s` (the puncture on the skin first) and, once
/// `a > s`, a **tip node** at `a`. So the tip node is always between `s`
/// and `2 s` ahead of the last shaft node: a node placed right next to a
/// node already on the needle would make slivers that no operation
/// avoids. While `a <= s` the puncture node is the channel's end.
///
/// Each step, what no longer matches the tip is taken back (the tip node,
/// and shaft nodes past the tip when it retracts); the tip node moves with
/// the tip by [`Place::Move`] (its operation taken back and the best one
/// for the new point applied, the seed's composite undo-then-apply) and
/// new nodes come by [`Place::New`]. Out of the tissue every operation is
/// taken back, and the mesh is the one it started as.
#[derive(Debug, Clone)]
pub struct Channel {
    remesher: Remesher,
    /// Coupling nodes, one per stack entry: arclength past the puncture (m)
    /// and node; the last is the tip node when `tip` is set.
    points: Vec<(f64, usize)>,
    tip: bool,
    /// Arclength between shaft nodes (m).
    spacing: f64,
}

impl Channel {
    /// A channel not yet cut in `mesh`, with shaft nodes every `spacing` (m).
    pub fn new(mesh: &TetMesh, spacing: f64) -> Self {
        Self {
            remesher: Remesher::new(mesh),
            points: Vec::new(),
            tip: false,
            spacing,
        }
    }

    /// The remeshed tissue.
    pub fn remesher(&self) -> &Remesher {
        &self.remesher
    }

    /// The coupling nodes from the puncture to the tip: arclength past the
    /// puncture (m) and node.
    pub fn points(&self) -> &[(f64, usize)] {
        &self.points
    }

    /// Move the tip to arclength `a` (m past the puncture) of the needle's
    /// path in material coordinates, `path(a)`, `path(0)` on the skin.
    pub fn tip_to(&mut self, a: f64, path: impl Fn(f64) -> Vec3) -> Result<ChannelStep, RemeshError> {
        let mut step = ChannelStep::default();
        let s = self.spacing;
        let (want_shaft, want_tip) = if a <= 0.0 {
            (0, false)
        } else {
            let m = ((a / s).ceil() as usize).saturating_sub(1);
            (m.max(1), m >= 1)
        };
        let shaft = self.points.len() - usize::from(self.tip);
        if self.tip && want_tip && shaft == want_shaft {
            let p = self.remesher.place(path(a), Place::Move)?;
            *self.points.last_mut().expect("a tip node") = (a, p.node);
            step.placed = Some(p);
            return Ok(step);
        }
        let keep = want_shaft.min(shaft);
        while self.points.len() > keep {
            self.remesher.pop();
            self.points.pop();
            step.popped += 1;
        }
        self.tip = false;
        while self.points.len() < want_shaft {
            let ak = self.points.len() as f64 * s;
            let p = self.remesher.place(path(ak), Place::New)?;
            self.points.push((ak, p.node));
            step.placed = Some(p);
        }
        if want_tip {
            let p = self.remesher.place(path(a), Place::New)?;
            self.points.push((a, p.node));
            self.tip = true;
            step.placed = Some(p);
        }
        Ok(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quality_is_one_for_a_regular_tet_and_signed() {
        let p = [
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
        ];
        let q = tet_quality(&p);
        // A regular tet: 1 up to the rounding of sqrt(2) and one division.
        assert!((q.abs() - 1.0).abs() < 1e-14, "{q}");
        let flipped = [p[0], p[1], p[3], p[2]];
        assert_eq!(tet_quality(&flipped), -q);
    }

    #[test]
    fn the_worst_tet_decides_then_the_next() {
        // The second vector's worst tet is better: it wins although its
        // other tets are worse.
        assert_eq!(compare_quality(&[0.1, 0.9], &[0.2, 0.3]), Ordering::Less);
        // Equal worst: the next entry decides.
        assert_eq!(compare_quality(&[0.2, 0.5, 0.6], &[0.2, 0.4, 0.9]), Ordering::Greater);
        // A prefix: fewer changed tets is better.
        assert_eq!(compare_quality(&[0.2, 0.5], &[0.2, 0.5, 0.6]), Ordering::Greater);
        assert_eq!(compare_quality(&[0.3], &[0.3]), Ordering::Equal);
    }
}
