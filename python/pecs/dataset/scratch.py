"""What a dataset run leaves outside its output folder, cleaned up by the next run when the run
was killed outright (SIGKILL, the OOM killer, a lost node) and could not clean up itself.

- Each sequence is simulated in a scratch folder of the process that runs it (a Ray worker or
  the driver), `pecs-sequence-<pid>.<host>.<hex>` in the temporary folder (TMPDIR).
- A run that starts a local Ray records the processes Ray started for it (pid and start time)
  in `pecs-ray-<pid>.<host>.<hex>.json` there: Ray makes its GCS and raylet die with the driver,
  but not the agents the raylet starts, which wait a minute on the dead GCS before they exit.

Names record their owner as `pecs._atomic` does for its temporaries, and the same liveness
check decides: an owner is gone when it ran on this host and no process has its id. Each run
(and each worker process, once) removes what gone owners left, ending the recorded Ray
processes still running: only those whose start time matches the record, so never a process
that reused an id. Folders of live owners, of other hosts and of other users are left alone.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from pecs._atomic import _HOST, _registered, _writer_alive, atomic_path

SEQUENCE_PREFIX = "pecs-sequence-"
RAY_PREFIX = "pecs-ray-"
_OWNED = re.compile(r"pecs-(sequence|ray)-(\d+)\.([0-9a-f]{8})\.[0-9a-f]{12}(\.json)?")
_SUFFIX = {"sequence": None, "ray": ".json"}
# Whether this process has already removed what gone owners left (once per worker process).
_swept = False
# This process's Ray records. Not in `pecs._atomic`'s registry of open temporaries, whose
# files the pecs command deletes when SIGTERM stops it: a record must outlive its owner.
_RECORDS: set[Path] = set()


@contextlib.contextmanager
def sequence_folder() -> Iterator[Path]:
    """A new empty scratch folder owned by this process, deleted when the block ends."""
    _remove_stale_once()
    path = _owned_path(SEQUENCE_PREFIX, "")
    with _registered(path):
        path.mkdir(mode=0o700)
        try:
            yield path
        finally:
            shutil.rmtree(path, ignore_errors=True)


class RayProcesses:
    """The record of the processes a local Ray started for this process: the Ray executables
    and scripts among its children, and everything they started. Close it after
    `ray.shutdown()`."""

    def __init__(self) -> None:
        self.path = _owned_path(RAY_PREFIX, ".json")
        _RECORDS.add(self.path)
        self._recorded: list[list[Any]] = []

    def update(self) -> None:
        """Record Ray's processes as they are now (the raylet starts some after `ray.init`)."""
        psutil = _psutil()
        if psutil is None:
            return
        processes = sorted(_started_by_ray(psutil))
        if processes != self._recorded:
            self._recorded = processes
            with atomic_path(self.path) as tmp:
                tmp.write_text(json.dumps({"processes": processes}))

    def close(self) -> None:
        self.path.unlink(missing_ok=True)
        _RECORDS.discard(self.path)


def remove_stale() -> list[Path]:
    """Remove the scratch folders and Ray records in the temporary folder whose owner is gone,
    ending the recorded Ray processes still running; return what was removed."""
    try:
        entries = list(Path(tempfile.gettempdir()).absolute().iterdir())
    except OSError:
        return []
    owned = [(entry, _OWNED.fullmatch(entry.name)) for entry in entries]
    owned = [
        (entry, found)
        for entry, found in owned
        if found and found[4] == _SUFFIX[found[1]] and _mine(entry)
    ]
    removed = []
    # Ray records first: the workers they end leave scratch folders of their own.
    ended: set[int] = set()
    for entry, found in owned:
        if found[1] == "ray" and not _owner_alive(entry, int(found[2]), found[3]):
            ended |= _end_recorded_processes(entry)
            entry.unlink(missing_ok=True)
            removed.append(entry)
    for entry, found in owned:
        pid, host = int(found[2]), found[3]
        if found[1] == "sequence" and (
            (host == _HOST and pid in ended) or not _owner_alive(entry, pid, host)
        ):
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


def _remove_stale_once() -> None:
    global _swept
    if not _swept:
        _swept = True
        remove_stale()


def _owned_path(prefix: str, suffix: str) -> Path:
    name = f"{prefix}{os.getpid()}.{_HOST}.{secrets.token_hex(6)}{suffix}"
    return Path(tempfile.gettempdir()).absolute() / name


def _owner_alive(entry: Path, pid: int, host: str) -> bool:
    """`pecs._atomic`'s check: alive unless it ran on this host and no process has its id
    (this process: unless the entry is one of its open ones)."""
    return entry in _RECORDS or _writer_alive(entry, pid, host)


def _mine(entry: Path) -> bool:
    """Whether this user owns `entry`: another user's record must not say what to end."""
    try:
        return not hasattr(os, "getuid") or entry.lstat().st_uid == os.getuid()
    except OSError:
        return False


def _end_recorded_processes(record: Path) -> set[int]:
    """Kill the recorded processes still running; return their ids (a killed process whose
    parent is gone may linger as a zombie where nothing reaps orphans)."""
    psutil = _psutil()
    if psutil is None:  # Ray is no longer installed: nothing to check the record with
        return set()
    try:
        processes = json.loads(record.read_text())["processes"]
    except (OSError, ValueError, KeyError, TypeError):
        return set()
    ended = set()
    for item in processes:
        with contextlib.suppress(psutil.Error, TypeError, ValueError):
            pid, started = item
            process = psutil.Process(pid)
            # A process that reused the id started later: not Ray's.
            if process.create_time() == started:
                # SIGKILL: an orphaned agent ignores SIGTERM while it waits on the dead GCS.
                process.kill()
                ended.add(pid)
    return ended


def _started_by_ray(psutil: Any) -> list[list[Any]]:
    """[pid, start time] of this process's children that run Ray's executables or scripts,
    and of all they started (the raylet's agents and workers)."""
    import ray

    ray_dir = os.path.dirname(os.path.abspath(ray.__file__))
    found = []
    for child in psutil.Process().children():
        with contextlib.suppress(psutil.Error):
            if any(arg.startswith(ray_dir) for arg in child.cmdline()):
                found += [child, *child.children(recursive=True)]
    started = []
    for process in found:
        with contextlib.suppress(psutil.Error):  # a worker may have ended meanwhile
            started.append([process.pid, process.create_time()])
    return started


def _psutil() -> Any | None:
    """psutil, which Ray ships and puts on the path when imported; None without Ray."""
    try:
        import ray  # noqa: F401  (first: it puts the psutil it ships on the path)
    except ImportError:
        return None
    try:
        import psutil
    except ImportError:
        return None
    return psutil
