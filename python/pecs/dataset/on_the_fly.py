"""Windows of events generated from a spec where they are read: no dataset folder.

`GeneratedWindows(spec, window_us=50_000)` is a map-style sequence of training items, like
`open_dataset(DIR).windows(duration_us=...)`, whose item i renders and simulates the sequence it
needs (`run_sequence`, as `pecs dataset run` does) and returns the window's arrays. A sequence
depends on the spec and its index alone (its draws and seed come from the dataset seed and the
index), so item i is the same, bit for bit, in any process and in any order of access: DataLoader
workers need nothing but the picklable object.

Where a sequence lives while it is read:

- without `cache_dir`, in a private scratch folder of the process (`pecs.dataset.scratch`: a
  killed worker's folder is removed by the next run), deleted when another sequence takes its
  place, when the object is garbage collected, or when the process ends;
- with `cache_dir`, in `cache_dir/NAME.KEY/` (KEY: a hash of the sequence's parameters, its
  scene file and the pecs version), written once and reused by every process and every later
  run. It is built in a temporary folder beside it and renamed into place only when complete,
  and never replaced: when two workers ask for the same uncached sequence at once, both simulate
  it (identical copies), the first rename wins and the other worker reads the winner's and
  deletes its own. No locks, so a killed worker leaves nothing that blocks the others (its
  temporary folder is removed by the next process that writes there), and a shared network
  folder works.

Each cached or held sequence is a one-sequence dataset folder (`open_dataset` reads it), so its
windows are read exactly as a dataset run's.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import multiprocessing.util
import os
import weakref
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from pecs import _atomic
from pecs.dataset import layout, scratch
from pecs.dataset.spec import DatasetSpec, SequenceTask, load_spec
from pecs.dataset.windows import EventWindows, open_dataset

#: The spec kinds of ground truth a window's dense ground truth is computed from.
DENSE_KINDS = frozenset({"depth", "instances"})


@dataclass
class _Held:
    """The sequence this process holds (the LRU of one): its windows, and how to let it go."""

    index: int
    windows: EventWindows
    release: Callable[[], Any]
    #: The process that made it: a forked DataLoader worker inherits it and must not use or
    #: delete a folder its parent may still be reading.
    pid: int


class GeneratedWindows:
    """Windows of `window_us` microseconds of a spec's sequences, generated on demand.

    `len()` is the number of sequences times each one's windows, `ceil(duration / window_us)`
    (its duration from the spec, or its scene file): windows tile [0, duration) from t = 0, the
    last one running past the duration and taking the latency tail up to its end. `[i]` is
    window i (sequence order, then time order) as `EventWindow.arrays()` (events t, x, y, p and
    the per-event columns the spec asks for; frame_t_us, frame, pose; with `dense_ground_truth`
    flow_px, flow_valid, flow_t_us, depth_m, instance) plus `window_t_us` (start, end) and
    `sequence_index`. The same arrays as `open_dataset` gives for a `pecs dataset run` of the
    spec (tested); `open_dataset` may give one window more, holding only latency-tail events.
    """

    def __init__(
        self,
        spec: DatasetSpec | str | os.PathLike[str],
        *,
        window_us: int,
        cache_dir: str | os.PathLike[str] | None = None,
        dense_ground_truth: bool = False,
    ) -> None:
        if isinstance(window_us, bool) or not isinstance(window_us, (int, np.integer)):
            raise ValueError(
                f"window_us must be an integer number of microseconds, got {window_us!r}"
            )
        if window_us < 1:
            raise ValueError(f"window_us must be at least 1, got {window_us}")
        self.spec = spec if isinstance(spec, DatasetSpec) else load_spec(spec)
        if dense_ground_truth:
            _check_dense_kinds(self.spec)
        self.window_us = int(window_us)
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.dense_ground_truth = dense_ground_truth
        #: Sequences this object simulated in this process (cache hits and held ones not).
        self.simulated = 0
        self._held: _Held | None = None

    @property
    def tasks(self) -> tuple[SequenceTask, ...]:
        return self.spec.sequences

    @cached_property
    def _first_window(self) -> np.ndarray:
        """Index of each sequence's first window, and the total at the end."""
        counts = [max(1, math.ceil(_duration_us(t) / self.window_us)) for t in self.tasks]
        return np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])

    def __len__(self) -> int:
        return int(self._first_window[-1])

    def __iter__(self) -> Iterator[dict[str, np.ndarray]]:
        for i in range(len(self)):
            yield self[i]

    def locate(self, i: int) -> tuple[SequenceTask, int]:
        """The sequence of window `i` and the window's number within it; nothing generated."""
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"window index must be an integer, got {i!r}")
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"window {i} of {n}")
        i = int(i) % n
        s = int(np.searchsorted(self._first_window, i, side="right")) - 1
        return self.tasks[s], i - int(self._first_window[s])

    def __getitem__(self, i: int) -> dict[str, np.ndarray]:
        task, k = self.locate(i)
        window = self._sequence(task)[k]
        return {
            **window.arrays(),
            "window_t_us": np.array([window.start_us, window.end_us], dtype=np.int64),
            "sequence_index": np.array(task.index, dtype=np.int64),
        }

    def cached_path(self, task: SequenceTask) -> Path:
        """Where `cache_dir` keeps a sequence (a one-sequence dataset folder)."""
        if self.cache_dir is None:
            raise ValueError("no cache_dir: generated sequences are not kept")
        return self.cache_dir / f"{task.name}.{sequence_key(task)}"

    def __getstate__(self) -> dict[str, Any]:
        # A held sequence's folder belongs to this process: a DataLoader worker makes its own.
        return {**self.__dict__, "_held": None}

    def _sequence(self, task: SequenceTask) -> EventWindows:
        """The windows of `task`'s sequence: the one held, else cached, else simulated now."""
        held = self._held
        if held is not None and held.pid == os.getpid() and held.index == task.index:
            return held.windows
        self._release()
        if self.cache_dir is None:
            folder, release = self._scratch_folder()
            try:
                self._simulate(task, folder)
            except BaseException:
                release()
                raise
        else:
            folder, release = self.cached_path(task), _nothing
            if layout.finished_record(folder, task.name) is None:
                with _created_once(folder) as building:
                    self._simulate(task, building)
            if layout.finished_record(folder, task.name) is None:
                raise FileExistsError(
                    f"{folder}: not a finished sequence of the cache; delete it to regenerate"
                )
        windows = open_dataset(folder).windows(
            duration_us=self.window_us, dense_ground_truth=self.dense_ground_truth
        )
        self._held = _Held(task.index, windows, release, os.getpid())
        return windows

    def _release(self) -> None:
        held, self._held = self._held, None
        if held is not None and held.pid == os.getpid():
            held.release()

    def _scratch_folder(self) -> tuple[Path, Callable[[], Any]]:
        """A new scratch folder of this process, and the call that deletes it (also made when
        this object is collected or the process ends)."""
        stack = contextlib.ExitStack()
        folder = stack.enter_context(scratch.sequence_folder())
        release = weakref.finalize(self, _close_in, os.getpid(), stack, str(folder))
        _release_at_process_exit(str(folder), release)
        return folder, release

    def _simulate(self, task: SequenceTask, root: Path) -> None:
        write_sequence(self.spec, task, root)
        self.simulated += 1


