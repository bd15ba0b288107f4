//! [`Index`]: Chipmunk's spatial index (`cpBBTree`) as far as it decides the ORDER in which a step finds
//! the touching shape pairs — which is the order of the contact solver, and with ten Gauss–Seidel
//! iterations on the near-singular systems I-PHYRE makes, that order shows in the trajectories.
//!
//! Two trees, as a Chipmunk space has: static shapes in one (tight boxes), dynamic shapes in the other
//! (boxes grown by a tenth of their size, or by a tenth of a time unit of their body's velocity, kept
//! until the shape leaves them). Leaves are linked by *pairs*: a pair joins two leaves whose tree boxes
//! overlapped when one of them was last (re-)inserted, sits at the head of both leaves' pair lists, and
//! carries the collision id (the narrow phase's cached closest features) from step to step. A step
//! (`reindex_query`):
//!
//! 1. visits the dynamic leaves in the order of Chipmunk's leaf hash set (shape number modulo a prime
//!    table size, newest first within a bin) and re-inserts each one whose shape left its box: removed
//!    from the tree, inserted again by the area heuristic, its pairs dropped, stamped with this step;
//! 2. walks the dynamic tree depth first (child A before B). A leaf stamped this step queries the static
//!    tree and then, walking up, the sibling subtree of each ancestor: siblings on the B side get a pair
//!    and are reported when they are visited, siblings on the A side are reported now (this leaf first)
//!    and get a pair if they are older; any other leaf reports the pairs in its list in which it is the
//!    second leaf (the other leaf first), newest pair first.
//!
//! Everything here reproduces `cpBBTree.c` and `cpHashSet.c` of Chipmunk 7.0.3 (as vendored by pymunk
//! 6.11.1) in behaviour, not in code: nodes and pairs live in arenas with free lists instead of pools.
//!
//! **Owns:** the trees, the pairs and their collision ids, the leaf order.
//! **Does not:** test shapes for contact (the caller gets the candidate pairs and does that) or know
//! about bodies beyond the velocity it is given for growing a box.

use std::collections::HashMap;

use crate::shape::Bb;

/// "No node / no pair".
const NONE: usize = usize::MAX;

/// Chipmunk's hash set sizes (`prime.h`): a set grows to the next one when it holds as many entries as
/// it has bins.
const PRIMES: [usize; 12] = [5, 13, 23, 47, 97, 193, 389, 769, 1543, 3079, 6151, 12289];

/// The smallest table size ≥ `n`.
fn next_prime(n: usize) -> usize {
    PRIMES.iter().copied().find(|&p| p >= n).unwrap_or(n | 1)
}

/// A candidate pair for the narrow phase, in the order Chipmunk reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Query {
    /// The first shape (as reported; the narrow phase may still put a circle first).
    pub a: usize,
    /// The second shape.
    pub b: usize,
    /// The collision id to start from (0: none).
    pub id: u32,
    /// The pair whose id the narrow phase's returned id replaces, if the query came from a pair list.
    pub pair: Option<usize>,
}

#[derive(Debug, Clone)]
struct Node {
    /// The shape of a leaf; None for an inner node.
    shape: Option<usize>,
    bb: Bb,
    parent: usize,
    /// Children of an inner node.
    a: usize,
    b: usize,
    /// A leaf's stamp: the index stamp when it was last (re-)inserted.
    stamp: u64,
    /// A leaf's pair list head.
    pairs: usize,
}

#[derive(Debug, Clone, Copy)]
struct Thread {
    prev: usize,
    leaf: usize,
    next: usize,
}

#[derive(Debug, Clone, Copy)]
struct Pair {
    a: Thread,
    b: Thread,
    id: u32,
}

/// Chipmunk's chained hash set of the dynamic leaves, kept only for its iteration order.
#[derive(Debug, Clone)]
struct LeafSet {
    /// Each bin's chain, head first: (shape number, leaf node).
    bins: Vec<Vec<(u64, usize)>>,
    entries: usize,
}

impl LeafSet {
    fn new() -> LeafSet {
        LeafSet {
            bins: vec![Vec::new(); next_prime(0)],
            entries: 0,
        }
    }

