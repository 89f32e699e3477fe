//! Two-level colouring of the tissue constraints, for a parallel Gauss-Seidel
//! solve whose result does not depend on the thread count.
//!
//! **Blocks (the parallel level).** Nodes get a breadth-first level from a
//! pseudo-peripheral node (the last node reached by a BFS from the lowest
//! unvisited node; each connected component is numbered after the previous
//! one), as in the Cuthill-McKee ordering. Every node of an edge or a tet is
//! joined to every other by a mesh edge, so a constraint whose lowest node
//! level is `L` touches levels `L` and `L + 1` only. Cutting the levels into
//! consecutive blocks of about equal constraint count and giving block `b`
//! colour `b mod 2`, two blocks of one colour never share a node: block `b`
//! touches levels up to `e_b + 1` and block `b + 2` starts at
//! `e_{b+1} + 1 >= e_b + 2`. The blocks of one colour can therefore be
//! projected concurrently, each in its own fixed order, and the result is the
//! same as projecting them one after the other in any order: bit-identical for
//! any thread count. The levels are topological, so a rigidly moved scene gets
//! the same partition.
//!
//! **Constraint colours (the order inside a block).** Within each kind (edges,
//! tets) constraints are greedily coloured in id order so that no two of one
//! colour share a node (at most 64 colours; further ones share the last
//! colour, which only costs overlap). Inside a block the constraints are
//! projected colour by colour: consecutive projections are independent, so
//! the processor overlaps them instead of waiting on the previous one's
//! result (the serial Gauss-Seidel sweep is latency-bound).
//!
//! The solve is therefore a colour-ordered Gauss-Seidel: per iteration, the
//! blocks of colour 0, then those of colour 1; in each block its edges by
//! colour, then its tets by colour.

use std::collections::VecDeque;

/// Number of level blocks aimed for (fewer on small meshes). A constant, so
/// the ordering, hence every number, does not depend on the thread count;
/// 16 blocks give 8 per colour, enough to balance 2 threads.
pub const TARGET_BLOCKS: usize = 16;

/// Storage order of the constraints and the blocks they form.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Partition {
    /// `edge_perm[new] = old` edge id.
    pub edge_perm: Vec<u32>,
    /// `tet_perm[new] = old` tet id.
    pub tet_perm: Vec<u32>,
    /// Edges of storage block `s`: `edge_start[s]..edge_start[s + 1]` (new ids).
    pub edge_start: Vec<usize>,
    /// Tets of storage block `s`: `tet_start[s]..tet_start[s + 1]` (new ids).
    pub tet_start: Vec<usize>,
    /// Storage blocks of colour `c`: `color_start[c]..color_start[c + 1]`.
    pub color_start: [usize; 3],
}

impl Partition {
    /// Number of blocks.
    pub fn blocks(&self) -> usize {
        self.edge_start.len() - 1
    }
}

/// BFS levels of the graph given by `edges` on `nn` nodes (see the module
/// docs); isolated nodes get a level of their own.
pub fn node_levels(nn: usize, edges: &[[u32; 2]]) -> Vec<u32> {
    // Compressed adjacency, neighbours in edge order (deterministic).
    let mut deg = vec![0usize; nn + 1];
    for e in edges {
        deg[e[0] as usize + 1] += 1;
        deg[e[1] as usize + 1] += 1;
    }
    for i in 0..nn {
        deg[i + 1] += deg[i];
    }
    let mut fill = deg.clone();
    let mut adj = vec![0u32; deg[nn]];
    for e in edges {
        for (a, b) in [(e[0], e[1]), (e[1], e[0])] {
            adj[fill[a as usize]] = b;
            fill[a as usize] += 1;
        }
    }
    let mut level = vec![u32::MAX; nn];
    let mut scratch = vec![u32::MAX; nn];
    let mut queue = VecDeque::new();
    // BFS from `s` over unvisited (in `lv`) nodes; returns the last node reached.
    let bfs = |s: usize, lv: &mut [u32], base: u32, queue: &mut VecDeque<usize>| -> (usize, u32) {
        lv[s] = base;
        queue.clear();
        queue.push_back(s);
        let mut last = (s, base);
        while let Some(i) = queue.pop_front() {
            last = (i, lv[i]);
            for &j in &adj[deg[i]..deg[i + 1]] {
                let j = j as usize;
                if lv[j] == u32::MAX {
                    lv[j] = lv[i] + 1;
                    queue.push_back(j);
                }
            }
        }
        last
    };
    let mut next_level = 0u32;
    for s in 0..nn {
        if level[s] != u32::MAX {
            continue;
        }
        // Pseudo-peripheral start: the farthest node from `s` (scratch BFS).
        let (far, _) = bfs(s, &mut scratch, 0, &mut queue);
        let (_, top) = bfs(far, &mut level, next_level, &mut queue);
        next_level = top + 1;
    }
    level
}

