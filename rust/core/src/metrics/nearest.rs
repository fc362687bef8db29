//! Exact nearest-neighbour distances between event point clouds, over obvhs BVHs.
//!
//! d(u, Q) = min over v in Q of ||u - v|| in (x~, y~, p~, t~). Within one stream p~ takes one
//! value per polarity, so the 4-D search is two 3-D searches: one per polarity of the target,
//! each with its polarity offset dp added in quadrature, d^2 = ||u - v||_xyt^2 + dp^2.
//!
//! Points are sorted along a Morton curve and cut into chunks of `CHUNK` consecutive points; the
//! obvhs BVH is built over the chunks' boxes (16x fewer primitives than points: a faster build
//! and a smaller tree that stays in cache), then laid out as one cache line per inner node.
//! Queries run along their own Morton curve in groups of `GROUP` that share one traversal
//! (box-to-box bound, nearer child first, prune), each checked against a leaf's box before its
//! points are scanned, with the previous group's neighbours as a starting bound.
//!
//! The BVH stores f32 boxes; they only prune, widened by a margin that covers the f32 rounding
//! of every coordinate, and every distance is computed in f64 from the original coordinates,
//! so the result equals brute force.

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::bvh2::Bvh2;
use obvhs::BvhBuildParams;
use rayon::prelude::*;
use std::time::Duration;

use super::normalize::Cloud;

/// How polarity enters the nearest-neighbour search.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolarityMatching {
    /// PECS: p~ is a coordinate, an opposite-polarity neighbour costs its p~ offset.
    Coordinate,
    /// Only same-polarity events match, over (x~, y~, t~); no match gives an infinite distance.
    Separate,
}

/// Points per BVH primitive (measured on 1e6-event streams: 16 beats 4, 8 and 32).
const CHUNK: usize = 16;

/// Marks a leaf child in `Pair::child`.
const LEAF: u32 = 1 << 31;

/// Both children of one inner node of the obvhs BVH, in one cache line: their f32 boxes (per
/// axis, per child) and, per child, the index of its own pair (inner) or `LEAF` | the first of
/// its slots in `PointBvh::slots` (leaf).
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
struct Pair {
    lo: [[f32; 2]; 3],
    hi: [[f32; 2]; 3],
    child: [u32; 2],
    chunks: [u32; 2],
}

/// A BVH over 3-D points: Morton-ordered f64 points, grouped in chunks that are its primitives.
///
/// obvhs builds the tree (PLOC over the chunks' f32 boxes); it is then laid out as `Pair`s in
/// depth-first order, so a traversal step reads one cache line for both children's bounds.
pub struct PointBvh {
    /// The tree's inner nodes; `pairs[0]` holds the root's children. Empty when the root is
    /// itself a leaf (at most one chunk).
    pairs: Vec<Pair>,
    /// The chunk ids of the leaves (obvhs's `primitive_indices`).
    slots: Vec<u32>,
    /// The points along the Morton curve; chunk c is `points[c * CHUNK..][..CHUNK]`.
    points: Vec<[f64; 3]>,
    /// `order[k]`: the input index of `points[k]`.
    order: Vec<u32>,
    /// Widens every f32 box so it contains the f64 points it was built from.
    margin: f64,
}

