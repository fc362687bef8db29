//! A pixel's first state: settled at its first-frame input, with the frozen draws that stay
//! with it (threshold mismatch, leak rate, hot or not) and where its noise starts, as a
//! powered-up sensor's would be; and when such a pixel first acts.

use super::wake::WAKE_MARGIN_S;
use super::{NoiseStart, PixelModel, PixelState};
use crate::noise;
use crate::rng::{Draw, Stream};

impl PixelModel {
    /// Frozen per-pixel thresholds (ON, OFF): N(theta, theta_sigma) each, at least theta_min.
    pub(super) fn base_thetas(&self, frozen: Draw) -> (f64, f64) {
        let p = &self.params;
        if p.theta_sigma == 0.0 {
            return (p.theta_on, p.theta_off);
        }
        let (z_on, z_off) = frozen.normal_pair(Stream::Theta);
        (
            frozen_theta(p.theta_on, p.theta_sigma, z_on, p.theta_min),
            frozen_theta(p.theta_off, p.theta_sigma, z_off, p.theta_min),
        )
    }

    /// The first frame: the pixel is settled at its input; a leaking pixel's reference starts
    /// at a random phase of its leak cycle, as a powered-up sensor's would.
    // Inlined into both callers (a state one at a time, a block's slow lanes): out of line, the
    // 128-byte state goes back through memory, 43 more instructions a state.
    #[inline(always)]
    pub fn init(&self, pixel: u64, frame_value: f64, t_s: f64) -> PixelState {
        let x = self.receptor.total_current(frame_value);
        let u = self.receptor.response(x);
        let frozen = Draw::new(self.params.seed, pixel, 0);
        let (theta_on, theta_off) = self.base_thetas(frozen);
        let start = self.noise_start(frozen, t_s, x);
        let leak_drift = start.leak_rate_hz * theta_on;
        PixelState {
            t_s,
            u,
            x,
            v: u,
            ref0: u,
            t_ref_s: leak_reference_time_s(t_s, start.leak_phase, theta_on, leak_drift),
            leak_drift,
            theta_on,
            theta_off,
            base_theta_on: theta_on,
            base_theta_off: theta_off,
            refractory_mark_s: f64::NEG_INFINITY,
            last_out_s: f64::NEG_INFINITY,
            shot_budget: start.shot_budget,
            hot_next_s: start.hot_next_s,
            draws: 1,
        }
    }

    /// The noise a pixel starts with at `t_s` and total photocurrent `x`: its leak rate and
    /// phase, the hazard before its first shot-noise event, its first hot-pixel event.
    /// `frozen` is the pixel's draw 0, which fixes what stays with it (thresholds, leak rate,
    /// hot or not) and where its noise starts.
    #[inline(always)]
    fn noise_start(&self, frozen: Draw, t_s: f64, x: f64) -> NoiseStart {
        let p = &self.params;
        let leak_rate_hz = noise::leak_rate_hz(p, frozen, x);
        NoiseStart {
            leak_rate_hz,
            leak_phase: if leak_rate_hz > 0.0 {
                frozen.uniform(Stream::LeakPhase)
            } else {
                0.0
            },
            shot_budget: if p.shot_rate_hz > 0.0 {
                frozen.exponential(Stream::ShotTime)
            } else {
                f64::INFINITY
            },
            hot_next_s: if noise::is_hot(p, frozen) {
                t_s + frozen.exponential(Stream::HotTime) / p.hot_pixel_rate_hz
            } else {
                f64::INFINITY
            },
        }
    }

    /// A lower bound on when a pixel that has kept its first-frame input since time 0 first
    /// acts: `wake_s` of the state `init` makes, from its noise draws alone, so that a static
    /// pixel costs no state. Settled, it crosses only by leak, after (1 - phase) / rate.
    #[inline]
    pub fn first_wake_s(&self, pixel: u64, frame_value: f64) -> f64 {
        let frozen = Draw::new(self.params.seed, pixel, 0);
        if self.is_time_invariant() && !noise::is_hot(&self.params, frozen) {
            return f64::INFINITY;
        }
        let x = self.receptor.total_current(frame_value);
        let start = self.noise_start(frozen, 0.0, x);
        let mut wake = start.hot_next_s;
        if self.params.shot_rate_hz > 0.0 {
            let shot_s = noise::shot_budget_lower_bound_s(&self.params, start.shot_budget, x);
            wake = wake.min(shot_s);
        }
        if start.leak_rate_hz > 0.0 {
            wake = wake.min((1.0 - start.leak_phase) / start.leak_rate_hz - WAKE_MARGIN_S);
        }
        wake.max(0.0)
    }
}

/// Frozen threshold mismatch: N(theta, sigma) from the pixel's normal draw z, at least `min`.
#[inline(always)]
pub(super) fn frozen_theta(theta: f64, sigma: f64, z: f64, min: f64) -> f64 {
    (theta + sigma * z).max(min)
}

/// When a leaking pixel's reference was last memorised, so that at `t_s` it has drifted by the
/// fraction `phase` of its ON threshold: the leak's first event comes at a uniform phase.
#[inline(always)]
pub(super) fn leak_reference_time_s(t_s: f64, phase: f64, theta_on: f64, leak_drift: f64) -> f64 {
    if leak_drift > 0.0 {
        t_s - phase * theta_on / leak_drift
    } else {
        t_s
    }
}
