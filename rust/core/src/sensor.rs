//! The streaming event sensor: per-pixel state over a whole array, fed photocurrent frames.
//!
//! Each call to `feed` simulates every pixel over (t_prev, t] in parallel. A pixel whose input is
//! inside its quiet band and that has nothing due before t is skipped without touching its
//! state, so a mostly static scene costs little more than reading the frame.

use std::fmt;

use rayon::prelude::*;

use crate::events::{Event, EventColumns};
use crate::params::{ParamError, SensorParams};
use crate::pixel::{PixelEvent, PixelModel, PixelState, Segment};

/// Pixels per parallel work item: large enough to amortise scheduling, small enough to balance.
const CHUNK: usize = 4096;
/// Below this many events a sort on one thread is faster than splitting it.
const PARALLEL_SORT_MIN: usize = 200_000;

/// Why a frame or time was refused. The sensor is unchanged after any of these.
#[derive(Clone, Debug, PartialEq)]
pub enum FeedError {
    Shape { expected: usize, got: usize },
    NotFinite { x: usize, y: usize, value: f32 },
    Negative { x: usize, y: usize, value: f32 },
    Time { t_us: i64, t_prev_us: i64 },
}

impl fmt::Display for FeedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Shape { expected, got } => {
                write!(f, "frame has {got} pixels, the sensor has {expected}")
            }
            Self::NotFinite { x, y, value } => {
                write!(f, "frame has a non-finite value ({value}) at x={x}, y={y}")
            }
            Self::Negative { x, y, value } => {
                write!(
                    f,
                    "frame has a negative photocurrent ({value}) at x={x}, y={y}"
                )
            }
            Self::Time { t_us, t_prev_us } => {
                write!(
                    f,
                    "t_us must increase from frame to frame: got {t_us} after {t_prev_us}"
                )
            }
        }
    }
}

impl std::error::Error for FeedError {}

/// What the per-frame loop reads first, one array per field so the test vectorises: the input
/// band in which each pixel stays quiet, and a lower bound on when it next needs attention anyway
/// (seconds since the first frame).
#[derive(Clone, Debug, Default)]
struct Gates {
    /// The band, for time-invariant models only (the others are quiet only while unchanged).
    lo: Vec<f32>,
    hi: Vec<f32>,
    wake_s: Vec<f32>,
}

/// A DVS sensor with state: feed it frames in time order, collect events.
pub struct EventSensor {
    model: PixelModel,
    time_invariant: bool,
    gates: Gates,
    last_frame: Vec<f32>,
    pixels: Vec<PixelState>,
    origin_us: Option<i64>,
    t_prev_us: i64,
    /// Events whose (delayed) time is beyond the last frame, in output order.
    pending: Vec<Event>,
    /// Step every pixel every frame (tests check that skipping quiet pixels changes nothing).
    never_skip: bool,
    /// Per pixel: whether this frame steps it (scratch, reused).
    busy: Vec<u8>,
    /// Time-invariant models: this frame's values, the next frame's ramp starts (scratch).
    staged: Vec<f32>,
}

impl EventSensor {
    pub fn new(params: SensorParams) -> Result<Self, ParamError> {
        params.validate()?;
        let model = PixelModel::new(params);
        Ok(Self {
            time_invariant: model.is_time_invariant(),
            model,
            gates: Gates::default(),
            last_frame: Vec::new(),
            pixels: Vec::new(),
            origin_us: None,
            t_prev_us: 0,
            pending: Vec::new(),
            never_skip: false,
            busy: Vec::new(),
            staged: Vec::new(),
        })
    }

    pub fn params(&self) -> &SensorParams {
        &self.model.params
    }

    fn pixel_count(&self) -> usize {
        self.model.params.width * self.model.params.height
    }

    /// Forget everything: the next frame initialises the pixels again.
    pub fn reset(&mut self) {
        self.gates = Gates::default();
        self.last_frame = Vec::new();
        self.pixels = Vec::new();
        self.origin_us = None;
        self.pending.clear();
    }

    /// Time of the last frame fed, if any.
    pub fn last_time_us(&self) -> Option<i64> {
        self.origin_us.map(|_| self.t_prev_us)
    }

