//! The sensor against itself with its shortcuts off (skipping, the dense path, lazy states, one
//! thread), and its refusals and their messages.

use super::noise_gap::duration;
use super::*;
use crate::params::ReferenceReset;

/// A mostly static scene: a bright square moving over a textured background.
fn frames(width: usize, height: usize, n: usize) -> Vec<Vec<f32>> {
    (0..n)
        .map(|k| {
            (0..width * height)
                .map(|i| {
                    let (x, y) = (i % width, i / width);
                    let background = 0.1 + 0.05 * ((x * 7 + y * 13) % 11) as f32;
                    let inside = x >= 3 + 2 * k && x < 13 + 2 * k && (10..20).contains(&y);
                    if inside {
                        0.9
                    } else {
                        background
                    }
                })
                .collect()
        })
        .collect()
}

fn run(params: &SensorParams, never_skip: bool) -> Vec<EventColumns> {
    let mut sensor = EventSensor::new(params.clone()).unwrap();
    sensor.never_skip = never_skip;
    let mut out = Vec::new();
    for (k, frame) in frames(params.width, params.height, 12).iter().enumerate() {
        out.push(sensor.feed(frame, 1000 * k as i64 + 7).unwrap());
        if k == 0 && never_skip {
            // Every pixel a state and a step, every frame: no lazy bands either.
            sensor.tiles.iter_mut().for_each(Tile::without_lazy_bands);
        }
    }
    out.push(sensor.flush().unwrap());
    out
}

/// Every part of the pixel model on, noise at rates that make it happen within a few frames
/// 1 ms apart.
fn every_noise(width: usize, height: usize) -> SensorParams {
    SensorParams {
        theta_sigma: 0.03,
        theta_noise: 0.02,
        refractory_us: 200.0,
        cutoff_hz: 800.0,
        cutoff_half_photocurrent: 0.2,
        latency_us: 30.0,
        jitter_us: 10.0,
        leak_rate_hz: 5.0,
        leak_spread_decades: 0.3,
        // Leak that follows the light, at a stated light level.
        leak_light_rate_hz: 20.0,
        white_lux: 3000.0,
        shot_rate_hz: 30.0,
        hot_pixel_fraction: 0.01,
        hot_pixel_rate_hz: 300.0,
        ..SensorParams::ideal(width, height)
    }
}

#[test]
fn skipping_quiet_pixels_changes_no_event() {
    let mut esim = SensorParams::ideal(40, 30);
    esim.reference_reset = ReferenceReset::Event;
    esim.refractory_us = 300.0;
    esim.hot_pixel_fraction = 0.05;
    esim.hot_pixel_rate_hz = 400.0;
    let full = every_noise(40, 30);
    // Time-invariant with a reset held for a refractory period: woken to release it.
    let mut held = SensorParams::ideal(40, 30);
    held.refractory_us = 1500.0;
    held.hot_pixel_fraction = 0.05;
    held.hot_pixel_rate_hz = 400.0;
    for params in [SensorParams::ideal(40, 30), esim, held, full] {
        let skipping = run(&params, false);
        let stepping = run(&params, true);
        assert!(stepping.iter().map(|c| c.len()).sum::<usize>() > 100);
        assert_eq!(skipping, stepping, "{params:?}");
    }
}

/// Frames in which every pixel changes: a random texture under 2 % fresh grain, with a
/// jump on about one pixel in 20 (crossings, resets held, events of every kind) and one in
/// 10 held still (wake-ups of a held input).
fn grainy_frames(width: usize, height: usize, n: usize) -> Vec<Vec<f32>> {
    use crate::rng::{Draw, Stream};
    let draw =
        |i: usize, k: usize, stream: Stream| Draw::new(5, i as u64, k as u64).uniform(stream);
    let texture: Vec<f32> = (0..width * height)
        .map(|i| (0.02 + draw(i, 0, Stream::Theta)) as f32)
        .collect();
    let mut frames = vec![texture];
    for k in 1..n {
        let last = &frames[k - 1];
        let frame = (0..width * height)
            .map(|i| match draw(i, k, Stream::HotSelect) {
                u if u < 0.1 => last[i],
                u if u < 0.15 => (0.02 + draw(i, k, Stream::LeakPhase)) as f32,
                _ => frames[0][i] * (1.0 + 0.02 * (draw(i, k, Stream::Jitter) - 0.5)) as f32,
            })
            .collect();
        frames.push(frame);
    }
    frames
}

