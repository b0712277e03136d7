//! Fill-reducing orderings for the Cholesky factor of D_s: METIS nested
//! dissection, postordered by its elimination tree.
//!
//! faer orders by AMD (and postorders its result). A custom ordering is
//! taken as given, and a nested-dissection order is not postordered: the
//! columns of one supernode are then not consecutive, the supernodes
//! fragment, and the numeric factorisation ran slower than AMD's despite
//! 26 % less fill (measured: 8.7 ms against 5.3 ms at 10242 vertices).
//! Postordering (a depth-first numbering of the elimination tree, which
//! keeps the fill and the tree) restores the supernodes.

use faer::sparse::SymbolicSparseColMatRef;

/// The METIS nested-dissection order of the symmetric pattern whose lower
/// triangle is `lower`, postordered: `order[k]` is the vertex eliminated
/// k-th. `None` when METIS cannot order it (then use AMD).
pub(crate) fn nested_dissection(lower: SymbolicSparseColMatRef<'_, usize>) -> Option<Vec<usize>> {
    let n = lower.nrows();
    if n < 2 {
        return None;
    }
    let adj = adjacency(lower);
    let order = metis_node_nd(n, &adj)?;
    Some(postorder(&adj, &order))
}

/// Symmetric adjacency without the diagonal, CSR: (offsets, neighbours).
fn adjacency(lower: SymbolicSparseColMatRef<'_, usize>) -> (Vec<usize>, Vec<usize>) {
    let n = lower.nrows();
    let (col_ptr, row_idx) = (lower.col_ptr(), lower.row_idx());
    let mut ptr = vec![0usize; n + 1];
    for j in 0..n {
        for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
            if i != j {
                ptr[i + 1] += 1;
                ptr[j + 1] += 1;
            }
        }
    }
    for v in 0..n {
        ptr[v + 1] += ptr[v];
    }
    let mut fill = ptr.clone();
    let mut adj = vec![0usize; ptr[n]];
    for j in 0..n {
        for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
            if i != j {
                adj[fill[i]] = j;
                fill[i] += 1;
                adj[fill[j]] = i;
                fill[j] += 1;
            }
        }
    }
    (ptr, adj)
}

