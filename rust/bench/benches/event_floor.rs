//! What bounds the full model where many pixels fire (issue 37): the drifting sinusoid's cost
//! split into the part every pixel pays and the part each event pays, and the least an event
//! can cost when its pixel is stepped on its own.
//!
//! `cargo bench -p pecs-bench --bench event_floor -- [frames] [sinusoid|sinusoid-dense]
//! [WIDTHxHEIGHT]` (run it with `RAYON_NUM_THREADS=1`: the bound is for one thread) prints, in
//! one run:
//! - the full `davis346` model on the sinusoid, ns a pixel update, through `EventSensor::feed`;
//! - the same frames with thresholds out of reach (10 log units): no pixel crosses, so this is
//!   what the pixels cost without their events (the dense path's quiet step, the scan, the
//!   frame's bookkeeping; shot and hot-pixel events remain, a few hundred);
//! - the event floor: the sinusoid's real crossings (recorded from the one-pixel model, each
//!   with its pixel's state at the frame's start), each put through only the arithmetic an
//!   event cannot do without: its first crossing on the side it fires (`first_reach`, the
//!   Halley solve), the other side ruled out up to it, the low-pass at the crossing and at the
//!   frame's end (two exponentials), its random numbers (threshold noise pair, latency jitter)
//!   and writing it out. Warm caches, independent events one after another (out-of-order
//!   execution overlaps neighbours): a floor for any one-pixel-at-a-time event path;
//! - the floor of such a path, quiet cost + events a pixel update x event floor, and the full
//!   model's time over it;
//! - the quiet floor (`quiet_floor`): the least every pixel update costs before any event, its
//!   state's fields streamed and the arithmetic no quiet update can leave out; with the events
//!   solved together at their floor, the least an update of this model can cost on the machine.

use std::hint::black_box;
use std::time::Instant;

use pecs_core::crossing::Difference;
use pecs_core::exp::{exp_in_range, ln_in_range};
use pecs_core::photoreceptor::inverse_current;
use pecs_core::pixel::{PixelModel, Segment};
use pecs_core::rng::{Draw, Stream};
use pecs_core::{Event, SensorParams};

mod common;
mod quiet_floor;
use common::{davis346, primed, run, sinusoid_scene, DAVIS346, DENSE_SINUSOID, FRAME_US, SINUSOID};

/// One recorded crossing: the pixel's difference v - ref from the frame's start, the side it
/// fires and both thresholds, the frame's length, and what its random numbers are keyed by.
struct Crossing {
    d: Difference,
    on: bool,
    theta_on: f64,
    theta_off: f64,
    horizon_s: f64,
    pixel: u64,
    draws: u64,
    t0_s: f64,
}

/// Every crossing of the sequence where a pixel, not held in reset at the frame's start, emits
/// exactly one signal event in the frame (the common case: the refractory period outlasts the
/// rest of the frame), stepping each pixel with the one-pixel model as the tile does.
fn record_crossings(params: &SensorParams, frames: &[Vec<f32>]) -> Vec<Crossing> {
    let model = PixelModel::new(params.clone());
    let r = &model.receptor;
    let dt_s = FRAME_US as f64 * 1e-6;
    let mut crossings = Vec::new();
    for pixel in 0..frames[0].len() {
        let mut st = model.init(pixel as u64, frames[0][pixel] as f64, 0.0);
        for (k, frame) in frames.iter().enumerate().skip(1) {
            let (t0_s, t1_s) = ((k - 1) as f64 * dt_s, k as f64 * dt_s);
            let x1 = r.total_current(frame[pixel] as f64);
            let seg = Segment {
                t0_s,
                t1_s,
                u0: st.u,
                u1: r.response(x1),
                x0: st.x,
                x1,
            };
            let slope = (seg.u1 - seg.u0) / dt_s;
            let tau = r.segment_tau_s(inverse_current(seg.x0), inverse_current(seg.x1));
            let reference = st.ref0 - st.leak_drift * (st.t_s - st.t_ref_s);
            let d =
                Difference::of_pixel(st.u, st.v, reference, st.leak_drift, slope, tau, 1.0 / tau);
            let before = st.clone();
            let mut events = Vec::new();
            model.run(&mut st, pixel as u64, &seg, &mut |e| events.push(e));
            let free = before.refractory_mark_s <= t0_s && before.t_s == t0_s;
            if let [event] = events[..] {
                if free && event.cause == pecs_core::pixel::Cause::Signal {
                    crossings.push(Crossing {
                        d,
                        on: event.on,
                        theta_on: before.theta_on,
                        theta_off: before.theta_off,
                        horizon_s: t1_s - t0_s,
                        pixel: pixel as u64,
                        draws: before.draws,
                        t0_s,
                    });
                }
            }
        }
    }
    crossings
}

