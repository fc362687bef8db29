//! The EVT3 codec against hand-built word sequences from the specification, round trips of
//! random streams, and a bounded mutation loop (the decoder never panics on any bytes).

use super::word::*;
use super::*;
use crate::EventColumns;

/// SplitMix64: a small deterministic generator for the tests.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn w(kind: u16, content: u16) -> u16 {
    kind << 12 | content
}

fn bytes(words: &[u16]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

fn decode_all(data: &[u8], width: u16, height: u16) -> Result<EventColumns, Evt3Error> {
    let mut decoder = Evt3Decoder::new(width, height, 0).unwrap();
    let (events, used) = decoder.decode(data, usize::MAX)?;
    assert_eq!(used, data.len());
    decoder.finish()?;
    Ok(events)
}

type Rows = Vec<(i64, u16, u16, i8)>;

fn rows(c: &EventColumns) -> Rows {
    (0..c.len())
        .map(|i| (c.t_us[i], c.x[i], c.y[i], c.p[i]))
        .collect()
}

fn columns(rows: &Rows) -> (Vec<i64>, Vec<u16>, Vec<u16>, Vec<i8>) {
    (
        rows.iter().map(|r| r.0).collect(),
        rows.iter().map(|r| r.1).collect(),
        rows.iter().map(|r| r.2).collect(),
        rows.iter().map(|r| r.3).collect(),
    )
}

fn encode_all(rows: &Rows, width: u16, height: u16) -> Vec<u8> {
    let (t, x, y, p) = columns(rows);
    Evt3Encoder::new(width, height)
        .unwrap()
        .encode(&t, &x, &y, &p)
        .unwrap()
}

#[test]
fn single_event_time_is_high_then_low() {
    // TIME_HIGH 1, TIME_LOW 2 -> t = 1 * 4096 + 2; EVT_ADDR_Y 5; EVT_ADDR_X x 7, polarity 1.
    let data = bytes(&[
        w(TIME_HIGH, 1),
        w(TIME_LOW, 2),
        w(ADDR_Y, 5),
        w(ADDR_X, 1 << 11 | 7),
    ]);
    let events = decode_all(&data, 640, 480).unwrap();
    assert_eq!(rows(&events), vec![(4098, 7, 5, 1)]);
}

#[test]
fn vectors_expand_their_masks_from_the_base_and_advance_it() {
    // Base 100, OFF; VECT_12 bits 0 and 11 -> 100, 111; VECT_8 (base now 112) bits 0 and 7 ->
    // 112, 119 (bits 8..11 of a VECT_8 are not events); base now 120: VECT_12 bit 1 -> 121.
    let data = bytes(&[
        w(TIME_HIGH, 0),
        w(TIME_LOW, 9),
        w(ADDR_Y, 3),
        w(VECT_BASE_X, 100),
        w(VECT_12, 0x801),
        w(VECT_8, 0xF81),
        w(VECT_12, 0x002),
    ]);
    let events = decode_all(&data, 640, 480).unwrap();
    let want: Rows = [100, 111, 112, 119, 121]
        .iter()
        .map(|&x| (9, x, 3, 0))
        .collect();
    assert_eq!(rows(&events), want);
}

#[test]
fn time_high_wraps_add_2_24_us_and_time_low_restarts() {
    // High 0xFFF low 5, then TIME_HIGH 0 (a wrap) with no TIME_LOW: t = 2^24 + 0.
    let data = bytes(&[
        w(TIME_HIGH, 0xFFF),
        w(TIME_LOW, 5),
        w(ADDR_Y, 0),
        w(ADDR_X, 1),
        w(TIME_HIGH, 0),
        w(ADDR_X, 2),
        w(TIME_LOW, 7),
        w(ADDR_X, 3),
    ]);
    let events = decode_all(&data, 640, 480).unwrap();
    let first = 0xFFF << 12 | 5;
    assert_eq!(
        rows(&events),
        vec![
            (first, 1, 0, 0),
            (1 << 24, 2, 0, 0),
            ((1 << 24) + 7, 3, 0, 0)
        ]
    );
}

#[test]
fn triggers_others_and_continued_words_are_skipped() {
    let data = bytes(&[
        w(TIME_HIGH, 2),
        w(EXT_TRIGGER, 1),
        w(ADDR_Y, 4),
        w(OTHERS, 0x016),
        w(CONTINUED_12, 0xABC),
        w(CONTINUED_12, 0x123),
        w(CONTINUED_4, 0x5),
        w(IMU, 0x77),
        w(ADDR_X, 8),
    ]);
    let events = decode_all(&data, 640, 480).unwrap();
    assert_eq!(rows(&events), vec![(2 << 12, 8, 4, 0)]);
}

#[test]
fn words_before_the_first_time_high_or_row_are_skipped() {
    // An event before any TIME_HIGH has no time; one before any EVT_ADDR_Y no row.
    let data = bytes(&[w(ADDR_Y, 1), w(ADDR_X, 10), w(TIME_HIGH, 3), w(ADDR_X, 11)]);
    assert_eq!(
        rows(&decode_all(&data, 64, 64).unwrap()),
        vec![(3 << 12, 11, 1, 0)]
    );
    let no_row = bytes(&[w(TIME_HIGH, 3), w(ADDR_X, 11), w(ADDR_Y, 2), w(ADDR_X, 12)]);
    assert_eq!(
        rows(&decode_all(&no_row, 64, 64).unwrap()),
        vec![(3 << 12, 12, 2, 0)]
    );
}

#[test]
fn errors_name_the_offset_of_the_word_at_fault() {
    let offset_of = |words: &[u16], width, height| {
        let mut decoder = Evt3Decoder::new(width, height, 100).unwrap();
        decoder.decode(&bytes(words), usize::MAX).unwrap_err()
    };
    let base = [w(TIME_HIGH, 0), w(ADDR_Y, 1)];
    let reserved = offset_of(&[&base[..], &[w(0x9, 0)]].concat(), 64, 64);
    assert_eq!(reserved.offset, 104);
    assert!(
        reserved.problem.contains("reserved EVT3 word type 0x9"),
        "{reserved}"
    );
    let row = offset_of(&[w(TIME_HIGH, 0), w(ADDR_Y, 64)], 64, 64);
    assert_eq!((row.offset, row.problem.contains("row 64")), (102, true));
    let column = offset_of(&[&base[..], &[w(ADDR_X, 64)]].concat(), 64, 64);
    assert_eq!(
        (column.offset, column.problem.contains("column 64")),
        (104, true)
    );
    // Base 60 + bit 4 = column 64 of a 64-wide sensor.
    let vector = offset_of(
        &[&base[..], &[w(VECT_BASE_X, 60), w(VECT_8, 0x11)]].concat(),
        64,
        64,
    );
    assert_eq!(
        (vector.offset, vector.problem.contains("column 64")),
        (106, true)
    );
    let back = offset_of(&[w(TIME_HIGH, 10), w(TIME_HIGH, 9)], 64, 64);
    assert_eq!(
        (back.offset, back.problem.contains("goes back")),
        (102, true)
    );
    let mut decoder = Evt3Decoder::new(64, 64, 10).unwrap();
    let (_, used) = decoder.decode(&[0, 0x80, 7], usize::MAX).unwrap();
    assert_eq!(used, 3);
    assert_eq!(decoder.finish().unwrap_err().offset, 12);
}

/// A random stream: sparse single events, dense rows (vectors), bursts, long gaps.
fn random_rows(rng: &mut Rng, n: usize, width: u16, height: u16) -> Rows {
    let mut t = rng.below(1 << 20) as i64;
    let mut out = Rows::new();
    while out.len() < n {
        t += match rng.below(10) {
            0 => rng.below(1 << 25) as i64,
            1..=3 => 0,
            _ => rng.below(5000) as i64,
        };
        let y = rng.below(u64::from(height)) as u16;
        let p = rng.below(2) as i8;
        if rng.below(3) == 0 {
            // A row segment: increasing columns with holes, as a sensor's vector readout.
            let mut x = rng.below(u64::from(width)) as u16;
            for _ in 0..rng.below(40) {
                out.push((t, x, y, p));
                x += 1 + rng.below(3) as u16;
                if x >= width {
                    break;
                }
            }
        } else {
            out.push((t, rng.below(u64::from(width)) as u16, y, p));
        }
    }
    out
}

#[test]
fn random_streams_round_trip_in_any_chunks_and_batches() {
    let mut rng = Rng(42);
    for (width, height) in [(640, 480), (2048, 2048), (20, 7), (32, 1)] {
        let want = random_rows(&mut rng, 20_000, width, height);
        // Encoded in batches of random sizes: the encoder's state carries over.
        let mut encoder = Evt3Encoder::new(width, height).unwrap();
        let (t, x, y, p) = columns(&want);
        let mut data = Vec::new();
        let mut i = 0;
        while i < want.len() {
            let end = (i + 1 + rng.below(3000) as usize).min(want.len());
            data.extend(
                encoder
                    .encode(&t[i..end], &x[i..end], &y[i..end], &p[i..end])
                    .unwrap(),
            );
            i = end;
        }
        // Decoded in chunks of random sizes (odd ones too), batches of at most `max`.
        let mut decoder = Evt3Decoder::new(width, height, 0).unwrap();
        let mut got = Rows::new();
        let mut start = 0;
        while start < data.len() {
            let end = (start + 1 + rng.below(5000) as usize).min(data.len());
            let mut chunk = &data[start..end];
            while !chunk.is_empty() {
                let max = 1 + rng.below(100) as usize;
                let (events, used) = decoder.decode(chunk, max).unwrap();
                assert!(events.len() <= max.max(12));
                assert!(used > 0);
                got.extend(rows(&events));
                chunk = &chunk[used..];
            }
            start = end;
        }
        decoder.finish().unwrap();
        assert_eq!(got, want, "{width} x {height}");
    }
}

#[test]
fn writer_uses_vectors_for_rows_and_time_high_for_every_step() {
    // 32 events on one row at one time: one vector pattern, not 32 EVT_ADDR_X words.
    let row: Rows = (0..32).map(|x| (10, 600 + x, 5, 1)).collect();
    let data = encode_all(&row, 640, 480);
    let words: Vec<u16> = data
        .chunks(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    assert_eq!(
        words,
        vec![
            w(TIME_HIGH, 0),
            w(TIME_LOW, 10),
            w(ADDR_Y, 5),
            w(VECT_BASE_X, 1 << 11 | 600),
            w(VECT_12, 0xFFF),
            w(VECT_12, 0xFFF),
            w(VECT_8, 0xFF)
        ]
    );
    assert_eq!(rows(&decode_all(&data, 640, 480).unwrap()), row);
}

#[test]
fn gaps_of_any_length_read_back_exactly() {
    for gap in [(1 << 24) - 1, 1 << 24, 20_000_000, 100_000_000, 1 << 33] {
        let want: Rows = vec![(7, 1, 2, 1), (7 + gap, 3, 4, 0), (7 + 2 * gap, 5, 6, 1)];
        let data = encode_all(&want, 640, 480);
        assert_eq!(
            rows(&decode_all(&data, 640, 480).unwrap()),
            want,
            "gap {gap}"
        );
        let highs = data
            .chunks(2)
            .filter(|b| b[1] >> 4 == TIME_HIGH as u8)
            .count() as i64;
        assert_eq!(
            highs,
            ((7 + 2 * gap) >> 12) + 1,
            "one TIME_HIGH per step from 0"
        );
    }
}

#[test]
fn encoder_refuses_what_evt3_cannot_hold() {
    let mut encoder = Evt3Encoder::new(64, 32).unwrap();
    let err = |e: &mut Evt3Encoder, t: i64, x: u16, y: u16| e.encode(&[t], &[x], &[y], &[1]);
    assert!(err(&mut encoder, MAX_T_US, 0, 0)
        .unwrap_err()
        .contains("2^36"));
    assert!(err(&mut encoder, -1, 0, 0).is_err());
    assert!(err(&mut encoder, 0, 64, 0).unwrap_err().contains("outside"));
    assert!(err(&mut encoder, 0, 0, 32).unwrap_err().contains("outside"));
    encoder.encode(&[50], &[0], &[0], &[1]).unwrap();
    assert!(err(&mut encoder, 49, 0, 0)
        .unwrap_err()
        .contains("not sorted"));
    assert!(Evt3Encoder::new(0, 5).is_err() && Evt3Decoder::new(2049, 5, 0).is_err());
}

/// The decoder on hostile bytes: random words, valid streams cut anywhere or with bits flipped.
/// It must never panic, and an error must point inside the data.
#[test]
fn decoder_survives_random_truncated_and_flipped_streams() {
    let mut rng = Rng(7);
    let valid = encode_all(&random_rows(&mut rng, 3000, 640, 480), 640, 480);
    let start = 37;
    let check = |data: &[u8], width, height, max| {
        let mut decoder = Evt3Decoder::new(width, height, start).unwrap();
        let mut rest = data;
        let outcome = loop {
            match decoder.decode(rest, max) {
                Ok((_, used)) if used < rest.len() => rest = &rest[used..],
                Ok(_) => break decoder.finish(),
                Err(error) => break Err(error),
            }
        };
        if let Err(error) = outcome {
            assert!(
                (start..start + data.len() as u64).contains(&error.offset),
                "offset {} outside the data",
                error.offset
            );
        }
    };
    for round in 0..400 {
        let (width, height) = (1 + rng.below(2048) as u16, 1 + rng.below(2048) as u16);
        let max = 1 + rng.below(64) as usize;
        let random: Vec<u8> = (0..rng.below(4000)).map(|_| rng.next() as u8).collect();
        check(&random, width, height, max);
        let cut = &valid[..rng.below(valid.len() as u64) as usize];
        check(cut, 640, 480, max);
        let mut flipped = valid.clone();
        for _ in 0..1 + round % 20 {
            let bit = rng.below(8 * flipped.len() as u64) as usize;
            flipped[bit / 8] ^= 1 << (bit % 8);
        }
        check(&flipped, 640, 480, max);
        check(&flipped, width, height, max);
    }
}
