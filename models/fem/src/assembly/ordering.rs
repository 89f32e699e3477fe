//! Fill-reducing orderings of the block sparsity pattern: reverse
//! Cuthill-McKee and nested dissection.

use super::*;
use surgbench_core::Vec3;

impl Pattern {
    /// Reverse Cuthill-McKee ordering of the node graph (Cuthill and McKee
    /// 1969; George 1971): breadth-first from a pseudo-peripheral node,
    /// neighbours by increasing degree, then reversed. Returns the nodes in
    /// the new order (`order[k]` = old node index).
    pub fn rcm(&self) -> Vec<usize> {
        let n = self.n;
        let deg = |i: usize| self.row_ptr[i + 1] - self.row_ptr[i];
        let mut visited = vec![false; n];
        let mut order = Vec::with_capacity(n);
        let bfs = |start: usize, visited: &mut Vec<bool>, order: &mut Vec<usize>| -> usize {
            let first = order.len();
            visited[start] = true;
            order.push(start);
            let mut head = first;
            let mut last = start;
            while head < order.len() {
                let v = order[head];
                head += 1;
                last = v;
                let mut nb: Vec<usize> = self.col[self.row_ptr[v]..self.row_ptr[v + 1]]
                    .iter()
                    .copied()
                    .filter(|&u| !visited[u])
                    .collect();
                nb.sort_by_key(|&u| (deg(u), u));
                for u in nb {
                    visited[u] = true;
                    order.push(u);
                }
            }
            last
        };
        for s in 0..n {
            if visited[s] {
                continue;
            }
            // Pseudo-peripheral start: the last node reached by a BFS.
            let mut tmp_vis = visited.clone();
            let mut tmp = Vec::new();
            let far = bfs(s, &mut tmp_vis, &mut tmp);
            bfs(far, &mut visited, &mut order);
        }
        order.reverse();
        order
    }

    /// Nested-dissection ordering of the node graph (George 1973, "Nested
    /// dissection of a regular finite element mesh", SIAM J. Numer. Anal.
    /// 10(2)), with geometric bisection: a node set is split at the median
    /// coordinate along its longest bounding-box extent into a low side
    /// (coordinate below the median) and a high side; the separator is the
    /// nodes of the larger side adjacent to the other side. Both remaining
    /// parts are ordered recursively, the separator after them, so no
    /// factor fill couples the two parts. Sets of at most [`ND_LEAF`] nodes
    /// keep their index order. Returns the nodes in the new order
    /// (`order[k]` = old node index); deterministic (ties broken by index).
    pub fn nested_dissection(&self) -> Vec<usize> {
        let mut order = Vec::with_capacity(self.n);
        // Side of every node during a split: 0 outside, 1 low, 2 high.
        let mut side = vec![0u8; self.n];
        let mut stack: Vec<(Vec<usize>, Option<Vec<usize>>)> = vec![((0..self.n).collect(), None)];
        // Depth-first with explicit stack: an entry `(set, Some(sep))` means
        // "set already split; emit sep" after its parts.
        while let Some((set, sep)) = stack.pop() {
            if let Some(sep) = sep {
                order.extend(sep);
                continue;
            }
            if set.len() <= ND_LEAF {
                order.extend(set);
                continue;
            }
            let (lo, hi) = set.iter().fold(
                (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)),
                |(lo, hi), &i| (lo.inf(&self.coords[i]), hi.sup(&self.coords[i])),
            );
            let ext = hi - lo;
            let axis = ext.imax();
            let mut vals: Vec<f64> = set.iter().map(|&i| self.coords[i][axis]).collect();
            vals.sort_by(f64::total_cmp);
            let median = vals[vals.len() / 2];
            let (mut low, mut high): (Vec<usize>, Vec<usize>) =
                set.iter().partition(|&&i| self.coords[i][axis] < median);
            if low.is_empty() {
                // Degenerate extent (all at the median): split by position.
                let h = set.len() / 2;
                low = set[..h].to_vec();
                high = set[h..].to_vec();
            }
            for &i in &low {
                side[i] = 1;
            }
            for &i in &high {
                side[i] = 2;
            }
            let (big, other) = if high.len() >= low.len() { (2u8, 1u8) } else { (1, 2) };
            let touches = |i: usize| {
                self.col[self.row_ptr[i]..self.row_ptr[i + 1]]
                    .iter()
                    .any(|&j| side[j] == other)
            };
            let (mut part_a, mut part_b, mut sep) = (Vec::new(), Vec::new(), Vec::new());
            for &i in &set {
                if side[i] == big && touches(i) {
                    sep.push(i);
                } else if side[i] == 1 {
                    part_a.push(i);
                } else {
                    part_b.push(i);
                }
            }
            for &i in &set {
                side[i] = 0;
            }
            stack.push((Vec::new(), Some(sep)));
            stack.push((part_b, None));
            stack.push((part_a, None));
        }
        order
    }
}
