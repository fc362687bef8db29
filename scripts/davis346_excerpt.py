"""Write the test excerpt of the DAVIS346 road recording: its first N APS frames and the events up
to the last of them (event and frame streams only, ZSTD), with faery.

    python scripts/davis346_excerpt.py davis346_road.aedat4 tests/data/davis346_excerpt/davis346_road_3frames.aedat4 3
"""

from __future__ import annotations

import sys
from typing import Any

from faery.extension import aedat

EVENT_STREAM, FRAME_STREAM = 0, 1


def first_packets(source: str, frames: int) -> tuple[list[tuple[int, Any]], int]:
    """The event and frame packets up to the `frames`-th frame, and that frame's time."""
    packets: list[tuple[int, Any]] = []
    last_frame_us = 0
    seen = 0
    for track, packet in aedat.Decoder(source):
        if track.id == FRAME_STREAM:
            if seen == frames:
                break
            seen += 1
            last_frame_us = packet.t
            packets.append((FRAME_STREAM, packet))
        elif track.id == EVENT_STREAM:
            packets.append((EVENT_STREAM, packet))
    return packets, last_frame_us


def main(source: str, target: str, frames: int) -> None:
    (out_info,) = aedat.Decoder(source).description()
    streams = [
        node for node in out_info.nodes if node.name in (str(EVENT_STREAM), str(FRAME_STREAM))
    ]
    description = aedat.DescriptionNode(out_info.name, out_info.path, out_info.attributes, streams)
    packets, last_frame_us = first_packets(source, frames)
    with aedat.Encoder(target, [description], aedat.ZSTD_HIGHEST) as encoder:
        for stream, packet in packets:
            if stream == EVENT_STREAM:
                packet = packet[packet["t"] <= last_frame_us]
                if len(packet) == 0:
                    continue
            encoder.write(stream, packet)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
