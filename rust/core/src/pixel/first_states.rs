//! The first states of a block of pixels at once: `PixelModel::init`, lane by lane.
//!
//! Where every pixel changes, the sensor's first changed frame makes every pixel's state (921,600
//! at 1280 x 720), at about 560 instructions each one at a time: three frames' work in one.
//! Branch-free loops over the block's pixels, one a stage, run `init`'s operations in the same
//! order, so the compiler vectorises them (AVX-512 or AVX2, chosen at run time) and the states
//! are the same bits. A pixel off the common path is left to `init`: a threshold or leak draw in
//! a tail of the normal distribution (5 % of draws: a logarithm and a root), a photocurrent
//! outside `ln`'s fast range or below a lin-log knee, a leak factor outside `exp`'s, a hot
//! pixel. The exponential draws of shot noise take the C library's logarithm, one at a time.

// Lane loops index several arrays by the lane, the form the vectoriser takes best.
#![allow(clippy::needless_range_loop)]

use super::power_up::{frozen_theta, leak_reference_time_s};
use super::PixelModel;
use crate::cpu_dispatch::compiled_per_cpu;
use crate::exp::{exp_in_range, in_exp_range, ln_in_range};
use crate::noise::{has_leak, is_hot, leak_factor_exponent, leak_law_hz};
use crate::rng::{central_normal, is_central, unit_open, Draw, Stream};
use crate::state_block::{bits_of, StateBlock, LANES};

impl PixelModel {
    /// The states `init` makes at `t_s` for the pixels `first_pixel + k` with first-frame values
    /// `values[k]`, for the bits k of `pixels`, into `block`'s lanes (the others are left).
    pub fn init_block(
        &self,
        first_pixel: u64,
        values: &[f32; LANES],
        t_s: f64,
        pixels: u32,
        block: &mut StateBlock,
    ) {
        let lanes = Lanes {
            first_pixel,
            values,
            t_s,
        };
        let made = first_states_of_block(self, &lanes, pixels, block);
        let mut rest = pixels & !made;
        while rest != 0 {
            let k = rest.trailing_zeros() as usize;
            let state = self.init(first_pixel + k as u64, values[k] as f64, t_s);
            block.set(k, &state);
            rest &= rest - 1;
        }
    }
}

/// The pixels of a block and their first-frame values.
struct Lanes<'a> {
    first_pixel: u64,
    values: &'a [f32; LANES],
    t_s: f64,
}

compiled_per_cpu! {
    /// `init`'s states for the pixels of `pixels` on the common path, into their lanes of
    /// `block`; returns those lanes (bit k), the others being left to `init`.
    fn first_states_of_block(
        model: &PixelModel,
        lanes: &Lanes,
        pixels: u32,
        block: &mut StateBlock,
    ) -> u32 = first_states_lanes, avx512 first_states_avx512, avx2 first_states_avx2;
}

/// A pixel's first state, field by field, for a block's lanes.
struct FirstStates {
    u: [f64; LANES],
    x: [f64; LANES],
    theta_on: [f64; LANES],
    theta_off: [f64; LANES],
    leak_drift: [f64; LANES],
    t_ref_s: [f64; LANES],
    /// Lanes on the common path.
    common: [bool; LANES],
}

#[inline(always)]
fn first_states_lanes(
    model: &PixelModel,
    lanes: &Lanes,
    pixels: u32,
    block: &mut StateBlock,
) -> u32 {
    let p = &model.params;
    let frozen: [Draw; LANES] =
        std::array::from_fn(|k| Draw::new(p.seed, lanes.first_pixel + k as u64, 0));
    let mut first = FirstStates {
        u: [0.0; LANES],
        x: [0.0; LANES],
        theta_on: [p.theta_on; LANES],
        theta_off: [p.theta_off; LANES],
        leak_drift: [0.0; LANES],
        t_ref_s: [0.0; LANES],
        common: [true; LANES],
    };
    responses(model, lanes.values, &mut first);
    if p.theta_sigma != 0.0 {
        frozen_thetas(model, &frozen, &mut first);
    }
    leaks(model, &frozen, lanes.t_s, &mut first);
    if p.hot_pixel_fraction > 0.0 && p.hot_pixel_rate_hz > 0.0 {
        for k in 0..LANES {
            first.common[k] &= !is_hot(p, frozen[k]);
        }
    }
    let made = pixels & bits_of(&first.common);
    write_lanes(block, made, lanes.t_s, &first);
    // The shot-noise hazard: an exponential draw, the C library's logarithm (as `init`'s).
    if p.shot_rate_hz > 0.0 {
        let mut rest = made;
        while rest != 0 {
            let k = rest.trailing_zeros() as usize;
            block.shot_budget[k] = frozen[k].exponential(Stream::ShotTime);
            rest &= rest - 1;
        }
    } else {
        put(&mut block.shot_budget, made, &[f64::INFINITY; LANES]);
    }
    made
}

