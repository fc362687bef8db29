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

/// What the per-frame loop reads first: the input band in which the pixel stays quiet, and a
/// lower bound on when it next needs attention anyway (seconds since the first frame).
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Gate {
    lo: f32,
    hi: f32,
    wake_s: f32,
}

/// A DVS sensor with state: feed it frames in time order, collect events.
pub struct EventSensor {
    model: PixelModel,
    time_invariant: bool,
    gates: Vec<Gate>,
    last_frame: Vec<f32>,
    pixels: Vec<PixelState>,
    origin_us: Option<i64>,
    t_prev_us: i64,
    /// Events whose (delayed) time is beyond the last frame, in output order.
    pending: Vec<Event>,
    /// Step every pixel every frame (tests check that skipping quiet pixels changes nothing).
    never_skip: bool,
}

impl EventSensor {
    pub fn new(params: SensorParams) -> Result<Self, ParamError> {
        params.validate()?;
        let model = PixelModel::new(params);
        Ok(Self {
            time_invariant: model.is_time_invariant(),
            model,
            gates: Vec::new(),
            last_frame: Vec::new(),
            pixels: Vec::new(),
            origin_us: None,
            t_prev_us: 0,
            pending: Vec::new(),
            never_skip: false,
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
        self.gates = Vec::new();
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
        self.check_frame(frame)?;
        let Some(origin_us) = self.origin_us else {
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
        let fresh = self.step_pixels(frame, t0_s, t1_s);
        let floor_us = self.t_prev_us + 1;
        let width = self.model.params.width;
        self.pending
            .extend(fresh.into_iter().flatten().map(|(pixel, e)| Event {
                t_us: (origin_us + (e.t_s * 1e6).round() as i64).max(floor_us),
                x: (pixel as usize % width) as u16,
                y: (pixel as usize / width) as u16,
                p: e.on as i8,
                label: e.cause as u8,
            }));
        self.t_prev_us = t_us;
        Ok(self.take_pending_until(t_us))
    }

    /// Everything still held back by latency, in order.
    pub fn flush(&mut self) -> EventColumns {
        self.take_pending_until(i64::MAX)
    }

    fn take_pending_until(&mut self, t_us: i64) -> EventColumns {
        // Stable: one pixel's events with equal times keep the order it emitted them in.
        if self.pending.len() > PARALLEL_SORT_MIN {
            self.pending.par_sort_by_key(Event::order_key);
        } else {
            self.pending.sort_by_key(Event::order_key);
        }
        let due = self.pending.partition_point(|e| e.t_us <= t_us);
        let out = EventColumns::from_events(&self.pending[..due]);
        self.pending.drain(..due);
        out
    }

    fn check_frame(&self, frame: &[f32]) -> Result<(), FeedError> {
        let expected = self.pixel_count();
        if frame.len() != expected {
            return Err(FeedError::Shape {
                expected,
                got: frame.len(),
            });
        }
        // A parallel scan first; the slow search for where the bad value is runs only on error.
        let bad = frame
            .par_chunks(CHUNK)
            .any(|c| c.iter().any(|v| !(v.is_finite() && *v >= 0.0)));
        if !bad {
            return Ok(());
        }
        let index = frame
            .iter()
            .position(|v| !(v.is_finite() && *v >= 0.0))
            .unwrap_or(0);
        let (x, y) = (
            index % self.model.params.width,
            index / self.model.params.width,
        );
        let value = frame[index];
        Err(if value.is_finite() {
            FeedError::Negative { x, y, value }
        } else {
            FeedError::NotFinite { x, y, value }
        })
    }

    fn start(&mut self, frame: &[f32], t_us: i64) {
        let model = &self.model;
        self.pixels = frame
            .par_iter()
            .enumerate()
            .map(|(i, &v)| model.init(i as u64, v as f64, 0.0))
            .collect();
        let ti = self.time_invariant;
        self.gates = self
            .pixels
            .par_iter()
            .zip(frame.par_iter())
            .map(|(st, &v)| gate(model, ti, st, v))
            .collect();
        self.last_frame = frame.to_vec();
        self.origin_us = Some(t_us);
        self.t_prev_us = t_us;
        self.pending.clear();
    }

    /// Run every pixel that needs it over (t0, t1]; events per chunk, in pixel order.
    fn step_pixels(&mut self, frame: &[f32], t0_s: f64, t1_s: f64) -> Vec<Vec<(u32, PixelEvent)>> {
        let model = &self.model;
        let ti = self.time_invariant;
        let t1_up = if self.never_skip {
            f32::INFINITY
        } else {
            round_up_f32(t1_s)
        };
        self.gates
            .par_chunks_mut(CHUNK)
            .zip(self.last_frame.par_chunks_mut(CHUNK))
            .zip(self.pixels.par_chunks_mut(CHUNK))
            .zip(frame.par_chunks(CHUNK))
            .enumerate()
            .map(|(chunk, (((gates, last), pixels), values))| {
                let mut out = Vec::new();
                let mut scratch = Vec::new();
                for j in 0..values.len() {
                    let value = values[j];
                    let g = gates[j];
                    if value >= g.lo && value <= g.hi && t1_up < g.wake_s {
                        if ti {
                            last[j] = value;
                        }
                        continue;
                    }
                    let pixel = (chunk * CHUNK + j) as u64;
                    let st = &mut pixels[j];
                    step_pixel(
                        model,
                        ti,
                        st,
                        pixel,
                        last[j],
                        value,
                        t0_s,
                        t1_s,
                        &mut scratch,
                    );
                    out.extend(scratch.drain(..).map(|e| (pixel as u32, e)));
                    last[j] = value;
                    gates[j] = gate(model, ti, st, value);
                }
                out
            })
            .collect()
    }
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
    let x0 = r.total_current(last_value as f64);
    let u0 = r.response(x0);
    if time_invariant {
        // Skipped frames moved the input inside the quiet band, which changes nothing else.
        st.u = u0;
        st.x = x0;
        st.v = u0;
    }
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

fn gate(model: &PixelModel, time_invariant: bool, st: &PixelState, value: f32) -> Gate {
    let (lo, hi) = if time_invariant {
        let (lo, hi) = model.quiet_band(st);
        (round_up_f32(lo), round_down_f32(hi))
    } else {
        (value, value)
    };
    Gate {
        lo,
        hi,
        wake_s: round_down_f32(model.wake_s(st)),
    }
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
