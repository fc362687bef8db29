//! A pixel whose whole state is its reference: ESIM's model (Rebecq et al., CoRL 2018) and the
//! ideal sensor. With an instantaneous logarithmic response, the same thresholds at every pixel,
//! no refractory period, latency, leak or noise, nothing else a `PixelState` holds changes what
//! the pixel does next, so a tile keeps one number a pixel (`Tile::references`) instead of a
//! 128-byte state, and steps it without gathering or scattering the other fields.
//!
//! A step's logarithms (the ramp's ends, a first reference) and exponentials (the quiet band
//! around the new reference) are worked out for `GROUP` pixels at once, in branch-free loops the
//! compiler turns into vector code (AVX-512 or AVX2, chosen at run time), with `exp`'s functions:
//! the same operations as `response_to` and `reference_band`, so the same bits. One pixel at a
//! time, each is a chain of some 40 dependent operations, and these chains were most of a step.

use super::{rounded_band, PixelEvent, PixelModel, PixelState, Segment};
use crate::cpu_dispatch::compiled_per_cpu;
use crate::exp::{exp_in_range, in_exp_range, ln_in_range};
use crate::f32_bounds::band_inside_f32;

/// Pixels whose responses and bands are worked out together: the f64 lanes of an AVX-512
/// vector, two of AVX2.
pub const GROUP: usize = 8;

/// A group's frame values whose responses a step needs: rows of `GROUP` (see
/// `PixelModel::responses_to_group`).
pub const RAMP_VALUES: usize = 3 * GROUP;

impl PixelModel {
    /// Whether a pixel's state is its reference alone (see the module's note). Its events are
    /// then those `run` gives, bit for bit: the same arithmetic as `cross_fixed_threshold`.
    pub fn is_reference_only(&self) -> bool {
        self.is_time_invariant()
            && !self.acts_with_constant_input()
            && self.band_factors.is_some()
            && self.refractory_s == 0.0
            && self.latency_s == 0.0
            && self.jitter_s == 0.0
    }

    /// The response to a frame value: a pixel's first reference, and the ends of its ramps.
    #[inline]
    pub fn response_to(&self, frame_value: f32) -> f64 {
        let r = &self.receptor;
        r.response(r.total_current(frame_value as f64))
    }

    /// `response_to` of each value, bit for bit: the lanes' loop where the value is in ln's fast
    /// range, `response_to` one at a time elsewhere (no photocurrent, for one).
    pub fn responses_to_group(&self, values: &[f32; RAMP_VALUES]) -> [f64; RAMP_VALUES] {
        let (mut u, fast) = fast_responses(self, values);
        let mut slow = !fast & (u32::MAX >> (32 - RAMP_VALUES));
        while slow != 0 {
            let k = slow.trailing_zeros() as usize;
            u[k] = self.response_to(values[k]);
            slow &= slow - 1;
        }
        u
    }

    /// `reference_band` of each reference in f32 as a tile keeps it (`band_inside_f32`), bit
    /// for bit: the lanes' loop where e^reference is in exp's fast range, `reference_band` one at
    /// a time elsewhere.
    pub fn reference_bands_of_group(
        &self,
        references: &[f64; GROUP],
    ) -> ([f32; GROUP], [f32; GROUP]) {
        let factors = self
            .band_factors
            .expect("a reference-only model has band factors");
        let (mut lo, mut hi, fast) = fast_reference_bands(self, factors, references);
        let mut slow = !fast & (u32::MAX >> (32 - GROUP));
        while slow != 0 {
            let k = slow.trailing_zeros() as usize;
            (lo[k], hi[k]) = band_inside_f32(self.reference_band(references[k]));
            slow &= slow - 1;
        }
        (lo, hi)
    }

    /// The crossings of a reference-only pixel holding `reference`, along the ramp linear in log
    /// from u0 at t0 to u1 at t1, pushed in time order; returns the reference after them. The
    /// state `run_linear` takes is the reference with nothing else that acts (no earlier event
    /// it could come before, no photocurrent it reads): once inlined, only the reference and
    /// the crossings' time are left.
    #[inline(always)]
    pub fn cross_reference(
        &self,
        reference: f64,
        (t0_s, u0): (f64, f64),
        (t1_s, u1): (f64, f64),
        events: &mut impl FnMut(PixelEvent),
    ) -> f64 {
        let p = &self.params;
        let mut st = PixelState {
            t_s: t0_s,
            u: u0,
            x: 0.0,
            v: u0,
            ref0: reference,
            t_ref_s: t0_s,
            leak_drift: 0.0,
            theta_on: p.theta_on,
            theta_off: p.theta_off,
            base_theta_on: p.theta_on,
            base_theta_off: p.theta_off,
            refractory_mark_s: f64::NEG_INFINITY,
            last_out_s: f64::NEG_INFINITY,
            shot_budget: f64::INFINITY,
            hot_next_s: f64::INFINITY,
            draws: 0,
        };
        let ramp = Segment {
            t0_s,
            t1_s,
            u0,
            u1,
            x0: 0.0,
            x1: 0.0,
        };
        self.run_linear(&mut st, 0, &ramp, events);
        st.ref0
    }
}

