//! A pixel whose whole state is its reference: ESIM's model (Rebecq et al., CoRL 2018) and the
//! ideal sensor. With an instantaneous logarithmic response, the same thresholds at every pixel,
//! no refractory period, latency, leak or noise, nothing else a `PixelState` holds changes what
//! the pixel does next, so a tile keeps one number a pixel (`Tile::references`) instead of a
//! 128-byte state, and steps it without gathering or scattering the other fields.

use super::{PixelEvent, PixelModel, PixelState, Segment};

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
