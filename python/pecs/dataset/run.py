"""`run_dataset`: every sequence of a spec simulated (in this process or on Ray) into a Parquet
dataset partitioned by sequence, with a manifest kept up to date after each sequence.

Resumable: finished sequences (`pecs.dataset.layout`) are skipped, provided they were made with
the same parameters; a sequence that raises is retried, then recorded as failed while the others
go on. Only this process writes the output folder.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pecs.dataset import layout, scratch
from pecs.dataset.engine import Outcome, make_engine, schedule
from pecs.dataset.spec import DatasetSpec, SequenceTask, load_spec

MANIFEST_FORMAT = "pecs-dataset 1"


@dataclass(frozen=True)
class Progress:
    """Where a run stands: at the start, then after each sequence."""

    done: int
    failed: int
    skipped: int
    total: int
    events: int


@dataclass(frozen=True)
class DatasetSummary:
    out_dir: Path
    done: list[str]
    failed: list[str]
    skipped: list[str]
    events: int
    wall_s: float
    engine: str
    workers: int
    #: The dataset card written at the end of the run (`pecs.dataset.card`), or None.
    card: Path | None = None


def run_dataset(
    spec: DatasetSpec | str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    workers: int | None = None,
    address: str | None = None,
    engine: str | None = None,
    progress: Callable[[Progress], None] | None = None,
    card: bool = True,
) -> DatasetSummary:
    """Simulate the spec's unfinished sequences into `out_dir`.

    `workers`: sequences at a time (default: every CPU of the local Ray, or of the cluster);
    `address`: a running Ray cluster (`ray://...` or `auto`); `engine`: "sequential" (this
    process) or "ray", by default sequential for one worker and no address. Without Ray
    installed, Ray is a `RayNotInstalled` (an ImportError) that says how to install it.
    `card`: write the dataset card (`DIR/card.html`, `pecs.dataset.card`) at the end; a card
    that cannot be written is a warning, never a failed run.
    """
    if not isinstance(spec, DatasetSpec):
        spec = load_spec(spec)
    root = Path(out_dir)
    tasks = list(spec.sequences)
    layout.check_output_folder(root, [t.name for t in tasks])
    finished = _finished_records(root, tasks)
    todo = [t for t in tasks if t.name not in finished]
    for task in todo:
        layout.remove_unfinished(root, task.name)
    started = time.perf_counter()
    # Scratch folders and Ray processes of runs killed outright (SIGKILL) on this host.
    scratch.remove_stale()
    runner = make_engine(workers, address, engine)
    manifest = _Manifest(root, spec, runner.kind, runner.workers, address, finished)
    try:
        manifest.write()
        counts = Progress(0, 0, len(finished), len(tasks), manifest.events())
        if progress is not None:
            progress(counts)
        for outcome in schedule(runner, todo, spec.retries):
            manifest.record(_installed(root, outcome))
            counts = _counted(counts, outcome)
            manifest.write(wall_s=time.perf_counter() - started)
            if progress is not None:
                progress(counts)
    finally:
        runner.close()
    wall_s = time.perf_counter() - started  # the simulation's; the card's time is apart
    card_path = _written_card(root) if card else None
    statuses = manifest.statuses()
    return DatasetSummary(
        root,
        done=[n for n, s in statuses.items() if s == "done" and n not in finished],
        failed=[n for n, s in statuses.items() if s == "failed"],
        skipped=list(finished),
        events=manifest.events(),
        wall_s=wall_s,
        engine=runner.kind,
        workers=runner.workers,
        card=card_path,
    )


def _written_card(root: Path) -> Path | None:
    """The dataset card (`root/card.html`, `pecs.dataset.card`), rewritten for what the folder
    holds now. A report, not data: where it cannot be written, a one-line warning says why and
    the run's result stands."""
    try:
        from pecs.dataset.card import write_card

        return write_card(root)
    except Exception as error:  # noqa: BLE001 - any failure of the card leaves the run as it is
        reason = " ".join(str(error).split()) or type(error).__name__
        warnings.warn(f"{root}: dataset card not written ({reason})", stacklevel=3)
        return None