    /// Take a frame of linear photocurrent (row-major, height x width) at `t_us`; return the
    /// events with times in (t_prev, t_us], sorted by (t, y, x). The first frame only initialises.
    pub fn feed(&mut self, frame: &[f32], t_us: i64) -> Result<EventColumns, FeedError> {
        // One hop into the thread pool per frame: the parallel loops inside then start without
        // waking and blocking the calling thread each time.
        rayon::scope(|_| self.feed_in_pool(frame, t_us))
    }

    fn feed_in_pool(&mut self, frame: &[f32], t_us: i64) -> Result<EventColumns, FeedError> {
        self.check_shape(frame)?;
        let Some(origin_us) = self.origin_us else {
            if !all_valid(frame) {
                return Err(self.locate_bad_value(frame));
            }
            self.start(frame, t_us);
            return Ok(EventColumns::default());
        };
        if t_us <= self.t_prev_us {
            return Err(FeedError::Time {
                t_us,
                t_prev_us: self.t_prev_us,
            });
        }
        let t0_s = (self.t_prev_us - origin_us) as f64 * 1e-6;
        let t1_s = (t_us - origin_us) as f64 * 1e-6;
        // Validation and the choice of pixels to step share one read of the frame; nothing is
        // changed before the whole frame is known to be valid.
        if !self.mark_busy(frame, t1_s) {
            return Err(self.locate_bad_value(frame));
        }
        let clock = Clock {
            origin_us,
            floor_us: self.t_prev_us + 1,
            width: self.model.params.width,
        };
        for events in self.step_pixels(frame, t0_s, t1_s, &clock) {
            self.pending.extend_from_slice(&events);
        }
        self.t_prev_us = t_us;
        Ok(self.take_pending_until(t_us))
    }

    /// Everything still held back by latency, in order.
    pub fn flush(&mut self) -> EventColumns {
        self.take_pending_until(i64::MAX)
    }

    fn take_pending_until(&mut self, t_us: i64) -> EventColumns {
        sort_events(&mut self.pending);
        let due = self.pending.partition_point(|e| e.t_us <= t_us);
        let out = EventColumns::from_events(&self.pending[..due]);
        self.pending.drain(..due);
        out
    }

    fn check_shape(&self, frame: &[f32]) -> Result<(), FeedError> {
        let expected = self.pixel_count();
        if frame.len() != expected {
            return Err(FeedError::Shape {
                expected,
                got: frame.len(),
            });
        }
        Ok(())
    }

    /// Where the first invalid value is (the slow search runs only once a frame is refused).
    fn locate_bad_value(&self, frame: &[f32]) -> FeedError {
        let index = frame.iter().position(|v| !valid_value(*v)).unwrap_or(0);
        let (x, y) = (
            index % self.model.params.width,
            index / self.model.params.width,
        );
        let value = frame[index];
        if value.is_finite() {
            FeedError::Negative { x, y, value }
        } else {
            FeedError::NotFinite { x, y, value }
        }
    }

    /// Flag the pixels that need stepping to t1 (input outside the quiet band, or something due);
    /// returns whether every value is valid. Branch-free per chunk, so it vectorises.
    fn mark_busy(&mut self, frame: &[f32], t1_s: f64) -> bool {
        let t1_up = if self.never_skip {
            f32::INFINITY
        } else {
            round_up_f32(t1_s)
        };
        self.busy.resize(frame.len(), 0);
        let g = &self.gates;
        let busy = self
            .busy
            .par_chunks_mut(CHUNK)
            .zip(frame.par_chunks(CHUNK))
            .zip(g.wake_s.par_chunks(CHUNK));
        if self.time_invariant {
            // Quiet while inside the band; the values are staged as the next ramps' starts.
            self.staged.resize(frame.len(), 0.0);
            busy.zip(g.lo.par_chunks(CHUNK).zip(g.hi.par_chunks(CHUNK)))
                .zip(self.staged.par_chunks_mut(CHUNK))
                .map(|((((busy, values), wake), (lo, hi)), staged)| {
                    let mut ok = true;
                    for j in 0..values.len() {
                        let v = values[j];
                        ok &= valid_value(v);
                        busy[j] = !((v >= lo[j]) & (v <= hi[j]) & (t1_up < wake[j])) as u8;
                        staged[j] = v;
                    }
                    ok
                })
                .reduce(|| true, |a, b| a & b)
        } else {
            // Quiet only while the input is unchanged.
            busy.zip(self.last_frame.par_chunks(CHUNK))
                .map(|(((busy, values), wake), last)| {
                    let mut ok = true;
                    for j in 0..values.len() {
                        let v = values[j];
                        ok &= valid_value(v);
                        busy[j] = !((v == last[j]) & (t1_up < wake[j])) as u8;
                    }
                    ok
                })
                .reduce(|| true, |a, b| a & b)
        }
    }

