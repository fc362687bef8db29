//! Prophesee EVT 3.0, the 16-bit event encoding of Metavision RAW files
//! (docs.prophesee.ai/stable/data/encoding_formats/evt3.html): a streaming decoder and a
//! camera-style encoder. Byte chunks in, event columns out, and back; the `% ` text header is
//! the caller's.
//!
//! Each little-endian word carries its type in the top 4 bits and 12 bits of content. Time is
//! `TIME_HIGH:TIME_LOW` (12 bits each, 24 bits of microseconds); a camera writes a TIME_HIGH word
//! at every step of its high part, so a decoder counts the wraps of the 24-bit time (TIME_HIGH
//! going down) and reconstructs absolute time after any gap.

mod decode;
mod encode;
#[cfg(test)]
mod tests;

pub use decode::Evt3Decoder;
pub use encode::{Evt3Encoder, MAX_T_US};

/// Word types (the top 4 bits of a word), as the EVT 3.0 specification numbers them.
pub mod word {
    /// Row (bits 0..11) and system type (bit 11, master/slave camera).
    pub const ADDR_Y: u16 = 0x0;
    /// One event: column (bits 0..11) and polarity (bit 11).
    pub const ADDR_X: u16 = 0x2;
    /// First column (bits 0..11) and polarity (bit 11) of the vector words that follow.
    pub const VECT_BASE_X: u16 = 0x3;
    /// Events at base + k for each set bit k of 12; the base then advances by 12.
    pub const VECT_12: u16 = 0x4;
    /// Events at base + k for each set bit k of the low 8; the base then advances by 8.
    pub const VECT_8: u16 = 0x5;
    /// Low 12 bits of the time.
    pub const TIME_LOW: u16 = 0x6;
    /// Extra 4 bits of the word before (OTHERS payloads).
    pub const CONTINUED_4: u16 = 0x7;
    /// High 12 bits of the 24-bit time; steps every 4096 µs, wraps every 2^24 µs.
    pub const TIME_HIGH: u16 = 0x8;
    /// External trigger edge.
    pub const EXT_TRIGGER: u16 = 0xA;
    /// Inertial measurement (OpenEB's word table).
    pub const IMU: u16 = 0xD;
    /// Housekeeping (event-rate counters and the like), followed by CONTINUED words.
    pub const OTHERS: u16 = 0xE;
    /// Extra 12 bits of the word before (OTHERS payloads).
    pub const CONTINUED_12: u16 = 0xF;
}

/// Microseconds of one TIME_HIGH step (2^12) and of one wrap of the 24-bit time (2^24).
pub const TIME_HIGH_STEP_US: i64 = 1 << 12;
pub const TIME_WRAP_US: i64 = 1 << 24;
/// Addresses are 11 bits: sensors up to 2048 x 2048.
pub const MAX_SIZE: u16 = 2048;

/// Bad EVT3 data: the byte offset of the word at fault (counted from where the caller said the
/// data starts, usually after the header) and what is wrong with it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Evt3Error {
    pub offset: u64,
    pub problem: String,
}

impl std::fmt::Display for Evt3Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "at byte offset {}: {}", self.offset, self.problem)
    }
}

impl std::error::Error for Evt3Error {}

/// A sensor size the encoding can address (1 ..= 2048 each way), or why not.
pub fn check_size(width: u16, height: u16) -> Result<(), String> {
    if width == 0 || height == 0 || width > MAX_SIZE || height > MAX_SIZE {
        return Err(format!(
            "EVT3 addresses 1 to {MAX_SIZE} columns and rows; got {width} x {height}"
        ));
    }
    Ok(())
}
