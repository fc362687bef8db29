//! The EVT3 decoder on any bytes, split into two chunks anywhere, with any sensor size and batch
//! bound: it must not panic; its events must lie on the sensor in batches within the bound; an
//! error must name an offset inside the data.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pecs_core::evt3::Evt3Decoder;

fuzz_target!(|input: &[u8]| {
    let Some((head, data)) = input.split_first_chunk::<6>() else {
        return;
    };
    let width = 1 + u16::from_le_bytes([head[0], head[1]]) % 2048;
    let height = 1 + u16::from_le_bytes([head[2], head[3]]) % 2048;
    let max_events = 1 + usize::from(head[4]);
    let split = usize::from(head[5]).min(data.len());
    let start = 1000;
    let mut decoder = Evt3Decoder::new(width, height, start).unwrap();
    let mut outcome = Ok(());
    'chunks: for mut chunk in [&data[..split], &data[split..]] {
        while !chunk.is_empty() {
            match decoder.decode(chunk, max_events) {
                Ok((events, used)) => {
                    assert!(used > 0 && used <= chunk.len());
                    assert!(events.len() <= max_events.max(12));
                    assert!(events.x.iter().all(|&x| x < width));
                    assert!(events.y.iter().all(|&y| y < height));
                    assert!(events.p.iter().all(|&p| p == 0 || p == 1));
                    assert!(events.t_us.iter().all(|&t| t >= 0));
                    chunk = &chunk[used..];
                }
                Err(error) => {
                    outcome = Err(error);
                    break 'chunks;
                }
            }
        }
    }
    if let Err(error) = outcome.and_then(|()| decoder.finish()) {
        let end = start + data.len() as u64;
        assert!(
            (start..end).contains(&error.offset),
            "offset {}",
            error.offset
        );
    }
});
