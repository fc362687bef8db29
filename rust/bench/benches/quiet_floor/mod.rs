//! The least a quiet pixel update of the full model can cost (issue 37's bound): every pixel,
//! every frame, pays it before any event.
//!
//! - Memory: the state fields a quiet step reads (10 of a pixel's 16, 80 bytes) and writes back
//!   (8, 64 bytes), and the frame value now and a frame ago, streamed over a sensor's states kept
//!   as the tile keeps them (32 pixels a block, field by field), with no arithmetic to speak of.
//! - Arithmetic: the operations no quiet update can leave out, on states that stay in the
//!   first-level cache: the photocurrent and its logarithm, its inverse, the low-pass time
//!   constant and its inverse, the decay over the frame (an exponential), the new output, the
//!   reference with its drift, the shot-noise rate at both ends and the hazard taken from the
//!   budget (the series), and the test that neither threshold is reached (the loose bound on
//!   both sides). Nothing else the step does (the exact test, the gates, the exports, the
//!   leak's re-basing, the checks that keep it to the one-pixel path's bits) is counted.
//! - Both: that arithmetic over the sensor's states, as a quiet step must do it.
//!
//! Each as a branch-free loop over a block's 32 lanes, compiled for AVX-512 where the CPU has
//! it, as the dense path's step is.

use std::hint::black_box;

use pecs_core::exp::{exp_in_range, ln_in_range};
use pecs_core::noise::{exp_m1_over_x_series, shot_rate_of_law_hz};
use pecs_core::photoreceptor::{inverse_current, Photoreceptor};
use pecs_core::SensorParams;

#[cfg(target_arch = "x86_64")]
use super::common::has_avx512;

/// Pixels a block, as the tile keeps them.
const LANES: usize = 32;

/// A block's fields, as `StateBlock` keeps them (the order is this bench's own).
#[derive(Clone)]
struct Block {
    t_s: [f64; LANES],
    u: [f64; LANES],
    x: [f64; LANES],
    v: [f64; LANES],
    ref0: [f64; LANES],
    t_ref_s: [f64; LANES],
    leak_drift: [f64; LANES],
    shot_budget: [f64; LANES],
    theta_on: [f64; LANES],
    theta_off: [f64; LANES],
    /// The fields a quiet step does not read, there so that a block takes a state's 128 bytes.
    _unread: [[f64; LANES]; 6],
}

/// A sensor's states and its frames' values, block by block.
pub struct Floor {
    blocks: Vec<Block>,
    law: Law,
    frame_s: f64,
}

/// The sensor's constants the arithmetic reads.
struct Law {
    receptor: Photoreceptor,
    params: SensorParams,
}

/// What a pass does: stream the fields, do the arithmetic on cached ones, or both.
#[derive(Clone, Copy, PartialEq)]
pub enum Pass {
    Memory,
    Arithmetic,
    Both,
}

impl Floor {
    /// States for `pixels` pixels (a whole number of blocks), powered up on `first`'s values.
    pub fn new(params: &SensorParams, first: &[f32], frame_s: f64) -> Self {
        let receptor = Photoreceptor::new(params);
        let blocks = first
            .chunks(LANES)
            .map(|values| {
                let lane = |f: &dyn Fn(f64) -> f64| {
                    std::array::from_fn(|k| f(values.get(k).copied().unwrap_or(0.5) as f64))
                };
                let x = lane(&|v| receptor.total_current(v));
                let u = x.map(ln_in_range);
                Block {
                    t_s: [0.0; LANES],
                    u,
                    x,
                    v: u,
                    ref0: u,
                    t_ref_s: [0.0; LANES],
                    leak_drift: [-1e-4; LANES],
                    shot_budget: [3.0; LANES],
                    theta_on: [params.theta_on; LANES],
                    theta_off: [params.theta_off; LANES],
                    _unread: [[0.0; LANES]; 6],
                }
            })
            .collect();
        Self {
            blocks,
            law: Law {
                receptor,
                params: params.clone(),
            },
            frame_s,
        }
    }