impl PointBvh {
    /// A BVH over `points`; None when there are none.
    pub fn build(points: &[[f64; 3]]) -> Option<Self> {
        if points.is_empty() {
            return None;
        }
        let order = morton_order(points);
        let sorted: Vec<[f64; 3]> = order.iter().map(|&i| points[i as usize]).collect();
        let boxes: Vec<Aabb> = sorted
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk
                    .iter()
                    .fold(Aabb::INVALID, |mut aabb, &p| *aabb.extend(to_f32(p)))
            })
            .collect();
        // Measured: slower presets (more reinsertion, wider search) do not speed up the queries.
        let params = BvhBuildParams {
            max_prims_per_leaf: 1,
            ..BvhBuildParams::fastest_build()
        };
        let bvh = build_bvh2(&boxes, params, &mut Duration::default());
        // Rounding to f32 moves a coordinate c by at most |c| 2^-24; 2^-20 leaves a wide safety
        // factor for the f64 arithmetic of the bound itself.
        let largest = points.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()));
        let margin = largest * 2f64.powi(-20) + f64::MIN_POSITIVE;
        Some(Self {
            pairs: pairs_of(&bvh),
            slots: bvh.primitive_indices,
            points: sorted,
            order,
            margin,
        })
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The points in the tree's (Morton) order, with their input indices.
    pub fn ordered_points(&self) -> (&[[f64; 3]], &[u32]) {
        (&self.points, &self.order)
    }

    /// For each query q_j, lowers `best[j]` to the nearest point v with
    /// ||q_j - v||^2 + offset_sq < best[j].d_sq, if any.
    ///
    /// One depth-first traversal serves a group of queries that lie close together
    /// (consecutive along a Morton curve), nearer child first: a child is skipped when the
    /// distance between its (widened) box and the group's box, plus `offset_sq`, cannot beat the
    /// group's worst best. At a leaf each query is checked against the leaf's box before its
    /// points are scanned. Sharing the descent is what makes this faster than one traversal per
    /// query. `stack` is scratch.
    pub fn nearest_group(
        &self,
        queries: &[[f64; 3]],
        offset_sq: f64,
        best: &mut [Best],
        stack: &mut Vec<(f64, u32)>,
    ) {
        debug_assert_eq!(queries.len(), best.len());
        let worst_of = |best: &[Best]| best.iter().fold(0.0f64, |w, b| w.max(b.d_sq));
        if self.pairs.is_empty() {
            for (q, b) in queries.iter().zip(best.iter_mut()) {
                self.scan(&self.points, *q, offset_sq, b);
            }
            return;
        }
        let group = Bounds::of(queries);
        let mut worst = worst_of(best);
        stack.clear();
        stack.push((offset_sq, 0));
        while let Some((bound_sq, index)) = stack.pop() {
            if bound_sq >= worst {
                continue;
            }
            let pair = &self.pairs[index as usize];
            let bounds = self.box_distances_sq(pair, &group, offset_sq);
            let (near, far) = if bounds[0] <= bounds[1] {
                (0, 1)
            } else {
                (1, 0)
            };
            // Inner children go on the stack, farther first so the nearer is searched first.
            for c in [far, near] {
                if pair.child[c] & LEAF == 0 && bounds[c] < worst {
                    stack.push((bounds[c], pair.child[c]));
                }
            }
            for c in [near, far] {
                if pair.child[c] & LEAF == 0 || bounds[c] >= worst {
                    continue;
                }
                let first = (pair.child[c] & !LEAF) as usize;
                let slots = &self.slots[first..first + pair.chunks[c] as usize];
                for (q, b) in queries.iter().zip(best.iter_mut()) {
                    let point = Bounds { lo: *q, hi: *q };
                    if self.child_distance_sq(pair, c, &point) + offset_sq >= b.d_sq {
                        continue;
                    }
                    for &chunk in slots {
                        let start = chunk as usize * CHUNK;
                        let end = (start + CHUNK).min(self.points.len());
                        self.scan(&self.points[start..end], *q, offset_sq, b);
                    }
                }
                worst = worst_of(best);
            }
        }
    }

    /// Brute force over some points, in f64 (the best is written once, after the loop).
    #[inline]
    fn scan(&self, points: &[[f64; 3]], q: [f64; 3], offset_sq: f64, best: &mut Best) {
        let (mut d_best, mut i_best) = (best.d_sq, usize::MAX);
        for (i, v) in points.iter().enumerate() {
            let d_sq = distance_sq(q, *v) + offset_sq;
            if d_sq < d_best {
                (d_best, i_best) = (d_sq, i);
            }
        }
        if i_best != usize::MAX {
            *best = Best {
                d_sq: d_best,
                point: points[i_best],
            };
        }
    }

    /// The squared distance from q to its nearest point (plus `offset_sq`).
    pub fn nearest_sq(&self, q: [f64; 3], offset_sq: f64, stack: &mut Vec<(f64, u32)>) -> f64 {
        let mut best = [Best::NONE];
        self.nearest_group(&[q], offset_sq, &mut best, stack);
        best[0].d_sq
    }

    /// Squared distances between both children's boxes widened by the margin and `group`
    /// (plus `offset_sq`): lower bounds for every query in the group and point below the child.
    #[inline]
    fn box_distances_sq(&self, pair: &Pair, group: &Bounds, offset_sq: f64) -> [f64; 2] {
        [
            self.child_distance_sq(pair, 0, group) + offset_sq,
            self.child_distance_sq(pair, 1, group) + offset_sq,
        ]
    }

    #[inline]
    fn child_distance_sq(&self, pair: &Pair, c: usize, group: &Bounds) -> f64 {
        let mut sum = 0.0;
        for axis in 0..3 {
            let below = (f64::from(pair.lo[axis][c]) - self.margin) - group.hi[axis];
            let above = group.lo[axis] - (f64::from(pair.hi[axis][c]) + self.margin);
            let gap = below.max(above).max(0.0);
            sum += gap * gap;
        }
        sum
    }
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
                pair.chunks[c] = node.prim_count;
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

