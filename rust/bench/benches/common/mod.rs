//! What the criterion benches share: ESIM's and the full DAVIS346 model's parameters, the
//! drifting sinusoid, and feeding a frame sequence.

// Each bench uses a part.
#![allow(dead_code)]

use pecs_core::{EventSensor, ReferenceReset, SensorParams};

/// ESIM (Rebecq et al. 2018): the ideal pixel with the reference reset at each event.
pub fn esim(width: usize, height: usize) -> SensorParams {
    let mut p = SensorParams::ideal(width, height);
    p.reference_reset = ReferenceReset::Event;
    p
}

/// A sensor that has seen the first frame (its start is not part of the per-frame cost).
pub fn primed(params: &SensorParams, frames: &[Vec<f32>]) -> EventSensor {
    let mut sensor = EventSensor::new(params.clone()).unwrap();
    sensor.feed(&frames[0], 0).unwrap();
    sensor
}

/// Feed the rest of the sequence, `frame_us` apart; returns the number of events.
pub fn run(mut sensor: EventSensor, frames: &[Vec<f32>], frame_us: i64) -> usize {
    let mut events = 0;
    for (k, frame) in frames.iter().enumerate().skip(1) {
        events += sensor.feed(frame, frame_us * k as i64).unwrap().len();
    }
    events + sensor.flush().unwrap().len()
}

pub const DAVIS346: (usize, usize) = (346, 260);
/// Frames 500 us apart (2000 fps), as the Python bench.
pub const FRAME_US: i64 = 500;

/// python/pecs/config.py's "davis346" preset, at any size: the full model (threshold mismatch
/// and noise, 0.5 ms refractory period, a 300 Hz low-pass, latency and jitter, leak, shot noise
/// and hot pixels).
pub fn davis346(width: usize, height: usize) -> SensorParams {
    let mut p = SensorParams::ideal(width, height);
    p.theta_sigma = 0.03;
    p.theta_noise = 0.01;
    p.refractory_us = 500.0;
    p.cutoff_hz = 300.0;
    p.cutoff_half_photocurrent = 0.1;
    p.dark_current = 1e-4;
    p.latency_us = 20.0;
    p.jitter_us = 5.0;
    p.leak_rate_hz = 0.001;
    p.leak_light_rate_hz = 0.0004;
    p.leak_spread_decades = 0.3;
    p.shot_rate_hz = 10.0;
    p.hot_pixel_fraction = 1e-4;
    p.hot_pixel_rate_hz = 5.0;
    p
}

/// A sinusoidal grating over the whole frame, drifting `phase_step_rad` a frame: every pixel
/// changes every frame, and a sizeable share fire (benches/bench_sensor.py's sinusoid scenes).
/// Contrast `contrast` around 0.5, a period of 32 pixels along the diagonal (x + y / 2), so neighbouring
/// rows and columns differ.
pub fn sinusoid_scene(
    n: usize,
    phase_step_rad: f64,
    contrast: f64,
    (width, height): (usize, usize),
) -> Vec<Vec<f32>> {
    let wavenumber = std::f64::consts::TAU / SINUSOID_PERIOD_PX;
    (0..n)
        .map(|k| {
            let phase = phase_step_rad * k as f64;
            (0..width * height)
                .map(|i| {
                    let along = (i % width) as f64 + 0.5 * (i / width) as f64;
                    (0.5 * (1.0 + contrast * (wavenumber * along - phase).sin())) as f32
                })
                .collect()
        })
        .collect()
}

/// The sinusoid's period along its diagonal, pixels.
pub const SINUSOID_PERIOD_PX: f64 = 32.0;

/// The sinusoid's phase step a frame and contrast for the full `davis346` model's 0.15 and 0.5
/// events a pixel a frame (0.2 log thresholds, 300 Hz low-pass, 0.5 ms refractory: measured
/// with `--once`, 40 frames; `sinusoid:STEP_RAD:CONTRAST` tries others).
pub const SINUSOID: (f64, f64) = (0.14, 0.5);
pub const DENSE_SINUSOID: (f64, f64) = (0.55, 0.85);

/// Whether the CPU has AVX-512 F and DQ: the floor benches' vector passes then run in it, as
/// the dense path does.
#[cfg(target_arch = "x86_64")]
pub fn has_avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512dq")
}
