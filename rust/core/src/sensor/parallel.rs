//! A pass over the tiles on the thread pool or on the calling thread: the tiles are independent,
//! so the events are the same on any thread count; the pool only where a frame's work pays for it.

use rayon::prelude::*;

use crate::tile::{Tile, TILE};

/// Below this many pixels a frame's scan (about 0.25 ns a pixel) is faster on the calling thread
/// than with the hop into the thread pool and back (about 15 us on a desktop or a small VM)...
pub(super) const PARALLEL_MIN_PIXELS: usize = 1 << 18;

/// ... unless this many pixels had to be stepped in the last frame (about 0.1 us each).
pub(super) const PARALLEL_MIN_BUSY: usize = 256;

/// ... or unless noise is expected to give this many events (about 0.4 us each, sorted).
pub(super) const PARALLEL_MIN_NOISE_EVENTS: f64 = 4096.0;

/// Run `work` on every tile with its part of the frame, on the thread pool or here; returns
/// whether it returned true for all.
pub(super) fn for_each_tile(
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
