//! A BVH over 3-D points for exact nearest-neighbour search: the points are sorted along a
//! Morton curve and cut into `Leaf` blocks of consecutive points; obvhs builds its BVH over
//! the blocks' boxes (`LEAF_LANES` times fewer primitives than points: a faster build and a
//! tree that stays in cache), which is then laid out as one cache line per inner node.
//!
//! A search serves a `Group` of queries with one depth-first traversal: nearer
//! child first, a child skipped when its box is no nearer to the group's box than the group's
//! worst neighbour so far. At a leaf each query is checked against the leaf's box before the
//! leaf's points are scanned.
//!
//! The boxes are f32, rounded outwards so they contain their f64 points; every distance is
//! computed in f64 from the original coordinates, so the result equals brute force.

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::bvh2::Bvh2;
use obvhs::BvhBuildParams;
use rayon::prelude::*;
use std::time::Duration;

use super::block::{
    larger, max_lane, min_lane, Block, Bounds, Group, Leaf, GROUP_LANES, LEAF_LANES,
};
use super::morton::morton_order;

/// Marks a leaf child in `Pair::child`.
const LEAF: u32 = 1 << 31;

/// Both children of one inner node of the obvhs BVH, in one cache line: their boxes (per axis,
/// per child) and, per child, the index of its own pair (inner) or `LEAF` | the first of its
/// slots in `PointBvh::slots` (leaf).
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
struct Pair {
    lo: [[f32; 2]; 3],
    hi: [[f32; 2]; 3],
    child: [u32; 2],
    blocks: [u32; 2],
}

impl Pair {
    #[inline(always)]
    fn child_box(&self, c: usize) -> ([f64; 3], [f64; 3]) {
        let axis = |a: usize| (f64::from(self.lo[a][c]), f64::from(self.hi[a][c]));
        let ((x0, x1), (y0, y1), (t0, t1)) = (axis(0), axis(1), axis(2));
        ([x0, y0, t0], [x1, y1, t1])
    }

    /// Squared distances from `group` to both children's boxes: lower bounds for every query
    /// in the group and every point below the child.
    #[inline(always)]
    fn distances_sq(&self, group: &Bounds) -> [f64; 2] {
        let mut d_sq = [0.0; 2];
        for (c, d) in d_sq.iter_mut().enumerate() {
            let mut g = [0.0; 3];
            for (axis, g) in g.iter_mut().enumerate() {
                // The gap between two intervals: how far the group lies below or above the box.
                let below = f64::from(self.lo[axis][c]) - group.hi[axis];
                let above = group.lo[axis] - f64::from(self.hi[axis][c]);
                *g = larger(larger(below, above), 0.0);
            }
            *d = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
        }
        d_sq
    }
}

/// The nearest point found so far for each query lane of a group: its squared distance
/// (polarity offset included), where it is, and the polarity offset it was found with.
#[derive(Clone, Copy, Debug)]
pub struct Neighbours {
    pub d_sq: [f64; GROUP_LANES],
    pub at: Group,
    pub offset_sq: [f64; GROUP_LANES],
}

impl Neighbours {
    /// None found yet.
    pub const NONE: Self = Self {
        d_sq: [f64::INFINITY; GROUP_LANES],
        at: Block {
            x: [0.0; GROUP_LANES],
            y: [0.0; GROUP_LANES],
            t: [0.0; GROUP_LANES],
        },
        offset_sq: [f64::INFINITY; GROUP_LANES],
    };

    /// Offers each lane of `group` the point `p` (found with `offset_sq`).
    #[inline]
    pub fn offer(&mut self, group: &Group, p: [f64; 3], offset_sq: f64) {
        let d_sq = group.distances_sq(p);
        for lane in 0..GROUP_LANES {
            let d_sq = d_sq[lane] + offset_sq;
            if d_sq < self.d_sq[lane] {
                self.set(lane, d_sq, p, offset_sq);
            }
        }
    }

    #[inline(always)]
    fn set(&mut self, lane: usize, d_sq: f64, p: [f64; 3], offset_sq: f64) {
        self.d_sq[lane] = d_sq;
        (self.at.x[lane], self.at.y[lane], self.at.t[lane]) = (p[0], p[1], p[2]);
        self.offset_sq[lane] = offset_sq;
    }
}

/// A BVH over 3-D points: Morton-ordered blocks of points that are its primitives.
pub struct PointBvh {
    /// The tree's inner nodes; `pairs[0]` holds the root's children. Empty when the root is
    /// itself a leaf (one block).
    pairs: Vec<Pair>,
    /// The block ids of the leaves (obvhs's `primitive_indices`).
    slots: Vec<u32>,
    /// The points along the Morton curve in leaf blocks, the last one padded.
    blocks: Vec<Leaf>,
    /// `order[k]`: the input id of point k along the curve.
    order: Vec<u32>,
}

