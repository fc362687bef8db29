//! The threshold crossings of a block's pixels that `step_quiet` could not rule out, found
//! together: where many pixels fire (a moving pattern), an event's crossing time is its costliest
//! single part, a Halley solve whose steps each wait on an exponential and a division, and whose
//! branches depend on the data. Solved one pixel at a time it took 63 ns an event on the
//! drifting sinusoid (`benches/event_floor.rs`); here every lane of the block takes the same
//! steps in vector code, each lane's result kept once it has converged.
//!
//! Each lane does what `Difference::first_reach` does, operation for operation (the test at the
//! start, the bound, the split at the extremum, the bracketed Halley steps from the secant's
//! guess, to the same tolerance), first for +theta_on within the horizon and then for -theta_off
//! up to the ON crossing, as `PixelModel::next_happening` takes them: the results are the same
//! bits. A lane it cannot follow exactly (a linear difference, an exponential outside
//! `exp_in_range`'s range, more steps than `MAX_STEPS`) is left to the one-pixel path.

// Index loops over a block's lanes: written over iterators, the compiler leaves them scalar
// (`step_quiet`'s note).
#![allow(clippy::needless_range_loop)]

use super::Differences;
use crate::cpu_dispatch::compiled_per_cpu;
use crate::crossing::{lesser, TOLERANCE_S};
use crate::exp::{exp_in_range, in_exp_range};
use crate::state_block::LANES;

/// The first crossings of a block's pixels over the frame (seconds from the frame's start).
pub struct FirstCrossings {
    pub on_s: [f64; LANES],
    pub off_s: [f64; LANES],
    /// Bit k: pixel k crosses +theta_on (at `on_s[k]`); likewise -theta_off.
    pub on: u32,
    pub off: u32,
    /// Bit k: pixel k's crossings were found here (the others are the one-pixel path's).
    pub found: u32,
}

compiled_per_cpu! {
    /// The first crossings of the pixels of `lanes` (bit k: pixel k; each `usable` in
    /// `differences`) with thresholds `theta_on` and `theta_off`.
    pub fn first_crossings(
        differences: &Differences,
        theta_on: &[f64; LANES],
        theta_off: &[f64; LANES],
        lanes: u32,
    ) -> FirstCrossings = first_crossings_lanes, avx512 first_crossings_avx512,
        avx2 first_crossings_avx2;
}

#[inline(always)]
fn first_crossings_lanes(
    d: &Differences,
    theta_on: &[f64; LANES],
    theta_off: &[f64; LANES],
    lanes: u32,
) -> FirstCrossings {
    // Each side's first two tests over the horizon, as first_reach starts: past its level now,
    // or below it throughout by the bound. A side below it is below it over any shorter span
    // too (the bound grows with the span), so where one side is, only the other needs solving
    // over the horizon: next_happening, which looks for OFF up to the ON crossing, finds none
    // on the ruled-out side either way. A lane with neither side ruled out is left alone.
    let active = flags_of(lanes);
    let mut sign = [1.0; LANES];
    let mut level = [0.0; LANES];
    let mut open = [false; LANES];
    let mut solved_side_below = [false; LANES];
    for k in 0..LANES {
        let (a, m, c, inv_tau, h) = (d.a[k], d.m[k], d.c[k], d.inv_tau[k], d.horizon_s[k]);
        let on_below = below_throughout(a, m, c, inv_tau, h, theta_on[k]);
        let off_below = below_throughout(-a, -m, -c, inv_tau, h, theta_off[k]);
        let solves_on = off_below;
        sign[k] = if solves_on { 1.0 } else { -1.0 };
        level[k] = if solves_on { theta_on[k] } else { theta_off[k] };
        open[k] = active[k] && (on_below || off_below);
        solved_side_below[k] = if solves_on { on_below } else { off_below };
    }
    let s_turn = extremum_times(d, bits(&open));
    let reach = reach_lanes(d, &sign, &level, &solved_side_below, &s_turn, &open);
    let mut on = [false; LANES];
    let mut off = [false; LANES];
    for k in 0..LANES {
        on[k] = reach.hit[k] && sign[k] > 0.0;
        off[k] = reach.hit[k] && sign[k] < 0.0;
    }
    FirstCrossings {
        on_s: reach.s,
        off_s: reach.s,
        on: bits(&on),
        off: bits(&off),
        found: bits(&reach.decided),
    }
}

