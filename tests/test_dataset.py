"""Datasets (`pecs.dataset`, `pecs dataset`): specs and their per-sequence draws, runs in this
process (resumed after a kill, with a failing sequence), and reading windows back. The Ray runs
are in tests/test_dataset_ray.py."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from pecs.cli import main
from pecs.dataset import (
    RayNotInstalled,
    example_spec_text,
    open_dataset,
    parse_spec,
    run_dataset,
)
from pecs.render import Simulation

PYTHON_PATH = str(Path(__file__).resolve().parents[1] / "python")

# Two short sequences of built-in scenes (the example's settings, fewer sequences).
SMALL_SPEC = """
[dataset]
name = "small"
seed = 11
retries = 1

[defaults]
duration_s = 0.01
rate_hz = 1000
spp = 1
preset = "davis346"

[defaults.sensor]
width = 32
height = 24

[draw]
theta_on = { uniform = [0.15, 0.3] }
refractory_us = { log_uniform = [100.0, 1000.0] }

[[sequences]]
scene = "checkerboard"
count = 2
"""


@pytest.fixture(scope="module")
def example_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example spec, run once in this process (one worker)."""
    out = tmp_path_factory.mktemp("example") / "dataset"
    summary = run_dataset(parse_spec(example_spec_text()), out, workers=1)
    assert summary.engine == "sequential" and not summary.failed
    return out


def events_by_sequence(root: Path) -> dict[str, dict[str, np.ndarray]]:
    table = ds.dataset(root / "events", format="parquet", partitioning="hive").to_table()
    out = {}
    for name in set(table.column("sequence").to_pylist()):
        rows = table.filter(ds.field("sequence") == name)
        out[name] = {c: rows.column(c).to_numpy() for c in ("t", "x", "y", "p")}
    return out


# -- specs ------------------------------------------------------------------------------------


def test_example_spec_expands_counts_and_draws_within_the_stated_ranges() -> None:
    spec = parse_spec(example_spec_text())
    names = [t.name for t in spec.sequences]
    assert names == ["checkerboard-0", "checkerboard-1", "quadrant_disk", "room"]
    assert [t.index for t in spec.sequences] == [0, 1, 2, 3]
    for task in spec.sequences:
        assert 0.15 <= task.drawn["theta_on"] <= 0.3
        assert 100.0 <= task.drawn["refractory_us"] <= 1000.0
        assert task.sensor == {"width": 48, "height": 36}
    assert spec.sequences[3].settings["spp"] == 2  # the sequence's own setting wins
    assert len({t.seed for t in spec.sequences}) == 4  # every sequence its own seed


def test_draws_follow_their_distributions() -> None:
    """400 sequences: log_uniform on [1, 100] puts half below 10 (the geometric middle), uniform
    on [0, 1] has mean 1/2 and variance 1/12, normal(5, 2) has mean 5 and sd 2, choice is
    even; each within 4 standard errors."""
    spec = parse_spec(
        SMALL_SPEC.replace("count = 2", "count = 400").replace(
            "[draw]\n",
            "[draw]\nleak_rate_hz = { log_uniform = [1.0, 100.0] }\n"
            "theta_sigma = { uniform = [0.0, 1.0] }\n"
            "latency_us = { normal = [5.0, 2.0] }\n"
            "reference_reset = { choice = ['event', 'refractory_end'] }\n",
        )
    )
    drawn = {k: np.array([t.drawn[k] for t in spec.sequences]) for k in spec.sequences[0].drawn}
    n = 400
    assert abs(np.mean(drawn["leak_rate_hz"] < 10.0) - 0.5) < 4 * math.sqrt(0.25 / n)
    assert drawn["leak_rate_hz"].min() >= 1.0 and drawn["leak_rate_hz"].max() <= 100.0
    assert abs(drawn["theta_sigma"].mean() - 0.5) < 4 * math.sqrt(1 / 12 / n)
    assert abs(drawn["theta_sigma"].var() - 1 / 12) < 0.02
    assert abs(drawn["latency_us"].mean() - 5.0) < 4 * 2.0 / math.sqrt(n)
    assert abs(drawn["latency_us"].std() - 2.0) < 0.3
    assert abs(np.mean(drawn["reference_reset"] == "event") - 0.5) < 4 * math.sqrt(0.25 / n)