compiled_per_cpu! {
    /// `response_to` of each value where it is ln of the total photocurrent in ln's fast range;
    /// returns those lanes (bit k), the others being left to `response_to`.
    fn fast_responses(
        model: &PixelModel,
        values: &[f32; RAMP_VALUES],
    ) -> ([f64; RAMP_VALUES], u32) = fast_responses_lanes, avx512 fast_responses_avx512,
        avx2 fast_responses_avx2;
}

/// The lanes' loops of `fast_responses`: `response_to`'s operations, a loop a stage so the
/// chains of different vectors overlap.
#[inline(always)]
fn fast_responses_lanes(
    model: &PixelModel,
    values: &[f32; RAMP_VALUES],
) -> ([f64; RAMP_VALUES], u32) {
    let r = &model.receptor;
    let mut x = [0.0; RAMP_VALUES];
    for k in 0..RAMP_VALUES {
        x[k] = r.total_current(values[k] as f64);
    }
    let mut u = [0.0; RAMP_VALUES];
    for k in 0..RAMP_VALUES {
        u[k] = ln_in_range(x[k]);
    }
    let fast = (x.iter().enumerate()).fold(0, |fast, (k, &x)| {
        fast | (r.response_is_ln_in_range(x) as u32) << k
    });
    (u, fast)
}

compiled_per_cpu! {
    /// `reference_band`'s band with band factors (e^theta_on, e^-theta_off), rounded into f32,
    /// where e^reference is in exp's fast range; returns those lanes (bit k).
    fn fast_reference_bands(
        model: &PixelModel,
        factors: (f64, f64),
        references: &[f64; GROUP],
    ) -> ([f32; GROUP], [f32; GROUP], u32) = fast_reference_bands_lanes,
        avx512 fast_reference_bands_avx512, avx2 fast_reference_bands_avx2;
}

