//! The streaming event sensor: per-pixel state over a whole array, fed photocurrent frames.
//!
//! Each call to `feed` simulates every pixel over (t_prev, t], tile by tile, in parallel when
//! the frame is large or busy enough to pay for it. A pixel whose input is inside its quiet band
//! and that has nothing due before t is skipped without touching its state, so a mostly static
//! scene costs little more than reading the frame.
//!
//! The parts, a file each: a frame's passes through the tiles (`front`), run on the thread pool or
//! here (`parallel`); the noise a gap between frames would give (`noise_gap`); the errors
//! (`feed_error`). Here: the sensor, its public API and the checks of a call's arguments.

mod feed_error;
mod front;
mod noise_gap;
mod parallel;
#[cfg(test)]
mod tests;

use crate::events::{EventColumns, EventQueue, OutOfMemory};
use crate::fuse::MAX_EVENTS_PER_FEED;
use crate::params::{ParamError, SensorParams};
use crate::pixel::PixelModel;
use crate::readout::{Readout, ReadoutCounts};
use crate::tile::Tile;
pub use feed_error::{FeedError, Overflow};
pub use noise_gap::{NoiseRates, NoiseWork};
use parallel::{PARALLEL_MIN_BUSY, PARALLEL_MIN_NOISE_EVENTS, PARALLEL_MIN_PIXELS};

/// Times are turned into f64 seconds since the first frame, exact up to 2^53 us (285 years).
pub const MAX_ABS_TIME_US: i64 = 1 << 53;

/// A DVS sensor with state: feed it frames in time order, collect events.
pub struct EventSensor {
    model: PixelModel,
    tiles: Vec<Tile>,
    origin_us: Option<i64>,
    t_prev_us: i64,
    /// Events held back by latency, and the ordering of each frame's events.
    queue: EventQueue,
    /// Pixels stepped in the last frame (after the start, those whose first wake-ups the next
    /// scan works out): the hint for running the next one in parallel.
    busy_last_frame: usize,
    /// Noise the parameters give per second, to bound and plan each call's work.
    noise: NoiseRates,
    /// Step every pixel every frame (tests check that skipping quiet pixels changes nothing).
    never_skip: bool,
    /// Most events one call may give (lowered by tests), and what stopped a call mid-way.
    max_events: usize,
    stopped: Option<String>,
    /// How the events leave the chip (None: every readout stage off), and the readout delay of
    /// each event the last call gave.
    readout: Option<Readout>,
    delays_us: Vec<i64>,
}

impl EventSensor {
    pub fn new(params: SensorParams) -> Result<Self, ParamError> {
        params.validate()?;
        Ok(Self {
            readout: Readout::new(&params.readout),
            delays_us: Vec::new(),
            noise: NoiseRates::of(&params),
            model: PixelModel::new(params),
            tiles: Vec::new(),
            origin_us: None,
            t_prev_us: 0,
            queue: EventQueue::new(true),
            busy_last_frame: 0,
            never_skip: false,
            max_events: MAX_EVENTS_PER_FEED,
            stopped: None,
        })
    }

    /// With or without the label column (on by default); leaving it out saves its filling.
    pub fn with_labels(mut self, labels: bool) -> Self {
        self.queue = EventQueue::new(labels);
        self.readout = self.readout.map(|readout| readout.with_labels(labels));
        self
    }

    pub fn params(&self) -> &SensorParams {
        &self.model.params
    }

    fn pixel_count(&self) -> usize {
        self.model.params.width * self.model.params.height
    }

    /// Forget everything: the next frame initialises the pixels again (also after a call that
    /// stopped mid-way).
    pub fn reset(&mut self) {
        self.tiles = Vec::new();
        self.origin_us = None;
        self.queue.clear();
        self.busy_last_frame = 0;
        self.stopped = None;
        self.delays_us.clear();
        if let Some(readout) = &mut self.readout {
            readout.reset();
        }
    }

    /// What became of the events that went through the readout since the start (or `reset`);
    /// None when its stages are all off.
    pub fn readout_counts(&self) -> Option<ReadoutCounts> {
        self.readout.as_ref().map(Readout::counts)
    }

