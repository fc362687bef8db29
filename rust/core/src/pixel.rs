//! One DVS pixel: photoreceptor, change detector with refractory reset, and its noise sources,
//! simulated exactly between frame times (no time steps inside an interval).
//! Its parts, one concept a file: `power_up` (the first state; `first_states`, a block's at
//! once), `ramp` (following the input between happenings), `change_detector` (crossings and
//! what an event does), `quiet_band` and `wake` (when a frame can skip the pixel),
//! `reference_only` (ESIM's pixel, whose state is its reference alone).

use crate::exp::exp;
use crate::noise::{self, GeometricRate};
use crate::params::{ReferenceReset, SensorParams};
use crate::photoreceptor::Photoreceptor;

mod change_detector;
mod first_states;
mod power_up;
mod quiet_band;
mod ramp;
mod reference_only;
mod wake;
pub(crate) use change_detector::leak_outpaces_light;
pub(crate) use quiet_band::rounded_band;
pub(crate) use ramp::drive_slope;
pub use reference_only::{GROUP, RAMP_VALUES};

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

/// When v - ref first reaches +theta_on and -theta_off in a run's first turn that looks for a
/// crossing (the first, or the one after a reset's release), as `PixelModel::next_happening`
/// finds them: the ON crossing within the turn's horizon, the OFF crossing up to the ON one (or
/// the horizon); seconds from the state's time then, None for none.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FoundCrossings {
    pub on_s: Option<f64>,
    pub off_s: Option<f64>,
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

    /// The refractory period, seconds.
    #[inline(always)]
    pub(crate) fn refractory_s(&self) -> f64 {
        self.refractory_s
    }

    /// Whether a pixel's state stays the same while its input stays inside its threshold band
    /// (no low-pass, no leak drift, no light-dependent noise): then only crossings matter.
    pub fn is_time_invariant(&self) -> bool {
        self.receptor.is_instantaneous()
            && !noise::has_leak(&self.params)
            && self.params.shot_rate_hz == 0.0
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

    #[inline]
    fn reference_at(&self, st: &PixelState, t_s: f64) -> f64 {
        st.ref0 - st.leak_drift * (t_s - st.t_ref_s)
    }

    fn is_blind(&self, st: &PixelState) -> bool {
        self.params.reference_reset == ReferenceReset::RefractoryEnd
            && st.refractory_mark_s > st.t_s
    }

    /// Simulate the pixel from its state's time to the end of `seg`, pushing its events.
    pub fn run(
        &self,
        st: &mut PixelState,
        pixel: u64,
        seg: &Segment,
        events: &mut impl FnMut(PixelEvent),
    ) {
        self.run_found(st, pixel, seg, None, events);
    }

    /// `run`, with the threshold crossings of its first turn that looks for one (the first not
    /// held in reset) already found where `found` is given (the dense path finds a block's
    /// together); the same bits either way.
    pub(crate) fn run_found(
        &self,
        st: &mut PixelState,
        pixel: u64,
        seg: &Segment,
        mut found: Option<FoundCrossings>,
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
            // The crossings found are those of the first turn that looks for one.
            let found_now = if found.is_some() && !self.is_blind(st) {
                found.take()
            } else {
                None
            };
            let (s, next) = self.next_happening(st, &drive, shots.due_s, horizon, found_now);
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
}