/// The total photocurrents and their responses (ln x above the knee, in `ln`'s fast range).
#[inline(always)]
fn responses(model: &PixelModel, values: &[f32; LANES], first: &mut FirstStates) {
    let r = &model.receptor;
    for k in 0..LANES {
        first.x[k] = r.total_current(values[k] as f64);
    }
    for k in 0..LANES {
        let x = first.x[k];
        first.common[k] &= r.response_is_ln_in_range(x);
        first.u[k] = ln_in_range(x);
    }
}

/// `base_thetas`: the pair of normal draws of stream `Theta`, in their central region.
#[inline(always)]
fn frozen_thetas(model: &PixelModel, frozen: &[Draw; LANES], first: &mut FirstStates) {
    let p = &model.params;
    let (mut p_on, mut p_off) = ([0.5; LANES], [0.5; LANES]);
    for k in 0..LANES {
        p_on[k] = unit_open(frozen[k].bits(Stream::Theta, 0));
        p_off[k] = unit_open(frozen[k].bits(Stream::Theta, 1));
    }
    for k in 0..LANES {
        first.common[k] &= is_central(p_on[k]) & is_central(p_off[k]);
        let (z_on, z_off) = (central_normal(p_on[k]), central_normal(p_off[k]));
        first.theta_on[k] = frozen_theta(p.theta_on, p.theta_sigma, z_on, p.theta_min);
        first.theta_off[k] = frozen_theta(p.theta_off, p.theta_sigma, z_off, p.theta_min);
    }
}

/// `noise_start`'s leak: the rate (the leak factor's normal draw in its central region, its
/// exponential in `exp`'s fast range), the drift of the reference and its memorised time.
#[inline(always)]
fn leaks(model: &PixelModel, frozen: &[Draw; LANES], t_s: f64, first: &mut FirstStates) {
    let p = &model.params;
    let mut factor = [0.0; LANES];
    if has_leak(p) {
        let mut exponent = [0.0; LANES];
        for k in 0..LANES {
            let draw = unit_open(frozen[k].bits(Stream::LeakRate, 0));
            first.common[k] &= is_central(draw);
            exponent[k] = leak_factor_exponent(p, central_normal(draw));
        }
        for k in 0..LANES {
            first.common[k] &= in_exp_range(exponent[k]);
            factor[k] = exp_in_range(exponent[k]);
        }
    }
    for k in 0..LANES {
        let leak_rate_hz = factor[k] * leak_law_hz(p, first.x[k]);
        let phase = if leak_rate_hz > 0.0 {
            unit_open(frozen[k].bits(Stream::LeakPhase, 0))
        } else {
            0.0
        };
        let theta_on = first.theta_on[k];
        first.leak_drift[k] = leak_rate_hz * theta_on;
        first.t_ref_s[k] = leak_reference_time_s(t_s, phase, theta_on, first.leak_drift[k]);
    }
}

/// The first states into the lanes `made` of `block` (the others keep their values), but the
/// shot-noise hazard's draw.
#[inline(always)]
fn write_lanes(block: &mut StateBlock, made: u32, t_s: f64, first: &FirstStates) {
    put(&mut block.t_s, made, &[t_s; LANES]);
    put(&mut block.u, made, &first.u);
    put(&mut block.x, made, &first.x);
    put(&mut block.v, made, &first.u);
    put(&mut block.ref0, made, &first.u);
    put(&mut block.t_ref_s, made, &first.t_ref_s);
    put(&mut block.leak_drift, made, &first.leak_drift);
    put(&mut block.theta_on, made, &first.theta_on);
    put(&mut block.theta_off, made, &first.theta_off);
    put(&mut block.base_theta_on, made, &first.theta_on);
    put(&mut block.base_theta_off, made, &first.theta_off);
    put(
        &mut block.refractory_mark_s,
        made,
        &[f64::NEG_INFINITY; LANES],
    );
    put(&mut block.last_out_s, made, &[f64::NEG_INFINITY; LANES]);
    put(&mut block.hot_next_s, made, &[f64::INFINITY; LANES]);
    for (k, draws) in block.draws.iter_mut().enumerate() {
        *draws = if made >> k & 1 != 0 { 1 } else { *draws };
    }
}

