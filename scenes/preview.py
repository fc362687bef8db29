"""Preview images for the gallery in scenes/README.md: a rendered frame and the events.

For each scene: `preview.png`, the first frame's photocurrent (sRGB, scaled to its 99.5th
percentile), and `events.png`, the events of a short window (ON blue, OFF red), both at reduced
size (the pixel pitch scaled up so that the field of view stays), reduced spp and a fixed rate,
because full-size renders take minutes per frame on a small machine. The sensor is the scene's,
noise included.

Run: python scenes/preview.py [NAME ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow as pa
from pecs.examples import linear_to_srgb8
from pecs.render import Simulation
from pecs.sensor import EventSensor
from pecs.viz import event_frame, save_image
from scene_library import MOTION_WINDOW_S, SCENES

HERE = Path(__file__).resolve().parent
SCALE = 0.375  # 1280 x 720 -> 480 x 270
SPP = 4
RATE_HZ = 1000.0


def preview(name: str) -> None:
    path = HERE / name / "scene.toml"
    geometry = Simulation(path).geometry
    sensor = {
        "width": round(geometry.width * SCALE),
        "height": round(geometry.height * SCALE),
        "pixel_pitch_um": geometry.pitch_um / SCALE,
    }
    sim = Simulation(
        path, duration_s=MOTION_WINDOW_S[name], spp=SPP, rate_hz=RATE_HZ, sensor=sensor
    )
    pixels = EventSensor(sim.sensor_config)
    batches, first = [], None
    for frame in sim.frames():
        first = frame.photocurrent_pa if first is None else first
        batches.append(pixels.feed(frame.photocurrent_pa, frame.t_us))
    batches.append(pixels.flush())
    assert first is not None
    white = max(float(np.percentile(first, 99.5)), 1e-30)
    grey = linear_to_srgb8(np.clip(first / white, 0.0, 1.0))
    save_image(grey, HERE / name / "preview.png")
    events = pa.Table.from_batches(batches)
    save_image(
        event_frame(events, width=sensor["width"], height=sensor["height"]),
        HERE / name / "events.png",
    )
    print(
        f"{name}: {events.num_rows} events in {MOTION_WINDOW_S[name]} s at {sensor['width']} x {sensor['height']}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(SCENES))
    for name in parser.parse_args().names:
        preview(name)


if __name__ == "__main__":
    main()
