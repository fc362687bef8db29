"""A PyTorch `Dataset` over event windows (optional extra: `pip install "pecs[torch]"`).

Thin on purpose: `EventWindows` (a dataset folder's windows) or `GeneratedWindows` (windows
generated from a spec, `pecs.dataset.on_the_fly`) does the indexing, reading and generating; this
wraps it in `torch.utils.data.Dataset` and turns each window into tensors (or whatever
`transform` makes of it: a voxel grid, an event frame). Windows hold different numbers of
events, so batch them with `collate_fn=collate_tensors` (events concatenated with a `batch`
index), `batch_size=None`, or a `transform` to a fixed shape. Only `window_tensors`,
`item_tensors`, `collate_tensors` and `torch_dataset` import torch; the rest is numpy.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from pecs.dataset.windows import EventWindow, EventWindows

if TYPE_CHECKING:
    from pecs.dataset.on_the_fly import GeneratedWindows


def window_tensors(window: EventWindow) -> dict[str, Any]:
    """The default item: a window's arrays (`window_arrays`) as torch tensors, with its
    sequence name."""
    import torch

    tensors: dict[str, Any] = {
        name: _tensor(torch, array) for name, array in window_arrays(window).items()
    }
    tensors["sequence"] = window.sequence
    return tensors


def window_arrays(window: EventWindow) -> dict[str, np.ndarray]:
    """`EventWindow.arrays` (every per-event column: t, x, y, p, and labels and per-event
    ground truth where the dataset has them; the frames' times, indices and poses) in dtypes
    torch has."""
    return torch_safe(window.arrays())


def torch_safe(arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The arrays in dtypes torch has (unsigned 16 and 32 bit widened to signed)."""
    return {
        name: array.astype(_TORCH_SAFE.get(array.dtype.str, array.dtype), copy=False)
        for name, array in arrays.items()
    }


def item_tensors(item: EventWindow | Mapping[str, np.ndarray]) -> dict[str, Any]:
    """The default item of `torch_dataset`: a window's tensors (`window_tensors`), or a
    `GeneratedWindows` item's arrays as tensors."""
    if isinstance(item, EventWindow):
        return window_tensors(item)
    import torch

    return {name: _tensor(torch, array) for name, array in torch_safe(item).items()}


def _tensor(torch: Any, array: np.ndarray) -> Any:
    """`torch.from_numpy`, copying an array that does not own writable memory first (Arrow's
    columns are read-only): torch would warn that writing to the tensor is undefined."""
    return torch.from_numpy(array if array.flags.writeable else array.copy())


#: Columns that hold one value per event (the events file's; `pecs.ground_truth.event_truth`).
EVENT_COLUMNS = ("t", "x", "y", "p", "label", "gt_frame", "flow_x_px", "flow_y_px", "instance")


def collate_arrays(items: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """A batch of windows that hold different numbers of events, as numpy: the per-event
    columns (`EVENT_COLUMNS`) concatenated, with `batch` (int64, the item each event comes
    from); other arrays of one shape in every item stacked (dense ground truth, `window_t_us`);
    anything else (per-frame arrays of different lengths, sequence names) as a list per key."""
    if not items:
        raise ValueError("collate: no items to batch")
    counts = [len(item["t"]) for item in items]
    batch: dict[str, Any] = {"batch": np.repeat(np.arange(len(items), dtype=np.int64), counts)}
    for key in items[0]:
        values = [item[key] for item in items]
        arrays = all(isinstance(v, np.ndarray) for v in values)
        if (
            arrays
            and key in EVENT_COLUMNS
            and all(v.ndim == 1 and len(v) == n for v, n in zip(values, counts))
        ):
            batch[key] = np.concatenate(values)
        elif arrays and len({v.shape for v in values}) == 1:
            batch[key] = np.stack(values)
        else:
            batch[key] = values
    return batch


def collate_tensors(items: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """`collate_arrays` for items of tensors (a DataLoader's `collate_fn`): the same batch, as
    tensors."""
    import torch

    as_numpy = [
        {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in item.items()}
        for item in items
    ]

    def tensors(value: Any) -> Any:
        if isinstance(value, list):  # one per item: per-frame arrays, names
            return [tensors(v) for v in value]
        return _tensor(torch, value) if isinstance(value, np.ndarray) else value

    return {key: tensors(value) for key, value in collate_arrays(as_numpy).items()}


# torch has no uint16 or uint32 tensors in older releases: widen them to int32 / int64.
_TORCH_SAFE = {"<u2": "int32", "<u4": "int64"}


def torch_dataset(
    windows: EventWindows | GeneratedWindows, transform: Callable[[Any], Any] | None = None
) -> Any:
    """`windows` (a dataset's, or generated ones) as a `torch.utils.data.Dataset`; item i is
    `transform(windows[i])` (default: `item_tensors`). Batch with `collate_fn=collate_tensors`."""
    try:
        from torch.utils.data import Dataset
    except ImportError:
        raise ImportError('the PyTorch adaptor needs torch: pip install "pecs[torch]"') from None

    class EventWindowDataset(Dataset):
        def __init__(self) -> None:
            self.windows = windows
            self.transform = transform or item_tensors

        def __len__(self) -> int:
            return len(self.windows)

        def __getitem__(self, i: int) -> Any:
            return self.transform(self.windows[i])

    return EventWindowDataset()
