//! The pixels' states, made only when needed: pixel j gets one when its input first changes or it
//! first wakes, settled at time 0 s at its first-frame value; they are kept a block of 32
//! together, field by field, with the time until which each block's gates can matter.

use super::{Tile, NO_STATE};
use crate::pixel::PixelModel;
use crate::state_block::{StateBlock, LANES};

impl Tile {
    /// The first-frame values of the pixels without a state: `origin` where kept, else `last`
    /// (such a pixel has then had no change).
    pub(super) fn first_values(&self) -> &[f32] {
        if self.origin.is_empty() {
            &self.last
        } else {
            &self.origin
        }
    }

    /// Whether pixel `j` has a state.
    #[inline(always)]
    pub(super) fn has_state(&self, j: usize) -> bool {
        self.made[j / LANES] & (1 << (j % LANES)) != 0
    }

    /// Pixel `j`'s state, settled at time 0 s at its first-frame value (its block made first
    /// where it has none); returns where it is (block slot, lane).
    #[cold]
    fn make_state(&mut self, model: &PixelModel, j: usize) -> (usize, usize) {
        let (b, k) = (j / LANES, j % LANES);
        let slot = self.block_made(b);
        let pixel = (self.first_pixel + j) as u64;
        let state = model.init(pixel, self.first_values()[j] as f64, 0.0);
        self.blocks[slot].set(k, &state);
        self.note_gates(b, state.hot_next_s, state.refractory_mark_s);
        self.made[b] |= 1 << k;
        (slot, k)
    }

    /// A state of block `b` with these gates was made or stepped (see `block_gates_until_s`):
    /// kept only for the dense path.
    #[inline]
    pub(super) fn note_gates(&mut self, b: usize, hot_next_s: f64, refractory_mark_s: f64) {
        if !self.dense_path {
            return;
        }
        let until_s = if hot_next_s < f64::INFINITY {
            f64::INFINITY
        } else {
            refractory_mark_s
        };
        self.block_gates_until_s[b] = self.block_gates_until_s[b].max(until_s);
    }

    /// Whether the dense path must read the gates of block `b`'s states in a frame from `t0_s`
    /// (see `dense::Inputs::gates`).
    #[inline(always)]
    pub(super) fn reads_gates(&self, b: usize, t0_s: f64) -> bool {
        self.block_gates_until_s[b] > t0_s
    }

    /// `make_state` of the pixels of block `b` in `pixels` (bit k: pixel k; none has a state):
    /// where every pixel changes, the first changed frame makes every state, a block at once.
    pub(super) fn make_states(&mut self, model: &PixelModel, b: usize, pixels: u32) {
        if pixels.count_ones() < BLOCK_INIT_MIN_PIXELS {
            let mut rest = pixels;
            while rest != 0 {
                self.make_state(model, b * LANES + rest.trailing_zeros() as usize);
                rest &= rest - 1;
            }
            return;
        }
        let slot = self.block_made(b);
        let start = b * LANES;
        let first_values = lanes_from(self.first_values(), start);
        let first_pixel = (self.first_pixel + start) as u64;
        model.init_block(
            first_pixel,
            &first_values,
            0.0,
            pixels,
            &mut self.blocks[slot],
        );
        let mut rest = pixels;
        while rest != 0 {
            let k = rest.trailing_zeros() as usize;
            let block = &self.blocks[slot];
            self.note_gates(b, block.hot_next_s[k], block.refractory_mark_s[k]);
            rest &= rest - 1;
        }
        self.made[b] |= pixels;
    }

    /// Where block `b`'s states are (its slot), made empty first where it has none.
    fn block_made(&mut self, b: usize) -> usize {
        if self.block_slot[b] == NO_STATE {
            self.block_slot[b] = self.blocks.push(StateBlock::empty()) as u32;
        }
        self.block_slot[b] as usize
    }

    /// Where pixel `j`'s state is (block slot, lane), made now if it has none yet.
    #[inline]
    pub(super) fn state_slot(&mut self, model: &PixelModel, j: usize) -> (usize, usize) {
        if self.has_state(j) {
            (self.block_slot[j / LANES] as usize, j % LANES)
        } else {
            self.make_state(model, j)
        }
    }
}

/// Fewer pixels of a block than this get their first states one at a time (`init`), more all
/// at once (`init_block`, whose lanes cost about as many instructions as 12 pixels one at a
/// time: 6,800 a block on the AVX2 path, callgrind).
const BLOCK_INIT_MIN_PIXELS: u32 = 12;

/// The fields of a `StateBlock`; the first of them, which the dense path reads; and the two after
/// those, which it reads only where a block's gates can matter (`Tile::reads_gates`).
pub(super) const STATE_FIELDS: usize = 16;
pub(super) const DENSE_FIELDS: usize = 10;
pub(super) const GATE_FIELDS: usize = 2;

/// The block of `LANES` values from `start` (the last, shorter one padded with zeros).
#[inline(always)]
pub(super) fn lanes_from(values: &[f32], start: usize) -> [f32; LANES] {
    match values.get(start..start + LANES) {
        Some(whole) => whole.try_into().expect("a whole block"),
        None => {
            let mut padded = [0.0; LANES];
            padded[..values.len() - start].copy_from_slice(&values[start..]);
            padded
        }
    }
}
