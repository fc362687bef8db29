"""On-the-fly generation (`pecs.dataset.GeneratedWindows`): windows generated from a spec are
deterministic per index in any process and order, equal to a `pecs dataset run` read back with
`open_dataset`, cached once on disk even when two processes ask at the same time; and the
batching of windows that hold different numbers of events."""

from __future__ import annotations

import gc
import math
import multiprocessing
import pickle
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pecs.dataset import GeneratedWindows, open_dataset, parse_spec
from pecs.dataset.on_the_fly import _created_once
from pecs.dataset.torch_adaptor import collate_arrays

DURATION_US = 12_000
WINDOW_US = 5_000
SPEC = f"""
[dataset]
name = "fly"
seed = 7

[defaults]
duration_s = {DURATION_US / 1e6}
rate_hz = 1000
spp = 1
ground_truth = "depth,instances"

[defaults.sensor]
width = 32
height = 24

[draw]
theta_on = {{ uniform = [0.1, 0.2] }}

[[sequences]]
scene = "checkerboard"
count = 2
"""
# Windows tile [0, 12 ms) in 5 ms: [0, 5), [5, 10), [10, 15) ms per sequence, two sequences.
WINDOWS_PER_SEQUENCE = math.ceil(DURATION_US / WINDOW_US)
assert WINDOWS_PER_SEQUENCE == 3

# The barrier the pool's workers meet at, so that two of them ask for a sequence at once.
_BARRIER: Any = None


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("spec") / "fly.toml"
    path.write_text(SPEC)
    return path


@pytest.fixture(scope="module")
def in_process(spec_file: Path) -> list[dict[str, np.ndarray]]:
    """Every window, generated in this process in index order."""
    windows = GeneratedWindows(spec_file, window_us=WINDOW_US, dense_ground_truth=True)
    items = list(windows)
    # The LRU of one: consecutive windows of a sequence do not simulate it again.
    assert windows.simulated == 2
    return items


@pytest.fixture(scope="module")
def pool() -> Any:
    """Two worker processes started as DataLoader's spawn context starts them."""
    context = multiprocessing.get_context("spawn")
    barrier = context.Barrier(2)
    with context.Pool(2, initializer=_keep_barrier, initargs=(barrier,)) as workers:
        yield workers


def _keep_barrier(barrier: Any) -> None:
    global _BARRIER
    _BARRIER = barrier


def _windows_in_order(args: tuple[str, list[int]]) -> dict[int, dict[str, np.ndarray]]:
    spec, order = args
    windows = GeneratedWindows(spec, window_us=WINDOW_US, dense_ground_truth=True)
    return {i: windows[i] for i in order}


def _first_window_cached_at_once(args: tuple[str, str]) -> tuple[dict[str, np.ndarray], int]:
    spec, cache = args
    windows = GeneratedWindows(spec, window_us=WINDOW_US, cache_dir=cache, dense_ground_truth=True)
    _BARRIER.wait(timeout=60)  # both workers past their imports: ask at the same moment
    return windows[0], windows.simulated


def assert_same(a: dict[str, np.ndarray], b: dict[str, np.ndarray], keys: Any = None) -> None:
    for key in a.keys() if keys is None else keys:
        assert a[key].dtype == b[key].dtype, key
        assert np.array_equal(a[key], b[key]), key


def test_length_and_window_bounds_need_no_simulation(
    spec_file: Path, in_process: list[dict[str, np.ndarray]]
) -> None:
    windows = GeneratedWindows(spec_file, window_us=WINDOW_US)
    assert len(windows) == 2 * WINDOWS_PER_SEQUENCE and windows.simulated == 0
    for i, item in enumerate(in_process):
        task, k = windows.locate(i)
        assert (task.name, k) == (f"checkerboard-{i // 3}", i % 3)
        start_us, end_us = k * WINDOW_US, (k + 1) * WINDOW_US
        assert item["window_t_us"].tolist() == [start_us, end_us]
        assert item["sequence_index"] == i // 3
        assert np.all((item["t"] >= start_us) & (item["t"] < end_us))
        assert item["flow_px"].shape == (24, 32, 2) and item["depth_m"].shape == (24, 32)
    assert windows.simulated == 0
    # The two sequences drew different thresholds: different events.
    assert sum(len(item["t"]) for item in in_process) > 0
    assert not np.array_equal(in_process[0]["t"], in_process[3]["t"])