def test_draws_depend_on_the_seed_and_index_only() -> None:
    """A sequence's draws do not change when sequences are added after it or the [draw] keys
    are listed in another order; they change with the dataset seed."""
    base = parse_spec(SMALL_SPEC)
    longer = parse_spec(SMALL_SPEC + '\n[[sequences]]\nscene = "room"\n')
    reordered = parse_spec(
        SMALL_SPEC.replace(
            "theta_on = { uniform = [0.15, 0.3] }\nrefractory_us = { log_uniform = [100.0, 1000.0] }",
            "refractory_us = { log_uniform = [100.0, 1000.0] }\ntheta_on = { uniform = [0.15, 0.3] }",
        )
    )
    reseeded = parse_spec(SMALL_SPEC.replace("seed = 11", "seed = 12"))
    assert [t.record() for t in longer.sequences[:2]] == [t.record() for t in base.sequences]
    assert [t.record() for t in reordered.sequences] == [t.record() for t in base.sequences]
    assert all(
        a.seed != b.seed and a.drawn != b.drawn for a, b in zip(base.sequences, reseeded.sequences)
    )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("[draw]\n", "[draw]\ntheta_onn = { uniform = [0.1, 0.2] }\n"), "draw.theta_onn"),
        (("[draw]\n", "[draw]\ntheta_off = { uniform = [0.3, 0.2] }\n"), "above max"),
        (("[draw]\n", "[draw]\ntheta_off = { gamma = [1, 2] }\n"), "unknown distribution"),
        (("[draw]\n", "[draw]\nleak_rate_hz = { log_uniform = [0, 2] }\n"), "positive"),
        (('scene = "checkerboard"', 'scene = "no_such_scene"'), "no_such_scene"),
        (("count = 2", "count = 0"), "count"),
        (("count = 2", 'name = "a/b"'), "folder name"),
        (("spp = 1", "spp = 0"), "defaults.spp"),
        (('preset = "davis346"', 'preset = "davis999"'), "davis999"),
        (("width = 32", "colour = 3"), "defaults.sensor.colour"),
        (("seed = 11", "seed = -1"), "dataset.seed"),
    ],
)
def test_bad_spec_is_a_value_error_naming_the_key(change: tuple[str, str], message: str) -> None:
    assert change[0] in SMALL_SPEC
    with pytest.raises(ValueError, match=message):
        parse_spec(SMALL_SPEC.replace(*change))


def test_duplicate_sequence_names_are_refused() -> None:
    with pytest.raises(ValueError, match="two sequences are named 'room'"):
        parse_spec(SMALL_SPEC + '[[sequences]]\nscene = "room"\n[[sequences]]\nscene = "room"\n')


# -- running ----------------------------------------------------------------------------------


def test_each_sequence_holds_the_events_of_its_simulation(example_run: Path) -> None:
    """Every sequence's partition equals `pecs.Simulation` run on its own with the parameters
    the manifest records (scene, settings, seed, fixed and drawn sensor fields)."""
    manifest = json.loads((example_run / "manifest.json").read_text())
    assert manifest["counts"] == {"done": 4, "failed": 0, "pending": 0}
    stored = events_by_sequence(example_run)
    assert sorted(stored) == ["checkerboard-0", "checkerboard-1", "quadrant_disk", "room"]
    for record in manifest["sequences"]:
        task = record["task"]
        sim = Simulation(
            record["scene_path"],
            seed=task["seed"],
            sensor={**task["sensor"], **task["drawn"]},
            **task["settings"],
        )
        batches = [b for b in sim.event_batches() if b.num_rows]
        expected = {c: np.concatenate([b.column(c).to_numpy() for b in batches]) for c in "txyp"}
        got = stored[record["name"]]
        assert record["events"] == len(expected["t"]) > 100
        for column in "txyp":
            np.testing.assert_array_equal(got[column], expected[column])
        assert record["config"]["theta_on"] == task["drawn"]["theta_on"]
        assert record["config"]["seed"] == task["seed"]


