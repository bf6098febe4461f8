//! The binary tree the 8-wide nodes are collapsed from: binned SAH, top down.
//!
//! Input: each quad's box, in input order. Output: the binary nodes (root 0; an interior
//! node's children side by side) and the quads in the order the partitions leave them (a
//! leaf's quads are a range of it).
//! Invariants: the tree is a function of the input order alone: each node's bounds, bins,
//! split and partition depend only on its range of quads in the order its parent's partition
//! left them. The two halves under the root (and so on down while threads remain and the
//! halves are large) are built on their own threads, each into its own node list, and joined
//! into one list whose numbering differs but whose tree is the same: the 8-wide collapse reads
//! only the tree. (Partitioning the boxes themselves instead of their indices, so each pass
//! reads memory in sequence, was slower: 0.81 → 0.98 s for a million quads on one thread;
//! diced grids come in spatial order, so the indices already read nearby boxes.)

use glam::Vec3;

use super::{groups, Aabb, Node2, BINS, MAX_LEAF, TRAVERSAL_COST};

/// The quads' boxes and centroids, read through the order being partitioned.
struct Boxes<'a> {
    boxes: &'a [Aabb],
    cent: Vec<Vec3>,
}

/// Fewest quads in a half worth a thread of its own.
const PARALLEL_MIN: usize = 1 << 15;

/// The tree over `boxes` built with up to `threads` threads: its nodes and the quads' order.
pub(super) fn build(boxes: &[Aabb], threads: usize) -> (Vec<Node2>, Vec<u32>) {
    let b = Boxes {
        boxes,
        cent: boxes.iter().map(|b| (b.min + b.max) * 0.5).collect(),
    };
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    let nodes = subtree(&b, &mut order, 0, threads.max(1));
    (nodes, order)
}

/// What a node becomes.
enum Step {
    Leaf(Aabb),
    /// An interior node: its bounds and where its range splits (from the range's start).
    Split(Aabb, usize),
}