/// An axis-aligned box in f64.
struct Bounds {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Bounds {
    fn of(points: &[[f64; 3]]) -> Self {
        let mut bounds = Bounds {
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
        };
        for p in points {
            for (axis, &c) in p.iter().enumerate() {
                bounds.lo[axis] = bounds.lo[axis].min(c);
                bounds.hi[axis] = bounds.hi[axis].max(c);
            }
        }
        bounds
    }
}

/// The nearest point found so far and its squared distance (polarity offset included).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Best {
    pub d_sq: f64,
    pub point: [f64; 3],
}

impl Best {
    pub const NONE: Self = Self {
        d_sq: f64::INFINITY,
        point: [f64::NAN; 3],
    };
}

/// A cloud split by polarity, one BVH per polarity present, each with its p~ and the cloud
/// index of each of its points.
pub struct PolarityIndex {
    /// Indexed by polarity: 0 OFF, 1 ON.
    trees: [Option<PointBvh>; 2],
    /// `members[g][i]`: the cloud index of input point i of tree g.
    members: [Vec<u32>; 2],
    p_coord: [f64; 2],
    len: usize,
}

/// Queries searched together: consecutive points along the queries' Morton curve (measured on
/// 1e6-event streams: 8 and 16 beat 1, 4 and 32).
const GROUP: usize = 8;

/// Per-worker state: the traversal stack and the previous group's neighbours (with their tree).
struct Scratch {
    stack: Vec<(f64, u32)>,
    previous: Vec<(usize, [f64; 3])>,
}