/// `frames` fed 1 ms apart and flushed on a pool of `threads`, with `after_start` applied
/// to every tile once the first frame has made them: the events, and the sensor.
fn feed_on_threads(
    params: &SensorParams,
    frames: &[Vec<f32>],
    threads: usize,
    after_start: &(dyn Fn(&mut Tile) + Sync),
) -> (Vec<EventColumns>, EventSensor) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut sensor = EventSensor::new(params.clone()).unwrap();
        let mut out = Vec::new();
        for (k, frame) in frames.iter().enumerate() {
            out.push(sensor.feed(frame, 1000 * k as i64).unwrap());
            if k == 0 {
                sensor.tiles.iter_mut().for_each(after_start);
            }
        }
        out.push(sensor.flush().unwrap());
        (out, sensor)
    })
}

#[test]
fn the_dense_path_gives_the_events_and_states_of_the_one_pixel_path_on_any_thread_count() {
    // Every noise source on, at rates that make them happen within 20 frames; both reset
    // rules; both shot-noise laws; and the DAVIS346 preset (python/pecs/config.py). 127 x 81
    // is 3 tiles, the last ending in a block of 15 pixels (the dense path pads it). Ten
    // still frames at the end: the wake-up bounds the dense steps left unknown are worked
    // out, and the noise of a constant input comes at them.
    let (width, height) = (127, 81);
    let noisy = every_noise(width, height);
    let mut noisy_esim_reset = noisy.clone();
    noisy_esim_reset.reference_reset = ReferenceReset::Event;
    let mut davis346 = noisy.clone();
    (
        davis346.theta_noise,
        davis346.refractory_us,
        davis346.cutoff_hz,
    ) = (0.01, 500.0, 300.0);
    (davis346.cutoff_half_photocurrent, davis346.dark_current) = (0.1, 1e-4);
    (davis346.latency_us, davis346.jitter_us, davis346.white_lux) = (20.0, 5.0, 1000.0);
    (davis346.leak_rate_hz, davis346.leak_light_rate_hz) = (0.001, 0.0004);
    (davis346.shot_rate_hz, davis346.hot_pixel_fraction) = (10.0, 1e-4);
    davis346.hot_pixel_rate_hz = 5.0;
    // Shot noise falling with the square of light, from a dark current high enough that it
    // still comes at this light (0.1 / 1.6 squared, 1000 Hz: about 4 Hz).
    let mut steep_shot = noisy.clone();
    steep_shot.shot_light_exponent = 2.0;
    (steep_shot.dark_current, steep_shot.shot_rate_hz) = (0.1, 1000.0);
    // A reset longer than a frame: a pixel is held through the frame after its event, and
    // released in the one after that.
    let mut long_reset = davis346.clone();
    long_reset.refractory_us = 1500.0;
    let mut frames = grainy_frames(width, height, 20);
    frames.extend(std::iter::repeat_n(frames[19].clone(), 10));
    let run = |params: &SensorParams, dense: bool, threads: usize| {
        let keep = |_: &mut Tile| {};
        let one_by_one: fn(&mut Tile) = Tile::without_dense_path;
        let (out, sensor) = feed_on_threads(
            params,
            &frames,
            threads,
            if dense { &keep } else { &one_by_one },
        );
        let states: Vec<_> = sensor.tiles.iter().map(|t| t.states().to_vec()).collect();
        let dense_steps: usize = sensor.tiles.iter().map(|t| t.dense_steps).sum();
        let gated = sensor.tiles.iter().fold([0, 0], |[without, with], t| {
            [without + t.gated_blocks[0], with + t.gated_blocks[1]]
        });
        let unknown: usize = sensor.tiles.iter().map(|t| t.wakes_left_unknown).sum();
        let held: usize = sensor.tiles.iter().map(|t| t.dense_held_steps).sum();
        let found: usize = sensor.tiles.iter().map(|t| t.crossings_found).sum();
        let finished: usize = sensor.tiles.iter().map(|t| t.events_finished).sum();
        (
            out,
            states,
            (dense_steps, gated, unknown, held, found, finished),
        )
    };
    // Leak, shot and hot-pixel events too (also in the still frames), but from the
    // DAVIS346's rates in 29 ms.
    let noisy_all_causes = (4, 4);
    for (params, causes) in [
        (noisy, noisy_all_causes),
        (noisy_esim_reset, noisy_all_causes),
        (davis346, (2, 2)),
        (long_reset, (2, 2)),
        (steep_shot, noisy_all_causes),
    ] {
        let (one_by_one, states, (none, _, none_unknown, _, none_found, _)) =
            run(&params, false, 1);
        let events: usize = one_by_one.iter().map(EventColumns::len).sum();
        assert!(
            events > 2000 && none == 0 && none_unknown == 0 && none_found == 0,
            "{events} events"
        );
        let labels_of = |batches: &[EventColumns]| -> std::collections::HashSet<u8> {
            batches
                .iter()
                .flat_map(|c| c.label.iter().copied())
                .collect()
        };
        let labels = labels_of(&one_by_one);
        // The still frames' events (their noise) have causes of their own.
        let still_labels = labels_of(&one_by_one[20..]);
        assert!(labels.len() >= causes.0, "causes {labels:?}");
        assert!(still_labels.len() >= causes.1, "still {still_labels:?}");
        for threads in [1, 2, 3] {
            let (dense, dense_states, (steps, gated, unknown, held, found, finished)) =
                run(&params, true, threads);
            // Most of the 19 x 10,240 updates are quiet, and went through the dense path.
            assert!(steps > 19 * width * height / 2, "{steps} dense steps");
            // The others (an event, a reset to release) were stepped one at a time, their
            // wake-up bounds left for the still frames to work out.
            assert!(unknown > 100, "{unknown} wake-up bounds left unknown");
            // Blocks with a hot pixel or a pixel held in reset, whose gates the dense path
            // reads, and blocks without.
            assert!(
                gated[0] > 0 && gated[1] > 0,
                "{gated:?} without and with gates"
            );
            // Pixels held in reset at a frame's start, released within it or held through it
            // (the refractory rule alone).
            let holds = params.reference_reset == ReferenceReset::RefractoryEnd;
            assert!(holds == (held > 100), "{held} held pixels stepped densely");
            // The pixels that fire (5 % of them jump each frame): their crossings found a
            // tile's at a time (`dense::first_crossings`), released pixels' too.
            assert!(found > 10_000, "{found} pixels' crossings found together");
            // Of those, the pixels that fire once and are then held past the frame's end had
            // their frames finished together (`dense::finish_single_events`): 1.4-7 k a set,
            // with the reset held for a refractory period (ESIM's reset moves the reference).
            assert!(
                holds == (finished > 1000) && (holds || finished == 0),
                "{finished} single events finished together"
            );
            assert!(dense == one_by_one, "{threads} threads: events differ");
            assert!(dense_states == states, "{threads} threads: states differ");
        }
    }
}

