//! The streaming event sensor: per-pixel state over a whole array, fed photocurrent frames.
//!
//! Each call to `feed` simulates every pixel over (t_prev, t], tile by tile, in parallel when
//! the frame is large or busy enough to pay for it. A pixel whose input is inside its quiet band
//! and that has nothing due before t is skipped without touching its state, so a mostly static
//! scene costs little more than reading the frame.

use std::fmt;

use rayon::prelude::*;

use crate::events::{EventColumns, EventQueue};
use crate::params::{ParamError, SensorParams};
use crate::pixel::PixelModel;
use crate::tile::{round_up_f32, valid_value, Clock, Tile, TILE};

/// Below this many pixels a frame's scan (about 0.25 ns a pixel) is faster on the calling thread
/// than with the hop into the thread pool and back (about 15 us on a desktop or a small VM)...
const PARALLEL_MIN_PIXELS: usize = 1 << 18;
/// ... unless this many pixels had to be stepped in the last frame (about 0.1 us each).
const PARALLEL_MIN_BUSY: usize = 256;

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

/// A DVS sensor with state: feed it frames in time order, collect events.
pub struct EventSensor {
    model: PixelModel,
    tiles: Vec<Tile>,
    origin_us: Option<i64>,
    t_prev_us: i64,
    /// Events held back by latency, and the ordering of each frame's events.
    queue: EventQueue,
    /// Pixels stepped in the last frame: the hint for running the next one in parallel.
    busy_last_frame: usize,
    /// Step every pixel every frame (tests check that skipping quiet pixels changes nothing).
    never_skip: bool,
}

impl EventSensor {
    pub fn new(params: SensorParams) -> Result<Self, ParamError> {
        params.validate()?;
        Ok(Self {
            model: PixelModel::new(params),
            tiles: Vec::new(),
            origin_us: None,
            t_prev_us: 0,
            queue: EventQueue::new(true),
            busy_last_frame: 0,
            never_skip: false,
        })
    }

    /// With or without the label column (on by default); leaving it out saves its filling.
    pub fn with_labels(mut self, labels: bool) -> Self {
        self.queue = EventQueue::new(labels);
        self
    }

    pub fn params(&self) -> &SensorParams {
        &self.model.params
    }

    fn pixel_count(&self) -> usize {
        self.model.params.width * self.model.params.height
    }

    /// Forget everything: the next frame initialises the pixels again.
    pub fn reset(&mut self) {
        self.tiles = Vec::new();
        self.origin_us = None;
        self.queue.clear();
        self.busy_last_frame = 0;
    }

    /// Time of the last frame fed, if any.
    pub fn last_time_us(&self) -> Option<i64> {
        self.origin_us.map(|_| self.t_prev_us)
    }

    /// Take a frame of linear photocurrent (row-major, height x width) at `t_us`; return the
    /// events with times in (t_prev, t_us], sorted by (t, y, x). The first frame only initialises.
    pub fn feed(&mut self, frame: &[f32], t_us: i64) -> Result<EventColumns, FeedError> {
        self.check_shape(frame)?;
        if self.origin_us.is_some() && t_us <= self.t_prev_us {
            return Err(FeedError::Time {
                t_us,
                t_prev_us: self.t_prev_us,
            });
        }
        let parallel = rayon::current_num_threads() > 1
            && (frame.len() >= PARALLEL_MIN_PIXELS || self.busy_last_frame >= PARALLEL_MIN_BUSY);
        if parallel {
            // At most one hop into the thread pool per frame (none from a pool thread): the
            // parallel loops inside then start without waking and blocking the caller each time.
            rayon::scope(|_| self.feed_here(frame, t_us, true))
        } else {
            self.feed_here(frame, t_us, false)
        }
    }

    fn feed_here(
        &mut self,
        frame: &[f32],
        t_us: i64,
        parallel: bool,
    ) -> Result<EventColumns, FeedError> {
        let Some(origin_us) = self.origin_us else {
            if !frame
                .par_chunks(TILE)
                .all(|c| c.iter().all(|&v| valid_value(v)))
            {
                return Err(self.locate_bad_value(frame));
            }
            self.start(frame, t_us);
            return Ok(EventColumns::default());
        };
        let t0_s = (self.t_prev_us - origin_us) as f64 * 1e-6;
        let t1_s = (t_us - origin_us) as f64 * 1e-6;
        // Validation and the choice of pixels to step share one read of the frame; nothing is
        // changed before the whole frame is known to be valid.
        let t1_up = if self.never_skip {
            f32::INFINITY
        } else {
            round_up_f32(t1_s)
        };
        let all_valid = for_each_tile(&mut self.tiles, frame, parallel, |tile, values| {
            tile.scan(values, t1_up)
        });
        if !all_valid {
            return Err(self.locate_bad_value(frame));
        }
        self.busy_last_frame = self.tiles.iter().map(Tile::busy_count).sum();
        let clock = Clock {
            origin_us,
            floor_us: self.t_prev_us + 1,
            width: self.model.params.width,
        };
        let model = &self.model;
        for_each_tile(&mut self.tiles, frame, parallel, |tile, values| {
            tile.step(model, values, t0_s, t1_s, &clock);
            true
        });
        self.t_prev_us = t_us;
        let frame_events = self.tiles.iter().map(|tile| &tile.events);
        Ok(self.queue.push_and_take(frame_events, t_us))
    }

