//! The dense path: pixels stepped several at a time over a frame interval, for tiles where most
//! pixels changed (real video, moving-camera renders: every pixel, every frame).
//!
//! In such a frame almost every pixel only follows its input: the low-pass settles, the leak
//! drifts, the shot-noise hazard builds up, and no threshold, shot or hot-pixel event comes; at
//! most the reset an event left in the last frame is released. `step_quiet` finds those pixels
//! (a "quiet" step) and moves them on with the arithmetic of `PixelModel::run`, operation for
//! operation, so their states are the same bits as the one-pixel path gives; any pixel it
//! cannot rule an event out for is left untouched, for the one-pixel path. Where many pixels
//! fire (a moving pattern), a release is as frequent as an event: a drifting sinusoid at 0.15
//! events a pixel a frame sent 28 % of its pixel updates one at a time, half of them releases,
//! which this path now takes (14 % left; 562 -> 474 callgrind instructions an update). Their
//! wake-up bounds (`PixelModel::wake_s`) it leaves to the tile, which works one out only for a
//! pixel whose input then stays the same: where every pixel changes in every frame, none is
//! needed.
//!
//! The step reads the states where they are kept, one array per field (`StateBlock`), as one
//! branch-free loop over a block's pixels, which the compiler turns into vector code: AVX-512 (8
//! pixels an instruction) or AVX2 (4) where the CPU has it, chosen at run time, SSE2 otherwise.
//! It loads only the fields it uses and writes back only those it changes, of the pixels it
//! stepped. Two of the fields it tests, the hot-pixel clock and the end of a reset, matter only
//! in a block with a hot pixel or an event of late: elsewhere (`Inputs::gates`) they are not
//! read. At 1280 x 720 the states come from memory, whose traffic bounds the step: 80 bytes read
//! a pixel, not 96. The arithmetic is not fused into FMAs (Rust never contracts a * b + c): a
//! fused step rounds once where the one-pixel path rounds twice, and the two paths would part by
//! an ulp.
//! The exponential and logarithm are `exp`'s, whose scalar calls take the same branch-free code.

use crate::cpu_dispatch::compiled_per_cpu;
use crate::crossing::{greater, lesser, Difference};
use crate::exp::{exp_in_range, in_exp_range, in_ln_range, ln_in_range};
use crate::noise::{
    self, exp_m1_over_x, exp_m1_over_x_series, in_hazard_range, in_hazard_series_range,
};
use crate::params::ReferenceReset;
use crate::photoreceptor::inverse_current;
use crate::pixel::{drive_slope, PixelModel};
use crate::state_block::{StateBlock, LANES};

mod crossings;
mod single_event;
pub use crossings::{first_crossings, FirstCrossings};
pub use single_event::{finish_single_events, finishes_events, EventLanes, SingleEvent};

/// A block's inputs this frame: each pixel's frame value now and a frame ago, and which pixels
/// the scan listed (bit k: pixel k). Only listed pixels whose value changed are stepped.
pub struct Inputs {
    pub value: [f32; LANES],
    pub last: [f32; LANES],
    pub listed: u32,
    /// Whether a pixel of the block may be hot (`hot_next_s` finite) or held in reset at the
    /// frame's start (`refractory_mark_s` after it). Where none is, those fields are not read
    /// but taken as +inf and -inf: a pixel that is not hot has +inf; one stepped from the
    /// frame's start (the only ones stepped) with a mark at or before it is not held, as with
    /// -inf. Where one may be, a held pixel's reset is released on the way (or held through the
    /// frame), and its mark written back.
    pub gates: bool,
}

/// Whether `step_quiet` can take this model's pixels at all: a low-pass (so no pixel's
/// difference is linear, `PixelModel::run`'s other path) and a purely logarithmic response.
pub fn applies_to(model: &PixelModel) -> bool {
    !model.receptor.is_instantaneous() && model.receptor.is_logarithmic()
}

compiled_per_cpu! {
    /// Step every pixel of `block` that is quiet over (t0, t1] (see the module's note), all at
    /// once; returns which pixels it stepped. The others are left as they were. `t1_s - t0_s`
    /// must be positive and finite.
    pub fn step_quiet(
        model: &PixelModel,
        block: &mut StateBlock,
        inputs: &Inputs,
        t0_s: f64,
        t1_s: f64,
        differences: &mut Differences,
        export: bool,
    ) -> [bool; LANES] = step_quiet_lanes, avx512 step_quiet_avx512, avx2 step_quiet_avx2;
}

