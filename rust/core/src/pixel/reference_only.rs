//! A pixel whose whole state is its reference: ESIM's model (Rebecq et al., CoRL 2018) and the
//! ideal sensor. With an instantaneous logarithmic response, the same thresholds at every pixel,
//! no refractory period, latency, leak or noise, nothing else a `PixelState` holds changes what
//! the pixel does next, so a tile keeps one number a pixel (`Tile::references`) instead of a
//! 128-byte state, and steps it without gathering or scattering the other fields.

use super::{Cause, PixelEvent, PixelModel};

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

    /// The reference a pixel starts with (`init`'s): the response to its first frame value.
    #[inline]
    pub fn first_reference(&self, frame_value: f64) -> f64 {
        let r = &self.receptor;
        r.response(r.total_current(frame_value))
    }

    /// The response to a frame value, which the ramps of a reference-only pixel run between.
    #[inline]
    pub fn response_to(&self, frame_value: f32) -> f64 {
        self.first_reference(frame_value as f64)
    }

    /// The crossings of a reference-only pixel holding `reference`, along the ramp linear in log
    /// from u0 at t0 to u1 at t1 (u(t) = level at each), pushed in time order; returns the
    /// reference after them. `t1_s - t0_s` is positive.
    #[inline]
    pub fn cross_reference(
        &self,
        reference: f64,
        (t0_s, u0): (f64, f64),
        (t1_s, u1): (f64, f64),
        events: &mut impl FnMut(PixelEvent),
    ) -> f64 {
        let slope = (u1 - u0) / (t1_s - t0_s);
        let (theta_on, theta_off) = (self.params.theta_on, self.params.theta_off);
        // Only one direction can cross: the one the input moves in.
        let on = slope > 0.0 || (slope == 0.0 && u1 >= reference + theta_on);
        let step = if on { theta_on } else { -theta_off };
        let (mut t_s, mut reference, mut level) = (t0_s, reference, reference + step);
        while if on { u1 >= level } else { u1 <= level } {
            // `Segment::time_of`: kept within [the previous crossing, t1].
            t_s = if slope == 0.0 {
                t_s
            } else {
                (t0_s + (level - u0) / slope).max(t_s).min(t1_s)
            };
            events(PixelEvent {
                t_s,
                on,
                cause: Cause::Signal,
            });
            reference = level;
            level += step;
        }
        reference
    }
}