/// Decides the node over quads `items` (a non-empty range of the order), partitioning it in
/// place when it splits.
fn step(q: &Boxes, items: &mut [u32]) -> Step {
    let (boxes, cent) = (q.boxes, &q.cent[..]);
    let mut bb = Aabb::EMPTY;
    let mut cb = Aabb::EMPTY;
    for &k in items.iter() {
        bb.grow(&boxes[k as usize]);
        cb.grow_point(cent[k as usize]);
    }
    let count = items.len();
    if count <= 2 {
        return Step::Leaf(bb);
    }
    // The best split over the three axes.
    let ext = cb.max - cb.min;
    let mut best = (f32::INFINITY, 0usize, 0usize); // (cost, axis, last bin on the left)
                                                    // One pass bins every item on the three axes (an axis of no extent puts every item in its
                                                    // bin 0, where no split is possible).
    let scales: [f32; 3] = std::array::from_fn(|a| {
        if ext[a] > 0.0 && ext[a].is_finite() {
            BINS as f32 * (1.0 - 1e-6) / ext[a]
        } else {
            0.0
        }
    });
    let mut bins = [[(Aabb::EMPTY, 0u32); BINS]; 3];
    for &k in items.iter() {
        let c = cent[k as usize] - cb.min;
        let bx = &boxes[k as usize];
        for axis in 0..3 {
            let i = ((c[axis] * scales[axis]) as usize).min(BINS - 1);
            let bin = &mut bins[axis][i];
            bin.0.grow(bx);
            bin.1 += 1;
        }
    }
    for axis in 0..3 {
        if scales[axis] == 0.0 {
            continue;
        }
        let b = &bins[axis];
        let mut right_area = [0f32; BINS];
        let mut right_count = [0u32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for i in (1..BINS).rev() {
            acc.grow(&b[i].0);
            cnt += b[i].1;
            right_area[i] = acc.area();
            right_count[i] = cnt;
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for i in 0..BINS - 1 {
            acc.grow(&b[i].0);
            cnt += b[i].1;
            if cnt == 0 || right_count[i + 1] == 0 {
                continue;
            }
            let cost = acc.area() * groups(cnt) + right_area[i + 1] * groups(right_count[i + 1]);
            if cost < best.0 {
                best = (cost, axis, i);
            }
        }
    }
    let area = bb.area().max(f32::MIN_POSITIVE);
    let leaf_cost = groups(count as u32);
    let split_cost = TRAVERSAL_COST + best.0 / area;
    if best.0.is_finite() && (split_cost < leaf_cost || count > MAX_LEAF) {
        // In-place partition by the chosen bin.
        let axis = best.1;
        let (lo, scale) = (cb.min[axis], scales[axis]);
        let left_of =
            |k: u32| (((cent[k as usize][axis] - lo) * scale) as usize).min(BINS - 1) <= best.2;
        let (mut i, mut j) = (0, count);
        while i < j {
            if left_of(items[i]) {
                i += 1;
            } else {
                j -= 1;
                items.swap(i, j);
            }
        }
        Step::Split(bb, i)
    } else if count <= MAX_LEAF {
        Step::Leaf(bb)
    } else {
        // All centroids coincide: halve the range.
        Step::Split(bb, count / 2)
    }
}

/// The subtree over quads `items` (which start at `base` in the whole order): its nodes, its root
/// first, leaves naming their quads by position in the whole order.
fn subtree(q: &Boxes, items: &mut [u32], base: usize, threads: usize) -> Vec<Node2> {
    let n = items.len();
    if threads < 2 || n < 2 * PARALLEL_MIN {
        return sequential(q, items, base);
    }
    match step(q, items) {
        Step::Leaf(bb) => vec![Node2 {
            bb,
            first: base as u32,
            count: n as u32,
        }],
        Step::Split(bb, mid) => {
            let (l, r) = items.split_at_mut(mid);
            // Plain threads, not rayon: the build runs while render threads wait on it, and a
            // rayon join could take up one of their tasks, which would wait on this build.
            let (ln, rn) = std::thread::scope(|sc| {
                let right = sc.spawn(|| subtree(q, r, base + mid, threads / 2));
                let ln = subtree(q, l, base, threads - threads / 2);
                let rn = right
                    .join()
                    .unwrap_or_else(|e| std::panic::resume_unwind(e));
                (ln, rn)
            });
            join(bb, ln, rn)
        }
    }
}

/// One list of a root with bounds `bb` over subtrees `l` and `r` (roots first): the root,
/// the two subtree roots, then the rest of `l` and the rest of `r`.
fn join(bb: Aabb, l: Vec<Node2>, r: Vec<Node2>) -> Vec<Node2> {
    let rest_r = 3 + l.len() - 1;
    let place = |root: u32, rest: usize| {
        move |j: u32| {
            if j == 0 {
                root
            } else {
                (rest + j as usize - 1) as u32
            }
        }
    };
    let (pl, pr) = (place(1, 3), place(2, rest_r));
    let moved = |n: &Node2, p: &dyn Fn(u32) -> u32| {
        if n.count == 0 {
            Node2 {
                first: p(n.first),
                ..*n
            }
        } else {
            *n
        }
    };
    let mut out = Vec::with_capacity(1 + l.len() + r.len());
    out.push(Node2 {
        bb,
        first: 1,
        count: 0,
    });
    out.push(moved(&l[0], &pl));
    out.push(moved(&r[0], &pr));
    out.extend(l[1..].iter().map(|n| moved(n, &pl)));
    out.extend(r[1..].iter().map(|n| moved(n, &pr)));
    out
}

/// The subtree over `items` on this thread (depth first, left before right).
fn sequential(q: &Boxes, items: &mut [u32], base: usize) -> Vec<Node2> {
    let n = items.len();
    let blank = Node2 {
        bb: Aabb::EMPTY,
        first: 0,
        count: 0,
    };
    let mut nodes: Vec<Node2> = Vec::with_capacity(2 * n / 3 + 1);
    nodes.push(blank);
    let mut stack = vec![(0usize, 0usize, n)];
    while let Some((ni, s, e)) = stack.pop() {
        match step(q, &mut items[s..e]) {
            Step::Leaf(bb) => {
                nodes[ni] = Node2 {
                    bb,
                    first: (base + s) as u32,
                    count: (e - s) as u32,
                }
            }
            Step::Split(bb, m) => {
                let left = nodes.len();
                nodes.push(blank);
                nodes.push(blank);
                nodes[ni] = Node2 {
                    bb,
                    first: left as u32,
                    count: 0,
                };
                stack.push((left + 1, s + m, e));
                stack.push((left, s, s + m));
            }
        }
    }
    nodes
}