#[test]
fn lazy_bands_give_the_events_of_a_state_for_every_changed_pixel() {
    // Time-invariant models that never wake (ideal, ESIM's reset, threshold mismatch):
    // a pixel whose first change stays in its band gets no state. Every pixel changes in
    // every frame (grain), about one in 20 jumps: the same events, on any thread count, as
    // with a state made and stepped at every pixel's first change, with far fewer states.
    let (width, height) = (128, 80);
    let mut esim = SensorParams::ideal(width, height);
    esim.reference_reset = ReferenceReset::Event;
    let mut mismatched = SensorParams::ideal(width, height);
    mismatched.theta_sigma = 0.03;
    mismatched.latency_us = 30.0;
    mismatched.jitter_us = 10.0;
    let frames = grainy_frames(width, height, 20);
    let run = |params: &SensorParams, lazy: bool, threads: usize| {
        let keep = |_: &mut Tile| {};
        let eager: fn(&mut Tile) = Tile::without_lazy_bands;
        let (out, sensor) =
            feed_on_threads(params, &frames, threads, if lazy { &keep } else { &eager });
        let states: usize = sensor.tiles.iter().map(Tile::state_count).sum();
        (out, states)
    };
    for params in [SensorParams::ideal(width, height), esim, mismatched] {
        let (eager, eager_states) = run(&params, false, 1);
        let events: usize = eager.iter().map(EventColumns::len).sum();
        assert!(events > 1000, "{events} events");
        assert_eq!(eager_states, width * height);
        for threads in [1, 2, 3] {
            let (lazy, lazy_states) = run(&params, true, threads);
            assert!(lazy == eager, "{threads} threads: events differ");
            // About 1 - 0.95^19 = 62 % of the pixels jump at least once; grain alone stays
            // in the band.
            assert!(10 * lazy_states < 7 * eager_states, "{lazy_states} states");
        }
    }
}