/// `values` into the lanes `made` of `field`.
#[inline(always)]
fn put(field: &mut [f64; LANES], made: u32, values: &[f64; LANES]) {
    for (k, slot) in field.iter_mut().enumerate() {
        *slot = if made >> k & 1 != 0 { values[k] } else { *slot };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::SensorParams;

    /// The DAVIS346 preset's first-state parameters (python/pecs/config.py: the rest do not
    /// enter `init`), with hot pixels common enough to meet some, and variants that take each
    /// branch of `init`.
    fn models() -> Vec<PixelModel> {
        let davis = SensorParams {
            theta_sigma: 0.03,
            dark_current: 1e-4,
            leak_rate_hz: 0.001,
            leak_light_rate_hz: 0.0004,
            leak_spread_decades: 0.3,
            shot_rate_hz: 10.0,
            hot_pixel_fraction: 0.05,
            hot_pixel_rate_hz: 5.0,
            seed: 17,
            ..SensorParams::ideal(1, 1)
        };
        let mut no_noise = davis.clone();
        (no_noise.leak_rate_hz, no_noise.leak_light_rate_hz) = (0.0, 0.0);
        (no_noise.shot_rate_hz, no_noise.hot_pixel_fraction) = (0.0, 0.0);
        let mut wide_mismatch = davis.clone();
        (wide_mismatch.theta_sigma, wide_mismatch.theta_min) = (0.2, 0.05);
        let mut lin_log = davis.clone();
        (lin_log.lin_log_knee, lin_log.dark_current) = (0.01, 0.0);
        let mut wide_leak = davis.clone();
        wide_leak.leak_spread_decades = 250.0;
        [
            davis,
            no_noise,
            wide_mismatch,
            lin_log,
            wide_leak,
            SensorParams::ideal(1, 1),
        ]
        .into_iter()
        .map(PixelModel::new)
        .collect()
    }

    /// First-frame values from black to far above white, and some that are no photocurrent at
    /// the sensor's light (0 with no dark current).
    fn values(block: usize) -> [f32; LANES] {
        std::array::from_fn(|k| {
            let u = Draw::new(5, (block * LANES + k) as u64, 0).uniform(Stream::Jitter);
            match k % 8 {
                0 => 0.0,
                1 => f32::MIN_POSITIVE / 4.0,
                _ => (10f64.powf(12.0 * u - 8.0)) as f32,
            }
        })
    }

    fn bits(st: &crate::pixel::PixelState) -> [u64; 16] {
        [
            st.t_s,
            st.u,
            st.x,
            st.v,
            st.ref0,
            st.t_ref_s,
            st.leak_drift,
            st.theta_on,
            st.theta_off,
            st.base_theta_on,
            st.base_theta_off,
            st.refractory_mark_s,
            st.last_out_s,
            st.shot_budget,
            st.hot_next_s,
        ]
        .map(f64::to_bits)
        .into_iter()
        .chain([st.draws])
        .collect::<Vec<_>>()
        .try_into()
        .unwrap()
    }

    #[test]
    fn a_block_of_first_states_is_init_of_each_pixel_bit_for_bit() {
        let untouched = {
            let mut block = StateBlock::empty();
            block.u = [-3.0; LANES];
            block
        };
        let mut common = 0;
        for model in models() {
            for b in 0..300 {
                let values = values(b);
                // Whole blocks, and every third pixel left out.
                let pixels = if b % 2 == 0 { u32::MAX } else { 0x9249_2492 };
                let first_pixel = 64 * b as u64 + 3;
                let t_s = 0.25 * b as f64;
                let mut block = untouched;
                model.init_block(first_pixel, &values, t_s, pixels, &mut block);
                let lanes = Lanes {
                    first_pixel,
                    values: &values,
                    t_s,
                };
                let mut again = untouched;
                common += first_states_of_block(&model, &lanes, pixels, &mut again).count_ones();
                for k in 0..LANES {
                    let expected = if pixels >> k & 1 != 0 {
                        model.init(first_pixel + k as u64, values[k] as f64, t_s)
                    } else {
                        untouched.get(k)
                    };
                    assert_eq!(
                        bits(&block.get(k)),
                        bits(&expected),
                        "{:?}: pixel {k} of block {b}, value {:e}",
                        model.params,
                        values[k]
                    );
                }
            }
        }
        // Most pixels take the lanes' path (the others: `init`).
        assert!(
            common > 6 * 300 * 24 / 2,
            "{common} pixels on the common path"
        );
    }

    #[test]
    fn every_instruction_set_gives_the_same_first_states() {
        for model in models() {
            for b in 0..100 {
                let values = values(b);
                let lanes = Lanes {
                    first_pixel: 40 * b as u64,
                    values: &values,
                    t_s: 1.5,
                };
                let run = |f: &dyn Fn(&mut StateBlock) -> u32| {
                    let mut block = StateBlock::empty();
                    let made = f(&mut block);
                    (
                        made,
                        (0..LANES).map(|k| bits(&block.get(k))).collect::<Vec<_>>(),
                    )
                };
                let portable = run(&|block| first_states_lanes(&model, &lanes, u32::MAX, block));
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: the CPU supports AVX2 and FMA, checked just above.
                    let avx2 =
                        run(&|block| unsafe { first_states_avx2(&model, &lanes, u32::MAX, block) });
                    assert!(portable == avx2, "AVX2, block {b}");
                }
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: the CPU supports AVX-512F, checked just above.
                    let avx512 = run(&|block| unsafe {
                        first_states_avx512(&model, &lanes, u32::MAX, block)
                    });
                    assert!(portable == avx512, "AVX-512, block {b}");
                }
            }
        }
    }
}
