//! One DVS pixel: photoreceptor, change detector with refractory reset, and its noise sources,
//! simulated exactly between frame times (no time steps inside an interval).

use crate::crossing::{greater, Difference};
use crate::exp::exp;
use crate::noise::{self, GeometricRate};
use crate::params::{ReferenceReset, SensorParams};
use crate::photoreceptor::{inverse_current, Photoreceptor};
use crate::rng::{Draw, Stream};

mod first_states;
mod wake;
use wake::WAKE_MARGIN_S;

const _: () = assert!(std::mem::size_of::<PixelState>() == 128);

/// What caused an event (the `label` column).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Cause {
    Signal = 0,
    Leak = 1,
    Shot = 2,
    Hot = 3,
}

/// An event as the pixel emits it: time in seconds since the sensor's first frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelEvent {
    pub t_s: f64,
    pub on: bool,
    pub cause: Cause,
}

/// The state of one pixel at time `t_s`: 16 numbers, 128 bytes. A tile keeps them field by
/// field, 32 pixels a block (`state_block`); a pixel stepped alone is taken out into this.
#[derive(Clone, Debug, PartialEq)]
pub struct PixelState {
    pub t_s: f64,
    /// Photoreceptor input (response of the photocurrent) and total photocurrent at `t_s`.
    pub u: f64,
    pub x: f64,
    /// Photoreceptor output at `t_s`.
    pub v: f64,
    /// The reference memorised at `t_ref_s`; it drifts down at `leak_drift` per second after.
    pub ref0: f64,
    pub t_ref_s: f64,
    pub leak_drift: f64,
    /// Thresholds in force: frozen mismatch plus the noise drawn after the last event.
    pub theta_on: f64,
    pub theta_off: f64,
    /// The frozen mismatch alone (the noise is redrawn around it).
    pub base_theta_on: f64,
    pub base_theta_off: f64,
    /// The refractory period, as each reset rule needs it: with the reset held to the period's
    /// end, the time the pixel is held in reset until (blind before it); with the reset at the
    /// event (ESIM), the time of the last emitted event.
    pub refractory_mark_s: f64,
    /// Latest output time: latency jitter never reorders one pixel's events.
    pub last_out_s: f64,
    /// Unit-exponential hazard left before the next shot-noise event.
    pub shot_budget: f64,
    pub hot_next_s: f64,
    /// Counter of events drawn so far, the key of this pixel's random numbers.
    pub draws: u64,
}

/// A stretch of time over which the input is linear in log: from (t0_s, u0, x0) to (t1_s, u1, x1).
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    pub t0_s: f64,
    pub t1_s: f64,
    pub u0: f64,
    pub u1: f64,
    pub x0: f64,
    pub x1: f64,
}

impl Segment {
    pub fn constant(t0_s: f64, t1_s: f64, u: f64, x: f64) -> Self {
        Self {
            t0_s,
            t1_s,
            u0: u,
            u1: u,
            x0: x,
            x1: x,
        }
    }

    /// When the ramp reaches `level` (linear in log), kept within [after_s, t1] so that rounding
    /// cannot move a crossing before the previous one or out of the segment; a flat input is
    /// there at once.
    #[inline(always)]
    fn time_of(&self, level: f64, slope: f64, after_s: f64) -> f64 {
        if slope == 0.0 {
            return after_s;
        }
        let t_s = self.t0_s + (level - self.u0) / slope;
        let t_s = if t_s > after_s { t_s } else { after_s };
        if t_s < self.t1_s {
            t_s
        } else {
            self.t1_s
        }
    }

    #[inline]
    fn slope(&self) -> f64 {
        let dt = self.t1_s - self.t0_s;
        if dt > 0.0 {
            (self.u1 - self.u0) / dt
        } else {
            0.0
        }
    }
}

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

