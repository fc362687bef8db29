//! Hand-worked cases of each filter's rule, and batch independence. (The Python tests,
//! tests/test_filters.py, hold five cases or more per mode.)

use super::*;

const ON: i8 = 1;
const OFF: i8 = 0;

/// The times of the events the chain passes, the stream pushed whole and then finished.
fn kept(settings: FilterSettings, events: &[(i64, u16, u16, i8)]) -> Vec<i64> {
    let mut chain = FilterChain::new(&settings, 0, 0).unwrap();
    let t: Vec<i64> = events.iter().map(|e| e.0).collect();
    let x: Vec<u16> = events.iter().map(|e| e.1).collect();
    let y: Vec<u16> = events.iter().map(|e| e.2).collect();
    let p: Vec<i8> = events.iter().map(|e| e.3).collect();
    let mut verdicts = chain.push(&t, &x, &y, &p).unwrap();
    verdicts.extend(chain.finish());
    assert_eq!(verdicts.len(), t.len());
    t.iter()
        .zip(verdicts)
        .filter(|(_, keep)| *keep)
        .map(|(&t, _)| t)
        .collect()
}

fn trail(mode: TrailMode, threshold_ms: u32) -> FilterSettings {
    FilterSettings {
        trail: Some(TrailSettings { mode, threshold_ms }),
        ..Default::default()
    }
}

#[test]
fn trail_keeps_the_first_event_of_each_burst() {
    // 1 ms: 1000 us after the previous event is a new burst, 999 us is trail; a polarity change
    // is a new burst; another pixel has its own bursts.
    let events = [
        (0, 0, 0, ON),
        (999, 0, 0, ON),
        (1999, 0, 0, ON),
        (2000, 0, 0, OFF),
        (2001, 1, 0, OFF),
    ];
    assert_eq!(
        kept(trail(TrailMode::Trail, 1), &events),
        [0, 1999, 2000, 2001]
    );
}

#[test]
fn stc_cut_keeps_only_second_events_and_keep_trail_the_rest_of_the_burst() {
    let events = [
        (0, 0, 0, ON),
        (500, 0, 0, ON),
        (900, 0, 0, ON),
        (5000, 0, 0, ON),
    ];
    assert_eq!(kept(trail(TrailMode::StcCutTrail, 1), &events), [500]);
    assert_eq!(kept(trail(TrailMode::StcKeepTrail, 1), &events), [500, 900]);
}

#[test]
fn erc_keeps_count_events_of_a_busy_period_evenly_and_all_of_a_quiet_one() {
    // 10,000 events/s over 200 us periods: 2 a period. Period 0 has 5 (i x 2 mod 5 < 2 for
    // i = 0 and 3), period 1 has 2.
    let settings = FilterSettings {
        erc: Some(ErcSettings {
            rate_hz: 10_000.0,
            period_us: 200,
        }),
        ..Default::default()
    };
    let events = [
        (0, 0, 0, ON),
        (10, 1, 0, ON),
        (20, 2, 0, ON),
        (30, 3, 0, ON),
        (199, 4, 0, ON),
        (200, 0, 0, ON),
        (399, 0, 0, ON),
    ];
    assert_eq!(kept(settings, &events), [0, 30, 200, 399]);
}

#[test]
fn afk_band_stop_drops_a_region_once_six_periods_fall_in_the_band() {
    // 100 Hz in one 4 x 4 region, runs alternating every 5 ms over two pixels of it: the
    // periods measured from the third run on (10,000 us, 78 units, inside 15..=156) count
    // 1, 2, ... 6 at the eighth event, which the region then drops.
    let settings = FilterSettings {
        afk: Some(AfkSettings {
            low_hz: 50,
            high_hz: 520,
            mode: AfkMode::BandStop,
            start_threshold: 6,
            stop_threshold: 4,
        }),
        ..Default::default()
    };
    let events: Vec<_> = (0..10)
        .map(|k| {
            (
                k * 5000,
                (k % 2) as u16,
                3,
                if k % 2 == 0 { ON } else { OFF },
            )
        })
        .collect();
    assert_eq!(
        kept(settings, &events),
        [0, 5000, 10000, 15000, 20000, 25000, 30000]
    );
}

