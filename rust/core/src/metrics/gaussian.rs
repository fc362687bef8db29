//! Gaussian distance of PECS (ECCV 2024, supplement):
//! GD(P, P') = mean_{u in P} [1 - exp(-d(u, P')^2 / sigma)] + mean_{v in P'} [1 - exp(-d(v, P)^2 / sigma)].
//!
//! Note exp(-d^2 / sigma), not exp(-d^2 / (2 sigma^2)): with sigma 0.4 an event counts as matched
//! when a neighbour lies within about 0.5 normalised units. GD lies in [0, 2).

use super::chamfer::sum_parallel;
use super::MetricsError;

/// The sigma PECS uses.
pub const PECS_SIGMA: f64 = 0.4;

/// The Gaussian distance from the per-event nearest distances in both directions.
pub fn gaussian_distance(a_to_b: &[f64], b_to_a: &[f64], sigma: f64) -> f64 {
    mean_penalty(a_to_b, sigma) + mean_penalty(b_to_a, sigma)
}

/// mean of 1 - exp(-d^2 / sigma); an infinite distance costs 1.
fn mean_penalty(distances: &[f64], sigma: f64) -> f64 {
    // -expm1(-x) is 1 - exp(-x) without the cancellation for tiny distances.
    let total = sum_parallel(distances, |d| -(-d * d / sigma).exp_m1());
    total / distances.len() as f64
}

/// sigma must be positive and finite.
pub fn check_sigma(sigma: f64) -> Result<(), MetricsError> {
    if sigma > 0.0 && sigma.is_finite() {
        Ok(())
    } else {
        Err(MetricsError::Parameter(format!(
            "sigma must be positive and finite, got {sigma}"
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_formula() {
        let d = [0.0, 0.5, 2.0];
        let expected = (0.0 + (1.0 - (-0.25f64 / 0.4).exp()) + (1.0 - (-4.0f64 / 0.4).exp())) / 3.0;
        let got = gaussian_distance(&d, &[0.0], 0.4);
        assert!((got - expected).abs() < 1e-15);
        assert_eq!(
            gaussian_distance(&[f64::INFINITY], &[f64::INFINITY], 0.4),
            2.0
        );
        assert!(check_sigma(0.0).is_err() && check_sigma(f64::NAN).is_err());
    }
}
