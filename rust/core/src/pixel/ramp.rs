//! The pixel between happenings, following its input along a segment (a ramp in log): what
//! drives it, the low-pass's closed form, the leak drift that follows the light, the
//! shot-noise clock, and the linear case whose crossings have a closed form.

use super::{Drive, PixelEvent, PixelModel, PixelState, Segment, ShotClock};
use crate::crossing::{greater, Difference};
use crate::exp::exp;
use crate::noise::{self, GeometricRate};
use crate::params::ReferenceReset;
use crate::photoreceptor::inverse_current;
use crate::rng::Draw;

/// The input's slope over a segment for the low-pass, (u1 - u0) / dt, as a product by 1 / dt
/// (`inv_dt`, taken once per frame by the dense path); 0 for an empty segment.
#[inline(always)]
pub(crate) fn drive_slope(u0: f64, u1: f64, dt: f64, inv_dt: f64) -> f64 {
    if dt > 0.0 {
        (u1 - u0) * inv_dt
    } else {
        0.0
    }
}

impl PixelModel {
    /// v - ref from the state's time on, for a segment with input slope `slope`.
    #[inline(always)]
    pub(super) fn difference(
        &self,
        st: &PixelState,
        slope: f64,
        tau: f64,
        inv_tau: f64,
    ) -> Difference {
        let reference = self.reference_at(st, st.t_s);
        Difference::of_pixel(st.u, st.v, reference, st.leak_drift, slope, tau, inv_tau)
    }

    /// When the state's shot-noise budget runs out on the rest of the segment (infinity if it
    /// does not). The rate is monotone over a segment, so its larger end bounds the hazard and
    /// usually rules an event out without a logarithm.
    pub(super) fn shot_clock(&self, st: &PixelState, seg: &Segment, drive: &Drive) -> ShotClock {
        let never = ShotClock {
            settled_s: st.t_s,
            due_s: f64::INFINITY,
        };
        if self.params.shot_rate_hz == 0.0 {
            return never;
        }
        let horizon = seg.t1_s - st.t_s;
        let rate = drive.shot.later_by(st.t_s - seg.t0_s);
        if greater(rate.r_a, drive.shot_end_hz) * horizon < st.shot_budget {
            return never;
        }
        match rate.time_to(st.shot_budget).filter(|&s| s <= horizon) {
            Some(s) => ShotClock {
                due_s: st.t_s + s,
                ..never
            },
            None => never,
        }
    }

    /// Take the hazard used since the clock was set from the state's budget, at the end of a run.
    pub(super) fn settle_shots(
        &self,
        st: &mut PixelState,
        seg: &Segment,
        drive: &Drive,
        clock: &ShotClock,
    ) {
        if self.params.shot_rate_hz > 0.0 {
            let rate = drive.shot.later_by(clock.settled_s - seg.t0_s);
            st.shot_budget -= rate.hazard(st.t_s - clock.settled_s);
        }
    }

    /// What drives the pixel over a segment: input slope, low-pass time constant (held at the
    /// geometric-mean photocurrent) and the shot-noise rate from the segment's start. A division
    /// is the costliest single operation of a step, so each is taken once: 1 / dt (the dense
    /// path takes it once a frame), 1 / x at each end (the shot-noise rates and the time
    /// constant are products of it) and 1 / tau.
    pub(super) fn drive(&self, seg: &Segment) -> Drive {
        let dt = seg.t1_s - seg.t0_s;
        let inv_dt = 1.0 / dt;
        let (inv_x0, inv_x1) = (inverse_current(seg.x0), inverse_current(seg.x1));
        let (shot, shot_end_hz) = if self.params.shot_rate_hz > 0.0 {
            let g = if dt > 0.0 && dt.is_finite() && seg.x0 != seg.x1 {
                // ln(x1 / x0), which a logarithmic response already holds as u1 - u0.
                let log_ratio = if self.receptor.is_logarithmic() {
                    seg.u1 - seg.u0
                } else {
                    (seg.x1 / seg.x0).ln()
                };
                // g = -n ln(x1 / x0) / dt (n 1 or 2: the product by it is exact)
                -self.params.shot_light_exponent * log_ratio * inv_dt
            } else {
                0.0
            };
            let r_a = noise::shot_rate_at_inverse_hz(&self.params, inv_x0);
            (
                GeometricRate { r_a, g },
                noise::shot_rate_at_inverse_hz(&self.params, inv_x1),
            )
        } else {
            (GeometricRate { r_a: 0.0, g: 0.0 }, 0.0)
        };
        let tau = self.receptor.segment_tau_s(inv_x0, inv_x1);
        Drive {
            slope: drive_slope(seg.u0, seg.u1, dt, inv_dt),
            tau,
            inv_tau: 1.0 / tau,
            shot,
            shot_end_hz,
        }
    }

