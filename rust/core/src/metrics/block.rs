//! Points in small blocks, stored as a structure of arrays, and the distance kernels over
//! them. The kernels are plain loops over fixed-size arrays with no branches and no calls that
//! care about NaN (`f64::min` does), so the compiler turns them into vector instructions.
//!
//! Every squared distance here is computed as (dx * dx + dy * dy) + dt * dt, in this order, in
//! f64: the box bounds below use the same order on gaps that are never larger than the real
//! differences, so by the monotonicity of IEEE rounding a bound never exceeds a distance.

/// Points per leaf block, the BVH's primitive (measured on 1e6-event streams).
pub const LEAF_LANES: usize = 32;
/// Queries per group, searched together (measured on 1e6-event streams).
pub const GROUP_LANES: usize = 32;

/// Up to `N` points (a power of two), one array per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub struct Block<const N: usize> {
    pub x: [f64; N],
    pub y: [f64; N],
    pub t: [f64; N],
}

/// The points of a BVH leaf.
pub type Leaf = Block<LEAF_LANES>;
/// A group of queries.
pub type Group = Block<GROUP_LANES>;

/// An axis-aligned box in f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub lo: [f64; 3],
    pub hi: [f64; 3],
}

impl<const N: usize> Block<N> {
    /// The points of `blocks`, one after the other (`N` / `M` of them, the last repeated when
    /// there are fewer).
    pub fn concat<const M: usize>(blocks: &[Block<M>]) -> Self {
        let mut block = Block {
            x: [0.0; N],
            y: [0.0; N],
            t: [0.0; N],
        };
        for (k, part) in (0..N / M).map(|k| (k, &blocks[k.min(blocks.len() - 1)])) {
            block.x[k * M..][..M].copy_from_slice(&part.x);
            block.y[k * M..][..M].copy_from_slice(&part.y);
            block.t[k * M..][..M].copy_from_slice(&part.t);
        }
        block
    }

    /// The points `ids` of `points` (1 to `N` of them), padded with copies of the last:
    /// a copy has the same distances as its original, so no search needs to know.
    pub fn gather(points: &[[f64; 3]], ids: &[u32]) -> Self {
        let last = points[ids[ids.len() - 1] as usize];
        let mut block = Block {
            x: [last[0]; N],
            y: [last[1]; N],
            t: [last[2]; N],
        };
        for (lane, &id) in ids.iter().enumerate() {
            let p = points[id as usize];
            (block.x[lane], block.y[lane], block.t[lane]) = (p[0], p[1], p[2]);
        }
        block
    }

    #[inline(always)]
    pub fn point(&self, lane: usize) -> [f64; 3] {
        [self.x[lane], self.y[lane], self.t[lane]]
    }

    /// Squared distances from `q` to every lane.
    #[inline(always)]
    // Indexed loops over the fixed arrays: measured to vectorise better than zipped iterators.
    #[allow(clippy::needless_range_loop)]
    pub fn distances_sq(&self, q: [f64; 3]) -> [f64; N] {
        let mut d_sq = [0.0; N];
        for lane in 0..N {
            let (dx, dy, dt) = (
                self.x[lane] - q[0],
                self.y[lane] - q[1],
                self.t[lane] - q[2],
            );
            d_sq[lane] = dx * dx + dy * dy + dt * dt;
        }
        d_sq
    }

    /// Squared distances from every lane to the box (0 inside it): lower bounds of the
    /// distance from that lane to any point in the box.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)]
    pub fn box_distances_sq(&self, lo: [f64; 3], hi: [f64; 3]) -> [f64; N] {
        let mut d_sq = [0.0; N];
        for lane in 0..N {
            let gx = gap(self.x[lane], lo[0], hi[0]);
            let gy = gap(self.y[lane], lo[1], hi[1]);
            let gt = gap(self.t[lane], lo[2], hi[2]);
            d_sq[lane] = gx * gx + gy * gy + gt * gt;
        }
        d_sq
    }

    /// The smallest box around the lanes.
    #[inline(always)]
    pub fn bounds(&self) -> Bounds {
        let axis = |v: &[f64; N]| (min_lane(v), max_lane(v));
        let ((x0, x1), (y0, y1), (t0, t1)) = (axis(&self.x), axis(&self.y), axis(&self.t));
        Bounds {
            lo: [x0, y0, t0],
            hi: [x1, y1, t1],
        }
    }
}

/// How far `v` lies outside lo..hi (0 inside).
#[inline(always)]
pub fn gap(v: f64, lo: f64, hi: f64) -> f64 {
    larger(larger(lo - v, v - hi), 0.0)
}

/// The smallest lane.
#[inline(always)]
pub fn min_lane<const N: usize>(values: &[f64; N]) -> f64 {
    reduce_lanes(values, smaller)
}

/// The largest lane.
#[inline(always)]
pub fn max_lane<const N: usize>(values: &[f64; N]) -> f64 {
    reduce_lanes(values, larger)
}

/// The lanes reduced by `pick` as a tree of independent pairs rather than a running fold: one
/// vector step per level (N a power of two, so every lane takes part).
#[inline(always)]
fn reduce_lanes<const N: usize>(values: &[f64; N], pick: impl Fn(f64, f64) -> f64) -> f64 {
    const { assert!(N.is_power_of_two()) };
    let mut m = *values;
    let mut width = N / 2;
    while width > 0 {
        for lane in 0..width {
            m[lane] = pick(m[lane], m[lane + width]);
        }
        width /= 2;
    }
    m[0]
}

/// a < b ? a : b, which maps to one vector instruction (unlike `f64::min`, whose NaN rule
/// costs extra ones). Inputs here are never NaN.
#[inline(always)]
fn smaller(a: f64, b: f64) -> f64 {
    if a < b {
        a
    } else {
        b
    }
}

/// a > b ? a : b (see `smaller`).
#[inline(always)]
pub fn larger(a: f64, b: f64) -> f64 {
    if a > b {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gather_pads_with_the_last_point() {
        let points = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let block = Leaf::gather(&points, &[1, 0]);
        assert_eq!(block.point(0), [4.0, 5.0, 6.0]);
        assert_eq!(block.point(LEAF_LANES - 1), [1.0, 2.0, 3.0]);
        let d_sq = block.distances_sq([1.0, 2.0, 4.0]);
        assert_eq!(
            (d_sq[0], d_sq[1], d_sq[LEAF_LANES - 1]),
            (9.0 + 9.0 + 4.0, 1.0, 1.0)
        );
        assert_eq!(min_lane(&d_sq), 1.0);
        assert_eq!(max_lane(&d_sq), 22.0);
    }

    #[test]
    fn concat_repeats_the_last_block() {
        let a = Block::<2>::gather(&[[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], &[0, 1]);
        let b = Block::<2>::gather(&[[3.0, 0.0, 0.0]], &[0]);
        assert_eq!(
            Block::<8>::concat(&[a, b]).x,
            [1.0, 2.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0]
        );
    }

    #[test]
    fn box_distance_is_zero_inside_and_the_gap_outside() {
        let block = Leaf::gather(&[[0.5, 0.5, 0.5], [3.0, 0.5, -1.0]], &[0, 1]);
        let d_sq = block.box_distances_sq([0.0; 3], [1.0; 3]);
        assert_eq!((d_sq[0], d_sq[1]), (0.0, 4.0 + 1.0));
        let bounds = block.bounds();
        assert_eq!((bounds.lo, bounds.hi), ([0.5, 0.5, -1.0], [3.0, 0.5, 0.5]));
    }
}