/// Each pixel's difference v - ref over the frame, as `PixelModel::run` takes it on the frame's
/// ramp at its first turn that looks for a crossing, and that turn's horizon, which
/// `step_quiet` leaves for the pixels it does not step (`crossings` then finds their crossings
/// together). Only where `usable`: a changed pixel whose state is at the frame's start, on a
/// ramp the dense path computes as the one-pixel path does, not held in reset or released on
/// the way with nothing else before its release.
#[derive(Clone, Copy)]
pub struct Differences {
    pub a: [f64; LANES],
    pub m: [f64; LANES],
    pub c: [f64; LANES],
    pub tau: [f64; LANES],
    pub inv_tau: [f64; LANES],
    pub horizon_s: [f64; LANES],
    pub usable: [bool; LANES],
}

impl Differences {
    pub fn new() -> Self {
        let zeros = [0.0; LANES];
        Self {
            a: zeros,
            m: zeros,
            c: zeros,
            tau: zeros,
            inv_tau: zeros,
            horizon_s: zeros,
            usable: [false; LANES],
        }
    }
}

impl Default for Differences {
    fn default() -> Self {
        Self::new()
    }
}

#[inline(always)]
fn step_quiet_lanes(
    model: &PixelModel,
    block: &mut StateBlock,
    inputs: &Inputs,
    t0_s: f64,
    t1_s: f64,
    out: &mut Differences,
    export: bool,
) -> [bool; LANES] {
    // The shot-noise law, the gates and the export picked once, so that the loop computes one
    // law, not both, loads the gates or not, and stores the differences only where asked (the
    // stores cost a frame where few pixels fire 7 % of its time).
    // And whether a pixel's shot-noise rate may change by e^0.5 or more over the frame, which
    // takes the hazard's factor from a second exponential (`noise::exp_m1_over_x`): a block
    // whose values all move less than that keeps the loop to the series (the exponential costs
    // the drifting sinusoid and grain 6 %).
    let square = model.params.shot_light_exponent == 2.0;
    let wide = model.params.shot_rate_hz > 0.0 && !series_suffices(inputs, square);
    macro_rules! step_with {
        ($($square:literal, $gates:literal, $export:literal, $wide:literal);*) => {
            match (square, inputs.gates, export, wide) {
                $(($square, $gates, $export, $wide) => {
                    step_lanes_of_law::<$square, $gates, $export, $wide>(
                        model, block, inputs, t0_s, t1_s, out,
                    )
                })*
            }
        };
    }
    step_with!(
        true, true, true, true; true, true, false, true; true, false, true, true;
        true, false, false, true; false, true, true, true; false, true, false, true;
        false, false, true, true; false, false, false, true;
        true, true, true, false; true, true, false, false; true, false, true, false;
        true, false, false, false; false, true, true, false; false, true, false, false;
        false, false, true, false; false, false, false, false
    )
}

/// Whether every pixel of the block moves so little that n |ln(x1 / x0)| stays below 0.45, well
/// inside the hazard series' range: checked on the frame values, whose ratio the dark current
/// only brings closer to 1 (x = scale value + dark), with a margin far above any rounding.
#[inline(always)]
fn series_suffices(inputs: &Inputs, square: bool) -> bool {
    // e^(+-0.45 / n), to 5 digits, and products in single precision: the margin to 0.5
    // dwarfs their rounding.
    let (above, below): (f32, f32) = if square {
        (1.25232, 0.79852)
    } else {
        (1.56831, 0.63763)
    };
    let mut outside = 0u32;
    for k in 0..LANES {
        let (value, last) = (inputs.value[k], inputs.last[k]);
        let inside = last > 0.0 && value < last * above && value > last * below;
        outside |= (!inside as u32) << k;
    }
    outside == 0
}

/// `step_quiet_lanes` for one shot-noise law (`SQUARE`: n = 2), with the gates read or not
/// (`GATES`, see `Inputs::gates`), the differences stored or not (`EXPORT`), the hazard beyond
/// its series or not (`WIDE`).
#[inline(always)]
fn step_lanes_of_law<
    const SQUARE: bool,
    const GATES: bool,
    const EXPORT: bool,
    const WIDE: bool,
