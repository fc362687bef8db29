"""A PyTorch `Dataset` over event windows (optional extra: `pip install "pecs[torch]"`).

Thin on purpose: `EventWindows` does the indexing and reading; this wraps it in
`torch.utils.data.Dataset` and turns each window into tensors (or whatever `transform` makes of
it: a voxel grid, an event frame). Windows hold different numbers of events, so batch them with
`batch_size=None`, a `transform` to a fixed shape, or a `collate_fn` of your own.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pecs.dataset.windows import EventWindow, EventWindows


def window_tensors(window: EventWindow) -> dict[str, Any]:
    """The default item: a window's arrays (`window_arrays`) as torch tensors, with its
    sequence name."""
    import torch

    tensors: dict[str, Any] = {
        name: torch.from_numpy(array) for name, array in window_arrays(window).items()
    }
    tensors["sequence"] = window.sequence
    return tensors


def window_arrays(window: EventWindow) -> dict[str, np.ndarray]:
    """`EventWindow.arrays` (every per-event column: t, x, y, p, and labels and per-event
    ground truth where the dataset has them; the frames' times, indices and poses) in dtypes
    torch has."""
    return {
        name: array.astype(_TORCH_SAFE.get(array.dtype.str, array.dtype), copy=False)
        for name, array in window.arrays().items()
    }


# torch has no uint16 or uint32 tensors in older releases: widen them to int32 / int64.
_TORCH_SAFE = {"<u2": "int32", "<u4": "int64"}


def torch_dataset(
    windows: EventWindows, transform: Callable[[EventWindow], Any] | None = None
) -> Any:
    """`windows` as a `torch.utils.data.Dataset`; item i is `transform(windows[i])`
    (default: `window_tensors`)."""
    try:
        from torch.utils.data import Dataset
    except ImportError:
        raise ImportError('the PyTorch adaptor needs torch: pip install "pecs[torch]"') from None

    class EventWindowDataset(Dataset):
        def __init__(self) -> None:
            self.windows = windows
            self.transform = transform or window_tensors

        def __len__(self) -> int:
            return len(self.windows)

        def __getitem__(self, i: int) -> Any:
            return self.transform(self.windows[i])

    return EventWindowDataset()
