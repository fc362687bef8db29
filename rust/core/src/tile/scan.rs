//! The first pass of a frame: validate every value and list the pixels to step. Pixel j is listed
//! iff its value changed (time-invariant models: left its quiet band [lo, hi]) or its wake-up
//! time is by t1; a value that is not a photocurrent refuses the frame, which then changes nothing
//! a refused frame could leave behind.

use super::prefetch::prefetch_bytes;
use super::{min_f32, Tile};
use crate::block_flags::{self, Avx2, BLOCK};
use crate::first_band;
use crate::pixel::PixelModel;

impl Tile {
    /// Pixels that need stepping to `t1_up` (rounded up), listed for `step`; returns whether
    /// every value is a usable photocurrent. Changes nothing else but the first bands of the
    /// blocks that changed (see the module's note).
    pub fn scan(&mut self, model: &PixelModel, values: &[f32], t1_up: f32) -> bool {
        // The scan is most of a static frame's cost, and 8-wide compares halve it: compiled
        // twice, the AVX2 copy is chosen at run time so the wheel still runs on any x86-64.
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = Avx2::detect() {
            // SAFETY: the CPU supports AVX2 (an `Avx2` says so).
            return unsafe { self.scan_avx2(model, values, t1_up, avx2) };
        }
        self.scan_portable(model, values, t1_up, None)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn scan_avx2(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        t1_up: f32,
        avx2: Avx2,
    ) -> bool {
        self.scan_portable(model, values, t1_up, Some(avx2))
    }

    #[inline(always)]
    fn scan_portable(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        t1_up: f32,
        avx2: Option<Avx2>,
    ) -> bool {
        self.busy.clear();
        self.due_by_s = t1_up;
        if self.first_wakes_due {
            self.set_first_wakes(model, values);
        }
        // Most frames come before every pixel's wake-up time: then no block is due.
        let due_by = (t1_up >= self.wake_min_s).then_some(t1_up);
        let mut scan = Scan::new(
            std::mem::take(&mut self.busy),
            std::mem::take(&mut self.changed_blocks),
            avx2,
        );
        let full = values.len() / BLOCK * BLOCK;
        if self.copy_in_scan {
            self.next.resize(values.len(), 0.0);
        }
        match (due_by, self.copy_in_scan) {
            (None, false) => self.scan_whole_blocks::<false, false>(model, values, 0.0, &mut scan),
            (None, true) => self.scan_whole_blocks::<false, true>(model, values, 0.0, &mut scan),
            (Some(t1), false) => {
                self.scan_whole_blocks::<true, false>(model, values, t1, &mut scan)
            }
            (Some(t1), true) => self.scan_whole_blocks::<true, true>(model, values, t1, &mut scan),
        }
        if full < values.len() {
            self.scan_tail(model, values, full, due_by, &mut scan);
        }
        self.busy = scan.busy;
        self.changed_blocks = scan.changed_blocks;
        scan.valid
    }

    /// The whole blocks of `scan`, by iterators (no index checks); with `DUE`, a block whose
    /// earliest wake-up is by `t1_up` is looked at closely. Only a block with something
    /// noteworthy (a changed value, a wake-up due) goes further: its first bands where still
    /// due, then its flags. With `COPY`, every value goes into `next` too.
    #[inline(always)]
    fn scan_whole_blocks<const DUE: bool, const COPY: bool>(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        t1_up: f32,
        scan: &mut Scan,
    ) {
        let blocks = values
            .chunks_exact(BLOCK)
            .zip(self.last.chunks_exact(BLOCK))
            .zip(self.wake_s.chunks_exact(BLOCK))
            .zip(&self.block_wake_s);
        // Once every block has its first bands (or without them), the loop skips the test.
        let first_bands_left = !self.first_bands_due.is_empty();
        for (b, (((value, last), wake_s), &block_wake_s)) in blocks.enumerate() {
            let start = b * BLOCK;
            let (value, last) = (block_of(value), block_of(last));
            prefetch_bytes(value.as_ptr().wrapping_add(SCAN_PREFETCH_AHEAD), BLOCK * 4);
            if COPY {
                *block_of_mut(&mut self.next[start..start + BLOCK]) = *value;
            }
            let due_by = (DUE && t1_up >= block_wake_s).then_some(t1_up);
            let changed = any_changed(value, last);
            if !changed && due_by.is_none() {
                continue;
            }
            let first_bands = changed
                && first_bands_left
                && take_bit_if(&mut self.first_bands_due, b, || most_changed(value, last));
            if first_bands {
                let range = start..start + BLOCK;
                set_first_bands(
                    model,
                    self.first_pixel + start,
                    &self.origin[range.clone()],
                    self.made[b],
                    &mut self.lo[range.clone()],
                    &mut self.hi[range],
                );
                forget_if_none(&mut self.first_bands_due);
            }
            let range = start..start + BLOCK;
            let inputs = block_flags::Inputs {
                value,
                last,
                band: (!self.lo.is_empty())
                    .then(|| (block_of(&self.lo[range.clone()]), block_of(&self.hi[range]))),
                wake_s: block_of(wake_s),
            };
            scan.block(start, &inputs, changed, due_by, u32::MAX);
        }
    }

    /// The last, shorter block of `scan`, from pixel `full` on, as `scan_whole_blocks` takes a
    /// whole one.
    fn scan_tail(
        &mut self,
        model: &PixelModel,
        values: &[f32],
        full: usize,
        due_by: Option<f32>,
        scan: &mut Scan,
    ) {
        if self.copy_in_scan {
            self.next[full..].copy_from_slice(&values[full..]);
        }
        let (value, last) = (&values[full..], &self.last[full..]);
        let changed_count = value.iter().zip(last).filter(|(v, l)| v != l).count();
        let most_changed = || 2 * changed_count >= value.len();
        let changed = changed_count > 0;
        if changed && take_bit_if(&mut self.first_bands_due, full / BLOCK, most_changed) {
            self.set_first_bands(model, full..values.len());
        }
        let tail = Padded::new(self, values, full);
        let used = (1u32 << (values.len() - full)) - 1;
        let block_wake_s = self.block_wake_s[full / BLOCK];
        let due = due_by.filter(|&t| t >= block_wake_s);
        if changed || due.is_some() {
            scan.block(full, &tail.inputs(!self.lo.is_empty()), changed, due, used);
        }
    }

    /// The first wake-ups of the pixels without a state whose input has stayed at the first
    /// frame's (the others get a state this frame), and the earliest of the tile again. They
    /// depend on the first frame alone, so a frame the scan refuses may leave them.
    #[cold]
    fn set_first_wakes(&mut self, model: &PixelModel, values: &[f32]) {
        for (j, &value) in values.iter().enumerate() {
            if value == self.last[j] {
                self.settle_wake(model, j);
            }
        }
        for (block_wake_s, wake_s) in self.block_wake_s.iter_mut().zip(self.wake_s.chunks(BLOCK)) {
            *block_wake_s = min_f32(wake_s);
        }
        self.wake_min_s = min_f32(&self.block_wake_s);
        self.first_wakes_due = false;
    }

    /// The first bands of the pixels `range` (one block or less), for those without a state.
    fn set_first_bands(&mut self, model: &PixelModel, range: std::ops::Range<usize>) {
        set_first_bands(
            model,
            self.first_pixel + range.start,
            &self.origin[range.clone()],
            self.made[range.start / BLOCK],
            &mut self.lo[range.clone()],
            &mut self.hi[range],
        );
        forget_if_none(&mut self.first_bands_due);
    }
}

/// What `Tile::scan` gathers block by block.
struct Scan {
    /// The pixels to step, as indices in the tile.
    busy: Vec<u32>,
    valid: bool,
    /// Bit b of word w: a value changed in block 64 w + b.
    changed_blocks: Vec<u64>,
    /// The flags' AVX2 copy, where the CPU has it.
    avx2: Option<Avx2>,
}

impl Scan {
    fn new(busy: Vec<u32>, mut changed_blocks: Vec<u64>, avx2: Option<Avx2>) -> Self {
        changed_blocks.fill(0);
        Self {
            busy,
            valid: true,
            changed_blocks,
            avx2,
        }
    }