#[test]
fn a_stream_filtered_in_batches_gives_what_it_gives_whole() {
    let settings = FilterSettings {
        afk: Some(AfkSettings {
            low_hz: 80,
            high_hz: 120,
            mode: AfkMode::BandStop,
            start_threshold: 3,
            stop_threshold: 1,
        }),
        trail: Some(TrailSettings {
            mode: TrailMode::StcKeepTrail,
            threshold_ms: 2,
        }),
        erc: Some(ErcSettings {
            rate_hz: 50_000.0,
            period_us: 200,
        }),
    };
    // A deterministic jumble: 3000 events over 8 x 8 pixels in 60 ms, several per microsecond.
    let mut state = 12345u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        state >> 33
    };
    let mut events: Vec<(i64, u16, u16, i8)> = (0..3000)
        .map(|_| {
            (
                (next() % 60_000) as i64,
                (next() % 8) as u16,
                (next() % 8) as u16,
                (next() % 2) as i8,
            )
        })
        .collect();
    events.sort_by_key(|e| e.0);
    let whole = kept(settings, &events);
    for batch in [1, 7, 500] {
        let mut chain = FilterChain::new(&settings, 0, 0).unwrap();
        let mut verdicts = Vec::new();
        for part in events.chunks(batch) {
            let t: Vec<i64> = part.iter().map(|e| e.0).collect();
            let x: Vec<u16> = part.iter().map(|e| e.1).collect();
            let y: Vec<u16> = part.iter().map(|e| e.2).collect();
            let p: Vec<i8> = part.iter().map(|e| e.3).collect();
            verdicts.extend(chain.push(&t, &x, &y, &p).unwrap());
        }
        verdicts.extend(chain.finish());
        let batched: Vec<i64> = events
            .iter()
            .zip(verdicts)
            .filter(|(_, k)| *k)
            .map(|(e, _)| e.0)
            .collect();
        assert_eq!(batched, whole, "batches of {batch}");
        let counts = chain.counts();
        assert_eq!(counts.events_in, 3000);
        assert_eq!(
            counts.events_in - counts.afk_dropped - counts.trail_dropped - counts.erc_dropped,
            counts.events_out
        );
        assert_eq!(counts.events_out as usize, whole.len());
    }
    assert!(!whole.is_empty() && whole.len() < 3000);
}

#[test]
fn bad_input_is_refused_and_leaves_the_chain_as_it_was() {
    let mut chain = FilterChain::new(&trail(TrailMode::Trail, 1), 0, 0).unwrap();
    chain.push(&[10], &[0], &[0], &[ON]).unwrap();
    let error = chain
        .push(&[20, 5], &[0, 0], &[0, 0], &[ON, ON])
        .unwrap_err();
    assert!(
        error.message.contains("t = 5 us comes after t = 20 us"),
        "{error}"
    );
    assert!(
        chain.push(&[9], &[0], &[0], &[ON]).is_err(),
        "before the last event accepted"
    );
    assert!(chain.push(&[11, 12], &[0], &[0, 0], &[ON, ON]).is_err());
    // The refused batches changed nothing: 1010 us after the event at 10 is a new burst.
    assert_eq!(chain.push(&[1010], &[0], &[0], &[ON]).unwrap(), [true]);
}

#[test]
fn settings_out_of_the_chips_ranges_are_refused() {
    let band = |low_hz, high_hz| FilterSettings {
        afk: Some(AfkSettings {
            low_hz,
            high_hz,
            mode: AfkMode::BandPass,
            start_threshold: 6,
            stop_threshold: 4,
        }),
        ..Default::default()
    };
    for (low, high) in [(49, 100), (100, 521), (100, 100), (200, 100)] {
        assert!(band(low, high).validate().is_err(), "{low}-{high}");
    }
    assert!(band(50, 520).validate().is_ok());
    assert!(trail(TrailMode::Trail, 0).validate().is_err());
    assert!(trail(TrailMode::Trail, 101).validate().is_err());
    let erc = |rate_hz| FilterSettings {
        erc: Some(ErcSettings {
            rate_hz,
            period_us: 200,
        }),
        ..Default::default()
    };
    for rate in [0.0, -1.0, 4999.0, f64::NAN, f64::INFINITY] {
        assert!(erc(rate).validate().is_err(), "{rate}");
    }
    assert_eq!(
        ErcSettings {
            rate_hz: 50e6,
            period_us: 200
        }
        .count(),
        10_000
    );
    assert_eq!(
        ErcSettings {
            rate_hz: 20.1e6,
            period_us: 200
        }
        .count(),
        4020
    );
    assert_eq!(
        ErcSettings {
            rate_hz: 5000.0,
            period_us: 200
        }
        .count(),
        1
    );
}