#[test]
fn reference_only_pixels_give_the_events_of_whole_states_on_any_thread_count() {
    // ESIM's model and the ideal sensor keep a reference a pixel (`Tile::references`); the
    // same frames through whole states and `PixelModel::run` give the same events, bit for
    // bit. Grain with jumps (many crossings in one frame, both ways), a dark pixel at 0 and
    // a frame scale other than 1; 127 x 81 is 3 tiles, the last ending in a part block.
    let (width, height) = (127, 81);
    let mut esim = SensorParams::ideal(width, height);
    esim.reference_reset = ReferenceReset::Event;
    let mut scaled = esim.clone();
    (scaled.white_lux, scaled.dark_current, scaled.theta_on) = (300.0, 0.02, 0.15);
    let mut frames = grainy_frames(width, height, 20);
    for frame in &mut frames[3..] {
        frame[5] = 0.0;
    }
    let run = |params: &SensorParams, references: bool, threads: usize| {
        let keep = |_: &mut Tile| {};
        let whole: fn(&mut Tile) = Tile::with_whole_states;
        let hook: &(dyn Fn(&mut Tile) + Sync) = if references { &keep } else { &whole };
        feed_on_threads(params, &frames, threads, hook).0
    };
    for params in [SensorParams::ideal(width, height), esim, scaled] {
        assert!(PixelModel::new(params.clone()).is_reference_only());
        let whole = run(&params, false, 1);
        let events: usize = whole.iter().map(EventColumns::len).sum();
        assert!(events > 5000, "{events} events");
        for threads in [1, 2, 3] {
            assert!(run(&params, true, threads) == whole, "{threads} threads");
        }
    }
    // What a reference cannot hold: threshold mismatch, a refractory period, latency.
    let mut others = Vec::new();
    for change in 0..3 {
        let mut p = SensorParams::ideal(width, height);
        match change {
            0 => p.theta_sigma = 0.03,
            1 => p.refractory_us = 100.0,
            _ => p.latency_us = 10.0,
        }
        others.push(PixelModel::new(p).is_reference_only());
    }
    assert_eq!(others, [false; 3]);
}

#[test]
fn without_labels_the_same_events_come_without_their_label_column() {
    let mut params = SensorParams::ideal(40, 30);
    params.hot_pixel_fraction = 0.05;
    params.hot_pixel_rate_hz = 400.0;
    for latency_us in [0.0, 30.0] {
        params.latency_us = latency_us; // both ways through the queue
        let run = |labels: bool| {
            let mut sensor = EventSensor::new(params.clone())
                .unwrap()
                .with_labels(labels);
            let mut out = Vec::new();
            for (k, frame) in frames(40, 30, 12).iter().enumerate() {
                out.push(sensor.feed(frame, 1000 * k as i64).unwrap());
                if k == 5 {
                    sensor.reset(); // the choice survives a reset
                }
            }
            out.push(sensor.flush().unwrap());
            out
        };
        let (with, without) = (run(true), run(false));
        assert!(with.iter().map(|c| c.len()).sum::<usize>() > 100);
        for (a, b) in with.iter().zip(&without) {
            assert_eq!((&a.t_us, &a.x, &a.y, &a.p), (&b.t_us, &b.x, &b.y, &b.p));
            assert_eq!((a.label.len(), b.label.len()), (a.len(), 0));
        }
    }
}