def test_manifest_records_spec_versions_and_timings(example_run: Path) -> None:
    manifest = json.loads((example_run / "manifest.json").read_text())
    assert parse_spec(manifest["spec"]).sequences == parse_spec(example_spec_text()).sequences
    assert manifest["versions"]["pyarrow"] and manifest["versions"]["numpy"]
    assert manifest["engine"] == {"kind": "sequential", "workers": 1, "address": None}
    for record in manifest["sequences"]:
        assert record["status"] == "done" and record["attempts"] == 1
        assert record["wall_s"] > 0 and record["frames"] == 21  # 20 ms at 1 kHz, both ends


def test_a_killed_run_reruns_only_the_missing_sequences(tmp_path: Path) -> None:
    """`pecs dataset run` killed outright (SIGKILL) after its first sequence; the rerun leaves
    the finished ones untouched, does the rest, and the result equals an uninterrupted run."""
    spec = tmp_path / "spec.toml"
    spec.write_text(SMALL_SPEC.replace("count = 2", "count = 4"))
    out = tmp_path / "killed"
    env = {**os.environ, "PYTHONPATH": PYTHON_PATH}
    command = [sys.executable, "-m", "pecs", "dataset", "run", str(spec), "-o", str(out)]
    process = subprocess.Popen([*command, "--workers", "1", "--quiet"], env=env)
    try:
        deadline = time.monotonic() + 60
        while not list(out.glob("runs/[!.]*/sequence.json")) and time.monotonic() < deadline:
            assert process.poll() is None, "the run ended before it could be killed"
            time.sleep(0.01)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    finished = {p.parent.name: p.stat().st_mtime_ns for p in out.glob("runs/[!.]*/sequence.json")}
    assert 1 <= len(finished) < 4, finished

    summary = run_dataset(spec, out, workers=1)
    assert sorted(summary.skipped) == sorted(finished)
    assert sorted(summary.done + summary.skipped) == [f"checkerboard-{k}" for k in range(4)]
    for name, mtime in finished.items():
        assert (out / "runs" / name / "sequence.json").stat().st_mtime_ns == mtime
    assert not [p for p in out.rglob(".*") if p.name.endswith(".part")]
    reference = tmp_path / "reference"
    run_dataset(spec, reference, workers=1)
    resumed, clean = events_by_sequence(out), events_by_sequence(reference)
    assert sorted(resumed) == sorted(clean)
    for name in clean:
        for column in "txyp":
            np.testing.assert_array_equal(resumed[name][column], clean[name][column])


def test_an_events_file_without_its_run_folder_is_redone(tmp_path: Path) -> None:
    """A run stopped between a sequence's two renames (events file in place, run folder not):
    the sequence is not finished, so the rerun replaces the events file and marks it done."""
    out = tmp_path / "out"
    run_dataset(parse_spec(SMALL_SPEC), out, workers=1)
    original = pq.read_table(out / "events" / "sequence=checkerboard-1" / "part-0.parquet")
    shutil.rmtree(out / "runs" / "checkerboard-1")
    (out / "events" / "sequence=checkerboard-1" / "part-0.parquet").write_bytes(b"torn")
    assert open_dataset(out).sequences == ["checkerboard-0"]
    summary = run_dataset(parse_spec(SMALL_SPEC), out, workers=1)
    assert summary.skipped == ["checkerboard-0"] and summary.done == ["checkerboard-1"]
    redone = pq.read_table(out / "events" / "sequence=checkerboard-1" / "part-0.parquet")
    assert redone.equals(original)


