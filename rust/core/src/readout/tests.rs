//! Hand-worked cases of each readout stage.

use super::*;

fn columns(events: &[(i64, u16, u16)]) -> EventColumns {
    let list: Vec<Event> = events
        .iter()
        .map(|&(t_us, x, y)| Event {
            t_us,
            x,
            y,
            p: 1,
            label: 0,
        })
        .collect();
    EventColumns::from_events(&list, false).unwrap()
}

fn txy(batch: &ReadoutBatch) -> Vec<(i64, u16, u16)> {
    let e = &batch.events;
    (0..e.len()).map(|i| (e.t_us[i], e.x[i], e.y[i])).collect()
}

fn readout(settings: ReadoutSettings) -> Readout {
    settings.validate().unwrap();
    Readout::new(&settings).unwrap()
}

#[test]
fn every_stage_off_builds_no_readout() {
    assert!(Readout::new(&ReadoutSettings::default()).is_none());
    let one_us = ReadoutSettings {
        timestamp_step_us: 1,
        ..ReadoutSettings::default()
    };
    assert!(Readout::new(&one_us).is_none());
}

#[test]
fn a_bus_of_one_event_per_us_sends_simultaneous_events_one_after_another() {
    // 1 Meps: a slot of 1 us. Three events made at 10 us leave at 11, 12 and 13 us.
    let mut r = readout(ReadoutSettings {
        bus_rate_meps: 1.0,
        ..ReadoutSettings::default()
    });
    let out = r.finish(&columns(&[(10, 0, 0), (10, 0, 1), (10, 0, 2)]));
    assert_eq!(txy(&out), vec![(11, 0, 0), (12, 0, 1), (13, 0, 2)]);
    assert_eq!(out.delay_us, vec![1, 2, 3]);
    let c = r.counts();
    assert_eq!((c.events_in, c.events_out, c.delayed), (3, 3, 3));
    assert_eq!((c.delay_total_us, c.delay_max_us), (6, 3));
}

#[test]
fn events_that_leave_after_the_call_are_held_for_the_next() {
    let mut r = readout(ReadoutSettings {
        bus_rate_meps: 1.0,
        ..ReadoutSettings::default()
    });
    let first = r.push(&columns(&[(10, 0, 0), (10, 0, 1), (10, 0, 2)]), 10);
    assert!(first.events.is_empty());
    assert_eq!(r.counts().held, 3);
    let second = r.push(&columns(&[]), 12);
    assert_eq!(txy(&second), vec![(11, 0, 0), (12, 0, 1)]);
    let last = r.finish(&columns(&[]));
    assert_eq!(txy(&last), vec![(13, 0, 2)]);
    assert_eq!(r.counts().held, 0);
}

#[test]
fn a_late_row_grant_sends_the_rows_backlog_as_one_burst() {
    // 1 us a grant, no time per event: rows 0-4 each have an event at 0 us and row 4 two more
    // at 1 and 2 us. Grants at 0, 1, 2, 3, 4 us (oldest request first); row 4's grant at 4 us
    // takes its three events together, all leaving at 5 us.
    let mut r = readout(ReadoutSettings {
        row_service_ns: 1000.0,
        ..ReadoutSettings::default()
    });
    let input = [(0, 0, 0), (0, 0, 1), (0, 0, 2), (0, 0, 3), (0, 0, 4)];
    let mut first = r.push(&columns(&input), 0);
    first.append(r.finish(&columns(&[(1, 1, 4), (2, 2, 4)])));
    let expected = vec![
        (1, 0, 0),
        (2, 0, 1),
        (3, 0, 2),
        (4, 0, 3),
        (5, 0, 4),
        (5, 1, 4),
        (5, 2, 4),
    ];
    assert_eq!(txy(&first), expected);
}

#[test]
fn a_full_queue_drops_and_the_counts_add_up() {
    // Five events at once into a queue of two: two wait and leave 1 us apart, three are dropped.
    let mut r = readout(ReadoutSettings {
        bus_rate_meps: 1.0,
        overflow: ReadoutOverflow::Drop,
        queue_depth: 2,
        ..ReadoutSettings::default()
    });
    let input: Vec<(i64, u16, u16)> = (0..5).map(|y| (0, 0, y)).collect();
    let out = r.finish(&columns(&input));
    assert_eq!(txy(&out), vec![(1, 0, 0), (2, 0, 1)]);
    let c = r.counts();
    assert_eq!((c.events_in, c.events_out, c.dropped, c.held), (5, 2, 3, 0));
}

#[test]
fn timestamps_floor_to_the_step() {
    let mut r = readout(ReadoutSettings {
        timestamp_step_us: 100,
        ..ReadoutSettings::default()
    });
    let out = r.finish(&columns(&[
        (-1, 0, 0),
        (0, 0, 0),
        (99, 1, 0),
        (100, 0, 0),
        (250, 0, 0),
    ]));
    assert_eq!(out.events.t_us, vec![-100, 0, 0, 100, 200]);
    // One event (99 us, stamped 0) shares the stamp of the one before it.
    assert_eq!(r.counts().same_timestamp, 1);
}

#[test]
fn the_rate_controller_keeps_its_count_per_period() {
    // 10,000 events/s in 200 us periods: 2 a period. Five in the first period: the i-th is kept
    // where (i x 2) mod 5 < 2, events 0 and 3, as the filters' ERC decides.
    let mut r = readout(ReadoutSettings {
        erc_rate_hz: 10_000.0,
        ..ReadoutSettings::default()
    });
    let input: Vec<(i64, u16, u16)> = (0..5).map(|i| (i * 10, i as u16, 0)).collect();
    let held = r.push(&columns(&input), 100);
    assert!(held.events.is_empty(), "the open period waits");
    let out = r.finish(&columns(&[]));
    assert_eq!(txy(&out), vec![(0, 0, 0), (30, 3, 0)]);
    let c = r.counts();
    assert_eq!((c.events_out, c.erc_dropped, c.held), (2, 3, 0));
}

#[test]
fn settings_out_of_range_or_at_odds_name_their_field() {
    let cases = [
        (
            "readout_bus_rate_meps",
            ReadoutSettings {
                bus_rate_meps: -1.0,
                ..Default::default()
            },
        ),
        (
            "readout_row_service_ns",
            ReadoutSettings {
                row_service_ns: 1e9,
                ..Default::default()
            },
        ),
        (
            "readout_overflow",
            ReadoutSettings {
                overflow: ReadoutOverflow::Drop,
                queue_depth: 4,
                ..Default::default()
            },
        ),
        (
            "readout_queue_depth",
            ReadoutSettings {
                bus_rate_meps: 1.0,
                overflow: ReadoutOverflow::Drop,
                ..Default::default()
            },
        ),
        (
            "readout_queue_depth",
            ReadoutSettings {
                bus_rate_meps: 1.0,
                queue_depth: 4,
                ..Default::default()
            },
        ),
        (
            "timestamp_step_us",
            ReadoutSettings {
                timestamp_step_us: 2_000_000,
                ..Default::default()
            },
        ),
        (
            "erc_rate_hz",
            ReadoutSettings {
                erc_rate_hz: 10.0,
                ..Default::default()
            },
        ),
    ];
    for (field, settings) in cases {
        assert_eq!(
            settings.validate().unwrap_err().field,
            field,
            "{settings:?}"
        );
    }
}
