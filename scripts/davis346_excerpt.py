"""Write a test excerpt of a DAVIS346 AEDAT4 recording: its first N APS frames and the events up
to the last of them (event and frame streams only, ZSTD), with faery. "The last of them" is that
frame's exposure midpoint, as pecs times it (`pecs.footage.aedat4_frames.frame_time_us`).

    python scripts/davis346_excerpt.py davis346_road.aedat4 tests/data/davis346_excerpt/davis346_road_3frames.aedat4 3
    python scripts/davis346_excerpt.py demo-01.aedat4 tests/data/davis346_emlb_excerpt/davis346_emlb_3frames.aedat4 3
"""

from __future__ import annotations

import sys
from typing import Any

from faery.extension import aedat
from pecs.footage.aedat4_frames import frame_time_us


def stream_ids(source: str) -> tuple[int, int]:
    """The ids of the recording's first event stream and first frame stream."""
    tracks = aedat.Decoder(source).tracks()
    events = next(track.id for track in tracks if track.data_type == "events")
    frames = next(track.id for track in tracks if track.data_type == "frame")
    return events, frames


def first_packets(
    source: str, frames: int, event_stream: int, frame_stream: int
) -> tuple[list[tuple[int, Any]], int]:
    """The event and frame packets up to the `frames`-th frame, and that frame's time."""
    packets: list[tuple[int, Any]] = []
    last_frame_us = 0
    seen = 0
    for track, packet in aedat.Decoder(source):
        if track.id == frame_stream:
            if seen == frames:
                break
            seen += 1
            last_frame_us = frame_time_us(packet)
            packets.append((frame_stream, packet))
        elif track.id == event_stream:
            packets.append((event_stream, packet))
    return packets, last_frame_us


def main(source: str, target: str, frames: int) -> None:
    event_stream, frame_stream = stream_ids(source)
    (out_info,) = aedat.Decoder(source).description()
    kept = (str(event_stream), str(frame_stream))
    streams = [node for node in out_info.nodes if node.name in kept]
    description = aedat.DescriptionNode(out_info.name, out_info.path, out_info.attributes, streams)
    packets, last_frame_us = first_packets(source, frames, event_stream, frame_stream)
    with aedat.Encoder(target, [description], aedat.ZSTD_HIGHEST) as encoder:
        for stream, packet in packets:
            if stream == event_stream:
                # Event packets read before the next frame's run past the last frame's time.
                packet = packet[packet["t"] <= last_frame_us]
                if len(packet) == 0:
                    continue
            encoder.write(stream, packet)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
