//! Criterion benchmarks of the metrics' BVH: build over event-like points, nearest queries, and
//! a whole chamfer/Gaussian comparison. `cargo bench -p pecs-bench --bench bvh`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use pecs_core::metrics::nearest::PolarityIndex;
use pecs_core::metrics::{
    compare, normalize, Events, Normalization, PointBvh, PolarityMatching, PECS_SIGMA,
};
use std::hint::black_box;

/// Events of an edge sweeping across a 346 x 260 sensor over 100 ms, plus uniform noise.
/// A linear congruential generator keeps the bench free of extra crates.
struct Stream {
    t_us: Vec<i64>,
    x: Vec<u16>,
    y: Vec<u16>,
    p: Vec<i8>,
}

fn sweep(n: usize, seed: u64) -> Stream {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut uniform = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut events: Vec<(i64, u16, u16, i8)> = (0..n)
        .map(|i| {
            let y = (uniform() * 260.0) as u16;
            if i % 10 == 0 {
                // Background noise: anywhere, any time.
                let x = (uniform() * 346.0) as u16;
                (
                    (uniform() * 100_000.0) as i64,
                    x,
                    y,
                    (uniform() < 0.5) as i8,
                )
            } else {
                // The edge: x moves at 3.46 px/ms, events scattered within a pixel of it.
                let t = uniform() * 100_000.0;
                let x = (t * 346.0 / 100_000.0 + uniform() * 2.0 - 1.0).clamp(0.0, 345.0) as u16;
                (t as i64, x, y, 1)
            }
        })
        .collect();
    events.sort_unstable();
    Stream {
        t_us: events.iter().map(|e| e.0).collect(),
        x: events.iter().map(|e| e.1).collect(),
        y: events.iter().map(|e| e.2).collect(),
        p: events.iter().map(|e| e.3).collect(),
    }
}

fn points(stream: &Stream) -> Vec<[f64; 3]> {
    let t_end = *stream.t_us.last().unwrap() as f64;
    (0..stream.t_us.len())
        .map(|i| {
            [
                100.0 * f64::from(stream.x[i]) / 345.0,
                100.0 * f64::from(stream.y[i]) / 259.0,
                1000.0 * stream.t_us[i] as f64 / t_end,
            ]
        })
        .collect()
}

fn events(stream: &Stream) -> Events<'_> {
    Events {
        t_us: &stream.t_us,
        x: &stream.x,
        y: &stream.y,
        p: &stream.p,
    }
}

fn build_and_query(c: &mut Criterion) {
    let mut group = c.benchmark_group("bvh");
    group.sample_size(10);
    for n in [100_000usize, 1_000_000] {
        let targets = points(&sweep(n, 1));
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("build", n), &targets, |b, pts| {
            b.iter(|| PointBvh::build(black_box(pts)))
        });
        let tree = PointBvh::build(&targets).unwrap();
        let queries = points(&sweep(n, 2));
        // One traversal per query, in time order, one thread: the plain API.
        group.bench_with_input(
            BenchmarkId::new("query_one_by_one", n),
            &queries,
            |b, qs| {
                let mut stack = Vec::new();
                b.iter(|| {
                    qs.iter()
                        .map(|&q| tree.nearest_sq(q, 0.0, &mut stack))
                        .sum::<f64>()
                })
            },
        );
        // What the metrics do: Morton-ordered groups sharing traversals, on rayon.
        let (a, b) = (sweep(n, 1), sweep(n, 2));
        let index_a = PolarityIndex::build(&normalize(&events(&a), &Normalization::Pecs).unwrap());
        let index_b = PolarityIndex::build(&normalize(&events(&b), &Normalization::Pecs).unwrap());
        group.bench_function(BenchmarkId::new("query_all", n), |bench| {
            bench.iter(|| index_a.nearest_distances(&index_b, PolarityMatching::Coordinate))
        });
    }
    group.finish();
}

fn chamfer_and_gaussian(c: &mut Criterion) {
    let mut group = c.benchmark_group("compare");
    group.sample_size(10);
    let n = 1_000_000;
    let (a, b) = (sweep(n, 3), sweep(n, 4));
    group.throughput(Throughput::Elements(2 * n as u64));
    group.bench_function(BenchmarkId::new("pecs", n), |bench| {
        bench.iter(|| {
            compare(
                &events(&a),
                &events(&b),
                &Normalization::Pecs,
                PolarityMatching::Coordinate,
                PECS_SIGMA,
            )
        })
    });
    group.finish();
}

criterion_group!(benches, build_and_query, chamfer_and_gaussian);
criterion_main!(benches);
