"""Where a dataset's files go, and how a finished sequence is installed there atomically.

    DIR/manifest.json                             spec, per-sequence parameters, status, timings
    DIR/events/sequence=NAME/part-0.parquet       events, hive-partitioned by sequence
    DIR/runs/NAME/                                the rest of the sequence's `Simulation.run`
                                                  folder (ground_truth.parquet: camera poses;
                                                  preview.png; ...) and sequence.json

A sequence is finished when `runs/NAME/sequence.json` exists: its folder is renamed into place
only after its events file is, so a run killed at any point leaves each sequence finished or not,
never half-finished, and a rerun redoes exactly the unfinished ones.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from pecs._atomic import atomic_dir, atomic_path

MANIFEST = "manifest.json"
EVENTS_DIR = "events"
RUNS_DIR = "runs"
EVENTS_FILE = "part-0.parquet"
RECORD_FILE = "sequence.json"
# `Simulation.run`'s events file, which moves to the partitioned events folder.
RUN_EVENTS_FILE = "events.parquet"
POSES_FILE = "ground_truth.parquet"


def events_partition(root: Path, name: str) -> Path:
    return root / EVENTS_DIR / f"sequence={name}"


def run_dir(root: Path, name: str) -> Path:
    return root / RUNS_DIR / name


def finished_record(root: Path, name: str) -> dict[str, Any] | None:
    """The record of a finished sequence, or None when it is not finished."""
    path = run_dir(root, name) / RECORD_FILE
    if not path.is_file() or not (events_partition(root, name) / EVENTS_FILE).is_file():
        return None
    return json.loads(path.read_text())


def check_output_folder(root: Path, names: list[str]) -> None:
    """Refuse a folder that is not this dataset's: one with other files and no manifest, or
    with sequences the spec does not have (the dataset would silently hold them)."""
    if not root.exists():
        return
    if not root.is_dir():
        raise ValueError(f"{root}: exists and is not a folder; choose another output folder")
    entries = {entry.name for entry in root.iterdir() if not entry.name.startswith(".")}
    if entries and MANIFEST not in entries:
        raise ValueError(
            f"{root}: not empty and holds no {MANIFEST}; choose another output folder for a "
            "dataset (a rerun continues a folder that a dataset run made)"
        )
    known = set(names)
    strays = sorted(
        entry.name
        for entry in (root / RUNS_DIR).glob("*")
        if entry.is_dir() and not entry.name.startswith(".") and entry.name not in known
    )
    if strays:
        raise ValueError(
            f"{root}: holds sequences the spec does not have ({', '.join(strays[:5])}); "
            "run this spec in another folder"
        )


def remove_unfinished(root: Path, name: str) -> None:
    """Delete what an interrupted or failed attempt left of a sequence (its events file may be
    in place without its run folder)."""
    shutil.rmtree(events_partition(root, name), ignore_errors=True)
    shutil.rmtree(run_dir(root, name), ignore_errors=True)


def install_sequence(root: Path, files: dict[str, bytes], record: dict[str, Any]) -> None:
    """Write a finished sequence: its events into the partition, then its run folder (with its
    record) into place in one rename, which marks it finished."""
    name = record["name"]
    if RUN_EVENTS_FILE not in files:
        raise ValueError(f"sequence {name}: the simulation wrote no {RUN_EVENTS_FILE}")
    with atomic_path(events_partition(root, name) / EVENTS_FILE) as tmp:
        tmp.write_bytes(files[RUN_EVENTS_FILE])
    target = run_dir(root, name)
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_dir(target) as building:
        for relative, data in files.items():
            if relative == RUN_EVENTS_FILE:
                continue
            path = building / relative
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        (building / RECORD_FILE).write_text(json.dumps(record, indent=2, sort_keys=True))


def write_manifest(root: Path, manifest: dict[str, Any]) -> None:
    with atomic_path(root / MANIFEST) as tmp:
        tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True))


def read_manifest(root: Path) -> dict[str, Any]:
    path = root / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{root}: no {MANIFEST}; is this a pecs dataset folder?")
    return json.loads(path.read_text())
