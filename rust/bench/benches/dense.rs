//! The dense case: every pixel changes in every frame (a turning quadrant disk with 1 % fresh
//! multiplicative grain, as benches/bench_sensor.py's "every pixel changes" scenes), at
//! DAVIS346 resolution, in ESIM mode and with the full DAVIS346 model; and where many of them
//! fire (a drifting sinusoid, 0.15 and 0.5 events a pixel a frame with the full model).
//!
//! `cargo bench -p pecs-bench --bench dense` times it with criterion, and ESIM's first changed frame alone
//! (where every pixel gets its first quiet band). Run the built binary with
//! `--once esim|davis346 [frames] [grain|sinusoid|sinusoid-dense] [WIDTHxHEIGHT]` to feed the
//! sequence once without criterion (for callgrind: instructions per pixel update are its total
//! over frames x pixels, per event its total over the events printed; grain 0 is the sparse
//! case, where only the disk's edges change; 1280x720 is the size whose states do not fit in the
//! cache). With PECS_BENCH_CHECKSUM set it also prints a hash of the events, to compare builds.

use std::time::{Duration, Instant};

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput};
use pecs_core::rng::{Draw, Stream};
use pecs_core::{EventColumns, EventSensor, SensorParams};

mod common;
use common::{
    davis346, esim, primed, run, sinusoid_scene, DAVIS346, DENSE_SINUSOID, FRAME_US, SINUSOID,
};

/// Linear radiance of a disk with alternating white and black quadrants turned by `angle_rad`,
/// on a grey room (pecs.examples.quadrant_disk), one sample per pixel.
fn quadrant_disk(width: usize, height: usize, angle_rad: f64) -> Vec<f32> {
    let (cx, cy) = ((width - 1) as f64 / 2.0, (height - 1) as f64 / 2.0);
    let radius = 0.42 * width.min(height) as f64;
    (0..width * height)
        .map(|i| {
            let (x, y) = ((i % width) as f64 - cx, (i / width) as f64 - cy);
            if x.hypot(y) > radius {
                return 0.2;
            }
            let theta = (y.atan2(x) - angle_rad).rem_euclid(std::f64::consts::TAU);
            if (theta / std::f64::consts::FRAC_PI_2) as i64 % 2 == 0 {
                0.9
            } else {
                0.05
            }
        })
        .collect()
}

/// `n` frames of the disk turning at 2 rev/s, each pixel times 1 + `grain` N(0, 1), fresh each
/// frame.
fn disk_scene(n: usize, grain: f64, (width, height): (usize, usize)) -> Vec<Vec<f32>> {
    (0..n)
        .map(|k| {
            let angle = std::f64::consts::TAU * 2.0 * k as f64 * FRAME_US as f64 * 1e-6;
            let mut frame = quadrant_disk(width, height, angle);
            for (i, v) in frame.iter_mut().enumerate() {
                let z = Draw::new(99, i as u64, k as u64).normal(Stream::Jitter);
                *v *= (1.0 + grain * z) as f32;
            }
            frame
        })
        .collect()
}

/// The frames of a scene named on the command line: a grain (a number: the turning disk with
/// that much fresh grain, 0 for the sparse case), `sinusoid` or `sinusoid-dense`.
fn scene_named(scene: &str, n: usize, size: (usize, usize)) -> Vec<Vec<f32>> {
    match scene {
        "sinusoid" => sinusoid_scene(n, SINUSOID.0, SINUSOID.1, size),
        "sinusoid-dense" => sinusoid_scene(n, DENSE_SINUSOID.0, DENSE_SINUSOID.1, size),
        custom if custom.starts_with("sinusoid:") => {
            let (step, contrast) = custom["sinusoid:".len()..]
                .split_once(':')
                .expect("sinusoid:STEP_RAD:CONTRAST");
            sinusoid_scene(
                n,
                step.parse().expect("step"),
                contrast.parse().expect("contrast"),
                size,
            )
        }
        grain => disk_scene(
            n,
            grain.parse().expect("a grain, sinusoid or sinusoid-dense"),
            size,
        ),
    }
}

fn params_named(name: &str, (width, height): (usize, usize)) -> SensorParams {
    match name {
        "esim" => esim(width, height),
        "davis346" => davis346(width, height),
        other => panic!("unknown model {other}: esim or davis346"),
    }
}