def write_sequence(spec: DatasetSpec, task: SequenceTask, root: Path) -> None:
    """Simulate `task` (`run_sequence`, as a dataset run does) into `root` as a one-sequence
    dataset folder: its events, run folder and record, and a manifest naming it."""
    from pecs.dataset.engine import Outcome
    from pecs.dataset.run import MANIFEST_FORMAT, _installed
    from pecs.dataset.sequence import run_sequence

    record = _installed(root, Outcome(task, 1, run_sequence(task), None))
    if record["status"] != "done":
        raise OSError(f"sequence {task.name}: not written ({record.get('error')})")
    manifest = {"format": MANIFEST_FORMAT, "name": spec.name, "seed": spec.seed}
    layout.write_manifest(root, {**manifest, "spec": spec.text, "sequences": [record]})


def sequence_key(task: SequenceTask) -> str:
    """A hash of what a sequence's events depend on: its parameters (`task.record()`), its
    dataset seed, the bytes of its scene file, and the pecs version."""
    from pecs import __version__

    scene_file = Path(task.scene)
    scene_hash = (
        hashlib.sha256(scene_file.read_bytes()).hexdigest()
        if not task.generator and scene_file.is_absolute() and scene_file.is_file()
        else ""
    )
    what = [task.record(), task.dataset_seed, scene_hash, __version__]
    text = json.dumps(what, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@contextlib.contextmanager
def _created_once(target: Path) -> Iterator[Path]:
    """Yield an empty temporary folder beside `target`, renamed to `target` when the block
    succeeds, unless another process has put its folder there first: then the temporary is
    deleted and that folder stays (it holds the same sequence). `pecs._atomic`'s temporary names
    and clean-up of a killed writer's; unlike `atomic_dir` it never replaces a folder that
    another process may be reading."""
    target.parent.mkdir(parents=True, exist_ok=True)
    _atomic._sweep_once(target.parent)
    with _atomic._registered(_atomic._part_name(target)) as tmp:
        tmp.mkdir()
        try:
            yield tmp
            try:
                os.rename(tmp, target)
            except OSError as error:
                lost = error.errno in (errno.EEXIST, errno.ENOTEMPTY) and target.is_dir()
                if not lost:
                    raise
                _atomic._remove(tmp)
        except BaseException:
            _atomic._remove(tmp)
            raise


def _duration_us(task: SequenceTask) -> int:
    """A sequence's simulated duration, known before it is simulated: the spec's, a generated
    scene's default, or its scene file's (read, not rendered)."""
    if "duration_s" in task.settings or task.generator:
        from pecs.dataset.generators import task_settings

        return round(task_settings(task).duration_s * 1_000_000)
    from pecs.dataset.sequence import build_simulation

    return int(build_simulation(task).duration_us)


def _check_dense_kinds(spec: DatasetSpec) -> None:
    from pecs.ground_truth.layout import parse_kinds

    for task in spec.sequences:
        kinds = parse_kinds(task.settings.get("ground_truth"))
        if not DENSE_KINDS <= kinds:
            raise ValueError(
                f'dense ground truth needs ground_truth = "depth,instances" (or "all") in '
                f"the spec; sequence {task.name} has {task.settings.get('ground_truth', 'none')!r}"
            )


def _close_in(pid: int, stack: contextlib.ExitStack, folder: str) -> None:
    """Delete a scratch folder, in the process that made it only (not in a forked child)."""
    if os.getpid() == pid:
        _LIVE.pop(folder, None)
        stack.close()


# This process's held scratch folders, and the process that hooked their release to its exit.
_LIVE: dict[str, Callable[[], Any]] = {}
_HOOKED_PID: int | None = None


def _release_at_process_exit(folder: str, release: Callable[[], Any]) -> None:
    """`weakref.finalize` runs when the interpreter exits, but a multiprocessing worker (a
    DataLoader's) ends with `os._exit` after multiprocessing's own exit hooks: release the
    folders there too, or each worker would leave its last sequence in TMPDIR."""
    global _HOOKED_PID
    if _HOOKED_PID != os.getpid():
        _HOOKED_PID = os.getpid()
        _LIVE.clear()  # a forked parent's: not this process's to delete
        multiprocessing.util.Finalize(None, _release_live, exitpriority=0)
    _LIVE[folder] = release


def _release_live() -> None:
    for release in list(_LIVE.values()):
        release()


def _nothing() -> None:
    """A cached sequence stays on disk when another takes its place in memory."""
