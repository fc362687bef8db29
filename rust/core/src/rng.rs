//! Counter-based random numbers: every draw is a pure function of (seed, pixel, counter, stream).
//!
//! No generator state is shared between pixels, so the events are the same, bit for bit, for
//! any number of threads and any order of work. The mixing function is the SplitMix64 finaliser
//! (Steele, Lea, Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014).

/// What a draw is for; each purpose gets an independent sub-stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u64)]
pub enum Stream {
    /// Both frozen thresholds, as one Box-Muller pair (2 is retired).
    Theta = 1,
    LeakRate = 3,
    LeakPhase = 4,
    HotSelect = 5,
    HotTime = 6,
    HotPolarity = 7,
    ShotTime = 8,
    ShotPolarity = 9,
    /// Both thresholds' noise, as the two normals of one Box-Muller pair (11 is retired).
    ThetaNoise = 10,
    Jitter = 12,
}

#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The 64 random bits of draw number `counter` of `stream` for `pixel`.
#[inline]
pub fn bits(seed: u64, pixel: u64, counter: u64, stream: Stream, lane: u64) -> u64 {
    let h = mix64(seed.wrapping_add(0x9e37_79b9_7f4a_7c15));
    let h = mix64(h ^ pixel.wrapping_mul(0xd1b5_4a32_d192_ed03));
    let h = mix64(h ^ counter.wrapping_mul(0xaef1_7502_108e_f2d9));
    mix64(h ^ ((stream as u64) << 2 | lane))
}

/// Uniform in the open interval (0, 1).
#[inline]
pub fn uniform(seed: u64, pixel: u64, counter: u64, stream: Stream) -> f64 {
    unit_open(bits(seed, pixel, counter, stream, 0))
}

#[inline]
fn unit_open(b: u64) -> f64 {
    ((b >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
}

/// Standard normal, by the Box-Muller transform of two independent uniforms.
#[inline]
pub fn normal(seed: u64, pixel: u64, counter: u64, stream: Stream) -> f64 {
    let u1 = unit_open(bits(seed, pixel, counter, stream, 0));
    let u2 = unit_open(bits(seed, pixel, counter, stream, 1));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Two independent standard normals from one Box-Muller transform (its cosine and sine
/// halves), at the cost of one.
#[inline]
pub fn normal_pair(seed: u64, pixel: u64, counter: u64, stream: Stream) -> (f64, f64) {
    let u1 = unit_open(bits(seed, pixel, counter, stream, 0));
    let u2 = unit_open(bits(seed, pixel, counter, stream, 1));
    let r = (-2.0 * u1.ln()).sqrt();
    let (sin, cos) = (std::f64::consts::TAU * u2).sin_cos();
    (r * cos, r * sin)
}

/// Unit-rate exponential (the waiting time of a Poisson process of rate 1).
#[inline]
pub fn exponential(seed: u64, pixel: u64, counter: u64, stream: Stream) -> f64 {
    -uniform(seed, pixel, counter, stream).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_moments_match_the_uniform_distribution() {
        let n = 200_000u64;
        let (mut sum, mut sum2) = (0.0, 0.0);
        for i in 0..n {
            let u = uniform(7, i, 3, Stream::ShotTime);
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
            let z = normal(11, i, 0, Stream::Theta);
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
    fn a_normal_pair_is_two_uncorrelated_standard_normals() {
        let n = 200_000u64;
        let (mut s, mut s2, mut cross) = ([0.0; 2], [0.0; 2], 0.0);
        for i in 0..n {
            let (a, b) = normal_pair(5, i, 2, Stream::ThetaNoise);
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
        let a = uniform(1, 5, 0, Stream::Theta);
        assert_ne!(a, uniform(1, 5, 0, Stream::LeakRate));
        assert_ne!(a, uniform(1, 5, 1, Stream::Theta));
        assert_ne!(a, uniform(2, 5, 0, Stream::Theta));
        assert_eq!(a, uniform(1, 5, 0, Stream::Theta));
    }
}