    fn insert(&mut self, hash: u64, node: usize) {
        let size = self.bins.len();
        self.bins[(hash % size as u64) as usize].insert(0, (hash, node));
        self.entries += 1;
        if self.entries >= size {
            // Rehash chain by chain, each element pushed at the head of its new chain.
            let new_size = next_prime(size + 1);
            let mut bins = vec![Vec::new(); new_size];
            for chain in &self.bins {
                for &(h, n) in chain {
                    bins[(h % new_size as u64) as usize].insert(0, (h, n));
                }
            }
            self.bins = bins;
        }
    }

    fn remove(&mut self, hash: u64) {
        let size = self.bins.len() as u64;
        let chain = &mut self.bins[(hash % size) as usize];
        if let Some(i) = chain.iter().position(|&(h, _)| h == hash) {
            chain.remove(i);
            self.entries -= 1;
        }
    }

    fn nodes(&self) -> impl Iterator<Item = usize> + '_ {
        self.bins.iter().flatten().map(|&(_, n)| n)
    }
}

/// The static and the dynamic tree of one space, with their pairs.
#[derive(Debug, Clone)]
pub(crate) struct Index {
    nodes: Vec<Node>,
    free_nodes: Vec<usize>,
    pairs: Vec<Pair>,
    free_pairs: Vec<usize>,
    static_root: usize,
    dynamic_root: usize,
    /// The dynamic tree's stamp, which both trees use.
    stamp: u64,
    leaves: LeafSet,
    /// Leaf node by shape index.
    leaf_of: HashMap<usize, usize>,
}

impl Index {
    pub(crate) fn new() -> Index {
        Index {
            nodes: Vec::new(),
            free_nodes: Vec::new(),
            pairs: Vec::new(),
            free_pairs: Vec::new(),
            static_root: NONE,
            dynamic_root: NONE,
            stamp: 0,
            leaves: LeafSet::new(),
            leaf_of: HashMap::new(),
        }
    }

    fn new_node(&mut self, node: Node) -> usize {
        if let Some(i) = self.free_nodes.pop() {
            self.nodes[i] = node;
            i
        } else {
            self.nodes.push(node);
            self.nodes.len() - 1
        }
    }

    fn is_leaf(&self, n: usize) -> bool {
        self.nodes[n].shape.is_some()
    }

    fn set_a(&mut self, node: usize, value: usize) {
        self.nodes[node].a = value;
        self.nodes[value].parent = node;
    }

    fn set_b(&mut self, node: usize, value: usize) {
        self.nodes[node].b = value;
        self.nodes[value].parent = node;
    }

    /// An inner node over `a` (child A) and `b` (child B).
    fn inner(&mut self, a: usize, b: usize) -> usize {
        let bb = self.nodes[a].bb.merge(&self.nodes[b].bb);
        let n = self.new_node(Node {
            shape: None,
            bb,
            parent: NONE,
            a: NONE,
            b: NONE,
            stamp: 0,
            pairs: NONE,
        });
        self.set_a(n, a);
        self.set_b(n, b);
        n
    }

    fn other_child(&self, node: usize, child: usize) -> usize {
        let n = &self.nodes[node];
        if n.a == child { n.b } else { n.a }
    }

    /// Inserts `leaf` under `subtree`; returns the new subtree root.
    fn subtree_insert(&mut self, subtree: usize, leaf: usize) -> usize {
        if subtree == NONE {
            return leaf;
        }
        if self.is_leaf(subtree) {
            return self.inner(leaf, subtree);
        }
        let (ca, cb) = (self.nodes[subtree].a, self.nodes[subtree].b);
        let (bb_a, bb_b, bb_l) = (self.nodes[ca].bb, self.nodes[cb].bb, self.nodes[leaf].bb);
        let mut cost_a = bb_b.area() + bb_a.merged_area(&bb_l);
        let mut cost_b = bb_a.area() + bb_b.merged_area(&bb_l);
        if cost_a == cost_b {
            cost_a = bb_a.proximity(&bb_l);
            cost_b = bb_b.proximity(&bb_l);
        }
        if cost_b < cost_a {
            let n = self.subtree_insert(cb, leaf);
            self.set_b(subtree, n);
        } else {
            let n = self.subtree_insert(ca, leaf);
            self.set_a(subtree, n);
        }
        self.nodes[subtree].bb = self.nodes[subtree].bb.merge(&bb_l);
        subtree
    }