>(
    model: &PixelModel,
    block: &mut StateBlock,
    inputs: &Inputs,
    t0_s: f64,
    t1_s: f64,
    out: &mut Differences,
) -> [bool; LANES] {
    let mut stepped = [false; LANES];
    // 1 / dt once for the block, as `PixelModel::run` takes it once a segment.
    let inv_dt = 1.0 / (t1_s - t0_s);
    // A pixel held in reset may be released within the frame, which splits its segment there
    // and takes a second exponential: with the gates read, the block's are worked out first, in
    // a loop of their own (two exponentials in one loop leave it scalar: 727 against 292
    // million callgrind instructions in this function on the sinusoid, 20 frames).
    let release_decay = if GATES {
        release_decays(model, block, inputs)
    } else {
        [1.0; LANES]
    };
    // An index loop: written over `stepped.iter_mut()` the compiler leaves it scalar (1609
    // against 779 million callgrind instructions on the dense bench).
    #[allow(clippy::needless_range_loop)]
    for k in 0..LANES {
        let value = inputs.value[k];
        let changed = (inputs.listed >> k) & 1 != 0 && value != inputs.last[k];
        let mut lane = Lane::take::<GATES>(block, k, value as f64, changed);
        let (quiet, d, horizon_s, usable) =
            lane.step::<SQUARE, GATES, WIDE>(model, t0_s, t1_s, inv_dt, release_decay[k]);
        lane.give_if::<GATES>(quiet, block, k);
        stepped[k] = quiet;
        if EXPORT {
            (out.a[k], out.m[k], out.c[k]) = (d.a, d.m, d.c);
            (out.tau[k], out.inv_tau[k], out.horizon_s[k]) = (d.tau, d.inv_tau, horizon_s);
            out.usable[k] = usable;
        }
    }
    stepped
}

/// e^{-s/tau} for each pixel of the block over s from its state's time to the end of its reset
/// (`Lane::step`'s release; any value where that is not within `exp_in_range`'s range), with
/// the time constant and the times as `Lane::step` takes them.
#[inline(always)]
fn release_decays(model: &PixelModel, block: &StateBlock, inputs: &Inputs) -> [f64; LANES] {
    let r = &model.receptor;
    let mut decay = [0.0; LANES];
    #[allow(clippy::needless_range_loop)]
    for k in 0..LANES {
        let x1 = r.total_current(inputs.value[k] as f64);
        let tau = r.segment_tau_s(inverse_current(block.x[k]), inverse_current(x1));
        let inv_tau = 1.0 / tau;
        let t_s = block.t_s[k];
        let t_release_s = t_s + (block.refractory_mark_s[k] - t_s);
        decay[k] = exp_in_range(-(t_release_s - t_s) * inv_tau);
    }
    decay
}

/// One pixel's fields that a quiet step reads, and its input.
struct Lane {
    t_s: f64,
    u: f64,
    x: f64,
    v: f64,
    ref0: f64,
    t_ref_s: f64,
    leak_drift: f64,
    shot_budget: f64,
    theta_on: f64,
    theta_off: f64,
    refractory_mark_s: f64,
    hot_next_s: f64,
    value: f64,
    changed: bool,
}

impl Lane {
    #[inline(always)]
    fn take<const GATES: bool>(b: &StateBlock, k: usize, value: f64, changed: bool) -> Self {
        Self {
            t_s: b.t_s[k],
            u: b.u[k],
            x: b.x[k],
            v: b.v[k],
            ref0: b.ref0[k],
            t_ref_s: b.t_ref_s[k],
            leak_drift: b.leak_drift[k],
            shot_budget: b.shot_budget[k],
            theta_on: b.theta_on[k],
            theta_off: b.theta_off[k],
            refractory_mark_s: if GATES {
                b.refractory_mark_s[k]
            } else {
                f64::NEG_INFINITY
            },
            hot_next_s: if GATES {
                b.hot_next_s[k]
            } else {
                f64::INFINITY
            },
            value,
            changed,
        }
    }