/// Per-segment constants of the pixel's dynamics.
struct Drive {
    slope: f64,
    tau: f64,
    inv_tau: f64,
    shot: GeometricRate,
    /// Shot-noise rate at the segment's end.
    shot_end_hz: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Next {
    End,
    ReleaseReset,
    On,
    Off,
    Shot,
    Hot,
}

/// Shot noise over one run: the state's budget holds at `settled_s`, and runs out at `due_s`
/// (infinite when not within the segment).
struct ShotClock {
    settled_s: f64,
    due_s: f64,
}

/// The noise state a pixel is powered up with (`PixelModel::noise_start`).
struct NoiseStart {
    leak_rate_hz: f64,
    leak_phase: f64,
    shot_budget: f64,
    hot_next_s: f64,
}

/// The sensor-wide constants every pixel shares.
#[derive(Clone, Debug)]
pub struct PixelModel {
    pub params: SensorParams,
    pub receptor: Photoreceptor,
    refractory_s: f64,
    latency_s: f64,
    jitter_s: f64,
    /// e^theta_on and e^-theta_off when every pixel has these thresholds and the response is
    /// logarithmic: a quiet band's ends are then e^ref times them, one exponential, not two.
    band_factors: Option<(f64, f64)>,
}

impl PixelModel {
    pub fn new(params: SensorParams) -> Self {
        let receptor = Photoreceptor::new(&params);
        Self {
            band_factors: (receptor.is_logarithmic()
                && params.theta_sigma == 0.0
                && params.theta_noise == 0.0)
                .then(|| (exp(params.theta_on), exp(-params.theta_off))),
            receptor,
            refractory_s: params.refractory_us * 1e-6,
            latency_s: params.latency_us * 1e-6,
            jitter_s: params.jitter_us * 1e-6,
            params,
        }
    }

    /// Whether a pixel's state stays the same while its input stays inside its threshold band
    /// (no low-pass, no leak drift, no light-dependent noise): then only crossings matter.
    pub fn is_time_invariant(&self) -> bool {
        self.receptor.is_instantaneous()
            && !noise::has_leak(&self.params)
            && self.params.shot_rate_hz == 0.0
    }

    /// Frozen per-pixel thresholds (ON, OFF): N(theta, theta_sigma) each, at least theta_min.
    fn base_thetas(&self, frozen: Draw) -> (f64, f64) {
        let p = &self.params;
        if p.theta_sigma == 0.0 {
            return (p.theta_on, p.theta_off);
        }
        let (z_on, z_off) = frozen.normal_pair(Stream::Theta);
        (
            (p.theta_on + p.theta_sigma * z_on).max(p.theta_min),
            (p.theta_off + p.theta_sigma * z_off).max(p.theta_min),
        )
    }

    /// Whether any pixel can act while its input stays constant: with a low-pass still
    /// settling, leak, shot noise or hot pixels.
    pub fn acts_with_constant_input(&self) -> bool {
        !self.is_time_invariant()
            || (self.params.hot_pixel_fraction > 0.0 && self.params.hot_pixel_rate_hz > 0.0)
    }

    /// Whether a pixel ever needs stepping while its input stays constant: it acts by itself, or
    /// a reset held for a refractory period is released. Otherwise `wake_s` is always infinite.
    pub fn can_wake(&self) -> bool {
        self.acts_with_constant_input()
            || (self.params.reference_reset == ReferenceReset::RefractoryEnd
                && self.refractory_s > 0.0)
    }

    /// Whether a time-invariant pixel, held since its state's time at an input inside its quiet
    /// band, does nothing up to `t_s`: no hot-pixel event and no reset to release. Then only
    /// its time moves, and the run is skipped. (Either would have woken it at an earlier frame;
    /// the check keeps the shortcut safe should the wake-ups ever change.)
    #[inline]
    pub fn holds_still_until(&self, st: &PixelState, t_s: f64) -> bool {
        st.hot_next_s > t_s && !self.is_blind(st)
    }

    /// The thresholds in force after an event with random numbers `draw`: base plus
    /// N(0, theta_noise) each.
    fn drawn_thetas(&self, st: &PixelState, draw: Draw) -> (f64, f64) {
        let p = &self.params;
        let (z_on, z_off) = draw.normal_pair(Stream::ThetaNoise);
        (
            (st.base_theta_on + p.theta_noise * z_on).max(p.theta_min),
            (st.base_theta_off + p.theta_noise * z_off).max(p.theta_min),
        )
    }