    /// Removes `leaf` from `subtree`; returns the new subtree root.
    fn subtree_remove(&mut self, subtree: usize, leaf: usize) -> usize {
        if leaf == subtree {
            return NONE;
        }
        let parent = self.nodes[leaf].parent;
        if parent == subtree {
            let other = self.other_child(subtree, leaf);
            self.nodes[other].parent = self.nodes[subtree].parent;
            self.free_nodes.push(subtree);
            other
        } else {
            let grand = self.nodes[parent].parent;
            let other = self.other_child(parent, leaf);
            // Replace `parent` by `other` under `grand`, then refit the boxes up to the root.
            if self.nodes[grand].a == parent {
                self.set_a(grand, other);
            } else {
                self.set_b(grand, other);
            }
            self.free_nodes.push(parent);
            let mut node = grand;
            while node != NONE {
                let (a, b) = (self.nodes[node].a, self.nodes[node].b);
                self.nodes[node].bb = self.nodes[a].bb.merge(&self.nodes[b].bb);
                node = self.nodes[node].parent;
            }
            subtree
        }
    }

    fn pair_insert(&mut self, a: usize, b: usize) {
        let (next_a, next_b) = (self.nodes[a].pairs, self.nodes[b].pairs);
        let pair = Pair {
            a: Thread {
                prev: NONE,
                leaf: a,
                next: next_a,
            },
            b: Thread {
                prev: NONE,
                leaf: b,
                next: next_b,
            },
            id: 0,
        };
        let p = if let Some(i) = self.free_pairs.pop() {
            self.pairs[i] = pair;
            i
        } else {
            self.pairs.push(pair);
            self.pairs.len() - 1
        };
        self.nodes[a].pairs = p;
        self.nodes[b].pairs = p;
        for (next, leaf) in [(next_a, a), (next_b, b)] {
            if next != NONE {
                let n = &mut self.pairs[next];
                if n.a.leaf == leaf {
                    n.a.prev = p;
                } else {
                    n.b.prev = p;
                }
            }
        }
    }

    fn thread_unlink(&mut self, t: Thread) {
        if t.next != NONE {
            let n = &mut self.pairs[t.next];
            if n.a.leaf == t.leaf {
                n.a.prev = t.prev;
            } else {
                n.b.prev = t.prev;
            }
        }
        if t.prev != NONE {
            let p = &mut self.pairs[t.prev];
            if p.a.leaf == t.leaf {
                p.a.next = t.next;
            } else {
                p.b.next = t.next;
            }
        } else {
            self.nodes[t.leaf].pairs = t.next;
        }
    }

    /// Drops every pair of `leaf`.
    fn pairs_clear(&mut self, leaf: usize) {
        let mut pair = self.nodes[leaf].pairs;
        self.nodes[leaf].pairs = NONE;
        while pair != NONE {
            let p = self.pairs[pair];
            let next = if p.a.leaf == leaf {
                self.thread_unlink(p.b);
                p.a.next
            } else {
                self.thread_unlink(p.a);
                p.b.next
            };
            self.free_pairs.push(pair);
            pair = next;
        }
    }

    /// Pairs `leaf` with the leaves of `subtree` whose boxes overlap its box; see the module doc for
    /// `left` (the subtree is on the B side: pair only) and the reports it makes otherwise.
    fn mark_leaf_query(
        &mut self,
        subtree: usize,
        leaf: usize,
        left: bool,
        out: &mut Option<&mut Vec<Query>>,
    ) {
        if !self.nodes[leaf].bb.intersects(&self.nodes[subtree].bb) {
            return;
        }
        if let Some(other) = self.nodes[subtree].shape {
            if left {
                self.pair_insert(leaf, subtree);
            } else {
                if self.nodes[subtree].stamp < self.nodes[leaf].stamp {
                    self.pair_insert(subtree, leaf);
                }
                if let Some(out) = out {
                    let me = self.nodes[leaf].shape.expect("a leaf");
                    out.push(Query {
                        a: me,
                        b: other,
                        id: 0,
                        pair: None,
                    });
                }
            }
        } else {
            let (a, b) = (self.nodes[subtree].a, self.nodes[subtree].b);
            self.mark_leaf_query(a, leaf, left, out);
            self.mark_leaf_query(b, leaf, left, out);
        }
    }

