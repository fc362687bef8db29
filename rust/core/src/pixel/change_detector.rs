//! The change detector: when v - ref reaches a threshold or a noise event comes, and what an
//! event does: emission unless refractory (with latency and jitter), the reference reset, new
//! threshold noise, and its cause (light, leak, shot or hot pixel).

use super::{Cause, Drive, FoundCrossings, Next, PixelEvent, PixelModel, PixelState, Segment};
use crate::params::ReferenceReset;
use crate::rng::{Draw, Stream};

impl PixelModel {
    /// The thresholds in force after an event with random numbers `draw`, for a pixel whose
    /// frozen thresholds are `base_on` and `base_off`: base plus N(0, theta_noise) each.
    #[inline]
    pub(crate) fn drawn_thetas(&self, base_on: f64, base_off: f64, draw: Draw) -> (f64, f64) {
        let p = &self.params;
        let (z_on, z_off) = draw.normal_pair(Stream::ThetaNoise);
        (
            (base_on + p.theta_noise * z_on).max(p.theta_min),
            (base_off + p.theta_noise * z_off).max(p.theta_min),
        )
    }

    /// When an event at `t_s` comes out, with random numbers `draw`: after the latency and its
    /// jitter (never before the event), and not before the pixel's last output, `last_out_s`.
    #[inline]
    pub(crate) fn output_time(&self, t_s: f64, draw: Draw, last_out_s: f64) -> f64 {
        let jitter_s = if self.jitter_s > 0.0 {
            self.jitter_s * draw.normal(Stream::Jitter)
        } else {
            0.0
        };
        let delay = (self.latency_s + jitter_s).max(0.0);
        (t_s + delay).max(last_out_s)
    }

    /// Crossings of ref + k theta for one threshold, a sensor's most frequent work: the state
    /// is kept in registers and written back once. Emitting follows `fire` (ESIM's refractory
    /// check, a constant latency); a skipped crossing still moves the reference.
    #[inline(always)]
    pub(super) fn cross_fixed_threshold<const ON: bool>(
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
    pub(super) fn cross_noisy_thresholds(
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

    /// The earliest thing that happens within `horizon` seconds, and when; `found`, where given,
    /// holds the threshold crossings as this would find them (see `FoundCrossings`).
    #[inline(always)]
    pub(super) fn next_happening(
        &self,
        st: &PixelState,
        drive: &Drive,
        shot_due_s: f64,
        horizon: f64,
        found: Option<FoundCrossings>,
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
        } else if let Some(found) = found {
            consider(found.on_s, Next::On, &mut best);
            consider(found.off_s, Next::Off, &mut best);
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

    pub(super) fn apply(
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
        if on && leak_outpaces_light(st.leak_drift, st.u, st.v, drive.tau, drive.slope) {
            Cause::Leak
        } else {
            Cause::Signal
        }
    }

    /// The random numbers of the pixel's next event (its counter is the events drawn so far).
    #[inline]
    fn draw(&self, pixel: u64, st: &PixelState) -> Draw {
        self.draw_of(pixel, st.draws)
    }

    /// The random numbers of a pixel's event whose counter is `draws`.
    #[inline]
    pub(crate) fn draw_of(&self, pixel: u64, draws: u64) -> Draw {
        Draw::new(self.params.seed, pixel, draws)
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
            (st.theta_on, st.theta_off) =
                self.drawn_thetas(st.base_theta_on, st.base_theta_off, draw);
        }
        if emitted {
            let t_out = self.output_time(t, draw, st.last_out_s);
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
}

/// Whether the leak (drift k) closes the gap faster than the light as the pixel crosses
/// (`PixelModel::crossing_cause`): u - v < k tau with a low-pass (input u, output v, time
/// constant tau), the input's slope below k without one.
#[inline(always)]
pub(crate) fn leak_outpaces_light(leak_drift: f64, u: f64, v: f64, tau: f64, slope: f64) -> bool {
    leak_drift > 0.0
        && if tau > 0.0 {
            u - v < leak_drift * tau
        } else {
            slope < leak_drift
        }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::SensorParams;

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
