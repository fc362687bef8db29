//! A block's flags: which of 32 neighbouring pixels a frame's scan lists for stepping, and which
//! of their values are not photocurrents, as bit masks (bit k: pixel k) from vector compares of
//! the values against the last frame's, the quiet bands and the wake-up times.
//!
//! Written once as a plain loop over the block, which the compiler vectorises, and once with
//! AVX2 intrinsics: there each compare of 8 values becomes 8 bits with one `movemask`, where the
//! loop's bits cost a shift and a reduction of the vector (`Tile::scan` chooses at run time, and
//! the two give the same bits).

use crate::state_block::LANES;

/// Pixels a block has.
pub const BLOCK: usize = LANES;

/// A block's pixels as bit masks (bit k for pixel k).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Flags {
    /// To step.
    pub busy: u32,
    /// Not a photocurrent.
    pub invalid: u32,
}

/// What a block's flags read: its values, the last frame's, the quiet bands (time-invariant
/// pixels) and the wake-up times.
pub struct Inputs<'a> {
    pub value: &'a [f32; BLOCK],
    pub last: &'a [f32; BLOCK],
    pub band: Option<(&'a [f32; BLOCK], &'a [f32; BLOCK])>,
    pub wake_s: &'a [f32; BLOCK],
}

/// Proof that the CPU has AVX2: made only by `detect`.
#[derive(Clone, Copy, Debug)]
pub struct Avx2(());

impl Avx2 {
    pub fn detect() -> Option<Self> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            return Some(Self(()));
        }
        None
    }
}

/// A time-invariant pixel (one with a band) steps only when its input leaves the band (an
/// unchanged input cannot cross); the others whenever it changed; any pixel when a wake-up is
/// due by `due_by`. With `avx2`, the intrinsics' copy.
#[inline(always)]
pub fn flags(inputs: &Inputs, due_by: Option<f32>, avx2: Option<Avx2>) -> Flags {
    match (inputs.band, due_by) {
        (Some(band), Some(t1_up)) => flags_of::<true, true>(inputs, band, t1_up, avx2),
        (Some(band), None) => flags_of::<true, false>(inputs, band, 0.0, avx2),
        (None, Some(t1_up)) => {
            flags_of::<false, true>(inputs, (inputs.last, inputs.last), t1_up, avx2)
        }
        (None, None) => flags_of::<false, false>(inputs, (inputs.last, inputs.last), 0.0, avx2),
    }
}

#[inline(always)]
fn flags_of<const BAND: bool, const DUE: bool>(
    inputs: &Inputs,
    band: (&[f32; BLOCK], &[f32; BLOCK]),
    t1_up: f32,
    avx2: Option<Avx2>,
) -> Flags {
    #[cfg(target_arch = "x86_64")]
    if avx2.is_some() {
        // SAFETY: an `Avx2` exists only where the CPU has AVX2.
        return unsafe { flags_avx2::<BAND, DUE>(inputs, band, t1_up) };
    }
    let _ = avx2;
    flags_portable::<BAND, DUE>(inputs, band, t1_up)
}

/// `flags` as a loop over the block's pixels.
#[inline(always)]
fn flags_portable<const BAND: bool, const DUE: bool>(
    inputs: &Inputs,
    (lo, hi): (&[f32; BLOCK], &[f32; BLOCK]),
    t1_up: f32,
) -> Flags {
    let mut flags = Flags {
        busy: 0,
        invalid: 0,
    };
    for k in 0..BLOCK {
        let v = inputs.value[k];
        let changed = v != inputs.last[k];
        let mut busy = if BAND {
            changed & !((v >= lo[k]) & (v <= hi[k]))
        } else {
            changed
        };
        if DUE {
            busy |= t1_up >= inputs.wake_s[k];
        }
        flags.busy |= (busy as u32) << k;
        flags.invalid |= (!valid_value(v) as u32) << k;
    }
    flags
}

