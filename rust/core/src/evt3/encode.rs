//! EVT 3.0 encoding as a camera writes it: every TIME_HIGH step, TIME_LOW and EVT_ADDR_Y when
//! they change, neighbouring events of a row as VECT_BASE_X + VECT_12 + VECT_12 + VECT_8 (the
//! 32-column pattern IMX636 sensors emit and OpenEB decodes), other events as EVT_ADDR_X.

use super::{check_size, word, TIME_HIGH_STEP_US};

/// Times are refused from 2^36 µs (19.1 hours) on: the clock starts at 0 and every TIME_HIGH
/// step up to the last event is written (2 bytes per 4096 µs), so this bounds that part of a
/// file to 32 MiB and the work to a fraction of a second.
pub const MAX_T_US: i64 = 1 << 36;

/// Columns one vector pattern covers (12 + 12 + 8).
const VECTOR_SPAN: u16 = 32;
/// A vector pattern costs 4 words (with its VECT_BASE_X): worth it from 5 events on.
const VECTOR_MIN_EVENTS: usize = 5;

/// Streaming EVT3 encoder: takes events sorted by t, batch after batch, and returns the words
/// as little-endian bytes. The clock starts at 0 µs, as a camera's does: the first batch
/// begins with TIME_HIGH 0 and every step up to its first event, so that a decoder that counts
/// TIME_HIGH wraps from the start of the file reads absolute times.
#[derive(Clone, Debug)]
pub struct Evt3Encoder {
    width: u16,
    height: u16,
    /// t >> 12 of the last TIME_HIGH written (not wrapped), and the last TIME_LOW and row.
    high_steps: Option<i64>,
    low: Option<u16>,
    y: Option<u16>,
    last_t_us: i64,
}

impl Evt3Encoder {
    pub fn new(width: u16, height: u16) -> Result<Self, String> {
        check_size(width, height)?;
        Ok(Self {
            width,
            height,
            high_steps: None,
            low: None,
            y: None,
            last_t_us: 0,
        })
    }

    /// Encodes one batch (columns of equal length; p is 1 for ON, 0 for OFF). An event that the
    /// format cannot hold (time before the last one or outside 0 .. 2^36 µs, address outside
    /// the sensor) is refused with its index in the batch and nothing of the batch is kept.
    pub fn encode(
        &mut self,
        t_us: &[i64],
        x: &[u16],
        y: &[u16],
        p: &[i8],
    ) -> Result<Vec<u8>, String> {
        let n = t_us.len();
        if x.len() != n || y.len() != n || p.len() != n {
            return Err(format!(
                "columns of unequal lengths: t {n}, x {}, y {}, p {}",
                x.len(),
                y.len(),
                p.len()
            ));
        }
        self.check(t_us, x, y)?;
        let mut words = Words(Vec::with_capacity(6 * n + 32));
        let mut i = 0;
        while i < n {
            self.set_time(t_us[i], &mut words);
            if self.y != Some(y[i]) {
                words.push(word::ADDR_Y << 12 | y[i]);
                self.y = Some(y[i]);
            }
            i += self.events(&t_us[i..], &x[i..], &y[i..], &p[i..], &mut words);
        }
        Ok(words.0)
    }

    fn check(&self, t_us: &[i64], x: &[u16], y: &[u16]) -> Result<(), String> {
        let mut last = self.last_t_us;
        for (i, &t) in t_us.iter().enumerate() {
            if !(0..MAX_T_US).contains(&t) {
                return Err(format!(
                    "event {i}: t = {t} µs outside what EVT3 holds here (0 <= t < 2^36 µs, \
                     19.1 hours: the file would carry a TIME_HIGH word every 4096 µs from 0); \
                     shift the times to start near 0"
                ));
            }
            if t < last {
                return Err(format!(
                    "event {i}: t = {t} µs after t = {last} µs (not sorted)"
                ));
            }
            last = t;
            if x[i] >= self.width || y[i] >= self.height {
                return Err(format!(
                    "event {i}: address ({}, {}) outside the {} x {} sensor",
                    x[i], y[i], self.width, self.height
                ));
            }
        }
        Ok(())
    }

    /// TIME_HIGH for every step from the last one written (from 0 at the start) up to `t_us`,
    /// then TIME_LOW if it changed (a decoder restarts TIME_LOW at 0 with each new TIME_HIGH).
    fn set_time(&mut self, t_us: i64, words: &mut Words) {
        let steps = t_us / TIME_HIGH_STEP_US;
        let first = self.high_steps.map_or(0, |written| written + 1);
        if first <= steps {
            for step in first..=steps {
                words.push(word::TIME_HIGH << 12 | (step & 0xFFF) as u16);
            }
            self.high_steps = Some(steps);
            self.low = None;
        }
        let low = (t_us % TIME_HIGH_STEP_US) as u16;
        if self.low != Some(low) {
            words.push(word::TIME_LOW << 12 | low);
            self.low = Some(low);
        }
        self.last_t_us = t_us;
    }

    /// Writes the first event, or a vector of it and the events after it on the same row, time
    /// and polarity within 32 columns in increasing x (the order a decoder gives them back).
    /// Returns how many events it wrote.
    fn events(&self, t: &[i64], x: &[u16], y: &[u16], p: &[i8], words: &mut Words) -> usize {
        let polarity = u16::from(p[0] > 0);
        if self.width >= VECTOR_SPAN {
            // Base as far left as the first event, but the pattern must end inside the sensor.
            let base = x[0].min(self.width - VECTOR_SPAN);
            let mut mask: u32 = 1 << (x[0] - base);
            let mut run = 1;
            while run < t.len()
                && t[run] == t[0]
                && y[run] == y[0]
                && (p[run] > 0) == (p[0] > 0)
                && x[run] > x[run - 1]
                && x[run] < base + VECTOR_SPAN
            {
                mask |= 1 << (x[run] - base);
                run += 1;
            }
            if run >= VECTOR_MIN_EVENTS {
                words.push(word::VECT_BASE_X << 12 | polarity << 11 | base);
                words.push(word::VECT_12 << 12 | (mask & 0xFFF) as u16);
                words.push(word::VECT_12 << 12 | (mask >> 12 & 0xFFF) as u16);
                words.push(word::VECT_8 << 12 | (mask >> 24) as u16);
                return run;
            }
        }
        words.push(word::ADDR_X << 12 | polarity << 11 | x[0]);
        1
    }
}

/// The output: words as little-endian bytes, appended as they are made.
struct Words(Vec<u8>);

impl Words {
    #[inline(always)]
    fn push(&mut self, w: u16) {
        self.0.extend_from_slice(&w.to_le_bytes());
    }
}