    /// The fields a step changes, back into pixel `k` of the block where `stepped` (written
    /// either way, the old value where not, so the loop stays branch-free); with `GATES`, the
    /// end of a reset too (a step may release one).
    #[inline(always)]
    fn give_if<const GATES: bool>(&self, stepped: bool, b: &mut StateBlock, k: usize) {
        let pick = |new: f64, old: f64| if stepped { new } else { old };
        b.t_s[k] = pick(self.t_s, b.t_s[k]);
        b.u[k] = pick(self.u, b.u[k]);
        b.x[k] = pick(self.x, b.x[k]);
        b.v[k] = pick(self.v, b.v[k]);
        b.ref0[k] = pick(self.ref0, b.ref0[k]);
        b.t_ref_s[k] = pick(self.t_ref_s, b.t_ref_s[k]);
        b.leak_drift[k] = pick(self.leak_drift, b.leak_drift[k]);
        b.shot_budget[k] = pick(self.shot_budget, b.shot_budget[k]);
        if GATES {
            b.refractory_mark_s[k] = pick(self.refractory_mark_s, b.refractory_mark_s[k]);
        }
    }

    /// The ramp from this state (at t0, input u, x) to the frame's value at t1, as `step_pixel`
    /// and `PixelModel::run` take it when nothing happens on it but the release of a reset
    /// (`GATES` alone: elsewhere no pixel is held): whether nothing else does, and the new state
    /// in place. A pixel held in reset at t0 is released where the reset ends within the frame
    /// (the segment split there: the low-pass advanced to the release, the reference memorised,
    /// then no crossing up to t1), or stays held through it (no crossing is looked for). Every
    /// line mirrors theirs (named in the comments) in the same operations and order, so the
    /// results are the same bits. Also returns the difference v - ref and the horizon of run's
    /// first turn, and whether they are that turn's (`Differences::usable`).
    #[inline(always)]
    fn step<const SQUARE: bool, const GATES: bool, const WIDE: bool>(
        &mut self,
        model: &PixelModel,
        t0_s: f64,
        t1_s: f64,
        inv_dt: f64,
        release_decay: f64,
    ) -> (bool, Difference, f64, bool) {
        let p = &model.params;
        let r = &model.receptor;
        let shot_noise = p.shot_rate_hz > 0.0;
        // step_pixel: the ramp's ends.
        let (u0, x0) = (self.u, self.x);
        let x1 = r.total_current(self.value);
        let u1 = ln_in_range(x1);
        // follow_light_with_leak: the drift at the new light, the reference re-based.
        let rebase = p.leak_light_rate_hz != 0.0 && x1 != self.x;
        let law_before = noise::leak_law_hz(p, self.x);
        let drift_after = self.leak_drift * (noise::leak_law_hz(p, x1) / law_before);
        let ref_now = self.ref0 - self.leak_drift * (self.t_s - self.t_ref_s);
        let ref0 = if rebase { ref_now } else { self.ref0 };
        let t_ref_s = if rebase { self.t_s } else { self.t_ref_s };
        let drift = if rebase { drift_after } else { self.leak_drift };
        // drive: slope, time constant, shot-noise rate at both ends, from 1 / x at each end.
        let dt = t1_s - t0_s;
        let slope = drive_slope(u0, u1, dt, inv_dt);
        // -n (u1 - u0) (1 / dt): the same bits as -(n slope), as n is 1 or 2 (products by
        // them and negation are exact, rounding symmetric).
        let g = if x0 != x1 {
            -(if SQUARE { 2.0 * slope } else { slope })
        } else {
            0.0
        };
        let (inv_x0, inv_x1) = (inverse_current(x0), inverse_current(x1));
        let r_a = noise::shot_rate_of_law_hz::<SQUARE>(p, inv_x0);
        let r_end = noise::shot_rate_of_law_hz::<SQUARE>(p, inv_x1);
        let tau = r.segment_tau_s(inv_x0, inv_x1);
        // 1 / tau once, as drive takes it: the decay, c / tau and the bounds multiply by it.
        let inv_tau = 1.0 / tau;
        // shot_clock: the budget outlasts the segment even at the rate's larger end.
        let horizon = t1_s - self.t_s;
        let no_shot = !shot_noise || greater(r_a, r_end) * horizon < self.shot_budget;
        // next_happening: held in reset, the release comes first if within the horizon (a tie
        // with the segment's end goes to it); else no crossing is looked for.
        let blind =
            p.reference_reset == ReferenceReset::RefractoryEnd && self.refractory_mark_s > self.t_s;
        let to_release_s = self.refractory_mark_s - self.t_s;
        let releases = GATES && blind && to_release_s <= horizon;
        let held_through = GATES && blind && !releases;
        // advance_to the release, then memorise: the reference is the output there.
        let t_release_s = self.t_s + to_release_s;
        let s_release = t_release_s - self.t_s;
        let u_release = if t_release_s >= t1_s {
            u1
        } else {
            u0 + slope * (t_release_s - t0_s)
        };
        let release_arg = -s_release * inv_tau;
        let v_release = u_release - slope * tau + (self.v - self.u + slope * tau) * release_decay;
        // The state the rest of the segment starts from: the release's, or the frame's start.
        let pick = |released: f64, held: f64| if releases { released } else { held };
        let (t_a_s, u_a, v_a) = (
            pick(t_release_s, self.t_s),
            pick(u_release, self.u),
            pick(v_release, self.v),
        );
        let (ref_a, t_ref_a_s) = (pick(v_release, ref0), pick(t_release_s, t_ref_s));
        // The next turn of run's loop: its horizon; not held, no crossing (first_reach's first
        // two tests), no hot-pixel event within it.
        let horizon_a = t1_s - t_a_s;
        let reference = ref_a - drift * (t_a_s - t_ref_a_s);
        let d = Difference::of_pixel(u_a, v_a, reference, drift, slope, tau, inv_tau);

        #[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN is no event, as in next_happening
        let no_hot =
            !(self.hot_next_s - self.t_s <= horizon) && !(self.hot_next_s - t_a_s <= horizon_a);
        // advance_to the segment's end.
        let t_end_s = t_a_s + horizon_a;
        let s = t_end_s - t_a_s;
        let decay_arg = -s * inv_tau;
        let decay = exp_in_range(decay_arg);
        let v1 = u1 - slope * tau + (v_a - u_a + slope * tau) * decay;
        // e^{-horizon/tau}, which the exact test of `stays_inside` takes, where it is this one.
        let decay_at_horizon = if s == horizon_a { decay } else { f64::NAN };
        let no_crossing = held_through
            | stays_inside(
                &d,
                self.theta_on,
                self.theta_off,
                horizon_a,
                decay_at_horizon,
            );
        // settle_shots: the hazard of the interval (from the frame's start: the clock was set
        // there) taken from the budget.
        let s_shot = t_end_s - self.t_s;
        let gs = g * s_shot;
        let budget = if shot_noise {
            let factor = if WIDE {
                exp_m1_over_x(gs)
            } else {
                exp_m1_over_x_series(gs)
            };
            self.shot_budget - r_a * s_shot * factor
        } else {
            self.shot_budget
        };
        // d is the first crossing turn's where the ramp is the one-pixel path's, from the
        // frame's start: the first turn, or the second for a pixel released on the way with
        // nothing else before it (no shot or hot-pixel event, which would redraw its
        // thresholds).
        let released_alone =
            releases && s_release > 0.0 && in_exp_range(release_arg) && no_shot && no_hot;
        let usable = self.changed
            && self.t_s == t0_s
            && in_ln_range(x1)
            && (!rebase || law_before > 0.0)
            && tau > 0.0
            && (!blind || released_alone);
        let quiet = self.changed
            && self.t_s == t0_s
            && in_ln_range(x1)
            && (!rebase || law_before > 0.0)
            && tau > 0.0
            && no_shot
            && (!blind | held_through | (s_release > 0.0) & in_exp_range(release_arg))
            && no_crossing
            && no_hot
            && horizon_a >= 0.0
            && s > 0.0
            && t_end_s >= t1_s
            && in_exp_range(decay_arg)
            && (!shot_noise
                || if WIDE {
                    in_hazard_range(gs)
                } else {
                    in_hazard_series_range(gs)
                });
        *self = Lane {
            t_s: t_end_s,
            u: u1,
            x: x1,
            v: v1,
            ref0: ref_a,
            t_ref_s: t_ref_a_s,
            leak_drift: drift,
            shot_budget: budget,
            refractory_mark_s: if releases {
                f64::NEG_INFINITY
            } else {
                self.refractory_mark_s
            },
            ..*self
        };
        (quiet, d, horizon_a, usable)
    }
}