/// Whether a + m s + c e^{-s/tau} stays below `level` over [0, s_max] by `first_reach`'s first
/// two tests: not past it now, and `Difference::upper_bound` below it.
#[inline(always)]
#[allow(clippy::neg_cmp_op_on_partial_ord)] // a NaN now is not past the level, as there
fn below_throughout(a: f64, m: f64, c: f64, inv_tau: f64, s_max: f64, level: f64) -> bool {
    let now = a + c + m * 0.0;
    let loose = a + (m * s_max).max(0.0) + c.max(0.0);
    let tangent = a + c + ((m - c * inv_tau) * s_max).max(0.0);
    let bound = if c >= 0.0 {
        loose
    } else {
        lesser(loose, tangent)
    };
    !(now >= level) && bound < level
}

/// Where d has its one extremum (m tau / c in (0, 1)), its time -tau ln(m tau / c); infinity
/// elsewhere. The same for -d (the ratio's signs cancel). With the C library's logarithm, as
/// `first_reach` takes it: a scalar call for each lane of `lanes` that has one.
#[inline(always)]
fn extremum_times(d: &Differences, lanes: u32) -> [f64; LANES] {
    let mut ratio = [0.0; LANES];
    let mut turns = [false; LANES];
    for k in 0..LANES {
        ratio[k] = d.m[k] * d.tau[k] / d.c[k];
        turns[k] = ratio[k] > 0.0 && ratio[k] < 1.0;
    }
    // The few lanes that turn (2 % on the sinusoid) found by their bits: a test of each lane in
    // the scalar loop would be a branch the processor mispredicts.
    let mut s_turn = [f64::INFINITY; LANES];
    let mut left = lanes & bits(&turns);
    while left != 0 {
        let k = left.trailing_zeros() as usize;
        left &= left - 1;
        s_turn[k] = -d.tau[k] * ratio[k].ln();
    }
    s_turn
}

/// One side's first crossings: each lane's time (`s`), whether it crosses (`hit`), and whether
/// it was followed to the end (`decided`).
struct Reach {
    s: [f64; LANES],
    hit: [bool; LANES],
    decided: [bool; LANES],
}