    /// One frame from `last` to `now` (values per pixel) over every block, `pass` of the work;
    /// returns how many pixels stayed inside both thresholds (kept, so nothing is optimised
    /// away). `Pass::Arithmetic` cycles over the first `CACHED_BLOCKS` blocks' states.
    pub fn frame(&mut self, last: &[f32], now: &[f32], t0_s: f64, pass: Pass) -> usize {
        let cached = CACHED_BLOCKS.min(self.blocks.len());
        let mut inside = 0;
        for (b, (last, now)) in last.chunks(LANES).zip(now.chunks(LANES)).enumerate() {
            if last.len() < LANES {
                break;
            }
            let block = if pass == Pass::Arithmetic {
                b % cached
            } else {
                b
            };
            let (last, now) = (lanes(last), lanes(now));
            if pass != Pass::Arithmetic {
                // As the tile asks for them: the block after next into the second-level cache,
                // the next into the first (the hardware's prefetcher stops at each page).
                prefetch_read_fields(self.blocks.get(b + 2), Level::Second);
                prefetch_read_fields(self.blocks.get(b + 1), Level::First);
            }
            let state = &mut self.blocks[block];
            inside += match pass {
                Pass::Memory => stream(state, &last, &now, t0_s, self.frame_s),
                _ => quiet_update(state, &now, t0_s, self.frame_s, &self.law),
            };
        }
        inside
    }
}

/// Which cache a prefetch fills.
#[derive(Clone, Copy)]
enum Level {
    First,
    Second,
}