def test_the_same_index_gives_the_same_arrays_in_any_order(
    spec_file: Path, in_process: list[dict[str, np.ndarray]]
) -> None:
    windows = GeneratedWindows(spec_file, window_us=WINDOW_US, dense_ground_truth=True)
    order = [4, 1, 5, 0, 3, 2]
    for i in order:
        assert_same(windows[i], in_process[i])
    assert windows.simulated == len(order)  # no sequence twice in a row: each access simulates


def test_other_processes_give_the_same_arrays(
    pool: Any, spec_file: Path, in_process: list[dict[str, np.ndarray]]
) -> None:
    forward, backward = list(range(6)), list(range(5, -1, -1))
    results = pool.map(_windows_in_order, [(str(spec_file), forward), (str(spec_file), backward)])
    for result in results:
        assert sorted(result) == forward
        for i, item in result.items():
            assert_same(item, in_process[i])


def test_windows_equal_those_of_a_dataset_run(
    spec_file: Path, in_process: list[dict[str, np.ndarray]], tmp_path: Path
) -> None:
    """The independent route: `pecs dataset run` in another process, read with open_dataset."""
    out = tmp_path / "data"
    command = [sys.executable, "-m", "pecs", "dataset", "run", str(spec_file), "-o", str(out)]
    subprocess.run([*command, "--workers", "1", "--quiet", "--no-card"], check=True)
    stored = open_dataset(out).windows(duration_us=WINDOW_US, dense_ground_truth=True)
    by_place = {(w.sequence, w.index): w for w in stored}
    names = ["checkerboard-0", "checkerboard-1"]
    for i, item in enumerate(in_process):
        window = by_place.pop((names[i // 3], i % 3))
        expected = window.arrays()
        assert set(item) == set(expected) | {"window_t_us", "sequence_index"}
        assert_same(item, expected, expected.keys())
    # What open_dataset has beyond them: at most a window of latency-tail events per sequence.
    for window in by_place.values():
        assert window.index == WINDOWS_PER_SEQUENCE and window.start_us >= DURATION_US


def test_a_cached_sequence_is_simulated_once(
    spec_file: Path, in_process: list[dict[str, np.ndarray]], tmp_path: Path
) -> None:
    cache = tmp_path / "cache"
    first = GeneratedWindows(
        spec_file, window_us=WINDOW_US, cache_dir=cache, dense_ground_truth=True
    )
    assert_same(first[0], in_process[0])
    assert first.simulated == 1
    # A new reader (a new epoch, another worker) finds it on disk: nothing simulated.
    again = GeneratedWindows(
        spec_file, window_us=WINDOW_US, cache_dir=cache, dense_ground_truth=True
    )
    for i in (2, 0, 1):
        assert_same(again[i], in_process[i])
    assert again.simulated == 0
    # The cache holds sequences, not windows: one 15 ms window is the three 5 ms ones.
    whole = GeneratedWindows(spec_file, window_us=3 * WINDOW_US, cache_dir=cache)[0]
    assert np.array_equal(whole["t"], np.concatenate([in_process[k]["t"] for k in range(3)]))
    assert [p.name for p in cache.iterdir()] == [first.cached_path(first.tasks[0]).name]
    # Sequence 1 is not cached yet.
    assert not first.cached_path(first.tasks[1]).exists()


def test_a_spec_change_is_not_read_from_the_cache(spec_file: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    spec = parse_spec(SPEC)
    other = parse_spec(SPEC.replace("seed = 7", "seed = 8"))
    a = GeneratedWindows(spec, window_us=WINDOW_US, cache_dir=cache)
    b = GeneratedWindows(other, window_us=WINDOW_US, cache_dir=cache)
    assert a.cached_path(a.tasks[0]) != b.cached_path(b.tasks[0])


def test_two_processes_at_once_leave_one_complete_cached_sequence(
    pool: Any, spec_file: Path, in_process: list[dict[str, np.ndarray]], tmp_path: Path
) -> None:
    cache = tmp_path / "cache"
    results = pool.map(_first_window_cached_at_once, [(str(spec_file), str(cache))] * 2)
    for item, _ in results:
        assert_same(item, in_process[0])
    assert sum(simulated for _, simulated in results) in (1, 2)
    # One folder, no temporaries beside it, and it is a finished one-sequence dataset.
    (entry,) = list(cache.iterdir())
    assert entry.name.startswith("checkerboard-0.")
    assert open_dataset(entry).sequences == ["checkerboard-0"]


def test_the_second_rename_keeps_the_first_folder(tmp_path: Path) -> None:
    """The race settled: a process whose folder is already there deletes its own copy."""
    target = tmp_path / "cache" / "seq.key"
    with _created_once(target) as building:
        (building / "mine").write_text("second")
        target.mkdir()  # another process renamed its copy in meanwhile
        (target / "theirs").write_text("first")
    assert [p.name for p in target.parent.iterdir()] == ["seq.key"]
    assert [p.name for p in target.iterdir()] == ["theirs"]
    with pytest.raises(RuntimeError), _created_once(tmp_path / "failed") as building:
        raise RuntimeError("simulation failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache"]


def test_a_held_sequence_folder_is_deleted_when_let_go(spec_file: Path) -> None:
    windows = GeneratedWindows(spec_file, window_us=WINDOW_US)
    windows[0]
    assert windows._held is not None
    first = windows._held.windows.dataset.root
    assert (first / "manifest.json").is_file()
    windows[3]  # the next sequence takes its place
    second = windows._held.windows.dataset.root
    assert not first.exists() and second.exists()
    # A spawned DataLoader worker gets it pickled, without the folder this process holds.
    copy = pickle.loads(pickle.dumps(windows))
    assert copy._held is None and len(copy) == len(windows)
    del copy
    gc.collect()
    assert second.exists()
    del windows
    gc.collect()
    assert not second.exists()


def _in_forked_child(windows: GeneratedWindows, queue: Any) -> None:
    item = windows[0]
    queue.put((windows.simulated, item["t"], str(windows._held.windows.dataset.root)))


def test_a_forked_worker_makes_its_own_folder_and_removes_it(spec_file: Path) -> None:
    """DataLoader's workers on Linux are forked: a worker inherits the held sequence of its
    parent, which it must neither use (a folder the parent may delete) nor delete."""
    windows = GeneratedWindows(spec_file, window_us=WINDOW_US)
    parent_item = windows[0]
    parent_folder = windows._held.windows.dataset.root
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_in_forked_child, args=(windows, queue))
    with warnings.catch_warnings():  # Python 3.12+ warns of fork in a threaded process
        warnings.simplefilter("ignore", DeprecationWarning)
        child.start()
    simulated, t, child_folder = queue.get(timeout=120)
    child.join(timeout=60)
    assert child.exitcode == 0
    assert simulated == 2 and np.array_equal(t, parent_item["t"])
    assert child_folder != str(parent_folder)
    assert parent_folder.exists() and not Path(child_folder).exists()


def test_a_scene_file_gives_the_duration(spec_file: Path) -> None:
    """Without duration_s in the spec, the scene file's: the built-in checkerboard's is 0.5 s
    (`[time] duration_s` of scenes/checkerboard.toml), ten 50 ms windows."""
    spec = parse_spec('[dataset]\nname = "a"\n[[sequences]]\nscene = "checkerboard"\n')
    windows = GeneratedWindows(spec, window_us=50_000)
    assert len(windows) == 10 and windows.simulated == 0


def test_bad_index_and_settings_are_clear_errors(spec_file: Path) -> None:
    windows = GeneratedWindows(spec_file, window_us=WINDOW_US)
    for bad in (6, -7, 100):
        with pytest.raises(IndexError, match=f"window {bad} of 6"):
            windows[bad]
    with pytest.raises(TypeError, match="integer"):
        windows[1.0]  # type: ignore[index]
    assert windows.simulated == 0
    with pytest.raises(ValueError, match="window_us must be at least 1"):
        GeneratedWindows(spec_file, window_us=0)
    no_truth = parse_spec(SPEC.replace('ground_truth = "depth,instances"', ""))
    with pytest.raises(ValueError, match='ground_truth = "depth,instances"'):
        GeneratedWindows(no_truth, window_us=WINDOW_US, dense_ground_truth=True)


def test_collate_concatenates_events_and_stacks_the_rest() -> None:
    items = [
        {
            "t": np.array([1, 2], dtype=np.int64),
            "p": np.array([1, 0], dtype=np.int8),
            "frame_t_us": np.array([0, 1000]),
            "window_t_us": np.array([0, 5000]),
            "depth_m": np.zeros((2, 3), dtype=np.float32),
        },
        {
            "t": np.array([7, 8, 9], dtype=np.int64),
            "p": np.array([0, 0, 1], dtype=np.int8),
            "frame_t_us": np.array([5000, 6000, 7000]),
            "window_t_us": np.array([5000, 10000]),
            "depth_m": np.ones((2, 3), dtype=np.float32),
        },
    ]
    batch = collate_arrays(items)
    assert batch["batch"].tolist() == [0, 0, 1, 1, 1]
    assert batch["t"].tolist() == [1, 2, 7, 8, 9] and batch["p"].dtype == np.int8
    assert batch["p"].tolist() == [1, 0, 0, 0, 1]
    assert batch["window_t_us"].tolist() == [[0, 5000], [5000, 10000]]
    assert batch["depth_m"].shape == (2, 2, 3) and batch["depth_m"][1].sum() == 6
    # Per-frame arrays of different lengths stay a list.
    assert [f.tolist() for f in batch["frame_t_us"]] == [[0, 1000], [5000, 6000, 7000]]
    with pytest.raises(ValueError, match="no items"):
        collate_arrays([])


def test_generated_windows_batch_for_training(in_process: list[dict[str, np.ndarray]]) -> None:
    batch = collate_arrays(in_process[:3])
    counts = [len(item["t"]) for item in in_process[:3]]
    assert np.bincount(batch["batch"], minlength=3).tolist() == counts
    assert batch["flow_px"].shape == (3, 24, 32, 2) and batch["flow_valid"].dtype == bool
    assert batch["sequence_index"].tolist() == [0, 0, 0]


def test_torch_dataset_over_generated_windows(spec_file: Path) -> None:
    torch = pytest.importorskip("torch", reason="torch is an optional extra (pecs[torch])")
    from pecs.dataset.torch_adaptor import collate_tensors, torch_dataset
    from torch.utils.data import DataLoader

    windows = GeneratedWindows(spec_file, window_us=WINDOW_US, dense_ground_truth=True)
    loader = DataLoader(torch_dataset(windows), batch_size=3, collate_fn=collate_tensors)
    batches = list(loader)
    assert len(batches) == 2
    for batch, first in zip(batches, (0, 3)):
        counts = [len(windows[i]["t"]) for i in range(first, first + 3)]
        assert torch.bincount(batch["batch"], minlength=3).tolist() == counts
        assert batch["x"].dtype == torch.int32 and batch["flow_px"].shape == (3, 24, 32, 2)