/// `Difference::first_reach(level, horizon)` of `sign` d (+1 or -1 a lane: negation is exact)
/// for every `open` lane, given which are below `level` throughout by `below_throughout`
/// (worked out for the side's choice), branch-free, in loops of at most one exponential each
/// (with two, the compiler leaves a loop scalar), each skipped where no lane needs it.
#[inline(always)]
fn reach_lanes(
    d: &Differences,
    sign: &[f64; LANES],
    level: &[f64; LANES],
    below: &[bool; LANES],
    s_turn: &[f64; LANES],
    open: &[bool; LANES],
) -> Reach {
    let terms = |k: usize| {
        let sign = sign[k];
        (sign * d.a[k], sign * d.m[k], sign * d.c[k], d.inv_tau[k])
    };
    // first_reach's start: past the level now (`at_start`); below it throughout by the bound
    // (`below`, given); else the first monotone piece, to the extremum or the horizon.
    let mut at_start = [false; LANES];
    let mut first_end = [0.0; LANES];
    let mut needs_end = false;
    for k in 0..LANES {
        let (a, m, c, _) = terms(k);
        let s_max = d.horizon_s[k];
        at_start[k] = a + c + m * 0.0 >= level[k];
        first_end[k] = s_turn[k].min(s_max);
        needs_end |= open[k] && !at_start[k] && !below[k];
    }
    // The value at the first piece's end, where a lane needs it.
    let mut d_end = [0.0; LANES];
    let mut end_fine = [true; LANES];
    if needs_end {
        for k in 0..LANES {
            let (a, m, c, inv_tau) = terms(k);
            (d_end[k], end_fine[k]) = at(a, m, c, inv_tau, first_end[k]);
        }
    }
    // The second piece's end, the horizon, where a lane turns before it and the first piece
    // stays below the level.
    let mut on_first = [false; LANES];
    let mut needs_max = false;
    for k in 0..LANES {
        on_first[k] = d_end[k] >= level[k];
        let undecided = open[k] && !at_start[k] && !below[k];
        needs_max |= undecided && !on_first[k] && s_turn[k] < d.horizon_s[k];
    }
    let mut d_max = [0.0; LANES];
    let mut max_fine = [true; LANES];
    if needs_max {
        for k in 0..LANES {
            let (a, m, c, inv_tau) = terms(k);
            (d_max[k], max_fine[k]) = at(a, m, c, inv_tau, d.horizon_s[k]);
        }
    }
    // The piece the crossing is on, if any.
    let mut piece_lo = [0.0; LANES];
    let mut piece_hi = [0.0; LANES];
    let mut d_hi = [0.0; LANES];
    let mut crosses = [false; LANES];
    let mut fine = [false; LANES];
    let mut needs_lo = false;
    for k in 0..LANES {
        let (_, _, c, _) = terms(k);
        let s_max = d.horizon_s[k];
        let turns_before_end = s_turn[k] < s_max;
        let second = !on_first[k] && turns_before_end && d_max[k] >= level[k];
        (piece_lo[k], piece_hi[k], d_hi[k]) = if on_first[k] {
            (0.0, first_end[k], d_end[k])
        } else {
            (s_turn[k], s_max, d_max[k])
        };
        crosses[k] = !at_start[k] && !below[k] && (on_first[k] || second);
        fine[k] = at_start[k]
            || below[k]
            || (c != 0.0 && end_fine[k] && (on_first[k] || !turns_before_end || max_fine[k]));
        needs_lo |= open[k] && crosses[k] && !on_first[k];
    }
    // solve_monotone's start on the piece: its low end (the extremum, for the second piece)
    // itself if already past, else the secant's guess.
    let mut d_lo = [0.0; LANES];
    let mut lo_fine = [true; LANES];
    for k in 0..LANES {
        let (a, m, c, _) = terms(k);
        d_lo[k] = a + c + m * 0.0;
    }
    if needs_lo {
        for k in 0..LANES {
            let (a, m, c, inv_tau) = terms(k);
            (d_lo[k], lo_fine[k]) = at(a, m, c, inv_tau, piece_lo[k]);
        }
    }
    let mut r = Reach {
        s: [0.0; LANES],
        hit: [false; LANES],
        decided: [false; LANES],
    };
    let mut lo = [0.0; LANES];
    let mut hi = [0.0; LANES];
    let mut s = [0.0; LANES];
    let mut solving = [false; LANES];
    for k in 0..LANES {
        let f_lo = d_lo[k] - level[k];
        let f_hi = d_hi[k] - level[k];
        let (p_lo, p_hi) = (piece_lo[k], piece_hi[k]);
        let guess = if f_hi > 0.0 {
            p_lo + (p_hi - p_lo) * (-f_lo / (f_hi - f_lo))
        } else {
            p_hi
        };
        let starts_past = f_lo >= 0.0;
        let followed = open[k] && fine[k] && (!crosses[k] || lo_fine[k]);
        r.decided[k] = followed && (starts_past || !crosses[k]);
        r.hit[k] = followed && (at_start[k] || (crosses[k] && starts_past));
        r.s[k] = if at_start[k] { 0.0 } else { p_lo };
        solving[k] = followed && crosses[k] && !starts_past;
        (lo[k], hi[k], s[k]) = (p_lo, p_hi, guess);
    }
    for _ in 0..MAX_STEPS {
        let mut left = 0u32;
        for k in 0..LANES {
            let (a, m, c, inv_tau) = terms(k);
            let level = level[k];
            let (s_now, lo_now, hi_now) = (s[k], lo[k], hi[k]);
            // solve_monotone's step: d, d' and d'' from one exponential.
            let arg = -s_now * inv_tau;
            let decay = c * exp_in_range(arg);
            let f = a + m * s_now + decay - level;
            let past = f >= 0.0;
            let hi_new = if past { s_now } else { hi_now };
            let lo_new = if past { lo_now } else { s_now };
            let slope = m - decay * inv_tau;
            let curvature = decay * inv_tau * inv_tau;
            let step = 2.0 * f * slope / (2.0 * slope * slope - f * curvature);
            let next = s_now - step;
            let converging = slope > 0.0 && next >= lo_new && next <= hi_new;
            let done = hi_new - lo_new <= TOLERANCE_S || (converging && step.abs() <= TOLERANCE_S);
            let root = if past { s_now } else { next };
            let going = solving[k];
            // A lane that ends here keeps its root; one whose exponential left the range stops,
            // undecided.
            let fine = in_exp_range(arg);
            let ends = going && done && fine;
            r.s[k] = if ends { root } else { r.s[k] };
            r.hit[k] |= ends;
            r.decided[k] |= ends;
            let goes_on = going && !done && fine;
            solving[k] = goes_on;
            lo[k] = if going { lo_new } else { lo_now };
            hi[k] = if going { hi_new } else { hi_now };
            let bisected = 0.5 * (lo_new + hi_new);
            s[k] = if goes_on {
                if converging {
                    next
                } else {
                    bisected
                }
            } else {
                s_now
            };
            left |= (goes_on as u32) << k;
        }
        if left == 0 {
            break;
        }
    }
    r
}

