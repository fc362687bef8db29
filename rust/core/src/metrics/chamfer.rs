//! Chamfer distance of PECS (ECCV 2024, supplement):
//! CD(P, P') = mean_{u in P} d(u, P') + mean_{v in P'} d(v, P).

use rayon::prelude::*;

/// The chamfer distance from the per-event nearest distances in both directions.
///
/// Infinite when a distance is (an event with no allowed match, see `PolarityMatching`);
/// NaN when a direction has no events, which callers rule out first.
pub fn chamfer_distance(a_to_b: &[f64], b_to_a: &[f64]) -> f64 {
    mean(a_to_b) + mean(b_to_a)
}

fn mean(values: &[f64]) -> f64 {
    sum_parallel(values, |d| d) / values.len() as f64
}

/// The sum of f(v) over the values, on rayon, in fixed chunks summed in order: the same
/// rounding, so the same result, whatever the number of threads.
pub fn sum_parallel(values: &[f64], f: impl Fn(f64) -> f64 + Sync) -> f64 {
    let partial: Vec<f64> = values
        .par_chunks(1 << 14)
        .map(|chunk| chunk.iter().map(|&v| f(v)).sum())
        .collect();
    partial.iter().sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_the_two_directional_means() {
        assert_eq!(chamfer_distance(&[1.0, 3.0], &[4.0]), 6.0);
        assert_eq!(chamfer_distance(&[0.0], &[0.0, 0.0]), 0.0);
    }
}