    fn start(&mut self, frame: &[f32], t_us: i64) {
        let model = &self.model;
        self.pixels = frame
            .par_iter()
            .enumerate()
            .map(|(i, &v)| model.init(i as u64, v as f64, 0.0))
            .collect();
        let ti = self.time_invariant;
        let gates: Vec<_> = self
            .pixels
            .par_iter()
            .zip(frame.par_iter())
            .map(|(st, &v)| gate(model, ti, st, v))
            .collect();
        self.gates = Gates {
            lo: gates.iter().map(|g| g.0).collect(),
            hi: gates.iter().map(|g| g.1).collect(),
            wake_s: gates.iter().map(|g| g.2).collect(),
        };
        self.last_frame = frame.to_vec();
        self.origin_us = Some(t_us);
        self.t_prev_us = t_us;
        self.pending.clear();
    }

    /// Step the pixels `mark_busy` flagged over (t0, t1]; events per chunk, in pixel order.
    fn step_pixels(
        &mut self,
        frame: &[f32],
        t0_s: f64,
        t1_s: f64,
        clock: &Clock,
    ) -> Vec<Vec<Event>> {
        let model = &self.model;
        let ti = self.time_invariant;
        let g = &mut self.gates;
        let events =
            g.lo.par_chunks_mut(CHUNK)
                .zip(g.hi.par_chunks_mut(CHUNK))
                .zip(g.wake_s.par_chunks_mut(CHUNK))
                .zip(self.last_frame.par_chunks_mut(CHUNK))
                .zip(self.pixels.par_chunks_mut(CHUNK))
                .zip(frame.par_chunks(CHUNK).zip(self.busy.par_chunks(CHUNK)))
                .enumerate()
                .map(
                    |(chunk, (((((lo, hi), wake), last), pixels), (values, busy)))| {
                        let mut out = Vec::new();
                        let mut scratch = Vec::new();
                        for (word, flags) in busy.chunks(8).enumerate() {
                            if u64::from_ne_bytes(pad8(flags)) == 0 {
                                continue;
                            }
                            for (k, _) in flags.iter().enumerate().filter(|(_, &f)| f != 0) {
                                let j = word * 8 + k;
                                let pixel = (chunk * CHUNK + j) as u64;
                                let st = &mut pixels[j];
                                step_pixel(
                                    model,
                                    ti,
                                    st,
                                    pixel,
                                    last[j],
                                    values[j],
                                    t0_s,
                                    t1_s,
                                    &mut scratch,
                                );
                                out.extend(scratch.drain(..).map(|e| clock.event(pixel, e)));
                                let (l, h, w) = gate(model, ti, st, values[j]);
                                wake[j] = w;
                                if ti {
                                    (lo[j], hi[j]) = (l, h);
                                } else {
                                    last[j] = values[j];
                                }
                            }
                        }
                        out
                    },
                )
                .collect();
        if ti {
            // Every value of this frame, staged by `mark_busy`, starts the next frame's ramps.
            std::mem::swap(&mut self.last_frame, &mut self.staged);
        }
        events
    }
}

/// Turns a pixel's event (seconds since the first frame) into an output event.
struct Clock {
    origin_us: i64,
    /// Events of this frame come after the previous frame's time, even when rounding says not.
    floor_us: i64,
    width: usize,
}