/// What each part of the floor takes: the solve alone, or everything.
#[derive(Clone, Copy, PartialEq)]
enum Part {
    Solve,
    Draws,
    Whole,
}

/// The floor's work over every recorded crossing, `part` of it; returns a sum of its results
/// (kept, so that nothing is left out as unused) and the events written.
fn floor_pass(crossings: &[Crossing], params: &SensorParams, part: Part, out: &mut Vec<Event>) {
    let (latency_s, jitter_s) = (params.latency_us * 1e-6, params.jitter_us * 1e-6);
    let width = params.width as u64;
    out.clear();
    let mut sum = 0.0;
    for c in crossings {
        let (near, far, level, other) = if c.on {
            (c.d, c.d.negated(), c.theta_on, c.theta_off)
        } else {
            (c.d.negated(), c.d, c.theta_off, c.theta_on)
        };
        // The crossing: solved (and the other side ruled out up to it), or the frame's start
        // where the draws alone are timed.
        let mut s = 0.0;
        if part != Part::Draws {
            s = near.first_reach(level, c.horizon_s).unwrap_or(c.horizon_s);
            sum += s;
            if part == Part::Solve {
                continue;
            }
            sum += far.first_reach(other, s).unwrap_or(0.0);
            // The low-pass at the crossing and at the frame's end: an exponential each.
            sum += c.d.at(s) + c.d.at(c.horizon_s - s);
        }
        let draw = Draw::new(params.seed, c.pixel, c.draws);
        let (z_on, z_off) = draw.normal_pair(Stream::ThetaNoise);
        let t_out_s = c.t0_s + s + latency_s + jitter_s * draw.normal(Stream::Jitter);
        sum += z_on + z_off;
        out.push(Event {
            t_us: (t_out_s * 1e6 + 0.5) as i64,
            x: (c.pixel % width) as u16,
            y: (c.pixel / width) as u16,
            p: if c.on { 1 } else { -1 },
            label: 0,
        });
    }
    black_box(sum);
}

/// Lanes of the vector solve: as the dense path's blocks are split for AVX-512.
const LANES: usize = 8;

/// Halley steps from the secant's guess, for every lane: the one-pixel solve needs 2.1 on
/// average (to 1e-10 s) and stops there; a lane-parallel one takes the same count everywhere.
const HALLEY_STEPS: usize = 4;

/// `LANES` crossings' near sides, field by field (as the dense path keeps pixel states): d(s) =
/// a + m s + c e^{-s/tau} reaching `level` within `h` seconds.
#[derive(Default)]
struct LaneBlock {
    a: [f64; LANES],
    m: [f64; LANES],
    c: [f64; LANES],
    tau: [f64; LANES],
    inv_tau: [f64; LANES],
    level: [f64; LANES],
    h: [f64; LANES],
}

/// The recorded crossings, `LANES` at a time (a whole number of blocks; the rest left out).
fn lane_blocks(crossings: &[Crossing]) -> Vec<LaneBlock> {
    crossings
        .chunks_exact(LANES)
        .map(|chunk| {
            let mut b = LaneBlock::default();
            for (k, c) in chunk.iter().enumerate() {
                let (d, level) = if c.on {
                    (c.d, c.theta_on)
                } else {
                    (c.d.negated(), c.theta_off)
                };
                (b.a[k], b.m[k], b.c[k], b.tau[k], b.inv_tau[k]) =
                    (d.a, d.m, d.c, d.tau, d.inv_tau);
                (b.level[k], b.h[k]) = (level, c.horizon_s);
            }
            b
        })
        .collect()
}

