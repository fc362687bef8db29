//! The listed pixels a block of 32 at a time: a block's quiet pixels stepped together
//! (`dense::step_quiet`, the same bits as one at a time), the others one at a time after, in pixel
//! order, so the events and states are the one-pixel path's.

use super::emit::FuseCount;
use super::prefetch::{prefetch_bytes, prefetch_bytes_to_l2};
use super::states::{lanes_from, DENSE_FIELDS, GATE_FIELDS};
use super::{Frame, Tile, WAKE_UNKNOWN_S};
use crate::block_flags::BLOCK;
use crate::dense::{self, Inputs};
use crate::pixel::PixelModel;
use crate::state_block::{bits_of, LANES};

impl Tile {
    /// The listed pixels a block at a time: the quiet ones of a block stepped together, the
    /// others (an event, a reset to release, ...) one at a time after, in pixel order, so the
    /// events come in the same order. Returns false where the fuse stopped it.
    pub(super) fn step_dense(
        &mut self,
        model: &PixelModel,
        busy: &[u32],
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        let mut rest = busy;
        while let Some((b, listed, after)) = first_block(rest) {
            rest = after;
            let mask = if listed.len() == LANES {
                u32::MAX
            } else {
                listed
                    .iter()
                    .fold(0, |mask, &j| mask | 1 << (j as usize % LANES))
            };
            // The block after next (its fields the step reads): asked for now, it is in the
            // cache by then, where the hardware's prefetcher stops at each page.
            if let Some(&ahead) = after.get(DENSE_PREFETCH_AHEAD) {
                self.prefetch_block(ahead as usize / LANES, frame.t0_s);
            }
            if let Some(&next) = after.first() {
                self.prefetch_block_to_l1(next as usize / LANES);
            }
            let went_on = if listed.len() >= DENSE_MIN_LISTED {
                self.step_block(model, b, mask, frame, count)
            } else {
                listed
                    .iter()
                    .all(|&j| self.step_one(model, j as usize, frame, count))
            };
            if !went_on {
                return false;
            }
        }
        true
    }

    /// The listed pixels of block `b` (bit k of `mask`: pixel k of the block) through the
    /// dense path (see `step_dense`).
    fn step_block(
        &mut self,
        model: &PixelModel,
        b: usize,
        mask: u32,
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        let start = b * LANES;
        let value = lanes_from(frame.values, start);
        let last = lanes_from(&self.last, start);
        // The listed pixels whose input changed: the only ones the dense step may take (the
        // others are listed for a wake-up, and need a state only if it is due).
        let changed = mask & changed_bits(&value, &last);
        let without_state = changed & !self.made[b];
        if without_state != 0 {
            self.make_states(model, b, without_state);
        }
        let inputs = Inputs {
            value,
            last,
            listed: mask,
            // Once the block's new states are made: they may be hot.
            gates: self.reads_gates(b, frame.t0_s),
        };
        #[cfg(test)]
        let mut held = 0u32;
        let stepped = if changed == 0 {
            [false; LANES]
        } else {
            let slot = self.block_slot[b] as usize;
            #[cfg(test)]
            for (k, &mark_s) in self.blocks[slot].refractory_mark_s.iter().enumerate() {
                held |= ((mark_s > frame.t0_s) as u32) << k;
            }
            dense::step_quiet(
                model,
                &mut self.blocks[slot],
                &inputs,
                frame.t0_s,
                frame.t1_s,
            )
        };
        let end = (start + LANES).min(self.last.len());
        for (wake_s, &stepped) in self.wake_s[start..end].iter_mut().zip(&stepped) {
            *wake_s = if stepped { WAKE_UNKNOWN_S } else { *wake_s };
        }
        let stepped = bits_of(&stepped);
        #[cfg(test)]
        {
            self.dense_steps += stepped.count_ones() as usize;
            self.gated_blocks[inputs.gates as usize] += (stepped != 0) as usize;
            self.dense_held_steps += (stepped & held).count_ones() as usize;
        }
        // The others one at a time, in pixel order.
        let mut others = mask & !stepped;
        // Their whole states, all asked for at once: the fields the dense step did not read are
        // in no cache, and asked for one pixel at a time each pixel's misses would wait for the
        // last pixel's step.
        let mut ahead = others;
        while ahead != 0 {
            self.prefetch_state((start + ahead.trailing_zeros() as usize) as u32);
            ahead &= ahead - 1;
        }
        while others != 0 {
            let j = start + others.trailing_zeros() as usize;
            if !self.step_one(model, j, frame, count) {
                return false;
            }
            others &= others - 1;
        }
        true
    }

    /// Ask for the fields of block `b`'s states that the dense path reads in a frame from
    /// `t0_s`, into the second-level cache: its 40 or 48 lines a block would fill the first
    /// level's few outstanding-miss slots, and the loads waiting for them stall (a 1280 x 720
    /// sensor, whose states come from memory: 14 against 17-18 ns a pixel update,
    /// `dense --once davis346 30 0.01 1280x720`).
    #[inline(always)]
    fn prefetch_block(&self, b: usize, t0_s: f64) {
        if let Some(block) = self.blocks.get(self.block_slot[b] as usize) {
            let fields = if self.reads_gates(b, t0_s) {
                DENSE_FIELDS + GATE_FIELDS
            } else {
                DENSE_FIELDS
            };
            prefetch_bytes_to_l2(std::ptr::from_ref(block), fields * LANES * 8);
        }
    }

    /// Ask for the fields of block `b`'s states that the dense path always reads, from the
    /// second-level cache (`prefetch_block`) into the first, a block ahead: the step's loads
    /// otherwise wait on them (1280 x 720, every pixel changing: about 5 % of a frame).
    #[inline(always)]
    fn prefetch_block_to_l1(&self, b: usize) {
        if let Some(block) = self.blocks.get(self.block_slot[b] as usize) {
            prefetch_bytes(std::ptr::from_ref(block), DENSE_FIELDS * LANES * 8);
        }
    }
}

/// How many listed pixels ahead the dense path asks for a block's states (in a busy tile about
/// two blocks).
const DENSE_PREFETCH_AHEAD: usize = 2 * LANES;

/// A block with fewer listed pixels than this has them stepped one at a time.
const DENSE_MIN_LISTED: usize = 8;

/// Bit k set where `value[k]` differs from `last[k]`.
#[inline(always)]
fn changed_bits(value: &[f32; LANES], last: &[f32; LANES]) -> u32 {
    let mut bits = 0;
    for k in 0..LANES {
        bits |= ((value[k] != last[k]) as u32) << k;
    }
    bits
}

/// The block of the first listed pixel (`busy` is in pixel order), that block's listed pixels,
/// and the pixels after them; None for an empty list.
#[inline(always)]
pub(super) fn first_block(busy: &[u32]) -> Option<(usize, &[u32], &[u32])> {
    let block = *busy.first()? as usize / BLOCK;
    let next = ((block + 1) * BLOCK) as u32;
    // A block has at most BLOCK listed pixels: the search looks at those alone. Where every
    // pixel changes, the block's last pixel is the BLOCK-th listed (the list has no repeats):
    // the whole block, without the search.
    let in_block = if busy.get(BLOCK - 1) == Some(&(next - 1)) {
        BLOCK
    } else {
        busy[..busy.len().min(BLOCK)].partition_point(|&j| j < next)
    };
    let (listed, after) = busy.split_at(in_block);
    Some((block, listed, after))
}