impl PointBvh {
    /// A BVH over `points`; None when there are none.
    pub fn build(points: &[[f64; 3]]) -> Option<Self> {
        let ids: Vec<u32> = (0..points.len() as u32).collect();
        Self::build_over(points, &ids)
    }

    /// A BVH over the points `ids` of `points`; None when `ids` is empty. `order` then holds
    /// ids of `points`.
    pub fn build_over(points: &[[f64; 3]], ids: &[u32]) -> Option<Self> {
        if ids.is_empty() {
            return None;
        }
        let order = morton_order(points, ids);
        let blocks: Vec<Leaf> = order
            .par_chunks(LEAF_LANES)
            .map(|ids| Leaf::gather(points, ids))
            .collect();
        let boxes: Vec<Aabb> = blocks.par_iter().map(|b| outward(&b.bounds())).collect();
        // Measured: slower presets (more reinsertion, wider search) do not speed up the queries.
        let params = BvhBuildParams {
            max_prims_per_leaf: 1,
            ..BvhBuildParams::fastest_build()
        };
        let bvh = build_bvh2(&boxes, params, &mut Duration::default());
        Some(Self {
            pairs: pairs_of(&bvh),
            slots: bvh.primitive_indices,
            blocks,
            order,
        })
    }

    pub fn len(&self) -> usize {
        self.order.len()
    }

    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// The points as blocks along the Morton curve, and the input id of each point.
    pub fn blocks(&self) -> (&[Leaf], &[u32]) {
        (&self.blocks, &self.order)
    }

    /// The squared distance from q to its nearest point (plus `offset_sq`).
    pub fn nearest_sq(&self, q: [f64; 3], offset_sq: f64, stack: &mut Vec<(f64, u32)>) -> f64 {
        let group = Group::gather(&[q], &[0]);
        let mut found = Neighbours::NONE;
        // The other lanes hold copies of q: nothing is closer than -inf, so they search nothing.
        found.d_sq[1..].fill(f64::NEG_INFINITY);
        self.search(&group, offset_sq, &mut found, stack);
        found.d_sq[0]
    }

    /// For each query lane of `group`, lowers `found` to the nearest point v with
    /// ||q - v||^2 + offset_sq below what it holds, if there is one.
    ///
    /// Sharing one descent between the nearby queries of a group is what makes this faster
    /// than one traversal per query. `stack` is scratch.
    pub fn search(
        &self,
        group: &Group,
        offset_sq: f64,
        found: &mut Neighbours,
        stack: &mut Vec<(f64, u32)>,
    ) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: this CPU has AVX2, checked just above.
            return unsafe { self.search_avx2(group, offset_sq, found, stack) };
        }
        self.search_portable(group, offset_sq, found, stack);
    }

    /// `search` compiled for AVX2: the distance kernels then work on 4 lanes at a time
    /// instead of 2 (same operations in the same order, so the same results).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn search_avx2(
        &self,
        group: &Group,
        offset_sq: f64,
        found: &mut Neighbours,
        stack: &mut Vec<(f64, u32)>,
    ) {
        self.search_portable(group, offset_sq, found, stack);
    }

    /// `search` for any CPU; always inlined, so that it takes the caller's instruction set.
    #[inline(always)]
    fn search_portable(
        &self,
        group: &Group,
        offset_sq: f64,
        found: &mut Neighbours,
        stack: &mut Vec<(f64, u32)>,
    ) {
        if self.pairs.is_empty() {
            self.visit_leaf(&[0], group, None, offset_sq, found);
            return;
        }
        let bounds = group.bounds();
        let mut worst = max_lane(&found.d_sq);
        stack.clear();
        stack.push((offset_sq, 0));
        while let Some((bound_sq, index)) = stack.pop() {
            if bound_sq >= worst {
                continue;
            }
            let pair = &self.pairs[index as usize];
            let d_sq = pair.distances_sq(&bounds).map(|d| d + offset_sq);
            let (near, far) = if d_sq[0] <= d_sq[1] { (0, 1) } else { (1, 0) };
            // Inner children go on the stack, farther first so the nearer is searched first.
            for c in [far, near] {
                if pair.child[c] & LEAF == 0 && d_sq[c] < worst {
                    stack.push((d_sq[c], pair.child[c]));
                }
            }
            for c in [near, far] {
                if pair.child[c] & LEAF == 0 || d_sq[c] >= worst {
                    continue;
                }
                let first = (pair.child[c] & !LEAF) as usize;
                let slots = &self.slots[first..first + pair.blocks[c] as usize];
                self.visit_leaf(slots, group, Some(pair.child_box(c)), offset_sq, found);
                worst = max_lane(&found.d_sq);
            }
        }
    }

    /// Scans the blocks `slots` for every query lane whose distance to the leaf's box (when
    /// given) could beat its neighbour so far.
    #[inline(always)]
    fn visit_leaf(
        &self,
        slots: &[u32],
        group: &Group,
        leaf_box: Option<([f64; 3], [f64; 3])>,
        offset_sq: f64,
        found: &mut Neighbours,
    ) {
        let lower_sq = match leaf_box {
            Some((lo, hi)) => group.box_distances_sq(lo, hi),
            None => [0.0; GROUP_LANES],
        };
        for (lane, &lower_sq) in lower_sq.iter().enumerate() {
            if lower_sq + offset_sq >= found.d_sq[lane] {
                continue;
            }
            let q = group.point(lane);
            for &block in slots {
                self.scan(&self.blocks[block as usize], q, lane, offset_sq, found);
            }
        }
    }

    /// Brute force over one leaf for one query lane, in f64.
    #[inline(always)]
    fn scan(&self, leaf: &Leaf, q: [f64; 3], lane: usize, offset_sq: f64, found: &mut Neighbours) {
        let d_sq = leaf.distances_sq(q);
        let nearest = min_lane(&d_sq);
        if nearest + offset_sq < found.d_sq[lane] {
            // Rare (the bound mostly holds), so finding which lane it was can be a plain search.
            let j = d_sq.iter().position(|&d| d == nearest).unwrap_or(0);
            found.set(lane, nearest + offset_sq, leaf.point(j), offset_sq);
        }
    }
}