    /// Move the state along the segment to `t_s` with no event in between.
    #[inline(always)]
    pub(super) fn advance_to(&self, st: &mut PixelState, seg: &Segment, drive: &Drive, t_s: f64) {
        let (tau, inv_tau) = (drive.tau, drive.inv_tau);
        let s = t_s - st.t_s;
        if s <= 0.0 {
            return;
        }
        let slope = drive.slope;
        let u = if t_s >= seg.t1_s {
            seg.u1
        } else {
            seg.u0 + slope * (t_s - seg.t0_s)
        };
        st.v = if tau > 0.0 {
            u - slope * tau + (st.v - st.u + slope * tau) * exp(-s * inv_tau)
        } else {
            u
        };
        st.u = u;
        // The photocurrent is read at segment ends only (next wake-up, next segment).
        if t_s >= seg.t1_s {
            st.x = seg.x1;
        }
        st.t_s = t_s;
    }

    /// The leak drift at a new light level x1 (`noise::leak_law_hz`), held over the segment that
    /// ends at it: exact for constant light, which is what the wake-up bound and a still pixel
    /// see; over a changing frame interval (tens of ms) against leak periods of seconds, the
    /// end value stands for the interval. The reference is re-based at the state's time, so the
    /// drift already done stays. The pixel's factor is the old drift over the old law, or its
    /// frozen draw when the old law was zero.
    #[inline]
    pub(super) fn follow_light_with_leak(&self, st: &mut PixelState, pixel: u64, x1: f64) {
        let p = &self.params;
        if p.leak_light_rate_hz == 0.0 || x1 == st.x {
            return;
        }
        let law_before = noise::leak_law_hz(p, st.x);
        let drift = if law_before > 0.0 {
            st.leak_drift * (noise::leak_law_hz(p, x1) / law_before)
        } else {
            let frozen = Draw::new(p.seed, pixel, 0);
            noise::leak_rate_hz(p, frozen, x1) * st.base_theta_on
        };
        st.ref0 = self.reference_at(st, st.t_s);
        st.t_ref_s = st.t_s;
        st.leak_drift = drift;
    }

    /// Whether v - ref is linear in time over the rest of `seg` with only crossings to come:
    /// instantaneous photoreceptor, no leak or shot noise, no hot-pixel event, and a reference
    /// that is set at the event (ESIM's rule, or no refractory period).
    #[inline]
    pub(super) fn is_linear(&self, st: &PixelState, seg: &Segment) -> bool {
        self.receptor.is_instantaneous()
            && st.leak_drift == 0.0
            && self.params.shot_rate_hz == 0.0
            && st.hot_next_s > seg.t1_s
            && (self.params.reference_reset == ReferenceReset::Event || self.refractory_s == 0.0)
    }

    /// `run` for a linear difference: each crossing in closed form, u(t) = level.
    pub(super) fn run_linear(
        &self,
        st: &mut PixelState,
        pixel: u64,
        seg: &Segment,
        events: &mut impl FnMut(PixelEvent),
    ) {
        if seg.t1_s < st.t_s {
            return;
        }
        let slope = seg.slope();
        // Only one direction can cross: the input moves one way (a constant input crosses only
        // if a state left it beyond a threshold, which the loop then catches at once).
        let on = slope > 0.0 || (slope == 0.0 && seg.u1 >= st.ref0 + st.theta_on);
        if self.params.theta_noise == 0.0 && self.jitter_s == 0.0 {
            if on {
                self.cross_fixed_threshold::<true>(st, seg, slope, events);
            } else {
                self.cross_fixed_threshold::<false>(st, seg, slope, events);
            }
        } else {
            self.cross_noisy_thresholds(st, pixel, seg, slope, on, events);
        }
        st.t_s = seg.t1_s;
        st.u = seg.u1;
        st.v = seg.u1;
        st.x = seg.x1;
    }
}