    fn mark_leaf(&mut self, leaf: usize, out: &mut Option<&mut Vec<Query>>) {
        if self.nodes[leaf].stamp == self.stamp {
            if self.static_root != NONE {
                self.mark_leaf_query(self.static_root, leaf, false, out);
            }
            let mut node = leaf;
            loop {
                let parent = self.nodes[node].parent;
                if parent == NONE {
                    break;
                }
                if self.nodes[parent].a == node {
                    let sibling = self.nodes[parent].b;
                    self.mark_leaf_query(sibling, leaf, true, out);
                } else {
                    let sibling = self.nodes[parent].a;
                    self.mark_leaf_query(sibling, leaf, false, out);
                }
                node = parent;
            }
        } else {
            let me = self.nodes[leaf].shape.expect("a leaf");
            let mut pair = self.nodes[leaf].pairs;
            while pair != NONE {
                let p = self.pairs[pair];
                if p.b.leaf == leaf {
                    if let Some(out) = out {
                        out.push(Query {
                            a: self.nodes[p.a.leaf].shape.expect("a leaf"),
                            b: me,
                            id: p.id,
                            pair: Some(pair),
                        });
                    }
                    pair = p.b.next;
                } else {
                    pair = p.a.next;
                }
            }
        }
    }

    fn mark_subtree(&mut self, subtree: usize, out: &mut Option<&mut Vec<Query>>) {
        if self.is_leaf(subtree) {
            self.mark_leaf(subtree, out);
        } else {
            let (a, b) = (self.nodes[subtree].a, self.nodes[subtree].b);
            self.mark_subtree(a, out);
            self.mark_subtree(b, out);
        }
    }

    fn new_leaf(&mut self, shape: usize, bb: Bb) -> usize {
        let leaf = self.new_node(Node {
            shape: Some(shape),
            bb,
            parent: NONE,
            a: NONE,
            b: NONE,
            stamp: 0,
            pairs: NONE,
        });
        self.leaf_of.insert(shape, leaf);
        leaf
    }

    /// Adds static shape `shape` (number `hash`) with box `bb`, pairing it with the dynamic leaves it
    /// overlaps.
    pub(crate) fn insert_static(&mut self, shape: usize, bb: Bb) {
        let leaf = self.new_leaf(shape, bb);
        self.static_root = self.subtree_insert(self.static_root, leaf);
        self.nodes[leaf].stamp = self.stamp;
        if self.dynamic_root != NONE {
            self.mark_leaf_query(self.dynamic_root, leaf, true, &mut None);
        }
        self.stamp += 1;
    }

    /// Adds dynamic shape `shape` (number `hash`) with tree box `bb` (already grown), pairing it with the
    /// leaves it overlaps.
    pub(crate) fn insert_dynamic(&mut self, shape: usize, hash: u64, bb: Bb) {
        let leaf = self.new_leaf(shape, bb);
        self.leaves.insert(hash, leaf);
        self.dynamic_root = self.subtree_insert(self.dynamic_root, leaf);
        self.nodes[leaf].stamp = self.stamp;
        self.mark_leaf(leaf, &mut None);
        self.stamp += 1;
    }

    /// Removes `shape` (number `hash`, in the static tree if `is_static`) and its pairs.
    pub(crate) fn remove(&mut self, shape: usize, hash: u64, is_static: bool) {
        let Some(leaf) = self.leaf_of.remove(&shape) else {
            return;
        };
        if is_static {
            self.static_root = self.subtree_remove(self.static_root, leaf);
        } else {
            self.leaves.remove(hash);
            self.dynamic_root = self.subtree_remove(self.dynamic_root, leaf);
        }
        self.pairs_clear(leaf);
        self.free_nodes.push(leaf);
    }