/// The crossing times of a block's `LANES` crossings at once, as a vector event path would find
/// them, branch-free: the piece of [0, h] holding the first crossing (split at d's one
/// extremum, where m tau / c is in (0, 1): a logarithm), the secant's guess on it,
/// `HALLEY_STEPS` Halley steps kept in the shrinking bracket; then the low-pass at the crossing
/// and at the frame's end (two exponentials). Returns the times and, per lane, those values.
#[inline(always)]
fn solve_lanes(b: &LaneBlock) -> ([f64; LANES], [f64; LANES]) {
    let mut times = [0.0; LANES];
    let mut values = [0.0; LANES];
    for k in 0..LANES {
        let (a, m, c, tau, inv_tau, level, h) = (
            b.a[k],
            b.m[k],
            b.c[k],
            b.tau[k],
            b.inv_tau[k],
            b.level[k],
            b.h[k],
        );
        let at = |s: f64| a + m * s + c * exp_in_range(-s * inv_tau);
        let ratio = m * tau / c;
        let turns = ratio > 0.0 && ratio < 1.0;
        let s_turn = if turns { -tau * ln_in_range(ratio) } else { h };
        let first_end = if s_turn < h { s_turn } else { h };
        let on_first = at(first_end) >= level;
        let mut lo = if on_first { 0.0 } else { first_end };
        let mut hi = if on_first { first_end } else { h };
        let (f_lo, f_hi) = (at(lo) - level, at(hi) - level);
        let mut s = lo + (hi - lo) * (-f_lo / (f_hi - f_lo));
        for _ in 0..HALLEY_STEPS {
            let decay = c * exp_in_range(-s * inv_tau);
            let f = a + m * s + decay - level;
            let past = f >= 0.0;
            hi = if past { s } else { hi };
            lo = if past { lo } else { s };
            let slope = m - decay * inv_tau;
            let curvature = decay * inv_tau * inv_tau;
            let next = s - 2.0 * f * slope / (2.0 * slope * slope - f * curvature);
            s = if next >= lo && next <= hi {
                next
            } else {
                0.5 * (lo + hi)
            };
        }
        times[k] = s;
        values[k] = c * exp_in_range(-s * inv_tau) + c * exp_in_range(-(h - s) * inv_tau);
    }
    (times, values)
}

/// `solve_lanes` over every block; returns how many of its times are further than
/// `AGREE_S` from the one-pixel solve's (`scalar_s`, block by block).
#[inline(always)]
fn vector_pass_lanes(blocks: &[LaneBlock], scalar_s: &[f64]) -> usize {
    let mut apart = 0;
    let mut sum = 0.0;
    for (b, scalar) in blocks.iter().zip(scalar_s.chunks_exact(LANES)) {
        let (times, values) = solve_lanes(b);
        for k in 0..LANES {
            sum += values[k];
            apart += ((times[k] - scalar[k]).abs() > AGREE_S) as usize;
        }
    }
    black_box(sum);
    apart
}

/// Times this close are the same crossing (the one-pixel solve stops within 1e-10 s; events
/// are written in microseconds).
const AGREE_S: f64 = 1e-9;

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx2,fma")]
unsafe fn vector_pass_avx512(blocks: &[LaneBlock], scalar_s: &[f64]) -> usize {
    vector_pass_lanes(blocks, scalar_s)
}

/// `vector_pass_lanes` in AVX-512 where the CPU has it (as the dense path runs), else plain.
fn vector_pass(blocks: &[LaneBlock], scalar_s: &[f64]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if common::has_avx512() {
        // SAFETY: the CPU supports AVX-512F and DQ, checked just above.
        return unsafe { vector_pass_avx512(blocks, scalar_s) };
    }
    vector_pass_lanes(blocks, scalar_s)
}

