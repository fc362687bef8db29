"""Datasets, trust round two: scratch folders of killed runs are cleaned up by the next run, and
windows keep every per-event column of the dataset (labels, per-event ground truth). The Ray
side (start-up chatter, Ray processes of a killed run) is in tests/test_dataset_ray.py."""

from __future__ import annotations

import hashlib
import os
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from pecs.dataset import open_dataset, run_dataset

PYTHON_PATH = str(Path(__file__).resolve().parents[1] / "python")

# One short sequence whose events carry noise labels and per-event ground truth.
LABELLED_SPEC = """
[dataset]
name = "labelled"
seed = 5

[defaults]
duration_s = 0.01
rate_hz = 1000
spp = 1
preset = "davis346"
ground_truth = "events"

[defaults.sensor]
width = 32
height = 24
labels = true
leak_rate_hz = 20.0

[[sequences]]
scene = "checkerboard"
"""


def _owned_name(pid: int, host_name: str) -> str:
    """A scratch folder name as a run records its owner: pid and a hash of the host name."""
    host = hashlib.sha256(host_name.encode()).hexdigest()[:8]
    return f"pecs-sequence-{pid}.{host}.{secrets.token_hex(6)}"


def test_the_next_run_removes_the_scratch_folder_of_a_killed_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`pecs dataset run` killed outright (SIGKILL) while a sequence is being simulated leaves
    its scratch folder in TMPDIR; the next run removes it, and leaves alone the folders of a
    live process and of another host (which it cannot check)."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    spec = tmp_path / "spec.toml"
    spec.write_text(LABELLED_SPEC)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": PYTHON_PATH, "TMPDIR": str(scratch)}
    command = [sys.executable, "-m", "pecs", "dataset", "run", str(spec), "-o", str(out)]
    process = subprocess.Popen([*command, "--workers", "1", "--quiet"], env=env)
    try:
        deadline = time.monotonic() + 60
        while not list(scratch.glob("pecs-sequence-*")) and time.monotonic() < deadline:
            assert process.poll() is None, "the run ended before it could be killed"
            time.sleep(0.01)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    (left,) = scratch.glob("pecs-sequence-*")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        of_live_process = scratch / _owned_name(live.pid, socket.gethostname())
        of_other_host = scratch / _owned_name(process.pid, "another-host.example")
        of_live_process.mkdir()
        of_other_host.mkdir()
        monkeypatch.setattr(tempfile, "tempdir", str(scratch))
        summary = run_dataset(spec, out, workers=1)
    finally:
        live.kill()
        live.wait()
    assert summary.done == ["checkerboard"]
    assert not left.exists()
    assert sorted(scratch.glob("pecs-sequence-*")) == sorted([of_live_process, of_other_host])


@pytest.fixture(scope="module")
def labelled_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("labelled")
    (root / "spec.toml").write_text(LABELLED_SPEC)
    summary = run_dataset(root / "spec.toml", root / "out", workers=1)
    assert summary.done == ["checkerboard"]
    return root / "out"


# What the events file holds with labels and ground_truth = "events" (docs/ground-truth.md).
PER_EVENT_COLUMNS = ["t", "x", "y", "p", "label", "gt_frame", "flow_x_px", "flow_y_px", "instance"]


def test_window_arrays_keep_every_per_event_column(labelled_run: Path) -> None:
    """A window's arrays hold each column of the sequence's events file for its events
    (read here straight from the Parquet file), not only t, x, y, p."""
    stored = pq.read_table(labelled_run / "events" / "sequence=checkerboard" / "part-0.parquet")
    assert stored.column_names == PER_EVENT_COLUMNS
    t = stored.column("t").to_numpy()
    windows = open_dataset(labelled_run).windows(duration_us=4_000)
    assert len(windows) >= 3
    labels_seen = set()
    for window in windows:
        arrays = window.arrays()
        rows = (t >= window.start_us) & (t < window.end_us)
        for name in PER_EVENT_COLUMNS:
            np.testing.assert_array_equal(arrays[name], stored.column(name).to_numpy()[rows])
        assert len(arrays["frame"]) == len(arrays["pose"]) >= 2
        labels_seen.update(arrays["label"].tolist())
    assert labels_seen == {0, 1}  # signal events and leak events (20 Hz per pixel, 768 pixels)


def test_the_pytorch_item_keeps_every_per_event_column(labelled_run: Path) -> None:
    """The default PyTorch item, built as numpy (then one tensor per array), holds every
    per-event column, in a dtype torch has: unsigned 16 and 32 bit widened to signed."""
    from pecs.dataset.torch_adaptor import window_arrays

    window = open_dataset(labelled_run).windows(count=40)[0]
    item = window_arrays(window)
    stored = window.events
    for name in PER_EVENT_COLUMNS:
        np.testing.assert_array_equal(item[name], stored.column(name).to_numpy())
    assert item["x"].dtype == np.int32 and item["gt_frame"].dtype == np.int64
    assert item["label"].dtype == np.uint8 and item["instance"].dtype == np.int32


def test_the_pytorch_tensors_keep_every_per_event_column(labelled_run: Path) -> None:
    torch = pytest.importorskip("torch", reason="torch is an optional extra (pecs[torch])")
    from pecs.dataset.torch_adaptor import window_tensors

    window = open_dataset(labelled_run).windows(count=40)[0]
    tensors = window_tensors(window)
    for name in PER_EVENT_COLUMNS:
        assert isinstance(tensors[name], torch.Tensor)
        np.testing.assert_array_equal(tensors[name].numpy(), window.events.column(name).to_numpy())


def test_open_dataset_is_at_the_top_level(labelled_run: Path) -> None:
    import pecs

    assert "open_dataset" in pecs.__all__
    assert pecs.open_dataset(labelled_run).sequences == ["checkerboard"]


def test_dense_ground_truth_does_not_replace_the_per_event_instance_column(tmp_path) -> None:
    # A window with both the events' ground truth (per-event `instance`) and dense ground truth
    # (an H x W instance map at its end): arrays() gave one `instance`, the map, and lost the
    # per-event column (the dict's later key won).
    spec = tmp_path / "spec.toml"
    spec.write_text(
        "[dataset]\nname = 'both'\nseed = 3\n[defaults]\n"
        "duration_s = 0.01\nrate_hz = 1000.0\nspp = 1\npreset = 'ideal'\n"
        "ground_truth = 'depth,instances,events'\n[defaults.sensor]\nwidth = 32\nheight = 24\n"
        "[[sequences]]\nscene = 'checkerboard'\n"
    )
    from pecs.dataset import open_dataset, run_dataset

    run_dataset(spec, tmp_path / "data", workers=1, card=False)
    [window] = list(
        open_dataset(tmp_path / "data").windows(duration_us=10_000, dense_ground_truth=True)
    )[:1]
    arrays = window.arrays()
    n_events = len(arrays["t"])
    assert n_events > 0
    assert arrays["instance"].shape == (n_events,)  # per event
    assert arrays["instance_map"].shape == (24, 32)  # per pixel, at the window's end
