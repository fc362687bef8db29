"""Real footage in, light out: frames from image folders, videos, EXR sequences, arrays and the
APS frames of AEDAT4 recordings, decoded to linear intensity with their times; how light moves
between two frames (linear, transition or optical-flow interpolation); and the read noise of
camera footage, estimated from the frames and held back before the pixels see it.

- `frames`: `open_frames` and the `FrameSource` it returns; decoding (sRGB, black level).
- `aedat4_frames`: APS frames of a DV recording, timed at their exposure midpoints.
- `frame_interpolation`, `flow_interpolation`: the light between two frames.
- `exposure`: the light at the frame times from frames averaged over their exposures.
- `input_noise`: `InputNoise` (the frames' noise level) and `InputDeadband` (holding it back).
"""

from pecs.footage.frames import FrameSource, open_frames
from pecs.footage.input_noise import InputDeadband, InputNoise

__all__ = ["FrameSource", "InputDeadband", "InputNoise", "open_frames"]
