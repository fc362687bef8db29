//! What the criterion benches share: ESIM's parameters and feeding a frame sequence.

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
