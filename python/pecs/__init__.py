"""pecs: a physically based event-camera simulator."""

from pecs._core import __version__
from pecs.io import read_events, write_events

__all__ = ["__version__", "read_events", "write_events"]
