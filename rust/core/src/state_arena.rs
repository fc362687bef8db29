//! Memory for the pixels' state blocks: one allocation for a whole sensor, in 2 MiB pages where
//! the system gives them.
//!
//! In a frame where every pixel changes, the dense path reads a full sensor's states (128 bytes
//! a pixel: 118 MB at 1280 x 720) from memory a block of 32 pixels (4 KiB) at a time. With 4 KiB
//! pages each block costs the processor a page walk; with 2 MiB pages (Linux's transparent huge
//! pages, asked for with `madvise(MADV_HUGEPAGE)`) one walk covers 512 blocks. A 2 MiB page is
//! committed whole, so only the models the dense path steps (whose pixels, with noise, soon all
//! have a state) take their blocks from an arena; the others keep a reserve per tile, whose
//! 4 KiB pages are committed one block at a time.
//!
//! A dropped sensor's arena is kept as the spare for the next sensor of about its size (one
//! spare, the latest): a process that converts clip after clip would otherwise map and zero its
//! 118 MB again for every clip.

use std::alloc::{self, Layout};
use std::ops::{Index, IndexMut};
use std::ptr::NonNull;
use std::sync::{Arc, Mutex, PoisonError};

use crate::state_block::StateBlock;

/// The size and alignment of a huge page on x86-64 and of most on AArch64.
const HUGE_PAGE_BYTES: usize = 2 << 20;
const BLOCKS_PER_HUGE_PAGE: usize = HUGE_PAGE_BYTES / std::mem::size_of::<StateBlock>();

/// Room for the blocks of many tiles (`blocks[i]` for tile i), as one store per tile carved
/// from one arena; None where the memory cannot be had (the caller reserves per tile instead).
pub fn stores_in_one_arena(blocks: &[usize]) -> Option<Vec<BlockStore>> {
    let pages = take_pages(blocks.iter().sum())?;
    let base = pages.start;
    let arena = Arc::new(Arena { pages: Some(pages) });
    let mut offset = 0;
    let stores = blocks
        .iter()
        .map(|&capacity| {
            // SAFETY: the offsets stay inside the arena, which holds the sum of the capacities.
            let start = unsafe { base.add(offset) };
            offset += capacity;
            BlockStore {
                start,
                capacity,
                len: 0,
                _memory: Memory::Shared(Arc::clone(&arena)),
            }
        })
        .collect();
    Some(stores)
}

/// Room for a tile's state blocks, taken in order (`push`) and found by their slot. Its memory
/// is its own, or its tile's part of an arena (no other store reaches it).
pub struct BlockStore {
    start: NonNull<StateBlock>,
    capacity: usize,
    len: usize,
    _memory: Memory,
}