#[test]
fn a_static_noiseless_scene_gives_no_event() {
    let mut sensor = EventSensor::new(SensorParams::ideal(40, 30)).unwrap();
    let frame = frames(40, 30, 1).remove(0);
    for k in 0..20 {
        assert!(sensor.feed(&frame, k * 1000).unwrap().is_empty());
    }
}

#[test]
fn only_pixels_that_change_or_wake_get_a_state() {
    let (width, height) = (40, 30);
    let mut params = SensorParams::ideal(width, height);
    params.cutoff_hz = 300.0;
    params.cutoff_half_photocurrent = 0.1;
    params.leak_rate_hz = 0.1;
    params.shot_rate_hz = 2.0;
    params.hot_pixel_fraction = 0.01;
    params.hot_pixel_rate_hz = 300.0;
    let mut sensor = EventSensor::new(params).unwrap();
    let states = |s: &EventSensor| s.tiles.iter().map(Tile::state_count).sum::<usize>();
    let static_frame = frames(width, height, 1).remove(0);
    for k in 0..20 {
        sensor.feed(&static_frame, k * 1000).unwrap();
    }
    // 12 hot pixels at 300 Hz wake within 20 ms; leak (0.1 Hz) and shot noise (at most
    // 2 Hz) wake about 1,200 x 2 Hz x 20 ms = 48 more at most.
    let woken = states(&sensor);
    assert!((1..=80).contains(&woken), "{woken} states");
    // The square moves by 2 pixels: its leading and trailing edges change.
    let moving = frames(width, height, 2).remove(1);
    let changed = static_frame
        .iter()
        .zip(&moving)
        .filter(|(a, b)| a != b)
        .count();
    sensor.feed(&moving, 20_000).unwrap();
    let after = states(&sensor);
    assert!(
        changed >= 40 && after >= changed && after <= woken + changed + 10,
        "{after}"
    );
}

#[test]
fn bad_frames_are_refused_without_changing_the_sensor() {
    let mut sensor = EventSensor::new(SensorParams::ideal(4, 2)).unwrap();
    sensor.feed(&[0.5; 8], 0).unwrap();
    let mut bad = [0.5f32; 8];
    bad[5] = f32::NAN;
    assert!(matches!(
        sensor.feed(&bad, 10),
        Err(FeedError::NotFinite { x: 1, y: 1, .. })
    ));
    bad[5] = -1.0;
    assert!(matches!(
        sensor.feed(&bad, 10),
        Err(FeedError::Negative { x: 1, y: 1, .. })
    ));
    assert!(matches!(
        sensor.feed(&[0.5; 7], 10),
        Err(FeedError::Shape {
            expected: 8,
            got: 7
        })
    ));
    assert!(matches!(
        sensor.feed(&[0.5; 8], 0),
        Err(FeedError::Time {
            t_us: 0,
            t_prev_us: 0
        })
    ));
    assert_eq!(sensor.last_time_us(), Some(0));
    // Unchanged: the next good frame gives what a sensor that never saw the bad ones gives.
    let mut fresh = EventSensor::new(SensorParams::ideal(4, 2)).unwrap();
    fresh.feed(&[0.5; 8], 0).unwrap();
    assert_eq!(
        sensor.feed(&[0.9; 8], 10).unwrap(),
        fresh.feed(&[0.9; 8], 10).unwrap()
    );
}

