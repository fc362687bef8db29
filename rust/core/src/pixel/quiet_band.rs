//! The quiet band of a time-invariant pixel: the frame values between which it cannot cross a
//! threshold, so that a frame inside it skips the pixel.

use super::{PixelModel, PixelState};
use crate::exp::exp;
use crate::f32_bounds::band_inside_f32;
use crate::photoreceptor::Photoreceptor;
use crate::rng::Draw;

impl PixelModel {
    /// For time-invariant models: the frame values (exclusive of dark current) between which the
    /// pixel cannot cross a threshold, shrunk by a relative margin so the test is conservative.
    pub fn quiet_band(&self, st: &PixelState) -> (f64, f64) {
        self.band_around(self.reference_at(st, st.t_s), st.theta_on, st.theta_off)
    }

    /// `quiet_band` of the state `init(pixel, frame_value, t_s)` would make, without making it:
    /// the same operations on the same values. Time-invariant models only (no leak moves the
    /// reference: it is the initial response).
    pub fn first_quiet_band(&self, pixel: u64, frame_value: f64) -> (f64, f64) {
        debug_assert!(self.is_time_invariant());
        let u = self
            .receptor
            .response(self.receptor.total_current(frame_value));
        let (theta_on, theta_off) = self.base_thetas(Draw::new(self.params.seed, pixel, 0));
        self.band_around(u, theta_on, theta_off)
    }

    /// `quiet_band` of a reference-only pixel (`is_reference_only`) holding `reference`.
    #[inline]
    pub fn reference_band(&self, reference: f64) -> (f64, f64) {
        self.band_around(reference, self.params.theta_on, self.params.theta_off)
    }

    fn band_around(&self, reference: f64, theta_on: f64, theta_off: f64) -> (f64, f64) {
        let r = &self.receptor;
        let (hi, lo) = match self.band_factors {
            Some((up, down)) => {
                let x_ref = exp(reference);
                (x_ref * up, x_ref * down)
            }
            None => (
                r.inverse_response(reference + theta_on),
                r.inverse_response(reference - theta_off),
            ),
        };
        narrowed_band(r.frame_value(lo), r.frame_value(hi))
    }

    /// e^theta_on and e^-theta_off where every pixel has these thresholds and the response is
    /// logarithmic: a quiet band is then e^reference times them (`band_around`).
    #[inline]
    pub(crate) fn band_factors(&self) -> Option<(f64, f64)> {
        self.band_factors
    }
}

/// The quiet band in f32 as a tile keeps it (`band_inside_f32`) of a pixel whose reference is
/// the response to the total photocurrent `x_ref`, for a model with band factors (up, down):
/// `band_around`'s operations, shared by the vectorised bands (`first_band`, `reference_only`)
/// so that they give its bits.
#[inline(always)]
pub(crate) fn rounded_band(r: &Photoreceptor, x_ref: f64, (up, down): (f64, f64)) -> (f32, f32) {
    band_inside_f32(narrowed_band(
        r.frame_value(x_ref * down),
        r.frame_value(x_ref * up),
    ))
}

/// The quiet band from the frame values at which a threshold is reached, narrowed by a relative
/// margin so that rounding never lets an input that crosses a threshold inside it (no lower end
/// where it is not above zero). Shared by `band_around` and `rounded_band`, so the two give the
/// same bits.
#[inline(always)]
fn narrowed_band(lo: f64, hi: f64) -> (f64, f64) {
    let margin = 1e-6;
    (
        if lo > 0.0 {
            lo * (1.0 + margin) + 1e-30
        } else {
            f64::NEG_INFINITY
        },
        hi * (1.0 - margin),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::SensorParams;

    #[test]
    fn the_first_quiet_band_is_the_band_of_the_first_state_bit_for_bit() {
        // Time-invariant models: ideal (log band factors), with threshold mismatch (a draw per
        // pixel), and a lin-log receptor (no band factors: inverse responses); values from
        // dark to bright, zero included.
        let ideal = SensorParams::ideal(1, 1);
        let mut mismatched = ideal.clone();
        mismatched.theta_sigma = 0.05;
        let mut linlog = mismatched.clone();
        linlog.lin_log_knee = 0.05;
        for params in [ideal, mismatched, linlog] {
            let model = PixelModel::new(params);
            assert!(model.is_time_invariant());
            for pixel in 0..500u64 {
                let value = [0.0, 1e-6, 0.003, 0.2, 0.77, 40.0][pixel as usize % 6]
                    * (1.0 + pixel as f64 * 1e-3);
                let made = model.quiet_band(&model.init(pixel, value, 0.0));
                let first = model.first_quiet_band(pixel, value);
                assert_eq!(
                    made.0.to_bits(),
                    first.0.to_bits(),
                    "lo, pixel {pixel}, {value}"
                );
                assert_eq!(
                    made.1.to_bits(),
                    first.1.to_bits(),
                    "hi, pixel {pixel}, {value}"
                );
            }
        }
    }
}
