//! A frame's one event, finished together for the pixels whose crossings were found together
//! (`first_crossings`): where many pixels fire (a moving pattern), most that do fire once in a
//! frame and are then held in reset past its end (the refractory period outlasts the rest of
//! the frame). One at a time, such a pixel's frame cost about 230 ns on the drifting sinusoid
//! against a floor of 50 (`benches/event_floor.rs`): its state gathered and scattered, the
//! segment's constants worked out again, the run's loop with its two turns, each step's
//! exponential, all in scalar code. Here every lane takes the steps of `PixelModel::run` for
//! that case in vector code, operation for operation, so the states and events are the same
//! bits: the light followed (the leak drift re-based), the segment's constants, the shot-noise
//! clock ruled out over the frame, the crossing (the earlier of the two found), the low-pass
//! advanced to it, what caused it, the reset held for the refractory period, the low-pass
//! advanced to the frame's end and the shot-noise hazard taken from the budget. The event's
//! random numbers (threshold noise, latency jitter) are drawn one lane at a time after, as
//! `fire` draws them: the inverse normal CDF's tails take the library's logarithm.
//!
//! A lane is finished only where every step is the one assumed: its state at the frame's start
//! and not held in reset, a crossing within the frame and no shot or hot-pixel event before the
//! frame's end, the reset not released within it, every exponential within `exp_in_range`'s
//! range. The others are left to the one-pixel path, with their crossings.

// Index loops over the lanes: written over iterators, the compiler leaves them scalar
// (`step_quiet`'s note).
#![allow(clippy::needless_range_loop)]

use crate::cpu_dispatch::compiled_per_cpu;
use crate::crossing::greater;
use crate::exp::{exp_in_range, in_exp_range, in_ln_range, ln_in_range};
use crate::noise::{self, exp_m1_over_x, in_hazard_range, shot_rate_of_law_hz};
use crate::params::ReferenceReset;
use crate::photoreceptor::inverse_current;
use crate::pixel::{drive_slope, leak_outpaces_light, Cause, PixelEvent, PixelModel};
use crate::state_block::{StateBlock, LANES};

use super::{Differences, FirstCrossings};

/// The pixels of a batch, lane by lane: their states at the frame's start (the fields the finish
/// reads, `EventLanes::take`) and frame values. `finish_single_events` leaves the finished lanes' frames in `states` (the
/// fields it moves), `t_s`, `on` and `leak`: `SingleEvent::of_lane` reads them out.
pub struct EventLanes {
    pub states: StateBlock,
    pub value: [f64; LANES],
    /// The crossing's time (seconds since the first frame), of the finished lanes.
    pub t_s: [f64; LANES],
    /// Bit k: lane k's event is ON; lane k's event has the leak for its cause.
    pub on: u32,
    pub leak: u32,
}

impl EventLanes {
    pub fn new() -> Self {
        Self {
            states: StateBlock::empty(),
            value: [0.0; LANES],
            t_s: [0.0; LANES],
            on: 0,
            leak: 0,
        }
    }

    /// Lane `i` takes pixel `k` of `block` (the fields the finish reads, all among those the
    /// dense step fetched) with frame value `value`. The frozen thresholds, the last output and
    /// the draw counter it does not fetch: `SingleEvent::write` reads them where the pixel's
    /// state is asked for ahead.
    #[inline(always)]
    pub fn take(&mut self, i: usize, block: &StateBlock, k: usize, value: f32) {
        let to = &mut self.states;
        (to.t_s[i], to.u[i], to.x[i], to.v[i]) = (block.t_s[k], block.u[k], block.x[k], block.v[k]);
        (to.ref0[i], to.t_ref_s[i]) = (block.ref0[k], block.t_ref_s[k]);
        (to.leak_drift[i], to.shot_budget[i]) = (block.leak_drift[k], block.shot_budget[k]);
        (to.refractory_mark_s[i], to.hot_next_s[i]) =
            (block.refractory_mark_s[k], block.hot_next_s[k]);
        self.value[i] = value as f64;
    }
}

impl Default for EventLanes {
    fn default() -> Self {
        Self::new()
    }
}