def _finished_records(root: Path, tasks: list[SequenceTask]) -> dict[str, dict[str, Any]]:
    """The sequences already finished in `root`; one made with other parameters is an error,
    since the dataset would mix two specs."""
    finished = {}
    for task in tasks:
        record = layout.finished_record(root, task.name)
        if record is None:
            continue
        expected = json.loads(json.dumps(task.record()))
        if record.get("task") != expected:
            raise ValueError(
                f"{root}: sequence {task.name} was made with other parameters than this spec "
                "gives it; run this spec in another output folder"
            )
        finished[task.name] = record
    return finished


def _installed(root: Path, outcome: Outcome) -> dict[str, Any]:
    """Write a finished sequence into the dataset; its record (done or failed) for the
    manifest. A sequence whose files cannot be written is failed too, and the run goes on."""
    record: dict[str, Any] = {
        "name": outcome.task.name,
        "task": outcome.task.record(),
        "scene_path": outcome.task.scene,
        "attempts": outcome.attempts,
        "finished_utc": _now(),
    }
    output = outcome.output
    if output is None:
        return {**record, "status": "failed", "error": outcome.error}
    record.update(
        status="done",
        events=output.events,
        frames=output.frames,
        simulated_s=output.simulated_s,
        wall_s=round(output.wall_s, 3),
        host=output.host,
        config=output.config,
    )
    try:
        layout.install_sequence(root, output.files, record)
    except (OSError, ValueError) as error:
        layout.remove_unfinished(root, outcome.task.name)
        return {**record, "status": "failed", "error": f"{type(error).__name__}: {error}"}
    return record


def _counted(counts: Progress, outcome: Outcome) -> Progress:
    if outcome.output is None:
        return Progress(counts.done, counts.failed + 1, counts.skipped, counts.total, counts.events)
    return Progress(
        counts.done + 1,
        counts.failed,
        counts.skipped,
        counts.total,
        counts.events + outcome.output.events,
    )


class _Manifest:
    """manifest.json: the spec, versions, engine, and each sequence's parameters, sensor
    configuration, status and timings; rewritten (atomically) after every sequence."""

    def __init__(
        self,
        root: Path,
        spec: DatasetSpec,
        engine: str,
        workers: int,
        address: str | None,
        finished: dict[str, dict[str, Any]],
    ) -> None:
        self.root = root
        self.head = {
            "format": MANIFEST_FORMAT,
            "name": spec.name,
            "seed": spec.seed,
            "retries": spec.retries,
            "spec": spec.text,
            "spec_file": str(spec.path) if spec.path else None,
            "versions": _versions(),
            "engine": {"kind": engine, "workers": workers, "address": address},
            "layout": {
                "events": f"{layout.EVENTS_DIR}/sequence=NAME/{layout.EVENTS_FILE}",
                "runs": f"{layout.RUNS_DIR}/NAME",
            },
            "started_utc": _now(),
        }
        self.sequences: dict[str, dict[str, Any]] = {}
        for task in spec.sequences:
            if task.name in finished:
                self.sequences[task.name] = {**finished[task.name], "resumed": True}
            else:
                self.sequences[task.name] = {
                    "name": task.name,
                    "task": task.record(),
                    "status": "pending",
                }

    def record(self, record: dict[str, Any]) -> None:
        self.sequences[record["name"]] = record

    def statuses(self) -> dict[str, str]:
        return {name: record["status"] for name, record in self.sequences.items()}

    def events(self) -> int:
        return sum(r.get("events", 0) for r in self.sequences.values() if r["status"] == "done")

    def write(self, wall_s: float = 0.0) -> None:
        statuses = list(self.statuses().values())
        manifest = {
            **self.head,
            "updated_utc": _now(),
            "wall_s": round(wall_s, 3),
            "counts": {s: statuses.count(s) for s in ("done", "failed", "pending")},
            "events": self.events(),
            "sequences": list(self.sequences.values()),
        }
        layout.write_manifest(self.root, manifest)


def _versions() -> dict[str, str | None]:
    from importlib import metadata

    from pecs import __version__

    versions: dict[str, str | None] = {"pecs": __version__, "python": platform.python_version()}
    for package in ("numpy", "pyarrow", "mitsuba", "ray"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = None
    return versions


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
