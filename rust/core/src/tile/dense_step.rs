//! The listed pixels a block of 32 at a time: a block's quiet pixels stepped together
//! (`dense::step_quiet`, the same bits as one at a time); the others (an event, a reset to
//! release, ...) one at a time after the tile's blocks, in pixel order, so the events and states
//! are the one-pixel path's. Their threshold crossings are found 32 at a time first
//! (`dense::first_crossings`, the same bits as `Difference::first_reach`), from the differences
//! the quiet step worked out: where many pixels fire, a block holds a few, and a tile's fill the
//! vectors. Those that fire once and are then held in reset past the frame's end have the frame
//! finished there too (`dense::finish_single_events`), and are only written out in their turn.

use super::emit::{FuseCount, PixelEvents};
use super::prefetch::{prefetch_bytes, prefetch_bytes_to_l2};
use super::states::{lanes_from, DENSE_FIELDS, GATE_FIELDS};
use super::{Frame, Tile, WAKE_UNKNOWN_S};
use crate::block_flags::BLOCK;
use crate::dense::{self, Differences, EventLanes, Inputs, SingleEvent};
use crate::pixel::{FoundCrossings, PixelModel};
use crate::state_block::{bits_of, StateBlock, LANES};

impl Tile {
    /// The listed pixels a block at a time: the quiet ones of each block stepped together, then
    /// the others one at a time, in pixel order, with the crossings of those the quiet step
    /// worked out found together first (and single events finished together, written out in
    /// their turn). Returns false where the fuse stopped it.
    pub(super) fn step_dense(
        &mut self,
        model: &PixelModel,
        busy: &[u32],
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        let mut others = std::mem::take(&mut self.others);
        let mut outcomes = std::mem::take(&mut self.outcomes);
        let mut finished = std::mem::take(&mut self.finished);
        others.clear();
        outcomes.clear();
        finished.clear();
        // Single events are finished in the batch where the pixels' wake-ups are left unknown
        // (as `step_one_found` leaves them after a dense frame).
        let finishes = frame.wake_when_still && dense::finishes_events(model);
        let mut batch = CrossingBatch::new(finishes, frame);
        let mut landing = Landing {
            model,
            outcomes: &mut outcomes,
            finished: &mut finished,
        };
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
            if listed.len() >= DENSE_MIN_LISTED {
                self.step_block(b, mask, frame, &mut others, &mut landing, &mut batch);
            } else {
                others.extend_from_slice(listed);
                landing.outcomes.resize(others.len(), Outcome::Step(None));
            }
        }
        batch.solve(&mut landing);
        #[cfg(test)]
        {
            let found = |o: &&Outcome| !matches!(o, Outcome::Step(None));
            self.crossings_found += outcomes.iter().filter(found).count();
            self.events_finished += finished.len();
        }
        // Next frame, the quiet step leaves its differences where this one left many pixels.
        self.finds_crossings = others.len() * FIND_CROSSINGS_FRACTION >= busy.len();
        let went_on = self.step_listed(model, &others, &outcomes, &finished, frame, count);
        self.others = others;
        self.outcomes = outcomes;
        self.finished = finished;
        went_on
    }

    /// The quiet pixels of block `b`'s listed ones (bit k of `mask`: pixel k of the block)
    /// stepped together; the others added to `others` (their crossings, where the quiet step
    /// worked out their differences, to `batch`, which lands them in `landing` once solved).
    fn step_block(
        &mut self,
        b: usize,
        mask: u32,
        frame: &Frame,
        others: &mut Vec<u32>,
        landing: &mut Landing,
        batch: &mut CrossingBatch,
    ) {
        let model = landing.model;
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
        let slot = self.block_slot[b] as usize;
        let stepped = if changed == 0 {
            [false; LANES]
        } else {
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
                // Written in full by the step, read only after one: kept in the tile.
                &mut self.differences,
                self.finds_crossings,
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
        let mut left = mask & !stepped;
        let usable = if changed == 0 || !self.finds_crossings {
            0
        } else {
            bits_of(&self.differences.usable)
        };
        while left != 0 {
            let k = left.trailing_zeros() as usize;
            left &= left - 1;
            others.push((start + k) as u32);
            landing.outcomes.push(Outcome::Step(None));
            if (usable >> k) & 1 != 0 {
                let pixel = LanePixel {
                    k,
                    at: others.len() - 1,
                    value: value[k],
                };
                batch.add(&self.differences, &self.blocks[slot], pixel, landing);
            }
        }
    }

    /// The pixels `others` one at a time, in their order, each with its crossings where
    /// `outcomes` holds them, or its frame finished together written out; returns false where
    /// the fuse stopped it. Their states are asked for a few pixels ahead, as `step_sparse`
    /// does.
    fn step_listed(
        &mut self,
        model: &PixelModel,
        others: &[u32],
        outcomes: &[Outcome],
        finished: &[SingleEvent],
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        for (k, (&j, &outcome)) in others.iter().zip(outcomes).enumerate() {
            if let Some(&ahead) = others.get(k + LISTED_PREFETCH_AHEAD) {
                self.prefetch_state(ahead);
            }
            let went_on = match outcome {
                Outcome::Step(crossings) => {
                    self.step_one_found(model, j as usize, frame, count, crossings)
                }
                Outcome::Finished(i) => {
                    self.write_finished(model, j as usize, &finished[i as usize], frame, count)
                }
            };
            if !went_on {
                return false;
            }
        }
        true
    }

    /// Pixel `j`'s frame as the batch finished it: its event's random numbers drawn, its state
    /// and event written, as `step_one_found` writes a dense frame's (its wake-up left
    /// unknown); returns false where the fuse stops the tile.
    fn write_finished(
        &mut self,
        model: &PixelModel,
        j: usize,
        done: &SingleEvent,
        frame: &Frame,
        count: &mut FuseCount,
    ) -> bool {
        let (slot, k) = (self.block_slot[j / LANES] as usize, j % LANES);
        let pixel = self.first_pixel + j;
        let block = &mut self.blocks[slot];
        let event = done.write(model, pixel as u64, block, k);
        let gates = (block.hot_next_s[k], block.refractory_mark_s[k]);
        let mut out = PixelEvents::open(&mut self.events, frame.clock, pixel);
        out.push(event);
        out.close();
        self.note_gates(j / LANES, gates.0, gates.1);
        self.wake_s[j] = WAKE_UNKNOWN_S;
        #[cfg(test)]
        {
            self.wakes_left_unknown += 1;
        }
        self.report_if_due(frame.fuse, count)
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

/// What the dense step leaves for each pixel it did not step (`Tile::others`): a step one at a
/// time, with its crossings where they were found together; or its frame finished together
/// (`dense::finish_single_events`), `Tile::finished`'s entry.
#[derive(Clone, Copy, Debug)]
pub(super) enum Outcome {
    Step(Option<FoundCrossings>),
    Finished(u32),
}

/// Where a batch puts what it found: each pixel's outcome, and the frames it finished.
struct Landing<'a> {
    model: &'a PixelModel,
    outcomes: &'a mut Vec<Outcome>,
    finished: &'a mut Vec<SingleEvent>,
}

/// A pixel the batch takes: lane `k` of its block, its place `at` in `Tile::others`, and its
/// frame value.
struct LanePixel {
    k: usize,
    at: usize,
    value: f32,
}

/// Pixels whose crossings are yet to be found, from several blocks, `LANES` at a time: each
/// one's frame difference and thresholds, and where its outcome goes; where the batch finishes
/// single events too (`finishes`), each one's state and input.
struct CrossingBatch {
    differences: Differences,
    theta_on: [f64; LANES],
    theta_off: [f64; LANES],
    at: [usize; LANES],
    len: usize,
    finishes: bool,
    events: Box<EventLanes>,
    t0_s: f64,
    t1_s: f64,
}

impl CrossingBatch {
    fn new(finishes: bool, frame: &Frame) -> Self {
        Self {
            differences: Differences::new(),
            theta_on: [0.0; LANES],
            theta_off: [0.0; LANES],
            at: [0; LANES],
            len: 0,
            finishes,
            events: Box::default(),
            t0_s: frame.t0_s,
            t1_s: frame.t1_s,
        }
    }

    /// `pixel` (its difference in `from`, its state in `block`), whose outcome goes to
    /// `landing`; solved once the batch is full.
    #[inline(always)]
    fn add(
        &mut self,
        from: &Differences,
        block: &StateBlock,
        pixel: LanePixel,
        landing: &mut Landing,
    ) {
        let (i, k, to) = (self.len, pixel.k, &mut self.differences);
        (to.a[i], to.m[i], to.c[i]) = (from.a[k], from.m[k], from.c[k]);
        (to.tau[i], to.inv_tau[i], to.horizon_s[i]) =
            (from.tau[k], from.inv_tau[k], from.horizon_s[k]);
        (self.theta_on[i], self.theta_off[i]) = (block.theta_on[k], block.theta_off[k]);
        self.at[i] = pixel.at;
        if self.finishes {
            self.events.take(i, block, k, pixel.value);
        }
        self.len += 1;
        if self.len == LANES {
            self.solve(landing);
        }
    }

    /// The batch's crossings, and where it finishes them its single events, into `landing`
    /// (a step one at a time where they could not be followed), and the batch emptied.
    fn solve(&mut self, landing: &mut Landing) {
        if self.len == 0 {
            return;
        }
        let lanes = if self.len == LANES {
            u32::MAX
        } else {
            (1u32 << self.len) - 1
        };
        let crossings =
            dense::first_crossings(&self.differences, &self.theta_on, &self.theta_off, lanes);
        let done = if self.finishes {
            dense::finish_single_events(
                landing.model,
                &mut self.events,
                &self.differences,
                &crossings,
                self.t0_s,
                self.t1_s,
                crossings.found & lanes,
            )
        } else {
            0
        };
        for i in 0..self.len {
            let bit = |bits: u32| (bits >> i) & 1 != 0;
            landing.outcomes[self.at[i]] = if bit(done) {
                landing.finished.push(SingleEvent::of_lane(&self.events, i));
                Outcome::Finished((landing.finished.len() - 1) as u32)
            } else {
                Outcome::Step(bit(crossings.found).then(|| FoundCrossings {
                    on_s: bit(crossings.on).then_some(crossings.on_s[i]),
                    off_s: bit(crossings.off).then_some(crossings.off_s[i]),
                }))
            };
        }
        self.len = 0;
    }
}

/// A dense frame finds the crossings of the pixels its quiet step leaves together where the
/// last one left at least 1 in this many of the listed pixels: on the drifting sinusoid 15-50 %
/// are left, and finding them together takes 9-10 % off a frame; with film grain 0.8 %, where
/// the differences' stores alone would cost 7 %.
const FIND_CROSSINGS_FRACTION: usize = 16;

/// How many pixels ahead `step_listed` asks for a state.
const LISTED_PREFETCH_AHEAD: usize = 4;

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