/// A pixel's frame as `finish_single_events` finished it, but for the event's random numbers:
/// the fields of its state it moved (to the frame's end), its crossing's time (seconds since
/// the first frame), the event's polarity and whether the leak caused it.
#[derive(Clone, Copy, Debug)]
pub struct SingleEvent {
    t_s: f64,
    u: f64,
    x: f64,
    v: f64,
    ref0: f64,
    t_ref_s: f64,
    leak_drift: f64,
    shot_budget: f64,
    refractory_mark_s: f64,
    crossing_s: f64,
    on: bool,
    leak: bool,
}

impl SingleEvent {
    /// Lane `k` of `lanes`, once `finish_single_events` finished it.
    #[inline(always)]
    pub fn of_lane(lanes: &EventLanes, k: usize) -> Self {
        let st = &lanes.states;
        Self {
            t_s: st.t_s[k],
            u: st.u[k],
            x: st.x[k],
            v: st.v[k],
            ref0: st.ref0[k],
            t_ref_s: st.t_ref_s[k],
            leak_drift: st.leak_drift[k],
            shot_budget: st.shot_budget[k],
            refractory_mark_s: st.refractory_mark_s[k],
            crossing_s: lanes.t_s[k],
            on: (lanes.on >> k) & 1 != 0,
            leak: (lanes.leak >> k) & 1 != 0,
        }
    }

    /// Pixel `k` of `block` (sensor pixel `pixel`) at the frame's end: the fields moved written,
    /// the event's random numbers drawn as `fire` draws them (its counter, the thresholds'
    /// noise, the latency's jitter); returns the event. The other fields stay as they are.
    #[inline]
    pub fn write(
        &self,
        model: &PixelModel,
        pixel: u64,
        block: &mut StateBlock,
        k: usize,
    ) -> PixelEvent {
        (block.t_s[k], block.u[k], block.x[k], block.v[k]) = (self.t_s, self.u, self.x, self.v);
        (block.ref0[k], block.t_ref_s[k]) = (self.ref0, self.t_ref_s);
        (block.leak_drift[k], block.shot_budget[k]) = (self.leak_drift, self.shot_budget);
        block.refractory_mark_s[k] = self.refractory_mark_s;
        let draw = model.draw_of(pixel, block.draws[k]);
        block.draws[k] += 1;
        if model.params.theta_noise > 0.0 {
            (block.theta_on[k], block.theta_off[k]) =
                model.drawn_thetas(block.base_theta_on[k], block.base_theta_off[k], draw);
        }
        block.last_out_s[k] = model.output_time(self.crossing_s, draw, block.last_out_s[k]);
        PixelEvent {
            t_s: block.last_out_s[k],
            on: self.on,
            cause: if self.leak {
                Cause::Leak
            } else {
                Cause::Signal
            },
        }
    }
}

/// Whether `finish_single_events` can take this model's pixels: the dense path's (a low-pass,
/// a logarithmic response), with the reset held for a refractory period (the others release
/// it, or move the reference, within the event's frame).
pub fn finishes_events(model: &PixelModel) -> bool {
    super::applies_to(model)
        && model.params.reference_reset == ReferenceReset::RefractoryEnd
        && model.params.refractory_us > 0.0
}

compiled_per_cpu! {
    /// Finish the frame (t0, t1] of the lanes `live` of `lanes` (see the module's note) where
    /// they fire once, from their segments' time constants (`differences`, as the quiet step
    /// left them) and first crossings (`crossings`); returns which it finished.
    /// `finishes_events(model)` must hold, and `t1_s - t0_s` be positive and finite.
    pub fn finish_single_events(
        model: &PixelModel,
        lanes: &mut EventLanes,
        differences: &Differences,
        crossings: &FirstCrossings,
        t0_s: f64,
        t1_s: f64,
        live: u32,
    ) -> u32 = finish_lanes, avx512 finish_avx512, avx2 finish_avx2;
}

#[inline(always)]
fn finish_lanes(
    model: &PixelModel,
    lanes: &mut EventLanes,
    differences: &Differences,
    crossings: &FirstCrossings,
    t0_s: f64,
    t1_s: f64,
    live: u32,
) -> u32 {
    let frame = (t0_s, t1_s, live);
    if model.params.shot_light_exponent == 2.0 {
        finish_lanes_of_law::<true>(model, lanes, differences, crossings, frame)
    } else {
        finish_lanes_of_law::<false>(model, lanes, differences, crossings, frame)
    }
}