    /// One block with a changed value (`changed`, from `any_changed`) or a wake-up due: the
    /// flags of all its pixels at once (vector compares), then the set ones alone.
    #[inline(always)]
    fn block(
        &mut self,
        start: usize,
        inputs: &block_flags::Inputs,
        changed: bool,
        due_by: Option<f32>,
        used: u32,
    ) {
        let flags = block_flags::flags(inputs, due_by, self.avx2);
        self.valid &= flags.invalid & used == 0;
        if changed {
            let block_index = start / BLOCK;
            self.changed_blocks[block_index / 64] |= 1 << (block_index % 64);
        }
        let mut busy = flags.busy & used;
        if busy == u32::MAX {
            // Every pixel of the block (every pixel changes): a run, without a test a pixel.
            self.busy.extend(start as u32..(start + BLOCK) as u32);
            return;
        }
        while busy != 0 {
            self.busy
                .push((start + busy.trailing_zeros() as usize) as u32);
            busy &= busy - 1;
        }
    }
}

/// Whether any value of a block differs from the last frame's: a branch-free test of all its
/// pixels at once (vector compares). The last frame's values are valid, so a value equal to one
/// is too (NaN equals nothing): validity is left to the flags.
#[inline(always)]
fn any_changed(value: &[f32; BLOCK], last: &[f32; BLOCK]) -> bool {
    let mut any = false;
    for k in 0..BLOCK {
        any |= value[k] != last[k];
    }
    any
}

/// Whether most values of a block differ from the last frame's (see `first_bands_due`).
#[inline(always)]
fn most_changed(value: &[f32; BLOCK], last: &[f32; BLOCK]) -> bool {
    let mut count = 0;
    for k in 0..BLOCK {
        count += (value[k] != last[k]) as u32;
    }
    2 * count as usize >= BLOCK
}

/// Clears bit `b` where it is set (absent: clear) and `also` holds (asked only then); returns
/// whether it did.
#[inline(always)]
fn take_bit_if(bits: &mut [u64], b: usize, also: impl FnOnce() -> bool) -> bool {
    match bits.get_mut(b / 64) {
        Some(word) if *word >> (b % 64) & 1 != 0 && also() => {
            *word &= !(1 << (b % 64));
            true
        }
        _ => false,
    }
}

/// Drops `bits` once none is set, so that a test of a bit in it is one of its length.
fn forget_if_none(bits: &mut Vec<u64>) {
    if bits.iter().all(|&word| word == 0) {
        *bits = Vec::new();
    }
}

/// `n` bits, all set.
pub(super) fn all_bits(n: usize) -> Vec<u64> {
    let mut bits = vec![u64::MAX; n.div_ceil(64)];
    if !n.is_multiple_of(64) {
        bits[n / 64] = (1 << (n % 64)) - 1;
    }
    bits
}

/// The first bands of the pixels from `first_pixel` on (one block or less, with first-frame
/// values `origin`) but those of `has_state`; worked out once a block, the first time it
/// changes.
#[cold]
#[inline(never)]
fn set_first_bands(
    model: &PixelModel,
    first_pixel: usize,
    origin: &[f32],
    has_state: u32,
    lo: &mut [f32],
    hi: &mut [f32],
) {
    first_band::set_first_bands(model, first_pixel as u64, origin, has_state, lo, hi);
}

#[inline(always)]
fn block_of(values: &[f32]) -> &[f32; BLOCK] {
    values.try_into().expect("a whole block")
}

#[inline(always)]
fn block_of_mut(values: &mut [f32]) -> &mut [f32; BLOCK] {
    values.try_into().expect("a whole block")
}

/// The last, shorter block of a tile, padded to a whole one (the padding is masked out).
struct Padded {
    value: [f32; BLOCK],
    last: [f32; BLOCK],
    lo: [f32; BLOCK],
    hi: [f32; BLOCK],
    wake_s: [f32; BLOCK],
}

impl Padded {
    fn new(tile: &Tile, values: &[f32], start: usize) -> Self {
        let fill = |from: &[f32]| {
            let mut block = [0.0; BLOCK];
            if !from.is_empty() {
                block[..from.len() - start].copy_from_slice(&from[start..]);
            }
            block
        };
        Self {
            value: fill(values),
            last: fill(&tile.last),
            lo: fill(&tile.lo),
            hi: fill(&tile.hi),
            wake_s: fill(&tile.wake_s),
        }
    }

    fn inputs(&self, with_band: bool) -> block_flags::Inputs<'_> {
        block_flags::Inputs {
            value: &self.value,
            last: &self.last,
            band: with_band.then_some((&self.lo, &self.hi)),
            wake_s: &self.wake_s,
        }
    }
}

/// Values asked for this far ahead of the scan (4 KiB): the frame comes from memory, not the
/// cache, and the hardware prefetcher stops at each 4 KiB page; asking ahead keeps the loads
/// of the next pages under way while a block is tested.
const SCAN_PREFETCH_AHEAD: usize = 1024;