    /// Everything still held back by latency, in order.
    pub fn flush(&mut self) -> EventColumns {
        self.queue.push_and_take(std::iter::empty(), i64::MAX)
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

    fn start(&mut self, frame: &[f32], t_us: i64) {
        let model = &self.model;
        self.tiles = frame
            .par_chunks(TILE)
            .enumerate()
            .map(|(i, values)| Tile::start(model, i * TILE, values))
            .collect();
        self.origin_us = Some(t_us);
        self.t_prev_us = t_us;
        self.queue.clear();
    }
}

/// Run `work` on every tile with its part of the frame, on the thread pool or here; returns
/// whether it returned true for all.
fn for_each_tile(
    tiles: &mut [Tile],
    frame: &[f32],
    parallel: bool,
    work: impl Fn(&mut Tile, &[f32]) -> bool + Sync + Send,
) -> bool {
    if parallel {
        tiles
            .par_iter_mut()
            .zip(frame.par_chunks(TILE))
            .map(|(tile, values)| work(tile, values))
            .reduce(|| true, |a, b| a & b)
    } else {
        tiles
            .iter_mut()
            .zip(frame.chunks(TILE))
            .fold(true, |ok, (tile, values)| ok & work(tile, values))
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
        full.leak_light_rate_hz = 20.0; // leak that follows the light, at a stated light level
        full.white_lux = 3000.0;
        full.shot_rate_hz = 30.0;
        full.hot_pixel_fraction = 0.01;
        full.hot_pixel_rate_hz = 300.0;
        // Time-invariant with a reset held for a refractory period: woken to release it.
        let mut held = SensorParams::ideal(40, 30);
        held.refractory_us = 1500.0;
        held.hot_pixel_fraction = 0.05;
        held.hot_pixel_rate_hz = 400.0;
        for params in [SensorParams::ideal(40, 30), esim, held, full] {
            let skipping = run(&params, false);
            let stepping = run(&params, true);
            assert!(stepping.iter().map(|c| c.len()).sum::<usize>() > 100);
            assert_eq!(skipping, stepping, "{params:?}");
        }
    }

    #[test]
    fn without_labels_the_same_events_come_without_their_label_column() {
        let mut params = SensorParams::ideal(40, 30);
        params.hot_pixel_fraction = 0.05;
        params.hot_pixel_rate_hz = 400.0;
        for latency_us in [0.0, 30.0] {
            params.latency_us = latency_us; // both ways through the queue
            let run = |labels: bool| {
                let mut sensor = EventSensor::new(params.clone())
                    .unwrap()
                    .with_labels(labels);
                let mut out = Vec::new();
                for (k, frame) in frames(40, 30, 12).iter().enumerate() {
                    out.push(sensor.feed(frame, 1000 * k as i64).unwrap());
                    if k == 5 {
                        sensor.reset(); // the choice survives a reset
                    }
                }
                out.push(sensor.flush());
                out
            };
            let (with, without) = (run(true), run(false));
            assert!(with.iter().map(|c| c.len()).sum::<usize>() > 100);
            for (a, b) in with.iter().zip(&without) {
                assert_eq!((&a.t_us, &a.x, &a.y, &a.p), (&b.t_us, &b.x, &b.y, &b.p));
                assert_eq!((a.label.len(), b.label.len()), (a.len(), 0));
            }
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
    fn only_pixels_that_change_or_wake_get_a_state() {
        let (width, height) = (40, 30);
        let mut params = SensorParams::ideal(width, height);
        params.cutoff_hz = 300.0;
        params.cutoff_half_photocurrent = 0.1;
        params.leak_rate_hz = 0.1;
        params.shot_rate_hz = 2.0;
        params.hot_pixel_fraction = 0.01;
        params.hot_pixel_rate_hz = 300.0;
        let mut sensor = EventSensor::new(params).unwrap();
        let states = |s: &EventSensor| s.tiles.iter().map(Tile::state_count).sum::<usize>();
        let static_frame = frames(width, height, 1).remove(0);
        for k in 0..20 {
            sensor.feed(&static_frame, k * 1000).unwrap();
        }
        // 12 hot pixels at 300 Hz wake within 20 ms; leak (0.1 Hz) and shot noise (at most
        // 2 Hz) wake about 1,200 x 2 Hz x 20 ms = 48 more at most.
        let woken = states(&sensor);
        assert!((1..=80).contains(&woken), "{woken} states");
        // The square moves by 2 pixels: its leading and trailing edges change.
        let moving = frames(width, height, 2).remove(1);
        let changed = static_frame
            .iter()
            .zip(&moving)
            .filter(|(a, b)| a != b)
            .count();
        sensor.feed(&moving, 20_000).unwrap();
        let after = states(&sensor);
        assert!(
            changed >= 40 && after >= changed && after <= woken + changed + 10,
            "{after}"
        );
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
