//! Exact nearest-neighbour distances between event point clouds, over obvhs BVHs.
//!
//! d(u, Q) = min over v in Q of ||u - v|| in (x~, y~, p~, t~). Within one stream p~ takes one
//! value per polarity, so the 4-D search is two 3-D searches: one per polarity of the target,
//! each with its polarity offset dp added in quadrature, d^2 = ||u - v||_xyt^2 + dp^2.
//!
//! Queries run along their own Morton curve in groups (consecutive leaf blocks of their own
//! tree) that share one traversal of the target tree (see `bvh`), the same polarity first; the
//! previous group's neighbours give each group a starting bound. Those bounds are real
//! distances, so the result stays exact.

use rayon::prelude::*;

use super::block::{Group, GROUP_LANES, LEAF_LANES};
use super::bvh::{Neighbours, PointBvh};
use super::normalize::Cloud;

/// How polarity enters the nearest-neighbour search.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PolarityMatching {
    /// PECS: p~ is a coordinate, an opposite-polarity neighbour costs its p~ offset.
    Coordinate,
    /// Only same-polarity events match, over (x~, y~, t~); no match gives an infinite distance.
    Separate,
}

/// A cloud split by polarity, one BVH per polarity present, each with its p~; the trees'
/// point ids are the cloud's indices.
pub struct PolarityIndex {
    /// Indexed by polarity: 0 OFF, 1 ON.
    trees: [Option<PointBvh>; 2],
    p_coord: [f64; 2],
    len: usize,
}

/// Per-worker state: the traversal stack and the previous group's neighbours.
struct Scratch {
    stack: Vec<(f64, u32)>,
    previous: Neighbours,
}

impl PolarityIndex {
    pub fn build(cloud: &Cloud) -> Self {
        let mut members: [Vec<u32>; 2] = [Vec::new(), Vec::new()];
        for (i, &on) in cloud.on.iter().enumerate() {
            members[usize::from(on)].push(i as u32);
        }
        let (off, on) = rayon::join(
            || PointBvh::build_over(&cloud.xyt, &members[0]),
            || PointBvh::build_over(&cloud.xyt, &members[1]),
        );
        Self {
            trees: [off, on],
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
    pub fn nearest_distances(
        &self,
        queries: &PolarityIndex,
        matching: PolarityMatching,
    ) -> Vec<f64> {
        let mut out = vec![f64::NAN; queries.len];
        for (g, tree) in queries.trees.iter().enumerate() {
            let Some(tree) = tree else { continue };
            let p = queries.p_coord[g];
            let (blocks, order) = tree.blocks();
            let mut sorted = vec![f64::NAN; order.len()];
            blocks
                .par_chunks(GROUP_LANES / LEAF_LANES)
                .zip(sorted.par_chunks_mut(GROUP_LANES))
                .with_min_len(16)
                .for_each_init(
                    || Scratch {
                        stack: Vec::with_capacity(128),
                        previous: Neighbours::NONE,
                    },
                    |scratch, (blocks, distances)| {
                        let group = Group::concat(blocks);
                        self.nearest_group(&group, g, p, matching, scratch, distances)
                    },
                );
            for (&id, value) in order.iter().zip(sorted) {
                out[id as usize] = value;
            }
        }
        out
    }

    /// Distances from the queries `group` of polarity `g` (0 OFF, 1 ON) and polarity
    /// coordinate `p` to their nearest points here, into `distances`; infinite when no point
    /// may match (separate polarities).
    fn nearest_group(
        &self,
        group: &Group,
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
        let mut found = Neighbours::NONE;
        // Warm start: the previous group lies close by, so its neighbours are near these too.
        // They were found for queries of this polarity too (one pass per polarity), so their
        // offsets and the polarity rule hold here.
        let previous = &scratch.previous;
        for lane in (0..GROUP_LANES).filter(|&lane| previous.d_sq[lane].is_finite()) {
            found.offer(group, previous.at.point(lane), previous.offset_sq[lane]);
        }
        // Same polarity first: it is usually nearer, so the opposite tree is pruned at its root.
        for target in [g, 1 - g] {
            if let Some(tree) = self.trees[target].as_ref().filter(|_| allowed(target)) {
                tree.search(group, offset_sq(target), &mut found, &mut scratch.stack);
            }
        }
        scratch.previous = found;
        for (d, d_sq) in distances.iter_mut().zip(found.d_sq) {
            *d = d_sq.sqrt();
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

#[cfg(test)]
mod tests {
    use super::*;

    fn distance_sq(a: [f64; 3], b: [f64; 3]) -> f64 {
        let (dx, dy, dt) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
        dx * dx + dy * dy + dt * dt
    }

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
    fn identical_points_are_at_distance_zero() {
        let mut rng = SplitMix(7);
        let points = cloud(1000, 1e6, &mut rng);
        let d = nearest_distances(&points, &points, PolarityMatching::Coordinate);
        assert!(d.iter().all(|&v| v == 0.0));
    }
}