/// The f32 box that contains `bounds`: each bound rounded outwards.
fn outward(bounds: &Bounds) -> Aabb {
    let down = |v: f64| {
        let f = v as f32;
        // f is the nearest f32, within half a unit in the last place of v; one unit less
        // (f |f| epsilon is at least that) is below v.
        if f64::from(f) > v {
            f - f.abs() * f32::EPSILON - f32::MIN_POSITIVE
        } else {
            f
        }
    };
    let up = |v: f64| -down(-v);
    let (lo, hi) = (bounds.lo, bounds.hi);
    Aabb::new(
        Vec3A::new(down(lo[0]), down(lo[1]), down(lo[2])),
        Vec3A::new(up(hi[0]), up(hi[1]), up(hi[2])),
    )
}

/// obvhs's node array as `Pair`s, depth-first from the root; empty when the root is a leaf.
fn pairs_of(bvh: &Bvh2) -> Vec<Pair> {
    if bvh.nodes.is_empty() || bvh.nodes[0].is_leaf() {
        return Vec::new();
    }
    let mut pairs = vec![Pair::default()];
    // (obvhs index of an inner node, the pair that will hold its children)
    let mut todo = vec![(0usize, 0usize)];
    while let Some((inner, slot)) = todo.pop() {
        let first = bvh.nodes[inner].first_index as usize;
        let mut pair = Pair::default();
        for c in 0..2 {
            let node = &bvh.nodes[first + c];
            let (lo, hi) = (node.aabb().min.to_array(), node.aabb().max.to_array());
            for axis in 0..3 {
                pair.lo[axis][c] = lo[axis];
                pair.hi[axis][c] = hi[axis];
            }
            if node.is_leaf() {
                pair.child[c] = LEAF | node.first_index;
                pair.blocks[c] = node.prim_count;
            } else {
                pair.child[c] = pairs.len() as u32;
                pairs.push(Pair::default());
                todo.push((first + c, pair.child[c] as usize));
            }
        }
        pairs[slot] = pair;
    }
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outward_boxes_contain_their_f64_bounds() {
        for v in [
            0.0,
            1e-3,
            0.1,
            1.0 / 3.0,
            99.99999,
            1000.0 * (2.0 / 3.0),
            -7.3,
        ] {
            let aabb = outward(&Bounds {
                lo: [v; 3],
                hi: [v; 3],
            });
            assert!(
                f64::from(aabb.min.x) <= v && v <= f64::from(aabb.max.x),
                "{v}"
            );
        }
    }

    #[test]
    fn single_query_search_finds_the_nearest() {
        let points: Vec<[f64; 3]> = (0..100).map(|i| [i as f64, 0.0, 0.0]).collect();
        let tree = PointBvh::build(&points).unwrap();
        let mut stack = Vec::new();
        assert_eq!(tree.nearest_sq([41.25, 1.0, 0.0], 0.0, &mut stack), 1.0625);
        assert_eq!(tree.nearest_sq([-3.0, 0.0, 0.0], 2.0, &mut stack), 11.0);
    }
}