impl Clock {
    #[inline]
    fn event(&self, pixel: u64, e: PixelEvent) -> Event {
        let pixel = pixel as usize;
        Event {
            t_us: (self.origin_us + (e.t_s * 1e6).round() as i64).max(self.floor_us),
            x: (pixel % self.width) as u16,
            y: (pixel / self.width) as u16,
            p: e.on as i8,
            label: e.cause as u8,
        }
    }
}

/// Sort by (t, y, x), stably: one pixel's events with equal times keep the order it emitted
/// them in. The key is packed into one integer when the time span allows (it always does within
/// a frame and its latency), which makes each comparison a single one.
fn sort_events(events: &mut [Event]) {
    let (Some(min), Some(max)) = (
        events.iter().map(|e| e.t_us).min(),
        events.iter().map(|e| e.t_us).max(),
    ) else {
        return;
    };
    if max - min < (1 << 31) {
        let key = |e: &Event| ((e.t_us - min) as u64) << 32 | (e.y as u64) << 16 | e.x as u64;
        if events.len() > PARALLEL_SORT_MIN {
            events.par_sort_by_key(key);
        } else {
            events.sort_by_key(key);
        }
    } else {
        events.par_sort_by_key(Event::order_key);
    }
}

/// Eight flags as one word (the last group of a chunk may be shorter).
#[inline]
fn pad8(flags: &[u8]) -> [u8; 8] {
    let mut word = [0u8; 8];
    word[..flags.len()].copy_from_slice(flags);
    word
}

/// A usable photocurrent: finite and >= 0 (-0.0 included), tested on the bits so loops vectorise.
#[inline]
fn valid_value(v: f32) -> bool {
    let b = v.to_bits();
    (b <= 0x7f7f_ffff) | (b == 0x8000_0000)
}

/// Whether every value of a frame is usable (parallel, vectorised).
fn all_valid(frame: &[f32]) -> bool {
    frame
        .par_chunks(CHUNK)
        .all(|c| c.iter().fold(true, |ok, &v| ok & valid_value(v)))
}

/// One pixel over (t0, t1]: held at its last input since its state's time, then the ramp (linear
/// in log) from the last frame's value to this one's.
#[allow(clippy::too_many_arguments)]
fn step_pixel(
    model: &PixelModel,
    time_invariant: bool,
    st: &mut PixelState,
    pixel: u64,
    last_value: f32,
    value: f32,
    t0_s: f64,
    t1_s: f64,
    events: &mut Vec<PixelEvent>,
) {
    let r = &model.receptor;
    if time_invariant {
        // Skipped frames moved the input inside the quiet band, which changes nothing else.
        st.x = r.total_current(last_value as f64);
        st.u = r.response(st.x);
        st.v = st.u;
    }
    // Otherwise a pixel is skipped only while its input is unchanged, so its state already holds
    // the response to the last frame's value.
    let (u0, x0) = (st.u, st.x);
    if st.t_s < t0_s {
        model.run(
            st,
            pixel,
            &Segment::constant(st.t_s, t0_s, st.u, st.x),
            events,
        );
    }
    let x1 = r.total_current(value as f64);
    let ramp = Segment {
        t0_s,
        t1_s,
        u0,
        u1: r.response(x1),
        x0,
        x1,
    };
    model.run(st, pixel, &ramp, events);
}

/// (lo, hi, wake_s) of a pixel's gate, rounded outwards to f32 so the test stays conservative.
fn gate(model: &PixelModel, time_invariant: bool, st: &PixelState, value: f32) -> (f32, f32, f32) {
    let (lo, hi) = if time_invariant {
        let (lo, hi) = model.quiet_band(st);
        (round_up_f32(lo), round_down_f32(hi))
    } else {
        (value, value)
    };
    (lo, hi, round_down_f32(model.wake_s(st)))
}

fn round_down_f32(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) > v {
        f.next_down()
    } else {
        f
    }
}

