"""pecs: a physically based event-camera simulator."""

from pecs import calibration, events, examples, filters, footage, metrics
from pecs._core import __version__
from pecs.calibration import calibrate, calibrate_noise
from pecs.config import SensorConfig
from pecs.dataset import open_dataset
from pecs.filters import filter_events
from pecs.footage import open_frames
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
    "calibration",
    "events",
    "examples",
    "filter_events",
    "filters",
    "footage",
    "metrics",
    "frames_to_events",
    "frames_to_file",
    "open_dataset",
    "open_frames",
    "read_ground_truth",
    "read_events",
    "write_events",
]
