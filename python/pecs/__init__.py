"""pecs: a physically based event-camera simulator."""

from pecs._core import __version__

__all__ = ["__version__"]