/// `flags` with AVX2, 8 pixels a compare: "changed" is not-equal-or-unordered (NaN changes),
/// "in the band" and "due" ordered compares, and a photocurrent 0 <= v <= f32::MAX, ordered
/// (NaN and the infinities fail, -0.0 passes): `valid_value`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn flags_avx2<const BAND: bool, const DUE: bool>(
    inputs: &Inputs,
    (lo, hi): (&[f32; BLOCK], &[f32; BLOCK]),
    t1_up: f32,
) -> Flags {
    use std::arch::x86_64::*;
    let (zero, largest, due_by) = (
        _mm256_setzero_ps(),
        _mm256_set1_ps(f32::MAX),
        _mm256_set1_ps(t1_up),
    );
    let (mut busy, mut valid) = (0u32, 0u32);
    for i in 0..BLOCK / 8 {
        let eight = |a: &[f32; BLOCK]| {
            let lanes: &[f32; 8] = a[8 * i..8 * i + 8].try_into().expect("8 lanes");
            // SAFETY: an unaligned load of 8 f32 from an array of 8.
            unsafe { _mm256_loadu_ps(lanes.as_ptr()) }
        };
        let v = eight(inputs.value);
        let mut to_step = _mm256_cmp_ps::<_CMP_NEQ_UQ>(v, eight(inputs.last));
        if BAND {
            let inside = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(v, eight(lo)),
                _mm256_cmp_ps::<_CMP_LE_OQ>(v, eight(hi)),
            );
            to_step = _mm256_andnot_ps(inside, to_step);
        }
        if DUE {
            let due = _mm256_cmp_ps::<_CMP_GE_OQ>(due_by, eight(inputs.wake_s));
            to_step = _mm256_or_ps(to_step, due);
        }
        busy |= (_mm256_movemask_ps(to_step) as u32) << (8 * i);
        let photocurrent = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(v, zero),
            _mm256_cmp_ps::<_CMP_LE_OQ>(v, largest),
        );
        valid |= (_mm256_movemask_ps(photocurrent) as u32) << (8 * i);
    }
    Flags {
        busy,
        invalid: !valid,
    }
}

/// A usable photocurrent: finite and >= 0 (-0.0 included), tested on the bits so loops vectorise.
#[inline(always)]
pub fn valid_value(v: f32) -> bool {
    let b = v.to_bits();
    (b <= 0x7f7f_ffff) | (b == 0x8000_0000)
}

/// Whether every value is a usable photocurrent (`valid_value`): one test for all, without a
/// branch a value (so the loop vectorises), for the first frame, which has no scan.
pub fn all_valid(values: &[f32]) -> bool {
    values.iter().fold(true, |ok, &v| ok & valid_value(v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Draw, Stream};

    /// Values no photocurrent has and the edges of those it may have.
    const SPECIAL: [f32; 14] = [
        0.0,
        -0.0,
        f32::from_bits(1),
        -f32::from_bits(1),
        f32::MIN_POSITIVE,
        -f32::MIN_POSITIVE,
        1.0,
        -1.0,
        f32::MAX,
        f32::MIN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        -f32::NAN,
    ];

    #[test]
    fn all_valid_finds_any_value_that_is_not_a_photocurrent() {
        // A photocurrent is finite and not below zero (-0.0 is zero): NaN, the infinities and
        // every negative number (subnormals included) are not, wherever they sit in a frame.
        let is_photocurrent = |v: f32| v.is_finite() && (v >= 0.0);
        let mut values = SPECIAL.to_vec();
        values.extend((0..64).map(|i| f32::from_bits(0x0123_4567u32.rotate_left(i / 2) ^ i)));
        for &v in &values {
            for at in [0, 5, 31, 32, 999] {
                let mut frame = vec![0.5f32; 1000];
                frame[at] = v;
                assert_eq!(all_valid(&frame), is_photocurrent(v), "{v:e} at {at}");
                assert_eq!(valid_value(v), is_photocurrent(v), "{v:e}");
            }
        }
    }

    #[test]
    fn the_avx2_flags_are_the_loops_bit_for_bit() {
        // Blocks whose values, last values, bands and wake-up times are drawn from a few
        // levels and the special values, so that values equal the last ones, the band's ends
        // and the wake-up time often; every mix of band and wake-up due.
        let Some(avx2) = Avx2::detect() else {
            return;
        };
        let levels = [0.25f32, 0.5, 0.75, 1.0];
        let pick = |seed: u64, k: usize, with_specials: bool| {
            let u = Draw::new(seed, k as u64, 0).uniform(Stream::Jitter);
            let specials = if with_specials { SPECIAL.len() } else { 0 };
            let i = (u * (levels.len() + specials) as f64) as usize;
            *levels.get(i).unwrap_or_else(|| &SPECIAL[i - levels.len()])
        };
        for b in 0..3000u64 {
            let block = |field: u64, specials: bool| -> [f32; BLOCK] {
                std::array::from_fn(|k| pick(5 * b + field, k, specials))
            };
            let (value, last) = (block(0, true), block(1, false));
            let (lo, hi, wake_s) = (block(2, false), block(3, false), block(4, false));
            let inputs = |band| Inputs {
                value: &value,
                last: &last,
                band,
                wake_s: &wake_s,
            };
            for band in [None, Some((&lo, &hi))] {
                for due_by in [None, Some(0.5), Some(f32::INFINITY)] {
                    let portable = flags(&inputs(band), due_by, None);
                    assert_eq!(
                        flags(&inputs(band), due_by, Some(avx2)),
                        portable,
                        "block {b}"
                    );
                }
            }
        }
    }
}