/// Whether `d` stays below `on` and above `-off` over [0, s_max], as `Difference::first_reach`
/// on `d` and on `-d` finds it, in two ways: its first two tests (its value now, then
/// `Difference::upper_bound`); or, where that bound fails but d is convex (c > 0; for -d,
/// c < 0), its exact test, the value at s_max (`Difference::at`, from `decay_at_s_max` =
/// e^{-s_max/tau}, NaN for none) below the level too. A convex d has its maximum at an end, and
/// `first_reach` finds no crossing exactly then: on its one monotone piece it checks the end
/// alone; where a minimum splits [0, s_max] it checks the minimum as well, which lies below d(0)
/// but for rounding, so the value now is asked to be `EXACT_TEST_MARGIN` below the level.
/// Written out so the two sides share the product c / tau = c (1 / tau): -d's is -(c / tau),
/// negation being exact, as is d's value at s_max negated.
#[inline(always)]
#[allow(clippy::neg_cmp_op_on_partial_ord)] // a NaN now is not past the level, as there
fn stays_inside(d: &Difference, on: f64, off: f64, s_max: f64, decay_at_s_max: f64) -> bool {
    let c_over_tau = d.c * d.inv_tau;
    let at_s_max = d.a + d.m * s_max + d.c * decay_at_s_max;
    let upper_bound = |a: f64, m: f64, c: f64, c_over_tau: f64| {
        let loose = a + (m * s_max).max(0.0) + c.max(0.0);
        let tangent = a + c + ((m - c_over_tau) * s_max).max(0.0);
        if c >= 0.0 {
            loose
        } else {
            lesser(loose, tangent)
        }
    };
    // The same for d and -d.
    let rounding = EXACT_TEST_MARGIN * (1.0 + d.a.abs() + d.c.abs() + (d.m * s_max).abs());
    let below = |a: f64, m: f64, c: f64, c_over_tau: f64, at_s_max: f64, level: f64| {
        // Difference::at(0): a + c + m 0.
        let now = a + c + m * 0.0;
        let convex_below = c > 0.0 && s_max > 0.0 && now < level - rounding && at_s_max < level;
        !(now >= level) && (upper_bound(a, m, c, c_over_tau) < level || convex_below)
    };
    below(d.a, d.m, d.c, c_over_tau, at_s_max, on)
        && below(-d.a, -d.m, -d.c, -c_over_tau, -at_s_max, off)
}

