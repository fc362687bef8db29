//! The quiet bands of pixels' first states, worked out a block of pixels at a time.
//!
//! A time-invariant pixel that never wakes starts settled at its first-frame value; while its
//! input stays inside the quiet band of that first state it cannot cross a threshold, so it
//! needs no state at all (`Tile::scan` lets such a change pass). Every pixel of a block gets its
//! first band the first time any pixel of the block changes: where every pixel changes (grain,
//! sensor noise) that is every pixel at the first changed frame.
//!
//! The band is `PixelModel::first_quiet_band` rounded into f32 (`tile::round_up_f32` and
//! `tile::round_down_f32`), operation for operation and so the same bits: with the same thresholds
//! for every pixel and a logarithmic response (the ideal pixel, ESIM) it is
//! e^ln(x) e^theta_on and e^ln(x) e^-theta_off in frame values, narrowed by the band's margin
//! (`band_of_currents`). One branch-free loop over the block's pixels computes it, which the
//! compiler turns into vector code (AVX-512 or AVX2 where the CPU has it, chosen at run time),
//! with `exp`'s logarithm and exponential; a pixel outside their fast range (no photocurrent,
//! for one) and every pixel of any other model take `first_quiet_band` one at a time.

use crate::exp::{exp_in_range, in_exp_range, in_ln_range, ln_in_range};
use crate::pixel::{band_of_currents, PixelModel};

/// Pixels a call works out at most (the scan's block).
pub const BLOCK: usize = 32;

/// The first bands of the pixels `first_pixel + k` with first-frame values `origin[k]`, into
/// `lo[k]` and `hi[k]`, except where bit k of `keep` is set (a pixel with a state keeps the
/// band its state gave it). `origin`, `lo` and `hi` have the same length, at most `BLOCK`.
pub fn set_first_bands(
    model: &PixelModel,
    first_pixel: u64,
    origin: &[f32],
    keep: u32,
    lo: &mut [f32],
    hi: &mut [f32],
) {
    let n = origin.len();
    assert!(n <= BLOCK && lo.len() == n && hi.len() == n);
    if n == 0 {
        return;
    }
    // A shorter block is padded (those lanes are worked out and dropped).
    let mut values = [0.0f32; BLOCK];
    values[..n].copy_from_slice(origin);
    let mut bands = Bands::default();
    let fast = match model.band_factors() {
        Some(factors) => first_bands_of_block(model, factors, &values, &mut bands),
        None => 0,
    };
    // The pixels the lanes could not take, one at a time.
    let mut slow = !fast & !keep & (u32::MAX >> (BLOCK - n));
    while slow != 0 {
        let k = slow.trailing_zeros() as usize;
        let (l, h) = model.first_quiet_band(first_pixel + k as u64, origin[k] as f64);
        (bands.lo[k], bands.hi[k]) = (round_up_lane(l), round_down_lane(h));
        slow &= slow - 1;
    }
    let news = bands.lo.iter().zip(&bands.hi);
    for (k, ((lo, hi), (&new_lo, &new_hi))) in lo.iter_mut().zip(hi).zip(news).enumerate() {
        let kept = keep >> k & 1 != 0;
        *lo = if kept { *lo } else { new_lo };
        *hi = if kept { *hi } else { new_hi };
    }
}

/// A block's bands in f32.
#[derive(Default)]
struct Bands {
    lo: [f32; BLOCK],
    hi: [f32; BLOCK],
}