#[test]
fn a_frame_refused_while_the_scan_copies_the_values_leaves_the_sensor_as_it_was() {
    // Grain changes most blocks, so from the second changed frame each tile of ESIM's
    // reference-only pixels copies the values its scan reads into the buffer that becomes
    // the last frame's after the step. A frame refused at its last pixel (every tile
    // scanned and copied by then) must leave the last frame's values: the frames after it
    // give the events of a sensor that never saw it. Whole states (threshold noise) copy
    // after the step instead.
    let (width, height) = (127, 81);
    let frames = grainy_frames(width, height, 12);
    let mut noisy = SensorParams::ideal(width, height);
    (noisy.theta_sigma, noisy.theta_noise) = (0.03, 0.01);
    let mut esim = SensorParams::ideal(width, height);
    esim.reference_reset = ReferenceReset::Event;
    for (params, copies) in [(esim, true), (noisy, false)] {
        let feed = |refuse_at: Option<usize>| {
            let mut sensor = EventSensor::new(params.clone()).unwrap();
            let mut out = Vec::new();
            for (k, frame) in frames.iter().enumerate() {
                if refuse_at == Some(k) {
                    assert!(sensor.tiles.iter().all(|t| t.copies_in_scan() == copies));
                    let mut bad = frame.clone();
                    *bad.last_mut().unwrap() = f32::NAN;
                    let refused = sensor.feed(&bad, 1000 * k as i64 - 500);
                    assert!(matches!(refused, Err(FeedError::NotFinite { .. })));
                }
                out.push(sensor.feed(frame, 1000 * k as i64).unwrap());
            }
            out
        };
        let clean = feed(None);
        assert!(clean.iter().map(EventColumns::len).sum::<usize>() > 1000);
        assert!(feed(Some(6)) == clean);
    }
}

#[test]
fn a_refused_frame_leaves_the_first_wake_ups_of_a_noisy_sensor_as_they_were() {
    // The first wake-ups of pixels without a state are worked out at the first scan after
    // the start, for the pixels whose input stayed; a refused frame in which half of them
    // changed leaves those half unknown, and the next frames work them out one by one: the
    // same noise events, at the same times, as a sensor that never saw the refused frame.
    let (width, height) = (40, 30);
    let params = every_noise(width, height);
    let still = frames(width, height, 1).remove(0);
    let mut bad: Vec<f32> = still.iter().map(|v| v * 1.5).collect();
    bad.truncate(width * height / 2);
    bad.extend_from_slice(&still[width * height / 2..]);
    bad[width * height - 1] = f32::NAN;
    let run = |with_bad: bool| {
        let mut sensor = EventSensor::new(params.clone()).unwrap();
        sensor.feed(&still, 0).unwrap();
        if with_bad {
            assert!(sensor.feed(&bad, 1000).is_err());
        }
        let mut out: Vec<_> = (1..30)
            .map(|k| sensor.feed(&still, 1000 * k).unwrap())
            .collect();
        out.push(sensor.flush().unwrap());
        out
    };
    let fresh = run(false);
    assert!(fresh.iter().map(EventColumns::len).sum::<usize>() > 100);
    assert_eq!(run(true), fresh);
}

fn davis_like(width: usize, height: usize) -> SensorParams {
    let mut p = SensorParams::ideal(width, height);
    p.leak_rate_hz = 0.1;
    p.shot_rate_hz = 2.0;
    p.hot_pixel_fraction = 1e-4;
    p.hot_pixel_rate_hz = 50.0;
    p
}

#[test]
fn a_duration_is_shown_in_the_unit_that_shows_it() {
    assert_eq!(duration(3600.0, 1), "3600.0 s");
    assert_eq!(duration(1e-3, 1), "1.0 ms");
    assert_eq!(duration(0.25, 1), "250.0 ms");
    assert_eq!(duration(5.4248e-4, 3), "542.480 us");
    assert_eq!(duration(1e-6, 1), "1.0 us");
}

