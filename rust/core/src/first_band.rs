//! The quiet bands of pixels' first states, worked out a block of pixels at a time.
//!
//! A time-invariant pixel that never wakes starts settled at its first-frame value; while its
//! input stays inside the quiet band of that first state it cannot cross a threshold, so it
//! needs no state at all (`Tile::scan` lets such a change pass). Every pixel of a block gets its
//! first band the first time any pixel of the block changes: where every pixel changes (grain,
//! sensor noise) that is every pixel at the first changed frame.
//!
//! The band is `PixelModel::first_quiet_band` rounded into f32 (`f32_bounds::band_inside_f32`,
//! branch-free), operation for operation and so the same bits: with the same thresholds
//! for every pixel and a logarithmic response (the ideal pixel, ESIM) it is
//! e^ln(x) e^theta_on and e^ln(x) e^-theta_off in frame values, narrowed by the band's margin
//! (`narrowed_band`). Branch-free loops over the block's pixels, one a stage, compute it; the
//! compiler turns them into vector code (AVX-512 or AVX2 where the CPU has it, chosen at run
//! time), with `exp`'s logarithm and exponential; a pixel outside their fast range (no
//! photocurrent, for one) and every pixel of any other model take `first_quiet_band` one at a
//! time.

use crate::cpu_dispatch::compiled_per_cpu;
use crate::exp::{exp_in_range, in_exp_range, in_ln_range, ln_in_range};
use crate::f32_bounds::band_inside_f32;
use crate::pixel::{rounded_band, PixelModel};

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
    if n == BLOCK {
        let mut lanes = Lanes {
            value: origin.try_into().expect("a whole block"),
            lo: lo.try_into().expect("a whole block"),
            hi: hi.try_into().expect("a whole block"),
        };
        return set_first_bands_of_block(model, first_pixel, keep, &mut lanes);
    }
    // A shorter block is padded; its padding is kept (worked out and dropped).
    let (mut value, mut lo_block, mut hi_block) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
    value[..n].copy_from_slice(origin);
    let mut lanes = Lanes {
        value: &value,
        lo: &mut lo_block,
        hi: &mut hi_block,
    };
    set_first_bands_of_block(model, first_pixel, keep | u32::MAX << n, &mut lanes);
    for k in 0..n {
        if keep >> k & 1 == 0 {
            (lo[k], hi[k]) = (lo_block[k], hi_block[k]);
        }
    }
}

/// A whole block's first-frame values and bands.
struct Lanes<'a> {
    value: &'a [f32; BLOCK],
    lo: &'a mut [f32; BLOCK],
    hi: &'a mut [f32; BLOCK],
}

/// `set_first_bands` of a whole block: the lanes' loops for models with band factors, then
/// `first_quiet_band` one pixel at a time for the pixels they cannot take.
fn set_first_bands_of_block(model: &PixelModel, first_pixel: u64, keep: u32, lanes: &mut Lanes) {
    let fast = match model.band_factors() {
        Some(factors) => first_bands_of_block(model, factors, keep, lanes),
        None => 0,
    };
    let mut slow = !fast & !keep;
    while slow != 0 {
        let k = slow.trailing_zeros() as usize;
        let band = model.first_quiet_band(first_pixel + k as u64, lanes.value[k] as f64);
        (lanes.lo[k], lanes.hi[k]) = band_inside_f32(band);
        slow &= slow - 1;
    }
}

compiled_per_cpu! {
    /// The first bands of a whole block for a model with band factors (e^theta_on,
    /// e^-theta_off), but in the lanes of `keep`; returns the lanes they hold (bit k), the others
    /// being left to `first_quiet_band`.
    fn first_bands_of_block(
        model: &PixelModel,
        factors: (f64, f64),
        keep: u32,
        lanes: &mut Lanes,
    ) -> u32 = first_bands_lanes, avx512 first_bands_avx512, avx2 first_bands_avx2;
}