/// The best of `repeats` timings of `pass`, seconds.
fn best_of(repeats: usize, mut pass: impl FnMut()) -> f64 {
    (0..repeats)
        .map(|_| {
            let start = Instant::now();
            pass();
            start.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let frames_n: usize = args.first().map_or(100, |n| n.parse().expect("frames"));
    let scene = args.get(1).map_or("sinusoid", String::as_str);
    let size = args.get(2).map_or(DAVIS346, |size| {
        let (w, h) = size.split_once('x').expect("size as WIDTHxHEIGHT");
        (w.parse().expect("width"), h.parse().expect("height"))
    });
    let (step, contrast) = match scene {
        "sinusoid" => SINUSOID,
        "sinusoid-dense" => DENSE_SINUSOID,
        other => panic!("unknown scene {other}: sinusoid or sinusoid-dense"),
    };
    let frames = sinusoid_scene(frames_n, step, contrast, size);
    let updates = ((frames_n - 1) * size.0 * size.1) as f64;
    let params = davis346(size.0, size.1);
    let mut silent = params.clone();
    (silent.theta_on, silent.theta_off) = (10.0, 10.0);

    let mut events = 0;
    let full_s = best_of(3, || {
        events = run(primed(&params, &frames), &frames, FRAME_US)
    });
    let mut silent_events = 0;
    let quiet_s = best_of(3, || {
        silent_events = run(primed(&silent, &frames), &frames, FRAME_US)
    });
    let (full_ns, quiet_ns) = (full_s * 1e9 / updates, quiet_s * 1e9 / updates);
    let rate = events as f64 / updates;
    println!(
        "{scene} {}x{}, {} frames, full davis346 model: {full_ns:.1} ns an update, {events} \
         events ({rate:.3} a pixel a frame)",
        size.0, size.1, frames_n
    );
    println!(
        "  the same without crossings (thresholds 10): {quiet_ns:.1} ns an update \
         ({silent_events} noise events): the events' share is {:.1} ns an update, {:.0} ns an \
         event",
        full_ns - quiet_ns,
        (full_ns - quiet_ns) / rate
    );

    let frame_s = FRAME_US as f64 * 1e-6;
    let floor_of =
        |pass| quiet_floor::time_pass(&params, &frames, frame_s, pass, 5) * 1e9 / updates;
    let (memory_ns, arithmetic_ns, both_ns) = (
        floor_of(quiet_floor::Pass::Memory),
        floor_of(quiet_floor::Pass::Arithmetic),
        floor_of(quiet_floor::Pass::Both),
    );
    println!(
        "  quiet floor (what every update needs, nothing else): its fields streamed \
         {memory_ns:.1} ns, its arithmetic on cached states {arithmetic_ns:.1} ns, both over \
         the sensor's states {both_ns:.1} ns an update"
    );

    let crossings = record_crossings(&params, &frames);
    let draws_what = "the random numbers and writing the event out";
    let mut out = Vec::with_capacity(crossings.len());
    let per_event_ns = |s: f64| s * 1e9 / crossings.len() as f64;
    let solve_ns = per_event_ns(best_of(5, || {
        floor_pass(&crossings, &params, Part::Solve, &mut out)
    }));
    let draws_ns = per_event_ns(best_of(5, || {
        floor_pass(&crossings, &params, Part::Draws, &mut out)
    }));
    let floor_ns = per_event_ns(best_of(5, || {
        floor_pass(&crossings, &params, Part::Whole, &mut out)
    }));
    println!(
        "  event floor over {} recorded single crossings ({:.0} % of the events): {floor_ns:.1} \
         ns an event (the solve alone {solve_ns:.1}, {draws_what} alone {draws_ns:.1})",
        crossings.len(),
        100.0 * crossings.len() as f64 / events as f64
    );
    let scalar_s: Vec<f64> = crossings
        .iter()
        .map(|c| {
            let (near, level) = if c.on {
                (c.d, c.theta_on)
            } else {
                (c.d.negated(), c.theta_off)
            };
            near.first_reach(level, c.horizon_s).unwrap_or(f64::NAN)
        })
        .collect();
    let blocks = lane_blocks(&crossings);
    let mut apart = 0;
    let vector_ns = best_of(5, || apart = vector_pass(&blocks, &scalar_s)) * 1e9
        / (blocks.len() * LANES) as f64;
    println!(
        "  the solve and both exponentials {LANES} crossings at a time ({HALLEY_STEPS} Halley \
         steps, branch-free): {vector_ns:.1} ns an event, {apart} of {} times further than \
         {AGREE_S:.0e} s from the one-pixel solve's; {draws_what} one at a time: {draws_ns:.1} ns",
        blocks.len() * LANES
    );
    let bound_ns = quiet_ns + rate * floor_ns;
    println!(
        "  floor of a one-pixel-at-a-time event path: {quiet_ns:.1} + {rate:.3} x {floor_ns:.1} \
         = {bound_ns:.1} ns an update; the full model takes {:.2}x that",
        full_ns / bound_ns
    );
    let vector_bound_ns = quiet_ns + rate * (vector_ns + draws_ns);
    println!(
        "  floor of a path solving a block's crossings together: {quiet_ns:.1} + {rate:.3} x \
         ({vector_ns:.1} + {draws_ns:.1}) = {vector_bound_ns:.1} ns an update; the full model \
         takes {:.2}x that",
        full_ns / vector_bound_ns
    );
    let model_floor_ns = both_ns + rate * (vector_ns + draws_ns);
    println!(
        "  the least an update of this model can cost here (quiet floor, events solved \
         together): {both_ns:.1} + {rate:.3} x ({vector_ns:.1} + {draws_ns:.1}) = \
         {model_floor_ns:.1} ns; the full model takes {:.2}x that",
        full_ns / model_floor_ns
    );
}