/// One pass over the sequence, timed, for profilers; `scene` as `scene_named` takes it.
/// Instructions per event are callgrind's count for `feed` over the events printed here.
fn once(name: &str, frames: usize, scene: &str, size: (usize, usize)) {
    let params = params_named(name, size);
    let scene = scene_named(scene, frames, size);
    if std::env::var_os("PECS_BENCH_CHECKSUM").is_some() {
        // Outside the timed pass (callgrind counts `feed` alone either way): a change meant to
        // keep the events bit for bit must keep this.
        println!(
            "events checksum {:016x}",
            checksum(primed(&params, &scene), &scene)
        );
    }
    let sensor = primed(&params, &scene);
    let (start, cpu_start_s) = (Instant::now(), cpu_time_s());
    let events = run(sensor, &scene, FRAME_US);
    let elapsed_s = start.elapsed().as_secs_f64();
    let cpu_s = cpu_time_s() - cpu_start_s;
    let updates = (frames - 1) * size.0 * size.1;
    let ns = elapsed_s * 1e9 / updates as f64;
    let cpu_ns = cpu_s * 1e9 / updates as f64;
    println!(
        "{name}: {updates} pixel updates, {events} events ({:.3} a pixel a frame), \
         {ns:.2} ns per update ({cpu_ns:.2} ns of CPU time: on a shared machine the wall time \
         is not all ours), {:.1} M events/s ({:.1} M per CPU second)",
        events as f64 / updates as f64,
        events as f64 / elapsed_s / 1e6,
        events as f64 / cpu_s / 1e6,
    );
}

/// A hash of every event of the rest of the sequence (time, address, polarity, cause), in order
/// (FNV-1a over their fields).
fn checksum(mut sensor: EventSensor, frames: &[Vec<f32>]) -> u64 {
    let mut hash = 0xcbf2_9ce4_8422_2325_u64;
    let mut add = |events: EventColumns| {
        for i in 0..events.len() {
            let label = events.label.get(i).copied().unwrap_or(0);
            let fields = [
                events.t_us[i] as u64,
                events.x[i] as u64,
                events.y[i] as u64,
                events.p[i] as u64,
                label as u64,
            ];
            for field in fields {
                hash = (hash ^ field).wrapping_mul(0x0100_0000_01b3);
            }
        }
    };
    for (k, frame) in frames.iter().enumerate().skip(1) {
        add(sensor.feed(frame, FRAME_US * k as i64).unwrap());
    }
    add(sensor.flush().unwrap());
    hash
}

/// User plus system CPU time of this process so far (Linux; NaN elsewhere), 10 ms resolution.
fn cpu_time_s() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the command name (which may hold spaces) start at its closing parenthesis.
    let fields: Vec<&str> = stat[stat.rfind(')').map_or(0, |i| i + 2)..]
        .split(' ')
        .collect();
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok());
    match (ticks(11), ticks(12)) {
        (Some(user), Some(system)) => (user + system) / 100.0,
        _ => f64::NAN,
    }
}

fn bench(c: &mut Criterion) {
    let frames = disk_scene(40, 0.01, DAVIS346);
    let pixels = DAVIS346.0 * DAVIS346.1;
    for name in ["esim", "davis346"] {
        let params = params_named(name, DAVIS346);
        let mut group = c.benchmark_group("dense-pixel-updates");
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(5));
        group.throughput(Throughput::Elements((pixels * (frames.len() - 1)) as u64));
        group.bench_function(BenchmarkId::from_parameter(name), |b| {
            b.iter_batched(
                || primed(&params, &frames),
                |s| run(s, &frames, FRAME_US),
                BatchSize::LargeInput,
            )
        });
        group.finish();
    }
    // Many pixels firing: events per second (criterion's throughput in elements is the events).
    for scene in ["sinusoid", "sinusoid-dense"] {
        let frames = scene_named(scene, 40, DAVIS346);
        for name in ["esim", "davis346"] {
            let params = params_named(name, DAVIS346);
            let events = run(primed(&params, &frames), &frames, FRAME_US);
            let mut group = c.benchmark_group(format!("{scene}-events"));
            group
                .sample_size(10)
                .measurement_time(Duration::from_secs(5));
            group.throughput(Throughput::Elements(events as u64));
            group.bench_function(BenchmarkId::from_parameter(name), |b| {
                b.iter_batched(
                    || primed(&params, &frames),
                    |s| run(s, &frames, FRAME_US),
                    BatchSize::LargeInput,
                )
            });
            group.finish();
        }
    }
    // ESIM's first changed frame alone: every pixel's first quiet band (`first_band`).
    let params = esim(DAVIS346.0, DAVIS346.1);
    let mut group = c.benchmark_group("first-changed-frame");
    group.throughput(Throughput::Elements(pixels as u64));
    group.bench_function(BenchmarkId::from_parameter("esim"), |b| {
        b.iter_batched(
            || primed(&params, &frames),
            |mut s| s.feed(&frames[1], FRAME_US).unwrap().len(),
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(at) = args.iter().position(|a| a == "--once") {
        let name = args.get(at + 1).map_or("davis346", String::as_str);
        let frames = args.get(at + 2).map_or(40, |n| n.parse().expect("frames"));
        let scene = args.get(at + 3).map_or("0.01", String::as_str);
        let size = args.get(at + 4).map_or(DAVIS346, |size| {
            let (w, h) = size.split_once('x').expect("size as WIDTHxHEIGHT");
            (w.parse().expect("width"), h.parse().expect("height"))
        });
        return once(name, frames, scene, size);
    }
    let mut c = Criterion::default().configure_from_args();
    bench(&mut c);
    c.final_summary();
}