    /// The readout delay (us) of each event the last `feed` or `flush` gave, in order; empty
    /// when the readout is off (every delay 0).
    pub fn delays_us(&self) -> &[i64] {
        &self.delays_us
    }

    /// A call's events from the pixels through the readout, where it is on; `t_us`: the time up
    /// to which the stream is complete (None: it ended).
    fn read_out(&mut self, events: EventColumns, t_us: Option<i64>) -> EventColumns {
        let Some(readout) = &mut self.readout else {
            return events;
        };
        let batch = match t_us {
            Some(t_us) => readout.push(&events, t_us),
            None => readout.finish(&events),
        };
        self.delays_us = batch.delay_us;
        batch.events
    }

    /// Refuse any call once one has stopped mid-way.
    fn check_running(&self) -> Result<(), FeedError> {
        match &self.stopped {
            Some(cause) => Err(FeedError::Stopped {
                cause: cause.clone(),
            }),
            None => Ok(()),
        }
    }

    /// Time of the last frame fed, if any.
    pub fn last_time_us(&self) -> Option<i64> {
        self.origin_us.map(|_| self.t_prev_us)
    }

    /// Take a frame of linear photocurrent (row-major, height x width) at `t_us`; return the
    /// events with times in (t_prev, t_us], sorted by (t, y, x). The first frame only initialises.
    /// A call whose events would pass the limit stops mid-way (`TooManyEvents`), and the sensor
    /// then refuses every call until `reset`.
    pub fn feed(&mut self, frame: &[f32], t_us: i64) -> Result<EventColumns, FeedError> {
        self.check_running()?;
        self.check_shape(frame)?;
        let noise_events = self.check_time(t_us)?;
        let parallel = rayon::current_num_threads() > 1
            && (frame.len() >= PARALLEL_MIN_PIXELS
                || self.busy_last_frame >= PARALLEL_MIN_BUSY
                || noise_events >= PARALLEL_MIN_NOISE_EVENTS);
        let events = if parallel {
            // At most one hop into the thread pool per frame (none from a pool thread): the
            // parallel loops inside then start without waking and blocking the caller each time.
            rayon::scope(|_| self.feed_here(frame, t_us, true))
        } else {
            self.feed_here(frame, t_us, false)
        }?;
        Ok(self.read_out(events, Some(t_us)))
    }

    /// A call stopped mid-way: the sensor refuses every call until `reset`.
    fn stop(&mut self, t_us: i64, events: usize, out_of_memory: bool) -> FeedError {
        let overflow = Overflow {
            t_us,
            t_prev_us: self.t_prev_us,
            events,
            limit: self.max_events,
            out_of_memory,
        };
        self.stopped = Some(overflow.cause());
        FeedError::TooManyEvents(overflow)
    }

    /// Everything still held back by latency, in order (at most the limit of one call: feed
    /// counts them on its fuse).
    pub fn flush(&mut self) -> Result<EventColumns, FeedError> {
        self.check_running()?;
        match self.queue.push_and_take(std::iter::empty(), i64::MAX) {
            Ok(events) => Ok(self.read_out(events, None)),
            Err(OutOfMemory { events }) => Err(self.stop(self.t_prev_us, events, true)),
        }
    }

    /// Refuse a time out of range or order, or a gap whose noise is more than one call may give;
    /// return the noise events expected over the gap.
    fn check_time(&self, t_us: i64) -> Result<f64, FeedError> {
        if !(-MAX_ABS_TIME_US..=MAX_ABS_TIME_US).contains(&t_us) {
            return Err(FeedError::TimeRange { t_us });
        }
        if self.origin_us.is_none() {
            return Ok(0.0);
        }
        let t_prev_us = self.t_prev_us;
        if t_us <= t_prev_us {
            return Err(FeedError::Time { t_us, t_prev_us });
        }
        let expected_events = self.noise.expected_events(t_us - t_prev_us);
        if expected_events > self.max_events as f64 {
            return Err(FeedError::TooMuchNoise(NoiseWork {
                t_us,
                t_prev_us,
                expected_events,
                rates: self.noise,
            }));
        }
        Ok(expected_events)
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
}