/// `finish_lanes` for one shot-noise law (`SQUARE`: n = 2), so that the loop computes one.
#[inline(always)]
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN is no event (not held), as in next_happening
fn finish_lanes_of_law<const SQUARE: bool>(
    model: &PixelModel,
    lanes: &mut EventLanes,
    differences: &Differences,
    crossings: &FirstCrossings,
    (t0_s, t1_s, live): (f64, f64, u32),
) -> u32 {
    let p = &model.params;
    let r = &model.receptor;
    let shot_noise = p.shot_rate_hz > 0.0;
    let refractory_s = model.refractory_s();
    // drive: 1 / dt once for the segment.
    let dt = t1_s - t0_s;
    let inv_dt = 1.0 / dt;
    let mut finished = [false; LANES];
    let mut on = [false; LANES];
    let mut leak = [false; LANES];
    let st = &mut lanes.states;
    for k in 0..LANES {
        let (t_s, u0, x0, v0) = (st.t_s[k], st.u[k], st.x[k], st.v[k]);
        let (tau, inv_tau) = (differences.tau[k], differences.inv_tau[k]);
        // step_pixel: the ramp's end.
        let x1 = r.total_current(lanes.value[k]);
        let u1 = ln_in_range(x1);
        // follow_light_with_leak: the drift at the new light, the reference re-based.
        let rebase = p.leak_light_rate_hz != 0.0 && x1 != x0;
        let law_before = noise::leak_law_hz(p, x0);
        let drift_after = st.leak_drift[k] * (noise::leak_law_hz(p, x1) / law_before);
        let ref_now = st.ref0[k] - st.leak_drift[k] * (t_s - st.t_ref_s[k]);
        let ref0 = if rebase { ref_now } else { st.ref0[k] };
        let t_ref_s = if rebase { t_s } else { st.t_ref_s[k] };
        let drift = if rebase {
            drift_after
        } else {
            st.leak_drift[k]
        };
        // drive: the slope, and the shot-noise rate at both ends and its log-slope (the time
        // constant and its inverse are the batch's, the quiet step's bits).
        let slope = drive_slope(u0, u1, dt, inv_dt);
        let (inv_x0, inv_x1) = (inverse_current(x0), inverse_current(x1));
        let log_ratio = u1 - u0;
        let g = if shot_noise && x0 != x1 {
            -p.shot_light_exponent * log_ratio * inv_dt
        } else {
            0.0
        };
        let r_a = shot_rate_of_law_hz::<SQUARE>(p, inv_x0);
        let r_end = shot_rate_of_law_hz::<SQUARE>(p, inv_x1);
        // shot_clock (from the frame's start, so the rate is the segment's): the budget
        // outlasts the frame even at the rate's larger end.
        let budget = st.shot_budget[k];
        let no_shot = !shot_noise || greater(r_a, r_end) * (t1_s - t_s) < budget;
        // next_happening, first turn: not held; the ON crossing within the horizon, then the
        // OFF one before it; no hot-pixel event first.
        let horizon = t1_s - t_s;
        let not_held = !(st.refractory_mark_s[k] > t_s);
        let crossing_s = |found: u32, s: &[f64; LANES]| {
            if (found >> k) & 1 != 0 {
                s[k]
            } else {
                f64::INFINITY
            }
        };
        let on_s = crossing_s(crossings.on, &crossings.on_s);
        let off_s = crossing_s(crossings.off, &crossings.off_s);
        let takes_on = on_s <= horizon;
        let mut best_s = if takes_on { on_s.max(0.0) } else { horizon };
        let takes_off = off_s < best_s || (off_s == best_s && !takes_on);
        best_s = if takes_off { off_s.max(0.0) } else { best_s };
        let fires = takes_on || takes_off;
        let hot_in_s = st.hot_next_s[k] - t_s;
        let no_hot_first = !(hot_in_s < best_s || (hot_in_s == best_s && !fires));
        // advance_to the crossing.
        let ramp = Ramp {
            t0_s,
            t1_s,
            u0,
            u1,
            x1,
            slope,
            tau,
            inv_tau,
        };
        let start = Moving {
            t_s,
            u: u0,
            v: v0,
            x: x0,
        };
        let (at_crossing, arg_c, moves) = advance(&ramp, start, t_s + best_s);
        let Moving {
            t_s: t_c_s,
            u: u_c,
            v: v_c,
            ..
        } = at_crossing;
        // apply: the cause (crossing_cause: the leak outpacing the light, ON only); fire: the
        // reset held for the refractory period.
        let on_now = !takes_off;
        let by_leak = leak_outpaces_light(drift, u_c, v_c, tau, slope);
        let mark_s = t_c_s + refractory_s;
        // next_happening, second turn: held, its release after the frame's end; no hot-pixel
        // event within it; then advance_to the end.
        let horizon_end = t1_s - t_c_s;
        let release_in_s = mark_s - t_c_s;
        let hot_end_s = st.hot_next_s[k] - t_c_s;
        let held_to_end = horizon_end >= 0.0
            && mark_s > t_c_s
            && release_in_s > horizon_end
            && !(hot_end_s <= horizon_end);
        let (at_end, arg_e, moves_to_end) = advance(&ramp, at_crossing, t_c_s + horizon_end);
        // settle_shots: the hazard since the frame's start.
        let s_shot = at_end.t_s - t_s;
        let gs = g * s_shot;
        let budget_end = if shot_noise {
            budget - r_a * s_shot * exp_m1_over_x(gs)
        } else {
            budget
        };
        finished[k] = (live >> k) & 1 != 0
            && t_s == t0_s
            && in_ln_range(x1)
            && (!rebase || law_before > 0.0)
            && tau > 0.0
            && no_shot
            && not_held
            && fires
            && no_hot_first
            && (!moves || in_exp_range(arg_c))
            && held_to_end
            && (!moves_to_end || in_exp_range(arg_e))
            && (!shot_noise || in_hazard_range(gs));
        on[k] = on_now;
        leak[k] = on_now && by_leak;
        lanes.t_s[k] = t_c_s;
        (st.t_s[k], st.u[k], st.x[k], st.v[k]) = (at_end.t_s, at_end.u, at_end.x, at_end.v);
        st.ref0[k] = ref0;
        st.t_ref_s[k] = t_ref_s;
        st.leak_drift[k] = drift;
        st.shot_budget[k] = budget_end;
        st.refractory_mark_s[k] = mark_s;
    }
    lanes.on = crate::state_block::bits_of(&on);
    lanes.leak = crate::state_block::bits_of(&leak);
    crate::state_block::bits_of(&finished)
}

