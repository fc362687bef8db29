//! Any sorted events on any sensor: encoded, then decoded in two chunks, they come back equal.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pecs_core::evt3::{Evt3Decoder, Evt3Encoder};

fuzz_target!(|input: &[u8]| {
    let Some((head, rest)) = input.split_first_chunk::<5>() else {
        return;
    };
    let width = 1 + u16::from_le_bytes([head[0], head[1]]) % 2048;
    let height = 1 + u16::from_le_bytes([head[2], head[3]]) % 2048;
    let (mut t, mut x, mut y, mut p) = (vec![], vec![], vec![], vec![]);
    let mut now: i64 = 0;
    for event in rest.chunks_exact(6) {
        // Time steps of 0 to 255 µs, or up to 2^24 µs (a wrap of the 24-bit time); libFuzzer's
        // inputs (4096 bytes) stay far below the encoder's 2^36 µs.
        let step = u16::from_le_bytes([event[0], event[1]]);
        now += if step & 1 == 1 {
            i64::from(step) << 8
        } else {
            i64::from(step >> 8)
        };
        t.push(now);
        x.push(u16::from_le_bytes([event[2], event[3]]) % width);
        y.push(u16::from(event[4]) * 8 % height);
        p.push((event[5] & 1) as i8);
    }
    let data = Evt3Encoder::new(width, height)
        .unwrap()
        .encode(&t, &x, &y, &p)
        .unwrap();
    let split = (usize::from(head[4]) * 7).min(data.len());
    let mut decoder = Evt3Decoder::new(width, height, 0).unwrap();
    let (mut got_t, mut got_x, mut got_y, mut got_p) = (vec![], vec![], vec![], vec![]);
    for mut chunk in [&data[..split], &data[split..]] {
        while !chunk.is_empty() {
            let (events, used) = decoder.decode(chunk, 100).unwrap();
            got_t.extend(events.t_us);
            got_x.extend(events.x);
            got_y.extend(events.y);
            got_p.extend(events.p);
            chunk = &chunk[used..];
        }
    }
    decoder.finish().unwrap();
    assert_eq!((got_t, got_x, got_y, got_p), (t, x, y, p));
});
