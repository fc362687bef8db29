"""Datasets on Ray: one local Ray session (2 CPUs) shared by the module's tests, since starting
Ray takes seconds. Skipped, with the reason, where Ray is not installed (`pecs[cluster]`)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from pecs.dataset import example_spec_text, parse_spec, run_dataset

ray = pytest.importorskip("ray", reason='Ray is an optional extra: pip install "pecs[cluster]"')

from test_dataset import SMALL_SPEC, events_by_sequence  # noqa: E402


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