/// A lane's state as the low-pass moves it along the frame's ramp.
#[derive(Clone, Copy)]
struct Moving {
    t_s: f64,
    u: f64,
    v: f64,
    x: f64,
}

/// The frame's ramp of a lane, from (t0, u0) to (t1, u1, x1), with its slope and the
/// low-pass's time constant and inverse.
struct Ramp {
    t0_s: f64,
    t1_s: f64,
    u0: f64,
    u1: f64,
    x1: f64,
    slope: f64,
    tau: f64,
    inv_tau: f64,
}

/// `PixelModel::advance_to` on a lane's `ramp`: `from` moved to `to_s` (unchanged where that is
/// no later); also the exponential's argument, which must be within `exp_in_range`'s range
/// where it moves, and whether it moves.
#[inline(always)]
fn advance(ramp: &Ramp, from: Moving, to_s: f64) -> (Moving, f64, bool) {
    let (slope, tau) = (ramp.slope, ramp.tau);
    let s = to_s - from.t_s;
    let moves = s > 0.0;
    let past_end = to_s >= ramp.t1_s;
    let u = if past_end {
        ramp.u1
    } else {
        ramp.u0 + slope * (to_s - ramp.t0_s)
    };
    let arg = -s * ramp.inv_tau;
    let v = u - slope * tau + (from.v - from.u + slope * tau) * exp_in_range(arg);
    let x = if moves & past_end { ramp.x1 } else { from.x };
    // Plain selects, field by field, in a free function: written as a method on `Ramp`
    // picking the whole `Moving` (or its fields through a closure), the lanes' loop stayed
    // scalar (55 against 741 AVX-512 instructions in `finish_avx512`).
    let to = Moving {
        t_s: if moves { to_s } else { from.t_s },
        u: if moves { u } else { from.u },
        v: if moves { v } else { from.v },
        x,
    };
    (to, arg, moves)
}