impl PolarityIndex {
    pub fn build(cloud: &Cloud) -> Self {
        let mut members: [Vec<u32>; 2] = [Vec::new(), Vec::new()];
        for (i, &on) in cloud.on.iter().enumerate() {
            members[usize::from(on)].push(i as u32);
        }
        let points = |g: usize| -> Vec<[f64; 3]> {
            members[g].iter().map(|&i| cloud.xyt[i as usize]).collect()
        };
        let (off, on) = rayon::join(
            || PointBvh::build(&points(0)),
            || PointBvh::build(&points(1)),
        );
        Self {
            trees: [off, on],
            members,
            p_coord: cloud.p_coord,
            len: cloud.xyt.len(),
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// For every point of `queries`, the distance to its nearest point here (rayon-parallel),
    /// in the queries' cloud order.
    ///
    /// Queries run in groups of consecutive points along their own Morton curve, one traversal
    /// per group; the previous group's neighbours give each group a tight starting bound. Those
    /// bounds are real distances, so the result stays exact.
    pub fn nearest_distances(
        &self,
        queries: &PolarityIndex,
        matching: PolarityMatching,
    ) -> Vec<f64> {
        let mut out = vec![f64::NAN; queries.len];
        for (g, tree) in queries.trees.iter().enumerate() {
            let Some(tree) = tree else { continue };
            let p = queries.p_coord[g];
            let (points, order) = tree.ordered_points();
            let mut sorted = vec![f64::NAN; points.len()];
            points
                .par_chunks(GROUP)
                .zip(sorted.par_chunks_mut(GROUP))
                .with_min_len(256)
                .for_each_init(
                    || Scratch {
                        stack: Vec::with_capacity(128),
                        previous: Vec::new(),
                    },
                    |scratch, (group, distances)| {
                        self.nearest_group(group, g, p, matching, scratch, distances)
                    },
                );
            for (&input, value) in order.iter().zip(sorted) {
                out[queries.members[g][input as usize] as usize] = value;
            }
        }
        out
    }

    /// Distances from the points `group` of polarity `g` (0 OFF, 1 ON) and polarity coordinate
    /// `p` to their nearest points here, into `distances`; infinite when no point may match
    /// (separate polarities).
    fn nearest_group(
        &self,
        group: &[[f64; 3]],
        g: usize,
        p: f64,
        matching: PolarityMatching,
        scratch: &mut Scratch,
        distances: &mut [f64],
    ) {
        let offset_sq = |target: usize| match matching {
            PolarityMatching::Coordinate => (p - self.p_coord[target]).powi(2),
            PolarityMatching::Separate => 0.0,
        };
        let allowed = |target: usize| matching == PolarityMatching::Coordinate || target == g;
        let mut best = [Best::NONE; GROUP];
        let mut tree_of = [usize::MAX; GROUP];
        let best = &mut best[..group.len()];
        // Warm start: the previous group lies close by, so its neighbours are near these too.
        for &(target, point) in scratch.previous.iter().filter(|(t, _)| allowed(*t)) {
            for ((q, b), t) in group.iter().zip(best.iter_mut()).zip(tree_of.iter_mut()) {
                let d_sq = distance_sq(*q, point) + offset_sq(target);
                if d_sq < b.d_sq {
                    *b = Best { d_sq, point };
                    *t = target;
                }
            }
        }
        // Same polarity first: it is usually nearer, so the opposite tree is pruned at its root.
        for target in [g, 1 - g] {
            let Some(tree) = self.trees[target].as_ref().filter(|_| allowed(target)) else {
                continue;
            };
            let mut before = [0.0; GROUP];
            for (old, b) in before.iter_mut().zip(best.iter()) {
                *old = b.d_sq;
            }
            tree.nearest_group(group, offset_sq(target), best, &mut scratch.stack);
            for ((b, t), old) in best.iter().zip(tree_of.iter_mut()).zip(before) {
                if b.d_sq < old {
                    *t = target;
                }
            }
        }
        scratch.previous.clear();
        for (b, &t) in best.iter().zip(&tree_of) {
            if t != usize::MAX {
                scratch.previous.push((t, b.point));
            }
        }
        for (d, b) in distances.iter_mut().zip(best.iter()) {
            *d = b.d_sq.sqrt();
        }
    }
}

/// For every point of `queries`, the distance to its nearest point of `targets`.
pub fn nearest_distances(queries: &Cloud, targets: &Cloud, matching: PolarityMatching) -> Vec<f64> {
    let (queries, targets) = rayon::join(
        || PolarityIndex::build(queries),
        || PolarityIndex::build(targets),
    );
    targets.nearest_distances(&queries, matching)
}

#[inline]
fn distance_sq(a: [f64; 3], b: [f64; 3]) -> f64 {
    let (dx, dy, dt) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dt * dt
}

/// Indices of `points` sorted along a 3-D Morton curve over their bounding box (ties by index).
fn morton_order(points: &[[f64; 3]]) -> Vec<u32> {
    let Bounds { lo, hi } = Bounds::of(points);
    const CELLS: f64 = ((1u64 << 21) - 1) as f64;
    let scale: Vec<f64> = (0..3)
        .map(|a| CELLS / (hi[a] - lo[a]).max(f64::MIN_POSITIVE))
        .collect();
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let cell = |axis: usize| ((p[axis] - lo[axis]) * scale[axis]).clamp(0.0, CELLS) as u64;
            (
                spread_bits(cell(0)) | spread_bits(cell(1)) << 1 | spread_bits(cell(2)) << 2,
                i as u32,
            )
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// The low 21 bits of v spread to every third bit (bit k to bit 3k).
fn spread_bits(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

fn to_f32(p: [f64; 3]) -> Vec3A {
    Vec3A::new(p[0] as f32, p[1] as f32, p[2] as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (SplitMix64) so the tests need no extra crate.
    struct SplitMix(u64);

    impl SplitMix {
        fn next_f64(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn cloud(n: usize, grid: f64, rng: &mut SplitMix) -> Cloud {
        // Points snapped to a coarse grid so there are duplicates and exact ties.
        let snap = |v: f64| (v * grid).floor() / grid;
        let xyt = (0..n)
            .map(|_| {
                [
                    snap(rng.next_f64()) * 100.0,
                    snap(rng.next_f64()) * 100.0,
                    snap(rng.next_f64()) * 1000.0,
                ]
            })
            .collect();
        let on = (0..n).map(|_| rng.next_f64() < 0.5).collect();
        Cloud {
            xyt,
            on,
            p_coord: [0.0, 100.0 / (1.0 + 1e-8)],
        }
    }

    fn brute_force(q: &Cloud, targets: &Cloud, matching: PolarityMatching) -> Vec<f64> {
        q.xyt
            .iter()
            .zip(&q.on)
            .map(|(&u, &on_u)| {
                let mut best = f64::INFINITY;
                for (&v, &on_v) in targets.xyt.iter().zip(&targets.on) {
                    let dp = q.p_coord[usize::from(on_u)] - targets.p_coord[usize::from(on_v)];
                    let d_sq = match matching {
                        PolarityMatching::Coordinate => distance_sq(u, v) + dp * dp,
                        PolarityMatching::Separate if on_u == on_v => distance_sq(u, v),
                        PolarityMatching::Separate => f64::INFINITY,
                    };
                    best = best.min(d_sq);
                }
                best.sqrt()
            })
            .collect()
    }

    #[test]
    fn equals_brute_force_on_clouds_with_duplicates_and_ties() {
        let mut rng = SplitMix(42);
        for &(n_q, n_t, grid) in &[
            (1, 1, 4.0),
            (50, 3, 3.0),
            (300, 700, 10.0),
            (500, 2000, 1e6),
        ] {
            let queries = cloud(n_q, grid, &mut rng);
            let targets = cloud(n_t, grid, &mut rng);
            for matching in [PolarityMatching::Coordinate, PolarityMatching::Separate] {
                let fast = nearest_distances(&queries, &targets, matching);
                let slow = brute_force(&queries, &targets, matching);
                for (f, s) in fast.iter().zip(&slow) {
                    assert!(f == s || (f - s).abs() <= 1e-12 * s.abs(), "{f} vs {s}");
                }
            }
        }
    }

    #[test]
    fn spread_bits_interleaves() {
        assert_eq!(spread_bits(0b111), 0b1001001);
        assert_eq!(spread_bits(0x1f_ffff), 0x1249_2492_4924_9249);
    }

    #[test]
    fn identical_points_are_at_distance_zero() {
        let mut rng = SplitMix(7);
        let points = cloud(1000, 1e6, &mut rng);
        let d = nearest_distances(&points, &points, PolarityMatching::Coordinate);
        assert!(d.iter().all(|&v| v == 0.0));
    }
}
