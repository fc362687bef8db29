"""Datasets on Ray: one local Ray session (2 CPUs) shared by the module's tests, since starting
Ray takes seconds. Skipped, with the reason, where Ray is not installed (`pecs[cluster]`)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from pecs.dataset import example_spec_text, parse_spec, run_dataset
from pecs.dataset.scratch import remove_stale

ray = pytest.importorskip("ray", reason='Ray is an optional extra: pip install "pecs[cluster]"')

import psutil  # noqa: E402  (Ray ships it; importable once Ray is imported)
from test_dataset import PYTHON_PATH, SMALL_SPEC, events_by_sequence  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def local_ray() -> Iterator[None]:
    """Ray of 2 CPUs for this module; `run_dataset` uses it and leaves it running."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_two_ray_workers_give_the_events_of_one_process(tmp_path: Path) -> None:
    """The example spec on 2 Ray workers: per sequence, the same events as in this process."""
    spec = parse_spec(example_spec_text())
    on_ray = run_dataset(spec, tmp_path / "ray", workers=2)
    in_process = run_dataset(spec, tmp_path / "one", workers=1)
    assert (on_ray.engine, on_ray.workers) == ("ray", 2)
    assert in_process.engine == "sequential"
    assert sorted(on_ray.done) == sorted(in_process.done) and len(on_ray.done) == 4
    assert ray.is_initialized()  # it used the running session and did not shut it down
    parallel, sequential = (
        events_by_sequence(tmp_path / "ray"),
        events_by_sequence(tmp_path / "one"),
    )
    assert sorted(parallel) == sorted(sequential)
    for name in sequential:
        assert len(sequential[name]["t"]) > 100
        for column in "txyp":
            np.testing.assert_array_equal(parallel[name][column], sequential[name][column])


def test_a_failing_ray_task_is_recorded_and_the_rest_finish(tmp_path: Path) -> None:
    """A sequence that raises in its Ray worker (a scene file that is not TOML) fails after
    its retry, with the worker's error in the manifest; the others are written."""
    (tmp_path / "broken.toml").write_text("[scene\n")
    spec = parse_spec(
        SMALL_SPEC + '\n[[sequences]]\nscene = "broken.toml"\n', tmp_path / "spec.toml"
    )
    summary = run_dataset(spec, tmp_path / "out", workers=2)
    assert summary.failed == ["broken"]
    assert sorted(summary.done) == ["checkerboard-0", "checkerboard-1"]
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    broken = next(r for r in manifest["sequences"] if r["name"] == "broken")
    assert broken["attempts"] == 2 and "not valid TOML" in broken["error"]
    assert sorted(events_by_sequence(tmp_path / "out")) == ["checkerboard-0", "checkerboard-1"]


def _cli_run_on_ray(spec: Path, out: Path, scratch: Path) -> list[str]:
    """`pecs dataset run SPEC -o OUT --workers 2` as a user types it, with TMPDIR `scratch`."""
    scratch.mkdir(exist_ok=True)
    command = ["dataset", "run", str(spec), "-o", str(out), "--workers", "2", "--quiet"]
    return [sys.executable, "-m", "pecs", *command]


def _env(scratch: Path) -> dict[str, str]:
    """TMPDIR `scratch` for the sequences' scratch folders; Ray's own folder stays where it
    was, since the path of a socket in it cannot exceed 107 bytes."""
    ray_tmpdir = os.environ.get("RAY_TMPDIR", tempfile.gettempdir())
    # As a user's shell has it: ray.init (the module's session) set RAY_AUTH_MODE here.
    env = {key: value for key, value in os.environ.items() if key != "RAY_AUTH_MODE"}
    return {
        **env,
        "PYTHONPATH": PYTHON_PATH,
        "TMPDIR": str(scratch),
        "RAY_TMPDIR": ray_tmpdir,
    }


def test_a_cli_run_on_ray_prints_nothing_but_its_summary(tmp_path: Path) -> None:
    """Ray's start-up chatter ("Token authentication is enabled ...", INFO lines) stays out
    of a `pecs dataset run` on a local Ray: with --quiet, stderr is empty."""
    spec = tmp_path / "spec.toml"
    spec.write_text(SMALL_SPEC.replace("count = 2", "count = 1"))
    command = _cli_run_on_ray(spec, tmp_path / "out", tmp_path / "tmp")
    done = subprocess.run(
        command, env=_env(tmp_path / "tmp"), capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "(ray, 2 workers)" in done.stdout
    assert done.stderr == ""


def test_the_next_run_ends_the_ray_processes_of_a_killed_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run on its own local Ray killed outright (SIGKILL) while a worker simulates a
    sequence: Ray's agents outlive it (they wait a minute on the dead GCS); the next run ends
    every process Ray started for the dead run. (The worker removes its own scratch folder:
    Ray stops it with SIGTERM.)"""
    scratch = tmp_path / "tmp"
    spec = tmp_path / "spec.toml"
    spec.write_text(SMALL_SPEC.replace("count = 2", "count = 1"))
    process = subprocess.Popen(_cli_run_on_ray(spec, tmp_path / "out", scratch), env=_env(scratch))
    try:
        deadline = time.monotonic() + 90
        while not list(scratch.glob("pecs-sequence-*")) and time.monotonic() < deadline:
            assert process.poll() is None, "the run ended before it could be killed"
            time.sleep(0.01)
        started_by_ray = psutil.Process(process.pid).children(recursive=True)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert len(started_by_ray) >= 5  # GCS, raylet, their helpers, agents, workers
    time.sleep(1.0)  # what dies with the driver has died by now
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    summary = run_dataset(spec, tmp_path / "out", workers=2)
    assert summary.done == ["checkerboard"]
    _, alive = psutil.wait_procs(started_by_ray, timeout=5)
    assert not alive, [p.name() for p in alive]
    assert not list(scratch.glob("pecs-sequence-*"))


def test_sigterm_stops_a_run_on_ray_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGTERM to `pecs dataset run` on a local Ray ends it as any pecs command (one line,
    exit status 128 + 15), not with the stack dump of Ray's signal handler. The command ends
    at once, so what Ray left is the next run's to end (here, directly)."""
    scratch = tmp_path / "tmp"
    spec = tmp_path / "spec.toml"
    spec.write_text(SMALL_SPEC)
    command = _cli_run_on_ray(spec, tmp_path / "out", scratch)
    process = subprocess.Popen(command, env=_env(scratch), stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 90
        while not list(scratch.glob("pecs-sequence-*")) and time.monotonic() < deadline:
            assert process.poll() is None, "the run ended before it could be stopped"
            time.sleep(0.01)
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
        process.wait()
    assert (process.returncode, stderr) == (128 + 15, "pecs dataset: terminated\n")
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    assert [p.name for p in remove_stale() if p.name.startswith("pecs-ray-")]