/// Greedy colours of constraints given by their node lists, in id order: the
/// lowest colour (0..=63) not used by a constraint sharing a node; 63 when
/// all are taken (ordering only, see the module docs).
pub fn greedy_colors<const K: usize>(nn: usize, cons: &[[u32; K]]) -> Vec<u8> {
    let mut used = vec![0u64; nn];
    cons.iter()
        .map(|c| {
            let taken = c.iter().fold(0u64, |m, &i| m | used[i as usize]);
            let col = (!taken).trailing_zeros().min(63);
            for &i in c {
                used[i as usize] |= 1u64 << col;
            }
            col as u8
        })
        .collect()
}

/// Partition edges and tets into level blocks and order them (see the module
/// docs).
pub fn partition(nn: usize, edges: &[[u32; 2]], tets: &[[u32; 4]]) -> Partition {
    let level = node_levels(nn, edges);
    let lmin = |c: &[u32]| c.iter().map(|&i| level[i as usize]).min().unwrap_or(0) as usize;
    let e_lv: Vec<usize> = edges.iter().map(|e| lmin(e)).collect();
    let t_lv: Vec<usize> = tets.iter().map(|t| lmin(t)).collect();
    let nl = e_lv.iter().chain(&t_lv).max().map_or(1, |m| m + 1);
    let mut count = vec![0usize; nl];
    for &l in e_lv.iter().chain(&t_lv) {
        count[l] += 1;
    }
    let total: usize = count.iter().sum::<usize>().max(1);
    // Raw block of each level by the constraints before it, then compacted
    // so that used blocks are consecutive (skipped ids would break colouring).
    let mut raw = vec![0usize; nl];
    let mut before = 0usize;
    for l in 0..nl {
        raw[l] = (before * TARGET_BLOCKS / total).min(TARGET_BLOCKS - 1);
        before += count[l];
    }
    let mut block_of_level = vec![0usize; nl];
    let mut nb = 0usize;
    for l in 0..nl {
        if l > 0 && raw[l] != raw[l - 1] {
            nb += 1;
        }
        block_of_level[l] = nb;
    }
    let nb = nb + 1;
    // Storage order: blocks of colour 0 (even), then colour 1 (odd).
    let n_even = nb.div_ceil(2);
    let store = |b: usize| if b.is_multiple_of(2) { b / 2 } else { n_even + b / 2 };
    let e_col = greedy_colors(nn, edges);
    let t_col = greedy_colors(nn, tets);
    let order = |lv: &[usize], col: &[u8]| -> (Vec<u32>, Vec<usize>) {
        let mut ids: Vec<u32> = (0..lv.len() as u32).collect();
        ids.sort_by_key(|&i| (store(block_of_level[lv[i as usize]]), col[i as usize], i));
        let mut start = vec![0usize; nb + 1];
        for &i in &ids {
            start[store(block_of_level[lv[i as usize]]) + 1] += 1;
        }
        for s in 0..nb {
            start[s + 1] += start[s];
        }
        (ids, start)
    };
    let (edge_perm, edge_start) = order(&e_lv, &e_col);
    let (tet_perm, tet_start) = order(&t_lv, &t_col);
    Partition {
        edge_perm,
        tet_perm,
        edge_start,
        tet_start,
        color_start: [0, n_even, nb],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use surgbench_core::Vec3;
    use surgbench_core::mesh;

    fn mesh_constraints(cells: [usize; 3]) -> (usize, Vec<[u32; 2]>, Vec<[u32; 4]>) {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), cells);
        let tets: Vec<[u32; 4]> = m.tets.iter().map(|t| t.map(|i| i as u32)).collect();
        let mut edges: Vec<[u32; 2]> = tets
            .iter()
            .flat_map(|t| {
                [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)].map(|(a, b)| [t[a].min(t[b]), t[a].max(t[b])])
            })
            .collect();
        edges.sort();
        edges.dedup();
        (m.nodes.len(), edges, tets)
    }

    #[test]
    fn blocks_of_one_colour_share_no_node_and_colours_are_proper() {
        for cells in [[8, 8, 50], [3, 3, 3], [1, 1, 4], [5, 2, 9]] {
            let (nn, edges, tets) = mesh_constraints(cells);
            let p = partition(nn, &edges, &tets);
            // Permutations are permutations.
            let mut e = p.edge_perm.clone();
            e.sort();
            assert!(
                e.iter().enumerate().all(|(i, &v)| i as u32 == v),
                "edge perm, cells {cells:?}"
            );
            let mut t = p.tet_perm.clone();
            t.sort();
            assert!(
                t.iter().enumerate().all(|(i, &v)| i as u32 == v),
                "tet perm, cells {cells:?}"
            );
            // Blocks of one colour touch disjoint node sets.
            for c in 0..2 {
                let mut owner = vec![usize::MAX; nn];
                for s in p.color_start[c]..p.color_start[c + 1] {
                    let nodes = p.edge_perm[p.edge_start[s]..p.edge_start[s + 1]]
                        .iter()
                        .flat_map(|&k| edges[k as usize].to_vec())
                        .chain(
                            p.tet_perm[p.tet_start[s]..p.tet_start[s + 1]]
                                .iter()
                                .flat_map(|&k| tets[k as usize].to_vec()),
                        );
                    for i in nodes {
                        let o = &mut owner[i as usize];
                        assert!(
                            *o == usize::MAX || *o == s,
                            "cells {cells:?}: node {i} in blocks {o} and {s} of colour {c}"
                        );
                        *o = s;
                    }
                }
            }
            // Greedy colours are proper below the 64-colour cap: the
            // constraints of one colour touch disjoint nodes.
            fn proper<const K: usize>(nn: usize, cons: &[[u32; K]], cells: [usize; 3]) -> u8 {
                let col = greedy_colors(nn, cons);
                let top = *col.iter().max().unwrap();
                for c in 0..top.min(62) + 1 {
                    let mut seen = vec![false; nn];
                    for (k, con) in cons.iter().enumerate().filter(|(k, _)| col[*k] == c) {
                        for &i in con {
                            assert!(
                                !seen[i as usize],
                                "cells {cells:?}: constraint {k} reuses node {i} in colour {c}"
                            );
                            seen[i as usize] = true;
                        }
                    }
                }
                top
            }
            let ce = proper(nn, &edges, cells);
            let ct = proper(nn, &tets, cells);
            println!(
                "cells {cells:?}: {} blocks, {} edge colours, {} tet colours",
                p.blocks(),
                ce + 1,
                ct + 1
            );
            if cells == [8, 8, 50] {
                assert!(p.blocks() >= 8, "only {} blocks on the 19k-tet block", p.blocks());
            }
        }
    }
}