/// What keeps a store's memory alive.
enum Memory {
    Own(#[allow(dead_code)] Vec<StateBlock>),
    Shared(#[allow(dead_code)] Arc<Arena>),
}

// SAFETY: a store is the only way to its blocks (its own vector, or a part of an arena that no
// other store overlaps), so it moves between threads as a Vec does, and shared references to
// it only read.
unsafe impl Send for BlockStore {}
unsafe impl Sync for BlockStore {}

impl BlockStore {
    /// Room for `capacity` blocks of its own: reserved, not touched, so the pages are only
    /// committed as blocks are made.
    pub fn with_capacity(capacity: usize) -> Self {
        let mut own = Vec::with_capacity(capacity);
        Self {
            start: NonNull::new(own.as_mut_ptr()).expect("a vector's pointer is never null"),
            capacity,
            len: 0,
            _memory: Memory::Own(own),
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Place `block` in the next slot; returns the slot.
    pub fn push(&mut self, block: StateBlock) -> usize {
        assert!(
            self.len < self.capacity,
            "a tile makes at most one block each"
        );
        // SAFETY: the slot is inside this store's memory (checked just above), which only it
        // reaches; writing a plain value over stale bytes drops nothing.
        unsafe { self.start.add(self.len).write(block) };
        self.len += 1;
        self.len - 1
    }

    pub fn get(&self, slot: usize) -> Option<&StateBlock> {
        // SAFETY: slots below `len` were written by `push`.
        (slot < self.len).then(|| unsafe { self.start.add(slot).as_ref() })
    }
}

impl Index<usize> for BlockStore {
    type Output = StateBlock;

    #[inline]
    fn index(&self, slot: usize) -> &StateBlock {
        self.get(slot).expect("a slot that was pushed")
    }
}

impl IndexMut<usize> for BlockStore {
    #[inline]
    fn index_mut(&mut self, slot: usize) -> &mut StateBlock {
        assert!(slot < self.len, "a slot that was pushed");
        // SAFETY: as `get`, and `&mut self` makes the reference the only one.
        unsafe { self.start.add(slot).as_mut() }
    }
}

/// A sensor's blocks in one allocation; dropped with its last store, when it becomes the spare.
struct Arena {
    pages: Option<Pages>,
}

impl Drop for Arena {
    fn drop(&mut self) {
        let old = spare().replace(self.pages.take().expect("an arena holds its pages"));
        // Freed after the lock is let go.
        drop(old);
    }
}

/// One allocation aligned to and a whole number of huge pages, advised to use them.
struct Pages {
    start: NonNull<StateBlock>,
    bytes: usize,
}

// SAFETY: plain memory, reached only through the stores of the arena that holds it (a shared
// reference to the pages gives out nothing but where they are).
unsafe impl Send for Pages {}
unsafe impl Sync for Pages {}

impl Pages {
    fn new(blocks: usize) -> Option<Self> {
        let bytes = blocks
            .max(1)
            .checked_mul(std::mem::size_of::<StateBlock>())?
            .checked_next_multiple_of(HUGE_PAGE_BYTES)?;
        let layout = Layout::from_size_align(bytes, HUGE_PAGE_BYTES).ok()?;
        // SAFETY: the layout's size is not zero.
        let start = NonNull::new(unsafe { alloc::alloc(layout) }.cast::<StateBlock>())?;
        advise_huge_pages(start.as_ptr().cast(), bytes);
        Some(Self { start, bytes })
    }

    fn blocks(&self) -> usize {
        self.bytes / std::mem::size_of::<StateBlock>()
    }
}

impl Drop for Pages {
    fn drop(&mut self) {
        // SAFETY: allocated in `new` with this size and alignment.
        unsafe {
            let layout = Layout::from_size_align_unchecked(self.bytes, HUGE_PAGE_BYTES);
            alloc::dealloc(self.start.as_ptr().cast(), layout);
        }
    }
}

/// The spare arena, if any.
fn spare() -> std::sync::MutexGuard<'static, Option<Pages>> {
    static SPARE: Mutex<Option<Pages>> = Mutex::new(None);
    SPARE.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Pages for `blocks` blocks: the spare where it fits, else new ones.
fn take_pages(blocks: usize) -> Option<Pages> {
    let mut spare = spare();
    if let Some(pages) = spare.take_if(|pages| spare_fits(pages.blocks(), blocks)) {
        return Some(pages);
    }
    drop(spare);
    Pages::new(blocks)
}

/// Whether a spare of `spare_blocks` takes `blocks` without holding more than twice the memory
/// (a huge page of slack aside): a small sensor must not sit on a large one's arena.
fn spare_fits(spare_blocks: usize, blocks: usize) -> bool {
    spare_blocks >= blocks && spare_blocks <= 2 * blocks + BLOCKS_PER_HUGE_PAGE
}

/// Ask the kernel to back the range with huge pages (refused or unsupported: it keeps 4 KiB
/// pages, which changes the speed, not the contents).
#[cfg(target_os = "linux")]
fn advise_huge_pages(start: *mut libc::c_void, bytes: usize) {
    // SAFETY: the range is one live allocation; the advice changes no byte of it.
    unsafe { libc::madvise(start, bytes, libc::MADV_HUGEPAGE) };
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_start: *mut std::ffi::c_void, _bytes: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block whose every field holds `tag`.
    fn tagged(tag: f64) -> StateBlock {
        let mut block = StateBlock::empty();
        block.t_s = [tag; 32];
        block.last_out_s = [tag; 32];
        block.draws = [tag as u64; 32];
        block
    }

    #[test]
    fn the_stores_of_one_arena_keep_their_blocks_apart() {
        // Tiles of 128, 3 and 77 blocks (a short last row), each filled to the last slot.
        let capacities = [128, 3, 77];
        let mut stores = stores_in_one_arena(&capacities).expect("memory for 208 blocks");
        for (i, store) in stores.iter_mut().enumerate() {
            for slot in 0..capacities[i] {
                assert_eq!(store.push(tagged((1000 * i + slot) as f64)), slot);
            }
        }
        for (i, store) in stores.iter().enumerate() {
            assert_eq!(store.len(), capacities[i]);
            for slot in 0..capacities[i] {
                let tag = (1000 * i + slot) as f64;
                assert!(store[slot] == tagged(tag), "store {i} slot {slot}");
            }
            assert!(store.get(capacities[i]).is_none());
        }
    }

    #[test]
    fn a_store_of_its_own_reads_back_what_was_pushed_and_refuses_a_slot_past_its_room() {
        let mut store = BlockStore::with_capacity(2);
        store.push(tagged(1.0));
        store.push(tagged(2.0));
        store[0].u[5] = 7.0;
        assert!(store[1] == tagged(2.0));
        assert_eq!(store[0].u[5], 7.0);
        let full = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            store.push(tagged(3.0));
        }));
        assert!(full.is_err());
    }

    #[test]
    fn a_spare_fits_a_sensor_needing_at_most_its_blocks_and_at_least_about_half() {
        // 1280 x 720: 28,800 blocks; 346 x 260 (22 tiles): 2,816.
        assert!(spare_fits(28_800, 28_800));
        assert!(spare_fits(28_800 + 511, 28_800));
        assert!(!spare_fits(28_799, 28_800));
        assert!(!spare_fits(28_800, 2_816));
        assert!(spare_fits(2 * 14_000 + 512, 14_000));
        assert!(!spare_fits(2 * 14_000 + 513, 14_000));
    }
}