    /// The first frame: the pixel is settled at its input; a leaking pixel's reference starts
    /// at a random phase of its leak cycle, as a powered-up sensor's would.
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
            t_ref_s: if leak_drift > 0.0 {
                t_s - start.leak_phase * theta_on / leak_drift
            } else {
                t_s
            },
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

    #[inline]
    fn reference_at(&self, st: &PixelState, t_s: f64) -> f64 {
        st.ref0 - st.leak_drift * (t_s - st.t_ref_s)
    }

    fn is_blind(&self, st: &PixelState) -> bool {
        self.params.reference_reset == ReferenceReset::RefractoryEnd
            && st.refractory_mark_s > st.t_s
    }

    /// v - ref from the state's time on, for a segment with input slope `slope`.
    #[inline(always)]
    fn difference(&self, st: &PixelState, slope: f64, tau: f64, inv_tau: f64) -> Difference {
        let reference = self.reference_at(st, st.t_s);
        Difference::of_pixel(st.u, st.v, reference, st.leak_drift, slope, tau, inv_tau)
    }

    /// When the state's shot-noise budget runs out on the rest of the segment (infinity if it
    /// does not). The rate is monotone over a segment, so its larger end bounds the hazard and
    /// usually rules an event out without a logarithm.
    fn shot_clock(&self, st: &PixelState, seg: &Segment, drive: &Drive) -> ShotClock {
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
    fn settle_shots(&self, st: &mut PixelState, seg: &Segment, drive: &Drive, clock: &ShotClock) {
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
    fn drive(&self, seg: &Segment) -> Drive {
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
    fn advance_to(&self, st: &mut PixelState, seg: &Segment, drive: &Drive, t_s: f64) {
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

    /// Simulate the pixel from its state's time to the end of `seg`, pushing its events.
    pub fn run(
        &self,
        st: &mut PixelState,
        pixel: u64,
        seg: &Segment,
        events: &mut impl FnMut(PixelEvent),
    ) {
        self.follow_light_with_leak(st, pixel, seg.x1);
        if self.is_linear(st, seg) {
            return self.run_linear(st, pixel, seg, events);
        }
        let drive = self.drive(seg);
        // The next shot-noise event is found once for the segment (again after each one), and
        // the budget it draws on is settled once at the end, not at every other happening.
        let mut shots = self.shot_clock(st, seg, &drive);
        loop {
            let horizon = seg.t1_s - st.t_s;
            if horizon < 0.0 {
                break;
            }
            let (s, next) = self.next_happening(st, &drive, shots.due_s, horizon);
            self.advance_to(st, seg, &drive, st.t_s + s);
            if next == Next::End {
                break;
            }
            self.apply(st, pixel, &drive, next, events);
            if next == Next::Shot {
                shots = self.shot_clock(st, seg, &drive); // a fresh budget from now
            }
        }
        self.settle_shots(st, seg, &drive, &shots);
    }

    /// The leak drift at a new light level x1 (`noise::leak_law_hz`), held over the segment that
    /// ends at it: exact for constant light, which is what the wake-up bound and a still pixel
    /// see; over a changing frame interval (tens of ms) against leak periods of seconds, the
    /// end value stands for the interval. The reference is re-based at the state's time, so the
    /// drift already done stays. The pixel's factor is the old drift over the old law, or its
    /// frozen draw when the old law was zero.
    #[inline]
    fn follow_light_with_leak(&self, st: &mut PixelState, pixel: u64, x1: f64) {
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
    fn is_linear(&self, st: &PixelState, seg: &Segment) -> bool {
        self.receptor.is_instantaneous()
            && st.leak_drift == 0.0
            && self.params.shot_rate_hz == 0.0
            && st.hot_next_s > seg.t1_s
            && (self.params.reference_reset == ReferenceReset::Event || self.refractory_s == 0.0)
    }

    /// `run` for a linear difference: each crossing in closed form, u(t) = level.
    fn run_linear(
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

    /// Crossings of ref + k theta for one threshold, a sensor's most frequent work: the state
    /// is kept in registers and written back once. Emitting follows `fire` (ESIM's refractory
    /// check, a constant latency); a skipped crossing still moves the reference.
    #[inline(always)]
    fn cross_fixed_threshold<const ON: bool>(
        &self,
        st: &mut PixelState,
        seg: &Segment,
        slope: f64,
        events: &mut impl FnMut(PixelEvent),
    ) {
        let step = if ON { st.theta_on } else { -st.theta_off };
        let check_refractory = self.params.reference_reset == ReferenceReset::Event;
        let (mut t_s, mut reference, mut level) = (st.t_s, st.ref0, st.ref0 + step);
        let (mut last_emit_s, mut last_out_s) = (st.refractory_mark_s, st.last_out_s);
        let mut crossings = 0;
        while if ON { seg.u1 >= level } else { seg.u1 <= level } {
            t_s = seg.time_of(level, slope, t_s);
            if !check_refractory || t_s - last_emit_s >= self.refractory_s {
                last_emit_s = t_s;
                let t_out_s = t_s + self.latency_s;
                last_out_s = if t_out_s > last_out_s {
                    t_out_s
                } else {
                    last_out_s
                };
                events(PixelEvent {
                    t_s: last_out_s,
                    on: ON,
                    cause: Cause::Signal,
                });
            }
            reference = level;
            level += step;
            crossings += 1;
        }
        if crossings > 0 {
            st.ref0 = reference;
            st.t_ref_s = t_s;
            st.draws += crossings;
            st.last_out_s = last_out_s;
            if check_refractory {
                st.refractory_mark_s = last_emit_s;
            }
        }
    }

    /// The same crossings with thresholds redrawn after each event, or jittered latency.
    fn cross_noisy_thresholds(
        &self,
        st: &mut PixelState,
        pixel: u64,
        seg: &Segment,
        slope: f64,
        on: bool,
        events: &mut impl FnMut(PixelEvent),
    ) {
        loop {
            let theta = if on { st.theta_on } else { st.theta_off };
            let level = st.ref0 + if on { theta } else { -theta };
            if (on && seg.u1 < level) || (!on && seg.u1 > level) {
                break;
            }
            let t_s = seg.time_of(level, slope, st.t_s);
            st.t_s = t_s;
            st.u = level;
            st.v = level;
            // Either rule puts the new reference at the level crossed: ESIM steps it by
            // theta, and memorising at the event reads v, which is the level.
            st.ref0 = level;
            st.t_ref_s = t_s;
            self.fire(st, self.draw(pixel, st), on, Cause::Signal, events);
        }
    }

    /// The earliest thing that happens within `horizon` seconds, and when.
    #[inline(always)]
    fn next_happening(
        &self,
        st: &PixelState,
        drive: &Drive,
        shot_due_s: f64,
        horizon: f64,
    ) -> (f64, Next) {
        let mut best = (horizon, Next::End);
        let consider = |s: Option<f64>, what: Next, best: &mut (f64, Next)| {
            if let Some(s) = s {
                if s < best.0 || (s == best.0 && best.1 == Next::End) {
                    *best = (s.max(0.0), what);
                }
            }
        };
        if self.is_blind(st) {
            consider(
                Some(st.refractory_mark_s - st.t_s),
                Next::ReleaseReset,
                &mut best,
            );
        } else {
            let d = self.difference(st, drive.slope, drive.tau, drive.inv_tau);
            consider(d.first_reach(st.theta_on, best.0), Next::On, &mut best);
            consider(
                d.negated().first_reach(st.theta_off, best.0),
                Next::Off,
                &mut best,
            );
        }
        consider(Some(shot_due_s - st.t_s), Next::Shot, &mut best);
        consider(Some(st.hot_next_s - st.t_s), Next::Hot, &mut best);
        best
    }

    fn apply(
        &self,
        st: &mut PixelState,
        pixel: u64,
        drive: &Drive,
        next: Next,
        events: &mut impl FnMut(PixelEvent),
    ) {
        let p = &self.params;
        let t = st.t_s;
        match next {
            Next::End => {}
            Next::ReleaseReset => self.memorise(st, t),
            Next::On | Next::Off => {
                let on = next == Next::On;
                let theta = if on { st.theta_on } else { st.theta_off };
                let cause = self.crossing_cause(st, drive, on);
                if p.reference_reset == ReferenceReset::Event {
                    // ESIM: the reference steps by the threshold, emitted or not.
                    st.ref0 = self.reference_at(st, t) + if on { theta } else { -theta };
                    st.t_ref_s = t;
                }
                self.fire(st, self.draw(pixel, st), on, cause, events);
            }
            Next::Shot => {
                let draw = self.draw(pixel, st);
                let on = draw.uniform(Stream::ShotPolarity) < 0.5;
                st.shot_budget = draw.exponential(Stream::ShotTime);
                self.fire(st, draw, on, Cause::Shot, events);
            }
            Next::Hot => {
                let draw = self.draw(pixel, st);
                let on = draw.uniform(Stream::HotPolarity) < 0.5;
                st.hot_next_s = t + draw.exponential(Stream::HotTime) / p.hot_pixel_rate_hz;
                self.fire(st, draw, on, Cause::Hot, events);
            }
        }
    }

    /// What made the pixel cross, the light or the leak, read from its state at the crossing.
    ///
    /// The difference d = v - ref reaches a threshold moving at d' = v' + k: the photoreceptor's
    /// change v' (the light) plus the leak's drift k of the reference. A crossing is leak when
    /// the leak was closing the gap faster than the light as the pixel crossed (v' < k: the
    /// light's share of d' under one half), signal otherwise. It asks whether the event would
    /// have come when it did without the light: a leak crossing comes about 1/rate seconds
    /// after the last reset whatever the light did before, a signal crossing when the light
    /// moves. Hence the rate at the crossing and not the distance covered since the last reset:
    /// a reference that has leaked most of theta over seconds before an edge arrives does not
    /// make the edge's first event a leak event, and the rest of a step left under threshold,
    /// finished by the leak seconds later, is leak. The leak moves the reference down, towards
    /// ON events only; an OFF crossing needs d' <= 0, so v' <= -k, the light falling faster
    /// than the leak: always signal. Nothing before the crossing enters, so the rule needs no
    /// state and is the same after either reset (the reference memorised at the end of the
    /// refractory period, or ESIM's ref += theta) and after a shot or hot-pixel event (which
    /// carry their own cause, and reset the reference).
    /// With a low-pass v' = (u - v) / tau (tau v' = u - v), compared as u - v < k tau; without
    /// one v = u and v' is the input's slope.
    #[inline]
    fn crossing_cause(&self, st: &PixelState, drive: &Drive, on: bool) -> Cause {
        let leak_outpaces_light = st.leak_drift > 0.0
            && if drive.tau > 0.0 {
                st.u - st.v < st.leak_drift * drive.tau
            } else {
                drive.slope < st.leak_drift
            };
        if on && leak_outpaces_light {
            Cause::Leak
        } else {
            Cause::Signal
        }
    }

    /// The random numbers of the pixel's next event (its counter is the events drawn so far).
    #[inline]
    fn draw(&self, pixel: u64, st: &PixelState) -> Draw {
        Draw::new(self.params.seed, pixel, st.draws)
    }

    /// An event at the state's time: emitted unless refractory, then the reset and new thresholds;
    /// `draw` holds its random numbers (threshold noise, jitter).
    fn fire(
        &self,
        st: &mut PixelState,
        draw: Draw,
        on: bool,
        cause: Cause,
        events: &mut impl FnMut(PixelEvent),
    ) {
        let p = &self.params;
        let t = st.t_s;
        st.draws += 1;
        let emitted = match p.reference_reset {
            ReferenceReset::Event => {
                let free = t - st.refractory_mark_s >= self.refractory_s;
                if free {
                    st.refractory_mark_s = t;
                }
                if cause != Cause::Signal && cause != Cause::Leak {
                    self.memorise(st, t); // noise events reset the reference to the present level
                }
                free
            }
            ReferenceReset::RefractoryEnd => {
                let free = !self.is_blind(st);
                if free {
                    if self.refractory_s > 0.0 {
                        st.refractory_mark_s = t + self.refractory_s;
                    } else {
                        self.memorise(st, t);
                    }
                }
                free
            }
        };
        if p.theta_noise > 0.0 {
            (st.theta_on, st.theta_off) = self.drawn_thetas(st, draw);
        }
        if emitted {
            let jitter_s = if self.jitter_s > 0.0 {
                self.jitter_s * draw.normal(Stream::Jitter)
            } else {
                0.0
            };
            let delay = (self.latency_s + jitter_s).max(0.0);
            let t_out = (t + delay).max(st.last_out_s);
            st.last_out_s = t_out;
            events(PixelEvent {
                t_s: t_out,
                on,
                cause,
            });
        }
    }

    /// The reference set to the present level; a reset held to the refractory period's end is
    /// released (with the reset at the event, the mark is the last emission and stays).
    fn memorise(&self, st: &mut PixelState, t_s: f64) {
        st.ref0 = st.v;
        st.t_ref_s = t_s;
        if self.params.reference_reset == ReferenceReset::RefractoryEnd {
            st.refractory_mark_s = f64::NEG_INFINITY;
        }
    }

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

/// The quiet band from the frame values at which a threshold is reached, narrowed by a relative
/// margin so that rounding never lets an input that crosses a threshold inside it (no lower end
/// where it is not above zero). Shared by `band_around` and the vectorised first bands
/// (`first_band`), so the two give the same bits.
#[inline(always)]
pub(crate) fn narrowed_band(lo: f64, hi: f64) -> (f64, f64) {
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

    /// The causes of the events a pixel with leak drift k = rate theta emits while its log input
    /// moves at `ratio` k per second for 50 s, with or without a low-pass.
    fn causes_under_ramp(ratio: f64, tau_s: f64) -> Vec<(bool, Cause)> {
        let mut p = SensorParams::ideal(1, 1);
        p.leak_rate_hz = 1.0;
        if tau_s > 0.0 {
            p.cutoff_hz = 1.0 / (2.0 * std::f64::consts::PI * tau_s); // light-independent
        }
        let model = PixelModel::new(p);
        let mut st = model.init(0, 0.5, 0.0);
        let k = st.leak_drift;
        let (t1_s, u0) = (50.0, st.u);
        let u1 = u0 + ratio * k * t1_s;
        let ramp = Segment {
            t0_s: 0.0,
            t1_s,
            u0,
            u1,
            x0: st.x,
            x1: u1.exp(),
        };
        let mut causes = Vec::new();
        model.run(&mut st, 0, &ramp, &mut |e| causes.push((e.on, e.cause)));
        causes
    }

    #[test]
    fn a_crossing_is_leak_when_the_leak_outpaces_the_light() {
        // d = v - ref moves at v' + k. Light rising faster than the leak drifts: signal; slower,
        // or falling slower than the leak drifts (d still rises): leak; falling faster than the
        // leak: OFF, signal. The low-pass follows a ramp at its slope after a few tau.
        for tau_s in [0.0, 1e-3] {
            for (ratio, on, cause) in [
                (1.05, true, Cause::Signal),
                (0.95, true, Cause::Leak),
                (-0.95, true, Cause::Leak),
                (-1.05, false, Cause::Signal),
            ] {
                let causes = causes_under_ramp(ratio, tau_s);
                // |v' + k| >= 0.05 k = 0.01 / s: d moves at least 0.5 in 50 s, enough to reach
                // either threshold (0.2) from anywhere between them.
                assert!(!causes.is_empty(), "ratio {ratio}, tau {tau_s}");
                assert!(
                    causes.iter().all(|&c| c == (on, cause)),
                    "ratio {ratio}, tau {tau_s}: {causes:?}"
                );
            }
        }
    }
}
