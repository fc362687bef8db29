"""pecs: a physically based event-camera simulator."""

from pecs._core import __version__
from pecs.lens import Lens

__all__ = ["Lens", "__version__"]