/// `Difference::at(s)` of a + m s + c e^{-s/tau} (c nonzero), and whether its exponential is
/// within `exp_in_range`'s range (or not taken, at s = 0). Both forms are worked out and one
/// picked: an exponential (a table look-up) on one branch only leaves the loop scalar.
#[inline(always)]
fn at(a: f64, m: f64, c: f64, inv_tau: f64, s: f64) -> (f64, bool) {
    let arg = -s * inv_tau;
    let curve = a + m * s + c * exp_in_range(arg);
    let start = a + c + m * s;
    if s == 0.0 {
        (start, true)
    } else {
        (curve, in_exp_range(arg))
    }
}

/// Steps a lane may take before it is left to the one-pixel path: the solve needs 2.1 on average
/// on the sinusoid (its own limit is 100).
const MAX_STEPS: usize = 8;

#[inline(always)]
fn flags_of(bits: u32) -> [bool; LANES] {
    let mut flags = [false; LANES];
    for (k, flag) in flags.iter_mut().enumerate() {
        *flag = (bits >> k) & 1 != 0;
    }
    flags
}

#[inline(always)]
fn bits(flags: &[bool; LANES]) -> u32 {
    crate::state_block::bits_of(flags)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crossing::Difference;
    use crate::rng::{Draw, Stream};

    #[test]
    fn finds_the_crossings_first_reach_finds_to_the_bit() {
        // Differences of every shape around both thresholds (convex and concave, with and
        // without an extremum inside the horizon, starting past a level, drifting either way),
        // 32 at a time; each lane found must hold exactly what next_happening's two first_reach
        // calls give (ON within the horizon, OFF up to the ON crossing).
        let (mut lanes, mut found, mut crossed, mut second_piece) = (0, 0, 0, 0);
        for batch in 0..4_000u64 {
            let mut d = Differences::new();
            let (mut theta_on, mut theta_off) = ([0.0; LANES], [0.0; LANES]);
            for k in 0..LANES {
                let i = batch * LANES as u64 + k as u64;
                let u = |j: u64| Draw::new(11, i, j).uniform(Stream::Theta);
                let tau = [1e-4, 5e-4, 2e-3][i as usize % 3];
                let curve = Difference::new(
                    0.5 * (2.0 * u(0) - 1.0),
                    [0.0, 40.0, -40.0, 400.0, -400.0][(i / 3) as usize % 5] * u(1),
                    [0.4 * (2.0 * u(2) - 1.0), 0.0][(u(6) < 0.02) as usize],
                    tau,
                );
                (d.a[k], d.m[k], d.c[k]) = (curve.a, curve.m, curve.c);
                (d.tau[k], d.inv_tau[k], d.horizon_s[k]) = (tau, curve.inv_tau, 1e-3 * u(3));
                (theta_on[k], theta_off[k]) = (0.1 + 0.2 * u(4), 0.1 + 0.2 * u(5));
            }
            let got = first_crossings(&d, &theta_on, &theta_off, u32::MAX);
            // Each instruction set's build gives the same: the plain one, and those this CPU
            // runs.
            let plain = first_crossings_lanes(&d, &theta_on, &theta_off, u32::MAX);
            let mut builds = vec![plain];
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: the CPU supports AVX2 and FMA, checked just above.
                    builds
                        .push(unsafe { first_crossings_avx2(&d, &theta_on, &theta_off, u32::MAX) });
                }
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: the CPU supports AVX-512F, checked just above.
                    builds.push(unsafe {
                        first_crossings_avx512(&d, &theta_on, &theta_off, u32::MAX)
                    });
                }
            }
            for build in &builds {
                assert_eq!(
                    (build.found, build.on, build.off),
                    (got.found, got.on, got.off)
                );
                for k in (0..LANES).filter(|&k| (got.found >> k) & 1 != 0) {
                    assert_eq!(build.on_s[k].to_bits(), got.on_s[k].to_bits());
                    assert_eq!(build.off_s[k].to_bits(), got.off_s[k].to_bits());
                }
            }
            for k in 0..LANES {
                lanes += 1;
                let curve = Difference {
                    a: d.a[k],
                    m: d.m[k],
                    c: d.c[k],
                    tau: d.tau[k],
                    inv_tau: d.inv_tau[k],
                };
                let horizon = d.horizon_s[k];
                let on = curve.first_reach(theta_on[k], horizon);
                let best = on.map_or(horizon, |s| s.max(0.0));
                let off = curve.negated().first_reach(theta_off[k], best);
                if (got.found >> k) & 1 == 0 {
                    continue;
                }
                found += 1;
                let bit = |bits: u32| (bits >> k) & 1 != 0;
                let mine = (
                    bit(got.on).then_some(got.on_s[k]),
                    bit(got.off).then_some(got.off_s[k]),
                );
                assert_eq!(
                    (mine.0.map(f64::to_bits), mine.1.map(f64::to_bits)),
                    (on.map(f64::to_bits), off.map(f64::to_bits)),
                    "{curve:?} on {} off {} horizon {horizon}",
                    theta_on[k],
                    theta_off[k]
                );
                crossed += (on.is_some() || off.is_some()) as usize;
                let ratio = curve.m * curve.tau / curve.c;
                second_piece += (ratio > 0.0 && ratio < 1.0 && on.is_some()) as usize;
            }
        }
        // Most lanes are found (the others: a linear difference, or both sides open), many of
        // them crossing, some on the second monotone piece.
        assert!(
            found > lanes * 3 / 4 && crossed > lanes / 10 && second_piece > 1_000,
            "{found} found, {crossed} crossing, {second_piece} past an extremum, of {lanes}"
        );
    }
}
