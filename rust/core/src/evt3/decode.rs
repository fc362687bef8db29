//! EVT 3.0 decoding, word by word with the state the specification describes, across chunks.

use super::{check_size, word, Evt3Error, TIME_WRAP_US};
use crate::EventColumns;

/// A TIME_HIGH that goes down by at least half its 12-bit range is the 24-bit time wrapping (as
/// OpenEB counts it); one that goes down by less is data out of order, an error.
const WRAP_MIN_DROP: u16 = 1 << 11;

/// Streaming EVT3 decoder: feed it the data after the header in chunks of any size; it keeps
/// its state (time, row, vector base, an odd byte) from one chunk to the next.
///
/// Words before the first TIME_HIGH have no time, and events before the first ADDR_Y (or
/// vectors before the first VECT_BASE_X) no address: they are skipped, as OpenEB skips them.
/// EXT_TRIGGER, OTHERS, CONTINUED and IMU words carry no change-detection event and are skipped.
/// Errors: a reserved word type, an address outside the sensor, a TIME_HIGH that goes back.
#[derive(Clone, Debug)]
pub struct Evt3Decoder {
    width: u16,
    height: u16,
    /// Byte offset of the next word (of `pending` when there is one).
    position: u64,
    pending: Option<u8>,
    /// Time: TIME_HIGH wraps since the first TIME_HIGH, the high and low parts, and the time
    /// they make (kept up to date, as events read it far more often than it changes).
    has_time: bool,
    wraps: i64,
    high: u16,
    low: u16,
    t_us: i64,
    /// Row, once an EVT_ADDR_Y came.
    y: Option<u16>,
    /// Column of the next vector bit and its polarity; u32 since it advances past 2047.
    base_x: Option<u32>,
    base_p: i8,
}

/// The events one word carries (for batch bounds).
#[inline]
fn events_in(w: u16) -> usize {
    match w >> 12 {
        word::ADDR_X => 1,
        word::VECT_12 => (w & 0xFFF).count_ones() as usize,
        word::VECT_8 => (w & 0xFF).count_ones() as usize,
        _ => 0,
    }
}

impl Evt3Decoder {
    /// `offset`: the byte offset of the first data byte in the file, so that errors name file
    /// offsets.
    pub fn new(width: u16, height: u16, offset: u64) -> Result<Self, String> {
        check_size(width, height)?;
        Ok(Self {
            width,
            height,
            position: offset,
            pending: None,
            has_time: false,
            wraps: 0,
            high: 0,
            low: 0,
            t_us: 0,
            y: None,
            base_x: None,
            base_p: 0,
        })
    }

    /// Decodes the next bytes of the stream, stopping before the word that would take the batch
    /// past `max_events` (a batch holds at least one word's events, at most 12, even when
    /// `max_events` is smaller). Returns the events and how many bytes of `bytes` were used;
    /// the caller passes the rest again. An odd byte at the end is kept for the next call.
    pub fn decode(
        &mut self,
        bytes: &[u8],
        max_events: usize,
    ) -> Result<(EventColumns, usize), Evt3Error> {
        let mut out = EventColumns::default();
        let expected = (bytes.len() / 2).min(max_events);
        out.t_us.reserve(expected);
        out.x.reserve(expected);
        out.y.reserve(expected);
        out.p.reserve(expected);
        let mut used = 0;
        if let Some(low_byte) = self.pending {
            let Some(&high_byte) = bytes.first() else {
                return Ok((out, 0));
            };
            self.pending = None;
            self.word(u16::from_le_bytes([low_byte, high_byte]), &mut out)?;
            self.position += 2;
            used = 1;
        }
        for pair in bytes[used..].chunks_exact(2) {
            let w = u16::from_le_bytes([pair[0], pair[1]]);
            // (The exact count only near the bound: at most 12 events a word.)
            if out.len() + 12 > max_events
                && out.len() + events_in(w) > max_events
                && !out.is_empty()
            {
                return Ok((out, used));
            }
            self.word(w, &mut out)?;
            self.position += 2;
            used += 2;
        }
        if used + 1 == bytes.len() {
            self.pending = Some(bytes[used]);
            used += 1;
        }
        Ok((out, used))
    }

