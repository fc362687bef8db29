//! Morton (Z-order) sorting of 3-D points: points close along the curve are close in space, so
//! consecutive runs make compact BVH primitives and query groups.

use rayon::prelude::*;

/// The ids of `points` sorted along a 3-D Morton curve over their bounding box (ties by id).
pub fn morton_order(points: &[[f64; 3]], ids: &[u32]) -> Vec<u32> {
    let (lo, hi) = bounds(points, ids);
    const CELLS: f64 = ((1u64 << 21) - 1) as f64;
    let scale: [f64; 3] = std::array::from_fn(|a| CELLS / (hi[a] - lo[a]).max(f64::MIN_POSITIVE));
    let mut keyed: Vec<(u64, u32)> = ids
        .par_iter()
        .map(|&id| {
            let p = points[id as usize];
            let cell = |axis: usize| ((p[axis] - lo[axis]) * scale[axis]).clamp(0.0, CELLS) as u64;
            let code = spread_bits(cell(0)) | spread_bits(cell(1)) << 1 | spread_bits(cell(2)) << 2;
            (code, id)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, id)| id).collect()
}

fn bounds(points: &[[f64; 3]], ids: &[u32]) -> ([f64; 3], [f64; 3]) {
    ids.iter().fold(
        ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
        |(mut lo, mut hi), &id| {
            for (axis, &c) in points[id as usize].iter().enumerate() {
                lo[axis] = lo[axis].min(c);
                hi[axis] = hi[axis].max(c);
            }
            (lo, hi)
        },
    )
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_bits_interleaves() {
        assert_eq!(spread_bits(0b111), 0b1001001);
        assert_eq!(spread_bits(0x1f_ffff), 0x1249_2492_4924_9249);
    }

    #[test]
    fn sorts_along_the_curve_and_keeps_every_id() {
        let points = [
            [1.0, 1.0, 1.0],
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        assert_eq!(morton_order(&points, &[0, 1, 2, 3]), vec![1, 2, 3, 0]);
        assert_eq!(morton_order(&points, &[3, 0]), vec![3, 0]);
    }
}