/// The first bands of a whole block for a model with band factors (e^theta_on, e^-theta_off);
/// returns the lanes they hold (bit k), the others being left to `first_quiet_band`.
fn first_bands_of_block(
    model: &PixelModel,
    factors: (f64, f64),
    values: &[f32; BLOCK],
    bands: &mut Bands,
) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU supports AVX-512F, checked just above.
        return unsafe { first_bands_avx512(model, factors, values, bands) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        return unsafe { first_bands_avx2(model, factors, values, bands) };
    }
    first_bands_lanes(model, factors, values, bands)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn first_bands_avx2(
    model: &PixelModel,
    factors: (f64, f64),
    values: &[f32; BLOCK],
    bands: &mut Bands,
) -> u32 {
    first_bands_lanes(model, factors, values, bands)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
unsafe fn first_bands_avx512(
    model: &PixelModel,
    factors: (f64, f64),
    values: &[f32; BLOCK],
    bands: &mut Bands,
) -> u32 {
    first_bands_lanes(model, factors, values, bands)
}

/// The lanes' loop: `first_quiet_band`'s operations with band factors (the response's ln, then
/// `band_around`'s exponential and products), with the C library's cases (x out of ln's fast
/// range, ln x out of exp's) marked for the fallback instead.
#[inline(always)]
fn first_bands_lanes(
    model: &PixelModel,
    (up, down): (f64, f64),
    values: &[f32; BLOCK],
    bands: &mut Bands,
) -> u32 {
    let r = &model.receptor;
    let mut fast = 0;
    for (k, &value) in values.iter().enumerate() {
        // first_quiet_band: the response to the first-frame value (x >= 0 >= the knee of a
        // logarithmic response: ln x).
        let x = r.total_current(value as f64);
        let u = ln_in_range(x);
        // band_around with band factors.
        let x_ref = exp_in_range(u);
        let (lo, hi) = band_of_currents(r, x_ref * down, x_ref * up);
        bands.lo[k] = round_up_lane(lo);
        bands.hi[k] = round_down_lane(hi);
        fast |= ((in_ln_range(x) & in_exp_range(u)) as u32) << k;
    }
    fast
}

/// `tile::round_up_f32` without a branch: the nearest f32, moved one up (`f32::next_up`) where it
/// fell below `v`.
#[inline(always)]
fn round_up_lane(v: f64) -> f32 {
    let f = v as f32;
    // f below v: neither NaN nor +inf, so next_up is one step on the bits.
    let below = (f as f64) < v;
    let bits = f.to_bits();
    let magnitude = bits & 0x7fff_ffff;
    let next_up = if magnitude == 0 {
        1 // the smallest subnormal, from either zero
    } else if bits == magnitude {
        bits + 1
    } else {
        bits - 1
    };
    f32::from_bits(if below { next_up } else { bits })
}

/// `tile::round_down_f32` without a branch: the nearest f32, moved one down (`f32::next_down`) where
/// it fell above `v`.
#[inline(always)]
fn round_down_lane(v: f64) -> f32 {
    let f = v as f32;
    // f above v: neither NaN nor -inf, so next_down is one step on the bits.
    let above = (f as f64) > v;
    let bits = f.to_bits();
    let magnitude = bits & 0x7fff_ffff;
    let next_down = if magnitude == 0 {
        0x8000_0001 // the smallest negative subnormal, from either zero
    } else if bits == magnitude {
        bits - 1
    } else {
        bits + 1
    };
    f32::from_bits(if above { next_down } else { bits })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::SensorParams;
    use crate::rng::{Draw, Stream};
    use crate::tile::{round_down_f32, round_up_f32};

    /// Edge values of f64 and f32 around zero, the subnormals, 1 and the largest f32, with
    /// random bit patterns of every exponent.
    fn edge_and_random_f64() -> Vec<f64> {
        let mut values = vec![
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            5e-324,
            -5e-324,
            f32::from_bits(1) as f64,
            f32::from_bits(1) as f64 * 0.5,
            f32::from_bits(1) as f64 * 0.75,
            f32::MIN_POSITIVE as f64,
            1.0,
            -1.0,
            1.0 + f64::EPSILON,
            1.0 - f64::EPSILON / 2.0,
            f32::MAX as f64,
            f32::MAX as f64 * (1.0 + f64::EPSILON),
            f32::MAX as f64 * (1.0 + 1e-8),
            f32::MAX as f64 * 1.5,
            -(f32::MAX as f64) * 1.5,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for i in 0..200_000u64 {
            let bits = Draw::new(7, i, 0).uniform(Stream::Jitter).to_bits() ^ (i << 52);
            values.push(f64::from_bits(bits.rotate_left((i % 64) as u32)));
        }
        values
    }

    #[test]
    fn branch_free_rounding_gives_the_bits_of_round_up_and_round_down() {
        for v in edge_and_random_f64() {
            assert_eq!(
                round_up_lane(v).to_bits(),
                round_up_f32(v).to_bits(),
                "up {v:e}"
            );
            assert_eq!(
                round_down_lane(v).to_bits(),
                round_down_f32(v).to_bits(),
                "down {v:e}"
            );
        }
        assert!(round_up_lane(f64::NAN).is_nan() && round_down_lane(f64::NAN).is_nan());
    }

    /// First-frame values from none to the largest f32: zero, the subnormals, the dark
    /// current's order, photocurrents, and random bit patterns of every exponent.
    fn first_frame_values() -> Vec<f32> {
        let mut values = vec![
            0.0,
            -0.0,
            f32::from_bits(1),
            f32::MIN_POSITIVE,
            1e-30,
            1e-9,
            1e-6,
            1e-3,
            0.05,
            0.2,
            0.5,
            0.9,
            1.0,
            40.0,
            1e6,
            1e30,
            f32::MAX,
        ];
        for i in 0..20_000u32 {
            let bits = (Draw::new(3, i as u64, 0).uniform(Stream::Jitter) * 2.0f64.powi(31)) as u32;
            values.push(f32::from_bits(bits % 0x7f80_0000)); // finite and >= 0
        }
        values
    }

    #[test]
    fn the_block_bands_are_the_rounded_first_quiet_bands_bit_for_bit() {
        // The vectorised models (the ideal pixel, ESIM's reset, no dark current, another light
        // level), and the ones that take `first_quiet_band` one pixel at a time (threshold
        // mismatch draws, a lin-log response).
        let ideal = SensorParams::ideal(1, 1);
        let mut esim = ideal.clone();
        esim.reference_reset = crate::params::ReferenceReset::Event;
        let mut dark_free_linlog = ideal.clone();
        (dark_free_linlog.dark_current, dark_free_linlog.lin_log_knee) = (0.0, 0.01);
        let mut dim = ideal.clone();
        (dim.white_lux, dim.theta_on, dim.theta_off) = (3.0, 0.15, 0.35);
        let mut mismatched = ideal.clone();
        mismatched.theta_sigma = 0.05;
        let values = first_frame_values();
        for params in [ideal, esim, dark_free_linlog, dim, mismatched] {
            let model = PixelModel::new(params);
            for (b, block) in values.chunks(BLOCK - 3).enumerate() {
                // Partial blocks (29 pixels), and every third pixel keeping its band.
                let first_pixel = 1000 + 29 * b as u64;
                let keep = 0x4924_9249 & ((1u32 << block.len()) - 1);
                let (mut lo, mut hi) = (vec![-7.0; block.len()], vec![7.0; block.len()]);
                set_first_bands(&model, first_pixel, block, keep, &mut lo, &mut hi);
                for (k, &value) in block.iter().enumerate() {
                    let (l, h) = model.first_quiet_band(first_pixel + k as u64, value as f64);
                    let expected = if keep >> k & 1 != 0 {
                        (-7.0, 7.0)
                    } else {
                        (round_up_f32(l), round_down_f32(h))
                    };
                    assert_eq!(
                        (lo[k].to_bits(), hi[k].to_bits()),
                        (expected.0.to_bits(), expected.1.to_bits()),
                        "{:?}: pixel {k} of block {b}, value {value:e}",
                        model.params
                    );
                }
            }
        }
    }

    #[test]
    fn every_instruction_set_gives_the_same_bands() {
        // `set_first_bands` takes the widest the CPU has; the narrower ones, run here directly,
        // must agree bit for bit (and on which lanes they hold).
        let model = PixelModel::new(SensorParams::ideal(1, 1));
        let factors = model
            .band_factors()
            .expect("the ideal pixel has band factors");
        for block in first_frame_values().chunks_exact(BLOCK) {
            let values: &[f32; BLOCK] = block.try_into().unwrap();
            let run = |f: &dyn Fn(&mut Bands) -> u32| {
                let mut bands = Bands::default();
                let fast = f(&mut bands);
                (fast, bands.lo.map(f32::to_bits), bands.hi.map(f32::to_bits))
            };
            let portable = run(&|b| first_bands_lanes(&model, factors, values, b));
            assert_eq!(
                portable,
                run(&|b| first_bands_of_block(&model, factors, values, b))
            );
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2, checked just above.
                let avx2 = run(&|b| unsafe { first_bands_avx2(&model, factors, values, b) });
                assert_eq!(portable, avx2);
            }
        }
    }

    #[test]
    fn the_fast_lanes_cover_photocurrents_and_leave_zero_to_the_library() {
        // The ideal pixel's dark current keeps every value in ln's range; without it a zero
        // photocurrent (ln 0 = -inf) goes to `first_quiet_band`, whose band has no lower end.
        let model = PixelModel::new(SensorParams::ideal(1, 1));
        let factors = model
            .band_factors()
            .expect("the ideal pixel has band factors");
        let mut values = [0.5f32; BLOCK];
        values[3] = 0.0;
        values[4] = f32::MAX;
        let mut bands = Bands::default();
        assert_eq!(
            first_bands_lanes(&model, factors, &values, &mut bands),
            u32::MAX
        );
        let mut dark_free = SensorParams::ideal(1, 1);
        (dark_free.dark_current, dark_free.lin_log_knee) = (0.0, 0.0);
        let model = PixelModel::new(dark_free);
        let fast = first_bands_lanes(&model, factors, &values, &mut bands);
        assert_eq!(fast, !(1 << 3));
        let (mut lo, mut hi) = ([0.0; BLOCK], [0.0; BLOCK]);
        set_first_bands(&model, 0, &values, 0, &mut lo, &mut hi);
        assert_eq!(lo[3], f32::NEG_INFINITY);
        // e^0.2 above nothing, narrowed by 1e-6: rounded down it is 0 itself.
        assert_eq!(hi[3], 0.0);
    }
}