#[test]
fn a_gap_with_more_noise_than_one_call_may_give_is_refused_without_change() {
    let (width, height) = (346, 260);
    let mut sensor = EventSensor::new(davis_like(width, height)).unwrap();
    let frame = vec![0.0f32; width * height];
    sensor.feed(&frame, 0).unwrap();
    // 89,960 pixels x (0.1 + 2) Hz + 9 hot pixels x 50 Hz = 189,366 Hz, worked out by hand:
    // 5e7 events take 264.039 s.
    let rate_hz = 89_960.0 * 2.1 + 8.996 * 50.0;
    let max_gap_us = (MAX_EVENTS_PER_FEED as f64 / rate_hz * 1e6) as i64;
    assert_eq!(max_gap_us / 10_000, 26_403);
    let error = sensor.feed(&frame, 1 << 62).unwrap_err();
    assert!(matches!(error, FeedError::TimeRange { .. }), "{error}");
    let error = sensor.feed(&frame, max_gap_us + 1000).unwrap_err();
    let FeedError::TooMuchNoise(work) = &error else {
        panic!("{error}")
    };
    assert!((work.expected_events / MAX_EVENTS_PER_FEED as f64 - 1.0).abs() < 1e-5);
    assert!(
        error.to_string().contains("feed frames at most 264"),
        "{error}"
    );
    assert_eq!(sensor.last_time_us(), Some(0));
    // A gap below the limit is simulated; the estimate is an upper bound of its events
    // (Poisson scatter sqrt(n) ~ 4e3).
    let events = sensor.feed(&frame, 1_000_000).unwrap();
    let n = events.len() as f64;
    assert!(
        n < rate_hz + 5.0 * rate_hz.sqrt() && n > 0.9 * rate_hz,
        "{n}"
    );
}

#[test]
fn a_noiseless_sensor_takes_any_gap_in_range_and_refuses_times_beyond() {
    let mut sensor = EventSensor::new(SensorParams::ideal(4, 2)).unwrap();
    assert!(matches!(
        sensor.feed(&[0.5; 8], i64::MIN),
        Err(FeedError::TimeRange { .. })
    ));
    sensor.feed(&[0.5; 8], -MAX_ABS_TIME_US).unwrap();
    let events = sensor.feed(&[0.9; 8], MAX_ABS_TIME_US).unwrap();
    assert_eq!(events.len(), 8 * 2); // ln(0.901 / 0.501) / 0.2 = 2.9
    assert!(events.t_us.iter().all(|&t| t <= MAX_ABS_TIME_US));
}

/// A dark frame, then one at 3e38 (a valid f32): with thresholds at their minimum of 0.01,
/// each pixel crosses floor(ln((3e38 + 1e-3) / 1e-3) / 0.01) = floor(9550.4) = 9,550 times.
const BRIGHT: f32 = 3e38;
const CROSSINGS_PER_PIXEL: usize = 9_550;

fn fine_thresholds(width: usize, height: usize) -> SensorParams {
    let mut p = SensorParams::ideal(width, height);
    p.theta_on = 0.01;
    p.theta_off = 0.01;
    p
}

/// The events of the dark-to-bright step, with the limit lowered to `max_events`.
fn bright_step(
    params: &SensorParams,
    max_events: usize,
) -> (EventSensor, Result<EventColumns, FeedError>) {
    let mut sensor = EventSensor::new(params.clone()).unwrap();
    sensor.max_events = max_events;
    let pixels = params.width * params.height;
    sensor.feed(&vec![0.0; pixels], 0).unwrap();
    let events = sensor.feed(&vec![BRIGHT; pixels], 1000);
    (sensor, events)
}

