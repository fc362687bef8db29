//! Counter-based random numbers: every draw is a pure function of (seed, pixel, counter, stream).
//!
//! No generator state is shared between pixels, so the events are the same, bit for bit, for
//! any number of threads and any order of work. The mixing function is the SplitMix64 finaliser
//! (Steele, Lea, Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014).

/// What a draw is for; each purpose gets an independent sub-stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u64)]
pub enum Stream {
    /// Both frozen thresholds, as one pair of normals (2 is retired).
    Theta = 1,
    LeakRate = 3,
    LeakPhase = 4,
    HotSelect = 5,
    HotTime = 6,
    HotPolarity = 7,
    ShotTime = 8,
    ShotPolarity = 9,
    /// Both thresholds' noise, as one pair of normals (11 is retired).
    ThetaNoise = 10,
    Jitter = 12,
}

#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Draw number `counter` of one pixel's random numbers: (seed, pixel, counter) mixed once, so the
/// several streams and lanes a draw serves each cost one more mix.
#[derive(Clone, Copy, Debug)]
pub struct Draw(u64);

impl Draw {
    #[inline]
    pub fn new(seed: u64, pixel: u64, counter: u64) -> Self {
        let h = mix64(seed.wrapping_add(0x9e37_79b9_7f4a_7c15));
        let h = mix64(h ^ pixel.wrapping_mul(0xd1b5_4a32_d192_ed03));
        Self(mix64(h ^ counter.wrapping_mul(0xaef1_7502_108e_f2d9)))
    }

    /// The 64 random bits of `stream`, `lane`.
    #[inline]
    pub fn bits(self, stream: Stream, lane: u64) -> u64 {
        mix64(self.0 ^ ((stream as u64) << 2 | lane))
    }

    /// Uniform in the open interval (0, 1).
    #[inline]
    pub fn uniform(self, stream: Stream) -> f64 {
        unit_open(self.bits(stream, 0))
    }

    /// Standard normal from one uniform, by the inverse of the normal CDF.
    #[inline]
    pub fn normal(self, stream: Stream) -> f64 {
        inverse_normal_cdf(self.uniform(stream))
    }

    /// Two independent standard normals (two lanes of one stream).
    #[inline]
    pub fn normal_pair(self, stream: Stream) -> (f64, f64) {
        (
            inverse_normal_cdf(unit_open(self.bits(stream, 0))),
            inverse_normal_cdf(unit_open(self.bits(stream, 1))),
        )
    }

    /// Unit-rate exponential (the waiting time of a Poisson process of rate 1).
    #[inline]
    pub fn exponential(self, stream: Stream) -> f64 {
        -self.uniform(stream).ln()
    }
}