/// The lanes' loops: `first_quiet_band`'s operations with band factors (the response's ln, then
/// `band_around`'s exponential and products), with the C library's cases (x out of ln's fast
/// range, ln x out of exp's) marked for the fallback instead. One loop a stage, over the whole
/// block: each stage is a long chain of dependent operations, and the block's vectors of one
/// stage, independent, overlap (in one loop, the chains of one or two vectors would fill the
/// processor's window and run one after the other).
#[inline(always)]
fn first_bands_lanes(
    model: &PixelModel,
    (up, down): (f64, f64),
    keep: u32,
    lanes: &mut Lanes,
) -> u32 {
    let r = &model.receptor;
    let value = *lanes.value;
    let (mut x, mut u, mut x_ref) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
    // first_quiet_band: the response to the first-frame value (x >= 0 >= the knee of a
    // logarithmic response: ln x).
    for k in 0..BLOCK {
        x[k] = r.total_current(value[k] as f64);
    }
    for k in 0..BLOCK {
        u[k] = ln_in_range(x[k]);
    }
    // band_around with band factors.
    for k in 0..BLOCK {
        x_ref[k] = exp_in_range(u[k]);
    }
    let (mut lo, mut hi) = ([0.0; BLOCK], [0.0; BLOCK]);
    let mut fast = 0;
    for k in 0..BLOCK {
        (lo[k], hi[k]) = rounded_band(r, x_ref[k], (up, down));
        fast |= ((in_ln_range(x[k]) & in_exp_range(u[k])) as u32) << k;
    }
    // The two bands apart: the compiler cannot tell that they never overlap.
    keep_or_take(keep, lanes.lo, &lo);
    keep_or_take(keep, lanes.hi, &hi);
    fast
}

/// `new`'s values into `band` but in the lanes of `keep`, chosen on the bits (a select the
/// compiler would turn into one branch a lane).
#[inline(always)]
fn keep_or_take(keep: u32, band: &mut [f32; BLOCK], new: &[f32; BLOCK]) {
    for k in 0..BLOCK {
        let kept = 0u32.wrapping_sub(keep >> k & 1);
        band[k] = f32::from_bits(band[k].to_bits() & kept | new[k].to_bits() & !kept);
    }
}

#[cfg(test)]
/// First-frame values from none to the largest f32: zero, the subnormals, the dark
/// current's order, photocurrents, and random bit patterns of every exponent.
pub(crate) fn first_frame_values() -> Vec<f32> {
    use crate::rng::{Draw, Stream};
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::f32_bounds::{round_down_f32, round_up_f32};
    use crate::params::SensorParams;

    #[test]
    fn the_block_bands_are_the_rounded_first_quiet_bands_bit_for_bit() {
        // The vectorised models (the ideal pixel, ESIM's reset, other light levels), and the
        // ones that take `first_quiet_band` one pixel at a time (threshold
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
        let (mut bright, mut dark) = (esim.clone(), esim.clone());
        (bright.white_lux, dark.white_lux) = (2.0e3, 1e3 / 1024.0);
        let values = first_frame_values();
        for params in [ideal, esim, dark_free_linlog, dim, mismatched, bright, dark] {
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
        // must agree bit for bit (and on which lanes they hold and keep).
        let model = PixelModel::new(SensorParams::ideal(1, 1));
        let factors = model
            .band_factors()
            .expect("the ideal pixel has band factors");
        for (b, block) in first_frame_values().chunks_exact(BLOCK).enumerate() {
            let values: &[f32; BLOCK] = block.try_into().unwrap();
            let keep = (b as u32).wrapping_mul(0x9e37_79b9);
            let run = |f: &dyn Fn(&mut Lanes) -> u32| {
                // Every band -7..7 before, to tell the kept ones.
                let (mut lo, mut hi) = ([-7.0; BLOCK], [7.0; BLOCK]);
                let mut lanes = Lanes {
                    value: values,
                    lo: &mut lo,
                    hi: &mut hi,
                };
                let fast = f(&mut lanes);
                (fast, lo.map(f32::to_bits), hi.map(f32::to_bits))
            };
            let portable = run(&|l| first_bands_lanes(&model, factors, keep, l));
            assert_eq!(
                portable,
                run(&|l| first_bands_of_block(&model, factors, keep, l))
            );
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports AVX2 and FMA, checked just above.
                let avx2 = run(&|l| unsafe { first_bands_avx2(&model, factors, keep, l) });
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
        let (mut lo, mut hi) = ([0.0; BLOCK], [0.0; BLOCK]);
        let mut lanes = Lanes {
            value: &values,
            lo: &mut lo,
            hi: &mut hi,
        };
        assert_eq!(first_bands_lanes(&model, factors, 0, &mut lanes), u32::MAX);
        let mut dark_free = SensorParams::ideal(1, 1);
        (dark_free.dark_current, dark_free.lin_log_knee) = (0.0, 0.0);
        let model = PixelModel::new(dark_free);
        let fast = first_bands_lanes(&model, factors, 0, &mut lanes);
        assert_eq!(fast, !(1 << 3));
        set_first_bands(&model, 0, &values, 0, &mut lo, &mut hi);
        assert_eq!(lo[3], f32::NEG_INFINITY);
        // e^0.2 above nothing, narrowed by 1e-6: rounded down it is 0 itself.
        assert_eq!(hi[3], 0.0);
    }
}