fn round_up_f32(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v {
        f.next_up()
    } else {
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ReferenceReset;

    /// A mostly static scene: a bright square moving over a textured background.
    fn frames(width: usize, height: usize, n: usize) -> Vec<Vec<f32>> {
        (0..n)
            .map(|k| {
                (0..width * height)
                    .map(|i| {
                        let (x, y) = (i % width, i / width);
                        let background = 0.1 + 0.05 * ((x * 7 + y * 13) % 11) as f32;
                        let inside = x >= 3 + 2 * k && x < 13 + 2 * k && (10..20).contains(&y);
                        if inside {
                            0.9
                        } else {
                            background
                        }
                    })
                    .collect()
            })
            .collect()
    }

    fn run(params: &SensorParams, never_skip: bool) -> Vec<EventColumns> {
        let mut sensor = EventSensor::new(params.clone()).unwrap();
        sensor.never_skip = never_skip;
        let mut out: Vec<EventColumns> = frames(params.width, params.height, 12)
            .iter()
            .enumerate()
            .map(|(k, f)| sensor.feed(f, 1000 * k as i64 + 7).unwrap())
            .collect();
        out.push(sensor.flush());
        out
    }

    #[test]
    fn skipping_quiet_pixels_changes_no_event() {
        let mut esim = SensorParams::ideal(40, 30);
        esim.reference_reset = ReferenceReset::Event;
        esim.refractory_us = 300.0;
        esim.hot_pixel_fraction = 0.05;
        esim.hot_pixel_rate_hz = 400.0;
        let mut full = SensorParams::ideal(40, 30);
        full.theta_sigma = 0.03;
        full.theta_noise = 0.02;
        full.refractory_us = 200.0;
        full.cutoff_hz = 800.0;
        full.cutoff_half_photocurrent = 0.2;
        full.latency_us = 30.0;
        full.jitter_us = 10.0;
        full.leak_rate_hz = 5.0;
        full.leak_spread_decades = 0.3;
        full.shot_rate_hz = 30.0;
        full.hot_pixel_fraction = 0.01;
        full.hot_pixel_rate_hz = 300.0;
        for params in [SensorParams::ideal(40, 30), esim, full] {
            let skipping = run(&params, false);
            let stepping = run(&params, true);
            assert!(stepping.iter().map(|c| c.len()).sum::<usize>() > 100);
            assert_eq!(skipping, stepping, "{params:?}");
        }
    }

    #[test]
    fn a_static_noiseless_scene_gives_no_event() {
        let mut sensor = EventSensor::new(SensorParams::ideal(40, 30)).unwrap();
        let frame = frames(40, 30, 1).remove(0);
        for k in 0..20 {
            assert!(sensor.feed(&frame, k * 1000).unwrap().is_empty());
        }
    }

    #[test]
    fn bad_frames_are_refused_without_changing_the_sensor() {
        let mut sensor = EventSensor::new(SensorParams::ideal(4, 2)).unwrap();
        sensor.feed(&[0.5; 8], 0).unwrap();
        let mut bad = [0.5f32; 8];
        bad[5] = f32::NAN;
        assert!(matches!(
            sensor.feed(&bad, 10),
            Err(FeedError::NotFinite { x: 1, y: 1, .. })
        ));
        bad[5] = -1.0;
        assert!(matches!(
            sensor.feed(&bad, 10),
            Err(FeedError::Negative { x: 1, y: 1, .. })
        ));
        assert!(matches!(
            sensor.feed(&[0.5; 7], 10),
            Err(FeedError::Shape {
                expected: 8,
                got: 7
            })
        ));
        assert!(matches!(
            sensor.feed(&[0.5; 8], 0),
            Err(FeedError::Time {
                t_us: 0,
                t_prev_us: 0
            })
        ));
        assert_eq!(sensor.last_time_us(), Some(0));
        // Unchanged: the next good frame gives what a sensor that never saw the bad ones gives.
        let mut fresh = EventSensor::new(SensorParams::ideal(4, 2)).unwrap();
        fresh.feed(&[0.5; 8], 0).unwrap();
        assert_eq!(
            sensor.feed(&[0.9; 8], 10).unwrap(),
            fresh.feed(&[0.9; 8], 10).unwrap()
        );
    }
}