/// Uniform in the open interval (0, 1) from 64 random bits.
#[inline(always)]
pub(crate) fn unit_open(b: u64) -> f64 {
    // The top 53-bit value plus a half rounds up to 1: kept just below it, where the inverse
    // normal CDF and the logarithms of the exponential draws are still finite.
    (((b >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)).min(1.0 - f64::EPSILON / 2.0)
}

/// Acklam's rational approximation of the inverse normal CDF (relative error below 1.2e-9):
/// no transcendental function in the central 95 %, one logarithm and one square root in the
/// tails. Cheaper than Box-Muller's logarithm, root and cosine on every draw.
#[inline]
fn inverse_normal_cdf(p: f64) -> f64 {
    if p < P_LOW {
        normal_tail(p)
    } else if p > 1.0 - P_LOW {
        -normal_tail(1.0 - p)
    } else {
        central_normal(p)
    }
}

/// Below this probability (and above 1 minus it) the inverse normal CDF takes its tail form.
const P_LOW: f64 = 0.02425;

/// Whether `central_normal` is the inverse normal CDF at `p` (the central 95 %).
#[inline(always)]
pub(crate) fn is_central(p: f64) -> bool {
    (P_LOW..=1.0 - P_LOW).contains(&p)
}

/// The inverse normal CDF in its central region (`is_central`): one rational function, no
/// branch, so loops over many draws vectorise.
#[inline(always)]
pub(crate) fn central_normal(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.38357751867269e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    let q = p - 0.5;
    let r = q * q;
    (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
        / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
}

/// The lower tail of the inverse normal CDF (p < `P_LOW`).
#[inline]
fn normal_tail(p: f64) -> f64 {
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let q = (-2.0 * p.ln()).sqrt();
    (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
        / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniforms_stay_inside_the_open_interval_at_its_ends() {
        assert!(unit_open(0) > 0.0);
        assert!(unit_open(u64::MAX) < 1.0);
        assert!(inverse_normal_cdf(unit_open(u64::MAX)).is_finite());
        assert!(inverse_normal_cdf(unit_open(0)).is_finite());
    }

    #[test]
    fn uniform_moments_match_the_uniform_distribution() {
        let n = 200_000u64;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for i in 0..n {
            let u = Draw::new(7, i, 3).uniform(Stream::ShotTime);
            assert!(u > 0.0 && u < 1.0);
            sum += u;
            sum2 += u * u;
        }
        let mean = sum / n as f64;
        let var = sum2 / n as f64 - mean * mean;
        assert!((mean - 0.5).abs() < 0.003, "mean {mean}");
        assert!((var - 1.0 / 12.0).abs() < 0.002, "variance {var}");
    }

    #[test]
    fn normal_moments_match_the_standard_normal() {
        let n = 200_000u64;
        let (mut sum, mut sum2, mut sum4) = (0.0, 0.0, 0.0);
        for i in 0..n {
            let z = Draw::new(11, i, 0).normal(Stream::Theta);
            sum += z;
            sum2 += z * z;
            sum4 += z.powi(4);
        }
        let n = n as f64;
        assert!((sum / n).abs() < 0.01);
        assert!((sum2 / n - 1.0).abs() < 0.015);
        assert!((sum4 / n - 3.0).abs() < 0.1, "kurtosis {}", sum4 / n);
    }

    #[test]
    fn the_inverse_cdf_gives_the_tabulated_quantiles() {
        // Quantiles of the standard normal, as scipy.special.ndtri gives them.
        for (p, z) in [
            (0.5, 0.0),
            (0.8413447460685429, 1.0),
            (0.975, 1.959963984540054),
            (0.99, 2.326347874040841),
            (0.999, 3.090232306167813),
            (1e-6, -4.753424308822899),
        ] {
            let got = inverse_normal_cdf(p);
            assert!(
                (got - z).abs() <= 2e-9 * z.abs().max(1.0),
                "{p}: {got} vs {z}"
            );
            assert!((inverse_normal_cdf(1.0 - p) + z).abs() <= 2e-9 * z.abs().max(1.0));
        }
    }

    #[test]
    fn a_normal_pair_is_two_uncorrelated_standard_normals() {
        let n = 200_000u64;
        let (mut s, mut s2, mut cross) = ([0.0; 2], [0.0; 2], 0.0);
        for i in 0..n {
            let (a, b) = Draw::new(5, i, 2).normal_pair(Stream::ThetaNoise);
            for (k, z) in [a, b].into_iter().enumerate() {
                s[k] += z;
                s2[k] += z * z;
            }
            cross += a * b;
        }
        let n = n as f64;
        for k in 0..2 {
            assert!((s[k] / n).abs() < 0.01);
            assert!((s2[k] / n - 1.0).abs() < 0.015);
        }
        // The standard error of the sample correlation is 1/sqrt(n) = 0.0022.
        assert!((cross / n).abs() < 0.01);
    }

    #[test]
    fn streams_and_counters_are_independent_draws() {
        let a = Draw::new(1, 5, 0).uniform(Stream::Theta);
        assert_ne!(a, Draw::new(1, 5, 0).uniform(Stream::LeakRate));
        assert_ne!(a, Draw::new(1, 5, 1).uniform(Stream::Theta));
        assert_ne!(a, Draw::new(2, 5, 0).uniform(Stream::Theta));
        assert_eq!(a, Draw::new(1, 5, 0).uniform(Stream::Theta));
    }
}