/// The lanes' loops of `fast_reference_bands`: `band_around`'s operations with band factors.
#[inline(always)]
fn fast_reference_bands_lanes(
    model: &PixelModel,
    factors: (f64, f64),
    references: &[f64; GROUP],
) -> ([f32; GROUP], [f32; GROUP], u32) {
    let r = &model.receptor;
    let mut x_ref = [0.0; GROUP];
    for k in 0..GROUP {
        x_ref[k] = exp_in_range(references[k]);
    }
    let (mut lo, mut hi) = ([0.0; GROUP], [0.0; GROUP]);
    let mut fast = 0;
    for k in 0..GROUP {
        (lo[k], hi[k]) = rounded_band(r, x_ref[k], factors);
        fast |= (in_exp_range(references[k]) as u32) << k;
    }
    (lo, hi, fast)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::f32_bounds::{round_down_f32, round_up_f32};
    use crate::first_band::first_frame_values;
    use crate::params::{ReferenceReset, SensorParams};

    /// Reference-only models: the ideal pixel, ESIM's reset at other light levels, and one
    /// without dark current (a zero photocurrent: ln 0 = -inf, out of the lanes' range).
    fn reference_only_models() -> Vec<PixelModel> {
        let ideal = SensorParams::ideal(1, 1);
        let mut esim = ideal.clone();
        esim.reference_reset = ReferenceReset::Event;
        let (mut bright, mut dim) = (esim.clone(), esim.clone());
        (bright.white_lux, bright.theta_on) = (2.0e3, 0.15);
        (dim.white_lux, dim.theta_off) = (1e3 / 1024.0, 0.35);
        let mut dark_free = ideal.clone();
        dark_free.dark_current = 0.0;
        let models: Vec<_> = [ideal, esim, bright, dim, dark_free]
            .into_iter()
            .map(PixelModel::new)
            .collect();
        assert!(models.iter().all(PixelModel::is_reference_only));
        models
    }

    /// References from every value's response and out of exp's fast range.
    fn references(model: &PixelModel) -> Vec<f64> {
        let mut references: Vec<f64> = first_frame_values()
            .into_iter()
            .map(|v| model.response_to(v))
            .collect();
        references.extend([-800.0, 800.0, -708.0, 707.9, 0.0, f64::NEG_INFINITY]);
        references
    }

    #[test]
    fn a_group_gives_the_responses_and_bands_of_one_pixel_at_a_time_bit_for_bit() {
        for model in reference_only_models() {
            for values in first_frame_values().chunks_exact(RAMP_VALUES) {
                let values: &[f32; RAMP_VALUES] = values.try_into().unwrap();
                let group = model.responses_to_group(values);
                for (u, &v) in group.iter().zip(values) {
                    assert_eq!(u.to_bits(), model.response_to(v).to_bits(), "{v:e}");
                }
            }
            for references in references(&model).chunks_exact(GROUP) {
                let references: &[f64; GROUP] = references.try_into().unwrap();
                let (lo, hi) = model.reference_bands_of_group(references);
                for k in 0..GROUP {
                    let (l, h) = model.reference_band(references[k]);
                    assert_eq!(
                        (lo[k].to_bits(), hi[k].to_bits()),
                        (round_up_f32(l).to_bits(), round_down_f32(h).to_bits()),
                        "{:e}",
                        references[k]
                    );
                }
            }
        }
    }

    #[test]
    fn every_instruction_set_gives_the_same_lanes() {
        // The group functions take the widest copy the CPU has; the others, run here directly,
        // must agree bit for bit, and on which lanes they leave to one pixel at a time.
        for model in reference_only_models() {
            let factors = model.band_factors().unwrap();
            let bits = |(u, fast): ([f64; RAMP_VALUES], u32)| (u.map(f64::to_bits), fast);
            let band_bits = |(lo, hi, fast): ([f32; GROUP], [f32; GROUP], u32)| {
                (lo.map(f32::to_bits), hi.map(f32::to_bits), fast)
            };
            for values in first_frame_values().chunks_exact(RAMP_VALUES) {
                let values: &[f32; RAMP_VALUES] = values.try_into().unwrap();
                let portable = bits(fast_responses_lanes(&model, values));
                assert_eq!(portable, bits(fast_responses(&model, values)));
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: the CPU supports AVX2 and FMA, checked just above.
                    assert_eq!(
                        portable,
                        bits(unsafe { fast_responses_avx2(&model, values) })
                    );
                }
            }
            for references in references(&model).chunks_exact(GROUP) {
                let references: &[f64; GROUP] = references.try_into().unwrap();
                let portable = band_bits(fast_reference_bands_lanes(&model, factors, references));
                assert_eq!(
                    portable,
                    band_bits(fast_reference_bands(&model, factors, references))
                );
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: the CPU supports AVX2 and FMA, checked just above.
                    let avx2 = unsafe { fast_reference_bands_avx2(&model, factors, references) };
                    assert_eq!(portable, band_bits(avx2));
                }
            }
        }
    }

    #[test]
    fn the_fast_lanes_leave_zero_photocurrent_and_huge_references_to_one_pixel_at_a_time() {
        let models = reference_only_models();
        let dark_free = models.last().unwrap();
        let mut values = [0.5f32; RAMP_VALUES];
        values[3] = 0.0;
        values[20] = f32::MAX;
        // With dark current every value is in ln's range; without it ln 0 is the library's.
        assert_eq!(fast_responses_lanes(&models[0], &values).1, u32::MAX >> 8);
        assert_eq!(
            fast_responses_lanes(dark_free, &values).1,
            u32::MAX >> 8 & !(1 << 3)
        );
        assert_eq!(dark_free.responses_to_group(&values)[3], f64::NEG_INFINITY);
        let mut references = [0.0; GROUP];
        references[1] = 800.0;
        references[6] = f64::NEG_INFINITY;
        let factors = dark_free.band_factors().unwrap();
        let fast = fast_reference_bands_lanes(dark_free, factors, &references).2;
        assert_eq!(fast, 0xff & !(1 << 1) & !(1 << 6));
        let (lo, hi) = dark_free.reference_bands_of_group(&references);
        // e^-inf = 0: a band from nothing (no lower end) to nothing.
        assert_eq!((lo[6], hi[6]), (f32::NEG_INFINITY, 0.0));
        assert_eq!(hi[1], f32::INFINITY);
    }
}