/// Ask for the fields of `block` a quiet step reads (its first 10, 80 bytes a pixel).
#[inline(always)]
fn prefetch_read_fields(block: Option<&Block>, level: Level) {
    #[cfg(target_arch = "x86_64")]
    if let Some(block) = block {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0, _MM_HINT_T1};
        let start = std::ptr::from_ref(block).cast::<i8>();
        for line in 0..READ_FIELDS * LANES * 8 / 64 {
            let at = start.wrapping_add(line * 64);
            // SAFETY: a prefetch is a hint; it reads nothing and cannot fault.
            unsafe {
                match level {
                    Level::First => _mm_prefetch::<_MM_HINT_T0>(at),
                    Level::Second => _mm_prefetch::<_MM_HINT_T1>(at),
                }
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (block, level);
}

/// The fields a quiet step reads, which `Block` keeps first.
const READ_FIELDS: usize = 10;

/// The blocks the arithmetic pass cycles over: 8, 32 KB, which stay in the first-level cache.
const CACHED_BLOCKS: usize = 8;

fn lanes(values: &[f32]) -> [f32; LANES] {
    std::array::from_fn(|k| values[k])
}

/// The fields a quiet step reads and writes, with next to no arithmetic.
fn stream(b: &mut Block, last: &[f32; LANES], now: &[f32; LANES], t0: f64, dt: f64) -> usize {
    #[cfg(target_arch = "x86_64")]
    if has_avx512() {
        // SAFETY: the CPU supports AVX-512F and DQ, checked just above.
        return unsafe { stream_avx512(b, last, now, t0, dt) };
    }
    stream_lanes(b, last, now, t0, dt)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx2,fma")]
unsafe fn stream_avx512(
    b: &mut Block,
    last: &[f32; LANES],
    now: &[f32; LANES],
    t0: f64,
    dt: f64,
) -> usize {
    stream_lanes(b, last, now, t0, dt)
}

#[inline(always)]
#[allow(clippy::needless_range_loop)] // an index loop over the lanes, as the dense step's
fn stream_lanes(b: &mut Block, last: &[f32; LANES], now: &[f32; LANES], t0: f64, dt: f64) -> usize {
    let mut inside = 0;
    for k in 0..LANES {
        let step = (now[k] - last[k]) as f64 * 1e-30;
        let sum = b.ref0[k] + b.t_ref_s[k] + b.theta_on[k] + b.theta_off[k];
        b.t_s[k] = t0 + dt + b.t_s[k] * 1e-30;
        b.u[k] += step;
        b.x[k] += step;
        b.v[k] += step;
        b.ref0[k] += step;
        b.t_ref_s[k] += step;
        b.leak_drift[k] += step;
        b.shot_budget[k] += step;
        inside += (sum < 1e300) as usize;
    }
    inside
}

/// The arithmetic every quiet update needs, a block at a time.
fn quiet_update(b: &mut Block, now: &[f32; LANES], t0: f64, dt: f64, law: &Law) -> usize {
    #[cfg(target_arch = "x86_64")]
    if has_avx512() {
        // SAFETY: the CPU supports AVX-512F and DQ, checked just above.
        return unsafe { quiet_avx512(b, now, t0, dt, law) };
    }
    quiet_lanes(b, now, t0, dt, law)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx2,fma")]
unsafe fn quiet_avx512(b: &mut Block, now: &[f32; LANES], t0: f64, dt: f64, law: &Law) -> usize {
    quiet_lanes(b, now, t0, dt, law)
}

#[inline(always)]
#[allow(clippy::needless_range_loop)] // an index loop over the lanes, as the dense step's
fn quiet_lanes(b: &mut Block, now: &[f32; LANES], t0: f64, dt: f64, law: &Law) -> usize {
    let (r, p) = (&law.receptor, &law.params);
    let inv_dt = 1.0 / dt;
    let mut inside = 0;
    for k in 0..LANES {
        // The ramp's ends: the photocurrent, its logarithm and inverse at each.
        let (u0, x0) = (b.u[k], b.x[k]);
        let x1 = r.total_current(now[k] as f64);
        let u1 = ln_in_range(x1);
        let (inv_x0, inv_x1) = (inverse_current(x0), inverse_current(x1));
        // The low-pass over the frame: its time constant, the decay, the new output.
        let slope = (u1 - u0) * inv_dt;
        let tau = r.segment_tau_s(inv_x0, inv_x1);
        let inv_tau = 1.0 / tau;
        let decay = exp_in_range(-dt * inv_tau);
        let v1 = u1 - slope * tau + (b.v[k] - u0 + slope * tau) * decay;
        // The reference with its drift; the difference's loose bound on both sides.
        let reference = b.ref0[k] - b.leak_drift[k] * (t0 - b.t_ref_s[k]);
        let a = u1 - slope * tau - reference;
        let c = b.v[k] - u0 + slope * tau;
        let m = slope - b.leak_drift[k];
        let high = a + (m * dt).max(0.0) + c.max(0.0);
        let low = a + (m * dt).min(0.0) + c.min(0.0);
        let quiet = high < b.theta_on[k] && low > -b.theta_off[k];
        // Shot noise: the rate at both ends, the budget outlasting the frame, the hazard.
        let r0 = shot_rate_of_law_hz::<false>(p, inv_x0);
        let r1 = shot_rate_of_law_hz::<false>(p, inv_x1);
        let no_shot = r0.max(r1) * dt < b.shot_budget[k];
        let hazard = r0 * dt * exp_m1_over_x_series(-slope * dt);
        b.t_s[k] = t0 + dt;
        b.u[k] = u1;
        b.x[k] = x1;
        b.v[k] = v1;
        b.shot_budget[k] -= hazard;
        inside += (quiet && no_shot) as usize;
    }
    inside
}

/// Every frame of `frames` through `floor`'s `pass`, seconds for the whole; best of `repeats`.
pub fn time_pass(
    params: &SensorParams,
    frames: &[Vec<f32>],
    frame_s: f64,
    pass: Pass,
    repeats: usize,
) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let mut floor = Floor::new(params, &frames[0], frame_s);
        let start = std::time::Instant::now();
        let mut inside = 0;
        for (k, pair) in frames.windows(2).enumerate() {
            inside += floor.frame(&pair[0], &pair[1], k as f64 * frame_s, pass);
        }
        best = best.min(start.elapsed().as_secs_f64());
        black_box(inside);
    }
    best
}