/// Held across every METIS call. METIS draws its random numbers (for the
/// matchings of its coarsening) from GKlib's Mersenne Twister, whose state
/// is a process-wide static (`GKlib/random.c`): each call reseeds it, but
/// two calls at once in two threads interleave their draws, a data race
/// that gave two atlases run side by side in one process other orderings,
/// so other roundings of the Cholesky factor, than each run alone.
static METIS: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// METIS_NodeND with default options: `order[k]` is the original index of
/// the k-th row of the permuted matrix (METIS's `perm`). One call at a time
/// in the process ([`METIS`]).
#[allow(unsafe_code)]
fn metis_node_nd(n: usize, (ptr, adj): &(Vec<usize>, Vec<usize>)) -> Option<Vec<usize>> {
    use metis_sys::idx_t;
    let mut nvtxs = idx_t::try_from(n).ok()?;
    let mut xadj: Vec<idx_t> = ptr.iter().map(|&v| idx_t::try_from(v)).collect::<Result<_, _>>().ok()?;
    let mut adjncy: Vec<idx_t> = adj.iter().map(|&v| idx_t::try_from(v)).collect::<Result<_, _>>().ok()?;
    let (mut perm, mut iperm) = (vec![0 as idx_t; n], vec![0 as idx_t; n]);
    // A poisoned lock only means another call panicked; METIS reseeds its
    // generator on entry, so the state it left does not matter.
    let _one_at_a_time = METIS.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // SAFETY: METIS reads nvtxs + 1 offsets and xadj[n] neighbours, and
    // writes n values to each of perm and iperm; every buffer has exactly
    // that length. Null vwgt and options mean unit weights and defaults.
    let status = unsafe {
        metis_sys::METIS_NodeND(
            &mut nvtxs,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return None;
    }
    let order: Vec<usize> = perm.iter().map(|&v| usize::try_from(v).ok()).collect::<Option<_>>()?;
    is_permutation(&order).then_some(order)
}

fn is_permutation(order: &[usize]) -> bool {
    let mut seen = vec![false; order.len()];
    order.iter().all(|&v| v < seen.len() && !std::mem::replace(&mut seen[v], true))
}

/// `order` renumbered by a depth-first postorder of the elimination tree
/// of the matrix permuted by `order` (children before parents, each
/// subtree's columns consecutive). Same tree, same fill.
fn postorder((ptr, adj): &(Vec<usize>, Vec<usize>), order: &[usize]) -> Vec<usize> {
    const NONE: usize = usize::MAX;
    let n = order.len();
    let mut inv = vec![0usize; n];
    for (k, &v) in order.iter().enumerate() {
        inv[v] = k;
    }
    // Liu's algorithm with path compression, in the permuted numbering.
    let (mut parent, mut ancestor) = (vec![NONE; n], vec![NONE; n]);
    for (k, &v) in order.iter().enumerate() {
        for &u in &adj[ptr[v]..ptr[v + 1]] {
            let mut r = inv[u];
            if r >= k {
                continue;
            }
            while ancestor[r] != NONE && ancestor[r] != k {
                let next = ancestor[r];
                ancestor[r] = k;
                r = next;
            }
            if ancestor[r] == NONE {
                ancestor[r] = k;
                parent[r] = k;
            }
        }
    }
    // Children lists (in increasing order), then an iterative DFS from the
    // roots.
    let (mut head, mut next) = (vec![NONE; n], vec![NONE; n]);
    for k in (0..n).rev() {
        if parent[k] != NONE {
            next[k] = head[parent[k]];
            head[parent[k]] = k;
        }
    }
    let mut post = Vec::with_capacity(n);
    let mut stack = Vec::new();
    for root in (0..n).filter(|&k| parent[k] == NONE) {
        stack.push(root);
        while let Some(&top) = stack.last() {
            let child = head[top];
            if child == NONE {
                post.push(order[top]);
                stack.pop();
            } else {
                head[top] = next[child];
                stack.push(child);
            }
        }
    }
    post
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Elimination tree parents (original numbering) by the definition:
    /// the parent of column j is the first row below j in column j of the
    /// Cholesky factor's pattern, computed by symbolic elimination on a
    /// dense boolean matrix (small n only).
    fn etree_dense(n: usize, edges: &[(usize, usize)], order: &[usize]) -> Vec<Option<usize>> {
        let mut inv = vec![0; n];
        for (k, &v) in order.iter().enumerate() {
            inv[v] = k;
        }
        let mut m = vec![vec![false; n]; n];
        for &(a, b) in edges {
            let (i, j) = (inv[a], inv[b]);
            m[i][j] = true;
            m[j][i] = true;
        }
        let mut parent = vec![None; n];
        for j in 0..n {
            let below: Vec<usize> = (j + 1..n).filter(|&i| m[i][j]).collect();
            parent[j] = below.first().copied();
            for &a in &below {
                for &b in &below {
                    m[a][b] = true;
                }
            }
        }
        let mut out = vec![None; n];
        for (k, &v) in order.iter().enumerate() {
            out[v] = parent[k].map(|p| order[p]);
        }
        out
    }

    #[test]
    fn postorder_keeps_the_elimination_tree_and_numbers_every_subtree_consecutively() {
        // A 6 × 5 grid graph (a mesh's connectivity in miniature), in a
        // scrambled elimination order.
        let (w, h) = (6, 5);
        let n = w * h;
        let mut edges = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let v = y * w + x;
                if x + 1 < w {
                    edges.push((v, v + 1));
                }
                if y + 1 < h {
                    edges.push((v, v + w));
                }
                if x + 1 < w && y + 1 < h {
                    edges.push((v, v + w + 1));
                }
            }
        }
        let mut ptr = vec![0; n + 1];
        for &(a, b) in &edges {
            ptr[a + 1] += 1;
            ptr[b + 1] += 1;
        }
        for v in 0..n {
            ptr[v + 1] += ptr[v];
        }
        let mut fill = ptr.clone();
        let mut adj = vec![0; ptr[n]];
        for &(a, b) in &edges {
            adj[fill[a]] = b;
            fill[a] += 1;
            adj[fill[b]] = a;
            fill[b] += 1;
        }
        let order: Vec<usize> = (0..n).map(|k| (k * 7 + 3) % n).collect();
        let post = postorder(&(ptr, adj), &order);
        assert!(is_permutation(&post));
        let (before, after) = (etree_dense(n, &edges, &order), etree_dense(n, &edges, &post));
        assert_eq!(before, after, "the same tree");
        // Postorder: every vertex comes after all of its descendants, and
        // a subtree's vertices are consecutive (each parent's position is
        // its subtree's last).
        let mut pos = vec![0; n];
        for (k, &v) in post.iter().enumerate() {
            pos[v] = k;
        }
        let mut size = vec![1usize; n];
        for &v in &post {
            if let Some(p) = after[v] {
                assert!(pos[p] > pos[v]);
                size[p] += size[v];
            }
        }
        for &v in &post {
            let first = pos[v] + 1 - size[v];
            // Every vertex in positions first..=pos[v] has v as an ancestor
            // or is v.
            for &u in &post[first..=pos[v]] {
                let mut a = Some(u);
                while a.is_some_and(|x| x != v) {
                    a = after[a.unwrap()];
                }
                assert_eq!(a, Some(v), "{u} in the span of {v}'s subtree");
            }
        }
    }

    /// A triangulated w × h grid's adjacency (CSR, no diagonal).
    fn grid(w: usize, h: usize) -> (Vec<usize>, Vec<usize>) {
        let n = w * h;
        let mut nbrs = vec![Vec::new(); n];
        for y in 0..h {
            for x in 0..w {
                let v = y * w + x;
                for (dx, dy) in [(1, 0), (0, 1), (1, 1)] {
                    if x + dx < w && y + dy < h {
                        let u = (y + dy) * w + x + dx;
                        nbrs[v].push(u);
                        nbrs[u].push(v);
                    }
                }
            }
        }
        let mut ptr = vec![0];
        let mut adj = Vec::new();
        for mut list in nbrs {
            list.sort_unstable();
            adj.extend(list);
            ptr.push(adj.len());
        }
        (ptr, adj)
    }

    #[test]
    fn metis_orders_the_same_when_called_from_many_threads_at_once() {
        // METIS's random generator is one process-wide state: without the
        // lock, calls at once interleave their draws and order differently.
        let adj = grid(90, 80);
        let reference = metis_node_nd(90 * 80, &adj).expect("METIS orders a grid");
        std::thread::scope(|s| {
            let handles: Vec<_> =
                (0..4).map(|_| s.spawn(|| (0..6).map(|_| metis_node_nd(90 * 80, &adj)).collect::<Vec<_>>())).collect();
            for h in handles {
                for order in h.join().expect("no panic") {
                    assert!(order.as_ref() == Some(&reference), "an ordering computed alongside others differs");
                }
            }
        });
    }
}