    /// One step's broad phase: re-inserts the dynamic shapes that left their boxes (`bb(shape)` gives a
    /// shape's current tight box and its grown one) and appends the candidate pairs to `out` in
    /// Chipmunk's order.
    pub(crate) fn reindex_query(&mut self, bb: impl Fn(usize) -> (Bb, Bb), out: &mut Vec<Query>) {
        if self.dynamic_root == NONE {
            return;
        }
        let order: Vec<usize> = self.leaves.nodes().collect();
        for leaf in order {
            let shape = self.nodes[leaf].shape.expect("a leaf");
            let (tight, grown) = bb(shape);
            if !self.nodes[leaf].bb.contains(&tight) {
                self.nodes[leaf].bb = grown;
                let root = self.subtree_remove(self.dynamic_root, leaf);
                self.dynamic_root = self.subtree_insert(root, leaf);
                self.pairs_clear(leaf);
                self.nodes[leaf].stamp = self.stamp;
            }
        }
        self.mark_subtree(self.dynamic_root, &mut Some(out));
        self.stamp += 1;
    }

    /// Stores the narrow phase's collision id for `pair`.
    pub(crate) fn set_pair_id(&mut self, pair: usize, id: u32) {
        self.pairs[pair].id = id;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bb(l: f64, b: f64, r: f64, t: f64) -> Bb {
        Bb { l, b, r, t }
    }

    #[test]
    fn the_leaf_set_iterates_bins_in_order_and_newest_first() {
        let mut s = LeafSet::new();
        for h in [0u64, 5, 1] {
            s.insert(h, h as usize);
        }
        // 5 bins: 0 and 5 share bin 0 (5 pushed in front), 1 in bin 1.
        assert_eq!(s.nodes().collect::<Vec<_>>(), vec![5, 0, 1]);
        for h in [2u64, 3] {
            s.insert(h, h as usize);
        }
        // The fifth entry grows the table to 13 bins: every shape in its own bin.
        assert_eq!(s.bins.len(), 13);
        assert_eq!(s.nodes().collect::<Vec<_>>(), vec![0, 1, 2, 3, 5]);
        s.remove(2);
        assert_eq!(s.nodes().collect::<Vec<_>>(), vec![0, 1, 3, 5]);
    }

    #[test]
    fn a_resting_pair_reports_the_older_leaf_first_and_a_moved_leaf_itself_first() {
        let mut index = Index::new();
        // A static floor, then a dynamic box resting on it.
        index.insert_static(0, bb(0.0, 0.0, 100.0, 10.0));
        let dyn_bb = bb(40.0, 9.0, 60.0, 29.0);
        index.insert_dynamic(1, 1, dyn_bb.grown(crate::vect::Vect::ZERO));
        let mut out = Vec::new();
        index.reindex_query(
            |_| (dyn_bb, dyn_bb.grown(crate::vect::Vect::ZERO)),
            &mut out,
        );
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].a, out[0].b, out[0].pair.is_some()), (0, 1, true));
        index.set_pair_id(out[0].pair.unwrap(), 7);
        out.clear();
        index.reindex_query(
            |_| (dyn_bb, dyn_bb.grown(crate::vect::Vect::ZERO)),
            &mut out,
        );
        assert_eq!((out[0].a, out[0].b, out[0].id), (0, 1, 7));
        // The box leaves its tree box: re-inserted, it reports itself first, without an id.
        let moved = bb(40.0, 5.0, 60.0, 25.0);
        out.clear();
        index.reindex_query(|_| (moved, moved.grown(crate::vect::Vect::ZERO)), &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(
            (out[0].a, out[0].b, out[0].id, out[0].pair),
            (1, 0, 0, None)
        );
        // Next step the new pair (static first) is reported from the list.
        out.clear();
        index.reindex_query(|_| (moved, moved.grown(crate::vect::Vect::ZERO)), &mut out);
        assert_eq!((out[0].a, out[0].b, out[0].pair.is_some()), (0, 1, true));
        index.remove(0, 0, true);
        out.clear();
        index.reindex_query(|_| (moved, moved.grown(crate::vect::Vect::ZERO)), &mut out);
        assert!(out.is_empty());
    }
}