    /// After the last chunk: an odd byte left over is a word cut short.
    pub fn finish(&self) -> Result<(), Evt3Error> {
        match self.pending {
            Some(_) => Err(self.error(
                "truncated EVT3 data: 1 byte of an incomplete 2-byte word at the end".into(),
            )),
            None => Ok(()),
        }
    }

    #[cold]
    fn error(&self, problem: String) -> Evt3Error {
        Evt3Error {
            offset: self.position,
            problem,
        }
    }

    #[cold]
    fn outside(&self, what: &str, address: u32) -> Evt3Error {
        self.error(format!(
            "{what} {address} outside the {} x {} sensor",
            self.width, self.height
        ))
    }

    /// One word at `position`: update the state or emit its events.
    #[inline(always)]
    fn word(&mut self, w: u16, out: &mut EventColumns) -> Result<(), Evt3Error> {
        let content = w & 0xFFF;
        match w >> 12 {
            word::ADDR_Y => {
                let y = content & 0x7FF;
                if y >= self.height {
                    return Err(self.outside("EVT_ADDR_Y row", y.into()));
                }
                self.y = Some(y);
            }
            word::ADDR_X => {
                let x = content & 0x7FF;
                if x >= self.width {
                    return Err(self.outside("EVT_ADDR_X column", x.into()));
                }
                if let (true, Some(y)) = (self.has_time, self.y) {
                    push(out, self.t_us, x, y, (content >> 11) as i8);
                }
            }
            word::VECT_BASE_X => {
                self.base_x = Some(u32::from(content & 0x7FF));
                self.base_p = (content >> 11) as i8;
            }
            word::VECT_12 => self.vector(u32::from(content), 12, out)?,
            word::VECT_8 => self.vector(u32::from(content & 0xFF), 8, out)?,
            word::TIME_LOW => {
                self.low = content;
                self.t_us = self.time();
            }
            word::TIME_HIGH => self.time_high(content)?,
            word::CONTINUED_4
            | word::EXT_TRIGGER
            | word::IMU
            | word::OTHERS
            | word::CONTINUED_12 => {}
            reserved => {
                return Err(self.error(format!(
                    "reserved EVT3 word type {reserved:#X} (word {w:#06X}): not EVT3 data"
                )))
            }
        }
        Ok(())
    }

    fn time(&self) -> i64 {
        self.wraps * TIME_WRAP_US + (i64::from(self.high) << 12 | i64::from(self.low))
    }

    /// VECT_12 / VECT_8: an event at base + k for each set bit k, then base += bits.
    #[inline(always)]
    fn vector(&mut self, mask: u32, bits: u32, out: &mut EventColumns) -> Result<(), Evt3Error> {
        let Some(base) = self.base_x else {
            return Ok(());
        };
        if mask != 0 {
            let top = base + (31 - mask.leading_zeros());
            if top >= u32::from(self.width) {
                return Err(self.outside("vector event at column", top));
            }
            if let (true, Some(y)) = (self.has_time, self.y) {
                let mut rest = mask;
                while rest != 0 {
                    let k = rest.trailing_zeros();
                    rest &= rest - 1;
                    push(out, self.t_us, (base + k) as u16, y, self.base_p);
                }
            }
        }
        self.base_x = Some(base + bits);
        Ok(())
    }

    /// TIME_HIGH: a new high part; going down by half the range or more is a wrap of the 24-bit
    /// time (+2^24 µs); TIME_LOW restarts at 0 with a new high part (OpenEB does the same).
    /// Words before the first TIME_HIGH have no time.
    fn time_high(&mut self, high: u16) -> Result<(), Evt3Error> {
        if self.has_time && high < self.high {
            if self.high - high < WRAP_MIN_DROP {
                return Err(self.error(format!(
                    "EVT_TIME_HIGH goes back from {} to {high} (time out of order)",
                    self.high
                )));
            }
            self.wraps += 1;
        }
        if !self.has_time || high != self.high {
            self.low = 0;
        }
        self.has_time = true;
        self.high = high;
        self.t_us = self.time();
        Ok(())
    }
}

#[inline(always)]
fn push(out: &mut EventColumns, t_us: i64, x: u16, y: u16, p: i8) {
    out.t_us.push(t_us);
    out.x.push(x);
    out.y.push(y);
    out.p.push(p);
}
