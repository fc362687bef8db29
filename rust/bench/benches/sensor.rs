//! Throughput of the event engine: pixel updates and events per second, at DAVIS346 and
//! 1280 x 720 resolution, in ESIM mode and with the full noise model, on a mostly static scene
//! (a textured bar moving over a static background) and on a scene where every pixel changes.
//! A pixel's state is made when its input first changes or it first wakes, so in the scene where
//! every pixel changes the timed frames include making all of them.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BatchSize, BenchmarkId, Criterion, Throughput};
use pecs_core::SensorParams;

mod common;
use common::{esim, primed, run};

const FRAMES: usize = 20;

#[derive(Clone, Copy, PartialEq)]
enum Motion {
    /// Nothing moves: the cost of reading frames and skipping quiet pixels.
    Static,
    /// A textured bar moves 2 px per frame over a static background.
    Bar,
    /// The bar plus a tiny per-frame change of every pixel (video noise): nothing is skipped.
    BarAndFlicker,
}

fn scene(width: usize, height: usize, motion: Motion) -> Vec<Vec<f32>> {
    let flicker = motion == Motion::BarAndFlicker;
    (0..FRAMES)
        .map(|k| {
            (0..width * height)
                .map(|i| {
                    let (x, y) = (i % width, i / width);
                    let background = 0.1 + 0.04 * ((x * 7 + y * 13) % 11) as f32;
                    let bar_x = if motion == Motion::Static {
                        40
                    } else {
                        40 + 2 * k
                    };
                    let value = if x >= bar_x && x < bar_x + 30 {
                        0.6 + 0.02 * (y % 5) as f32
                    } else {
                        background
                    };
                    if flicker {
                        value * (1.0 + 0.001 * ((i + k) % 3) as f32)
                    } else {
                        value
                    }
                })
                .collect()
        })
        .collect()
}

fn full_noise(width: usize, height: usize) -> SensorParams {
    let mut p = SensorParams::ideal(width, height);
    p.theta_sigma = 0.03;
    p.theta_noise = 0.01;
    p.refractory_us = 500.0;
    p.cutoff_hz = 300.0;
    p.cutoff_half_photocurrent = 0.1;
    p.latency_us = 20.0;
    p.jitter_us = 5.0;
    p.leak_rate_hz = 0.1;
    p.leak_spread_decades = 0.3;
    p.shot_rate_hz = 2.0;
    p.hot_pixel_fraction = 1e-4;
    p.hot_pixel_rate_hz = 50.0;
    p
}

fn bench(c: &mut Criterion) {
    for (width, height) in [(346, 260), (1280, 720)] {
        for (scene_name, motion) in [
            ("static", Motion::Static),
            ("moving-bar", Motion::Bar),
            ("all-changing", Motion::BarAndFlicker),
        ] {
            let frames = scene(width, height, motion);
            for (model, params) in [
                ("esim", esim(width, height)),
                ("full-noise", full_noise(width, height)),
            ] {
                let events = run(primed(&params, &frames), &frames, 1000);
                let id = format!("{width}x{height}/{scene_name}/{model}");
                for (unit, count) in [
                    ("pixel-updates", width * height * (FRAMES - 1)),
                    ("events", events),
                ] {
                    let mut group = c.benchmark_group(unit);
                    group
                        .sample_size(10)
                        .measurement_time(Duration::from_secs(3));
                    group.throughput(Throughput::Elements(count as u64));
                    group.bench_function(BenchmarkId::from_parameter(&id), |b| {
                        b.iter_batched(
                            || primed(&params, &frames),
                            |s| run(s, &frames, 1000),
                            BatchSize::LargeInput,
                        )
                    });
                    group.finish();
                }
            }
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