def test_a_failing_sequence_is_retried_recorded_and_the_rest_finish(tmp_path: Path) -> None:
    """A scene whose Mitsuba file is not XML fails on each of its 1 + retries attempts; the
    manifest says so, the other sequences are written, the CLI exits 1, and a rerun tries only
    the failed one again."""
    scene = tmp_path / "broken.toml"
    checkerboard = Path(__import__("pecs").__file__).parent / "scenes" / "checkerboard.toml"
    scene.write_text(checkerboard.read_text().replace("checkerboard.xml", "broken.xml"))
    (tmp_path / "broken.xml").write_text("<scene version='3.0.0'>")
    spec = tmp_path / "spec.toml"
    spec.write_text(SMALL_SPEC + '\n[[sequences]]\nscene = "broken.toml"\n')
    out = tmp_path / "out"
    assert main(["dataset", "run", str(spec), "-o", str(out), "--workers", "1", "--quiet"]) == 1
    manifest = json.loads((out / "manifest.json").read_text())
    records = {r["name"]: r for r in manifest["sequences"]}
    assert records["broken"]["status"] == "failed"
    assert records["broken"]["attempts"] == 2  # retries = 1
    assert "broken.xml" in records["broken"]["error"]
    assert records["checkerboard-0"]["status"] == records["checkerboard-1"]["status"] == "done"
    assert manifest["counts"] == {"done": 2, "failed": 1, "pending": 0}
    assert sorted(events_by_sequence(out)) == ["checkerboard-0", "checkerboard-1"]
    again = run_dataset(spec, out, workers=1)
    assert again.skipped == ["checkerboard-0", "checkerboard-1"] and again.failed == ["broken"]


def test_a_moved_project_still_resumes(tmp_path: Path) -> None:
    """Scene files named relative to the spec: moving the spec, its scenes and the output
    together keeps the finished sequences finished."""
    project = tmp_path / "project"
    (project / "scenes").mkdir(parents=True)
    builtin = Path(__import__("pecs").__file__).parent / "scenes"
    for file in ("checkerboard.toml", "checkerboard.xml"):
        shutil.copy(builtin / file, project / "scenes" / file)
    spec_text = SMALL_SPEC.replace('scene = "checkerboard"', 'scene = "scenes/checkerboard.toml"')
    (project / "spec.toml").write_text(spec_text)
    first = run_dataset(project / "spec.toml", project / "out", workers=1)
    assert len(first.done) == 2
    moved = tmp_path / "moved"
    project.rename(moved)
    again = run_dataset(moved / "spec.toml", moved / "out", workers=1)
    assert sorted(again.skipped) == sorted(first.done) and again.done == []
    manifest = json.loads((moved / "out" / "manifest.json").read_text())
    assert manifest["sequences"][0]["task"]["scene"] == "scenes/checkerboard.toml"


def test_a_rerun_with_another_spec_is_refused(tmp_path: Path, example_run: Path) -> None:
    changed = example_spec_text().replace("seed = 2024", "seed = 2025")
    with pytest.raises(ValueError, match="other parameters"):
        run_dataset(parse_spec(changed), example_run, workers=1)
    (tmp_path / "mine.txt").write_text("user data")
    with pytest.raises(ValueError, match="no manifest.json"):
        run_dataset(parse_spec(SMALL_SPEC), tmp_path, workers=1)


def test_without_ray_more_workers_say_how_to_install_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    with pytest.raises(RayNotInstalled, match=r'pip install "pecs\[cluster\]"'):
        run_dataset(parse_spec(SMALL_SPEC), tmp_path / "a", workers=2)
    spec = tmp_path / "spec.toml"
    spec.write_text(SMALL_SPEC)
    assert main(["dataset", "run", str(spec), "-o", str(tmp_path / "b"), "--quiet"]) == 2
    assert "--workers 1" in capsys.readouterr().err
    assert main(["dataset", "run", str(spec), "-o", str(tmp_path / "c"), "--workers", "1"]) == 0


