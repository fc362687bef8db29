"""pecs: a physically based event-camera simulator."""

from pecs import events, examples, input_noise, metrics
from pecs._core import __version__
from pecs.background_fit import calibrate_noise
from pecs.calibration import calibrate
from pecs.config import SensorConfig
from pecs.dataset import open_dataset
from pecs.frames import open_frames
from pecs.ground_truth import read_ground_truth
from pecs.io import read_events, write_events
from pecs.lens import Lens
from pecs.render import Simulation
from pecs.sensor import EventSensor, frames_to_events, frames_to_file

__all__ = [
    "EventSensor",
    "Lens",
    "SensorConfig",
    "Simulation",
    "__version__",
    "calibrate",
    "calibrate_noise",
    "events",
    "examples",
    "input_noise",
    "metrics",
    "frames_to_events",
    "frames_to_file",
    "open_dataset",
    "open_frames",
    "read_ground_truth",
    "read_events",
    "write_events",
]