/// How far below the level a convex d must start for the exact test, relative to the size of
/// d's terms: far above their rounding (a few ulps), far below any threshold.
const EXACT_TEST_MARGIN: f64 = 1e-9;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Draw, Stream};

    #[test]
    fn stays_inside_only_where_first_reach_finds_no_crossing_on_either_side() {
        // Differences of every shape near both levels (convex and concave, drifting either way,
        // starting just below a level); wherever `stays_inside` says so, `first_reach` finds
        // nothing on either side, and its exact test rules out many crossings the bound alone
        // would not.
        let (mut inside, mut by_exact_test) = (0, 0);
        for i in 0..200_000u64 {
            let u = |k: u64| Draw::new(5, i, k).uniform(Stream::Theta);
            let tau = [1e-4, 5e-4, 2e-3][i as usize % 3];
            let d = Difference::new(
                0.4 * (2.0 * u(0) - 1.0),
                [0.0, 20.0, -20.0, 300.0, -300.0][(i / 3) as usize % 5] * u(1),
                0.4 * (2.0 * u(2) - 1.0),
                tau,
            );
            let (on, off, s_max) = (0.15 + 0.1 * u(3), 0.15 + 0.1 * u(4), 1e-3 * u(5));
            let decay = exp_in_range(-s_max * d.inv_tau);
            if !stays_inside(&d, on, off, s_max, decay) {
                continue;
            }
            inside += 1;
            let reached = (
                d.first_reach(on, s_max),
                d.negated().first_reach(off, s_max),
            );
            assert_eq!(
                reached,
                (None, None),
                "{d:?} on {on} off {off} s_max {s_max}"
            );
            by_exact_test += !stays_inside(&d, on, off, s_max, f64::NAN) as usize;
        }
        assert!(
            inside > 20_000 && by_exact_test > 2_000,
            "{inside} {by_exact_test}"
        );
    }
}