def test_cli_example_prints_a_spec_that_runs(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dataset", "example"]) == 0
    spec = parse_spec(capsys.readouterr().out)
    assert spec.name == "example" and len(spec.sequences) == 4


# -- reading windows --------------------------------------------------------------------------


def test_duration_windows_tile_each_sequence(example_run: Path) -> None:
    """5 ms windows: every event of a sequence is in exactly one window, inside its bounds,
    and the poses reach from at or before the window's start to at or after its end."""
    dataset = open_dataset(example_run)
    windows = dataset.windows(duration_us=5000)
    by_sequence: dict[str, list] = {}
    for window in windows:
        by_sequence.setdefault(window.sequence, []).append(window)
        t = window.events.column("t").to_numpy()
        assert np.all((t >= window.start_us) & (t < window.end_us))
        assert window.end_us - window.start_us == 5000
        frames_t = window.frame_t_us
        assert frames_t[0] <= window.start_us and (
            frames_t[-1] >= window.end_us or frames_t[-1] == 20_000
        )
        assert np.all(np.diff(window.frame_indices) == 1)
    stored = events_by_sequence(example_run)
    for name, parts in by_sequence.items():
        assert [w.index for w in parts] == list(range(len(parts)))
        joined = np.concatenate([w.arrays()["t"] for w in parts])
        np.testing.assert_array_equal(joined, stored[name]["t"])
        # 20 ms of simulation, plus a window for events the latency pushes past its end
        assert len(parts) == math.ceil((stored[name]["t"].max() + 1) / 5000) >= 4


def test_count_windows_hold_that_many_events(example_run: Path) -> None:
    dataset = open_dataset(example_run)
    stored = events_by_sequence(example_run)
    windows = dataset.windows(count=100, sequences=["quadrant_disk"])
    total = len(stored["quadrant_disk"]["t"])
    assert len(windows) == math.ceil(total / 100)
    assert [w.events.num_rows for w in windows][:-1] == [100] * (len(windows) - 1)
    last = windows[-1]
    np.testing.assert_array_equal(
        last.arrays()["t"], stored["quadrant_disk"]["t"][-len(last.events) :]
    )
    assert (
        len(dataset.windows(count=100, sequences=["quadrant_disk"], drop_partial=True))
        == total // 100
    )
    assert windows[-1].start_us == stored["quadrant_disk"]["t"][(len(windows) - 1) * 100]


def test_window_arrays_pickling_and_ground_truth_access(
    example_run: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import pickle

    import pecs

    windows = open_dataset(example_run).windows(duration_us=10_000)
    copy = pickle.loads(pickle.dumps(windows))
    assert len(copy) == len(windows)
    a, b = windows[3].arrays(), copy[3].arrays()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert a["pose"].shape == (len(a["frame"]), 7)
    # unit quaternions, position of the room's camera on its first keyframe
    np.testing.assert_allclose(np.linalg.norm(a["pose"][:, 3:], axis=1), 1.0, atol=1e-9)
    room = next(w for w in windows if w.sequence == "room" and w.index == 0)
    np.testing.assert_allclose(room.arrays()["pose"][0, :3], [-0.5, 0.6, 2.0])
    with pytest.raises(IndexError):
        windows[len(windows)]
    if not hasattr(pecs, "read_ground_truth"):
        with pytest.raises(RuntimeError, match="read_ground_truth"):
            room.ground_truth()
    seen = []
    monkeypatch.setattr(pecs, "read_ground_truth", seen.append, raising=False)
    room.ground_truth()
    assert seen == [example_run / "runs" / "room"]


def test_bad_window_arguments_are_value_errors(example_run: Path) -> None:
    dataset = open_dataset(example_run)
    for kwargs in ({}, {"duration_us": 10, "count": 10}, {"count": 0}, {"duration_us": 1.5}):
        with pytest.raises(ValueError, match="windows"):
            dataset.windows(**kwargs)
    with pytest.raises(KeyError, match="nope"):
        dataset.windows(count=10, sequences=["nope"])


def test_torch_adaptor_gives_tensors(example_run: Path) -> None:
    torch = pytest.importorskip("torch", reason="torch is an optional extra (pecs[torch])")
    from pecs.dataset.torch_adaptor import torch_dataset

    windows = open_dataset(example_run).windows(count=50)
    data = torch_dataset(windows)
    assert len(data) == len(windows)
    item = data[0]
    assert isinstance(item["t"], torch.Tensor) and item["t"].shape == (50,)
    np.testing.assert_array_equal(item["x"].numpy(), windows[0].arrays()["x"])


def test_polars_and_duckdb_read_the_partitions(example_run: Path) -> None:
    """Each reads the hive partitions as pyarrow does (only where installed)."""
    counts = {k: len(v["t"]) for k, v in events_by_sequence(example_run).items()}
    pattern = str(example_run / "events" / "*" / "*.parquet")
    checked = 0
    try:
        import polars as pl

        frame = pl.scan_parquet(pattern, hive_partitioning=True).group_by("sequence").len()
        assert dict(frame.collect().iter_rows()) == counts
        checked += 1
    except ImportError:
        pass
    try:
        import duckdb

        rows = duckdb.sql(
            f"select sequence, count(*) from read_parquet('{pattern}', hive_partitioning=true) "
            "group by sequence"
        ).fetchall()
        assert dict(rows) == counts
        checked += 1
    except ImportError:
        pass
    if not checked:
        pytest.skip("neither polars nor duckdb is installed")
    # and pyarrow reads each partition's file with its own schema
    assert pq.read_table(next((example_run / "events").glob("*/*.parquet"))).num_rows > 0


def test_sequences_carry_the_ground_truth_they_ask_for(tmp_path: Path) -> None:
    """`ground_truth` and `imu_rate_hz` in a spec reach each sequence's Simulation; its window
    reads the ground truth back: the checkerboard's camera looks down -z from z = 1 m at the
    board in the plane z = 0, so the z-depth at the image centre is 1 m; the static camera's
    IMU reads gravity only (9.80665 m/s^2 along its +y, up), at the asked rate."""
    spec = tmp_path / "spec.toml"
    spec.write_text(
        SMALL_SPEC.replace("count = 2", "count = 1").replace(
            'preset = "davis346"',
            'preset = "davis346"\nground_truth = "depth,imu"\nimu_rate_hz = 2000.0',
        )
    )
    run_dataset(spec, tmp_path / "out", workers=1)
    window = open_dataset(tmp_path / "out").windows(duration_us=5_000)[0]
    truth = window.ground_truth()
    depth = truth.depth(window.frame_indices[0])
    assert depth.shape == (24, 32)
    np.testing.assert_allclose(depth[11:13, 15:17], 1.0, rtol=1e-4)
    imu = truth.imu.to_pydict()
    assert len(imu["t_us"]) == pytest.approx(0.01 * 2000 + 1, abs=1)
    accel = np.array([imu[f"accel_{axis}_m_s2"] for axis in "xyz"]).T
    np.testing.assert_allclose(accel, np.tile([0.0, 9.80665, 0.0], (len(accel), 1)), atol=1e-6)
    with pytest.raises(ValueError, match="defaults.ground_truth: unknown kind 'albedo'"):
        parse_spec(
            SMALL_SPEC.replace(
                'preset = "davis346"', 'preset = "davis346"\nground_truth = "albedo"'
            )
        )