#[test]
fn a_call_with_more_events_than_the_limit_stops_and_the_sensor_refuses_until_reset() {
    let params = fine_thresholds(16, 4);
    let all = 64 * CROSSINGS_PER_PIXEL; // 611,200
    let (_, events) = bright_step(&params, all);
    assert_eq!(events.unwrap().len(), all, "the limit itself is allowed");
    let limit = 100_000;
    let (mut sensor, events) = bright_step(&params, limit);
    let error = events.unwrap_err();
    let FeedError::TooManyEvents(overflow) = &error else {
        panic!("{error}")
    };
    // The tile reports every 65,536 events, after a pixel: it stops at its second report.
    assert!(
        overflow.events > limit && overflow.events < 2 * REPORT + CROSSINGS_PER_PIXEL,
        "{overflow:?}"
    );
    assert!(!overflow.out_of_memory && overflow.t_us == 1000 && overflow.t_prev_us == 0);
    let message = error.to_string();
    for words in [
        "the light changed by more than the thresholds can follow in one call",
        "feed frames closer in time, or lower the light range, or raise the thresholds",
        "call reset()",
    ] {
        assert!(message.contains(words), "{message}");
    }
    assert_eq!(sensor.last_time_us(), Some(0));
    let refused = sensor.feed(&[0.5; 64], 2000).unwrap_err();
    assert!(matches!(refused, FeedError::Stopped { .. }), "{refused}");
    assert!(
        refused
            .to_string()
            .starts_with("the sensor stopped mid-call after "),
        "{refused}"
    );
    assert!(matches!(sensor.flush(), Err(FeedError::Stopped { .. })));
    // After a reset it works as a fresh sensor does.
    sensor.reset();
    let mut fresh = EventSensor::new(params.clone()).unwrap();
    for (k, value) in [0.2f32, 0.5, 0.1].into_iter().enumerate() {
        let t_us = 1000 * k as i64;
        let got = sensor.feed(&[value; 64], t_us).unwrap();
        assert_eq!(got, fresh.feed(&[value; 64], t_us).unwrap());
    }
    // ln(0.501 / 0.201) / 0.01 = 91.3 ON, then ln(0.501 / 0.101) / 0.01 = 160.1 OFF.
    assert_eq!(sensor.flush().unwrap(), fresh.flush().unwrap());
}

const REPORT: usize = crate::fuse::REPORT_EVERY_EVENTS;

#[test]
fn one_past_the_limit_blows_the_fuse_on_many_tiles_in_parallel() {
    // 3 tiles of 4,096 pixels (the last one half filled), stepped on the thread pool; a
    // step from 0 to 0.5 crosses floor(ln(0.501 / 0.001) / 0.05) = floor(124.3) = 124
    // thresholds of 0.05 a pixel.
    let (width, height) = (64, 160);
    let pixels = width * height;
    let mut params = SensorParams::ideal(width, height);
    params.theta_on = 0.05;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let step = |max_events| {
        pool.install(|| {
            let mut sensor = EventSensor::new(params.clone()).unwrap();
            sensor.max_events = max_events;
            sensor.feed(&vec![0.0; pixels], 0).unwrap();
            sensor.feed(&vec![0.5; pixels], 1000)
        })
    };
    let all = pixels * 124;
    assert_eq!(step(all).unwrap().len(), all);
    let error = step(all - 1).unwrap_err();
    let FeedError::TooManyEvents(overflow) = error else {
        panic!("{error}")
    };
    assert_eq!((overflow.limit, overflow.events), (all - 1, all));
    // A low limit stops every tile early, at most one report and one pixel past it each.
    let error = step(1000).unwrap_err();
    let FeedError::TooManyEvents(overflow) = error else {
        panic!("{error}")
    };
    assert!(overflow.events < 1000 + 3 * (REPORT + 124), "{overflow:?}");
}

#[test]
fn events_held_back_by_latency_count_on_the_next_call() {
    let mut params = fine_thresholds(4, 2);
    params.latency_us = 1e6;
    let mut sensor = EventSensor::new(params).unwrap();
    // ln(0.501 / 0.101) / 0.01 = 160.1: 160 events a pixel, all held back a second.
    let held = 8 * 160;
    sensor.max_events = held;
    sensor.feed(&[0.1; 8], 0).unwrap();
    assert!(sensor.feed(&[0.5; 8], 1000).unwrap().is_empty());
    let error = sensor.feed(&[0.6; 8], 2000).unwrap_err();
    let FeedError::TooManyEvents(overflow) = error else {
        panic!("{error}")
    };
    // ln(0.601 / 0.501) / 0.01 = 18.2: 18 events more a pixel, on top of those held back.
    assert_eq!(overflow.events, held + 8 * 18);
}
