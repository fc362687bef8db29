"""Atomic output: write to a temporary file (or folder) beside the target, rename on success.

No output is ever left half-written: on any exception (Ctrl-C included; the CLI turns SIGTERM
into one too) the temporary is removed and the target path is untouched.

A process killed outright (SIGKILL, power loss) cannot clean up, so the temporary's name records
its writer: `.NAME.<pid>.<host>.<hex>.part`, host being a hash of the host name. A process's
first write into a folder removes the parts there whose writer is gone: same host and no process
with that id (or this very process, when the part is not one of its open writes). A part of a
live process, of another host (a shared network folder), or of a reused process id is left
alone, so concurrent writers of one target never delete each other's work; a file lock would
not do, since HDF5 locks its files itself and some writers replace the part's inode (OpenCV's
video). Once per folder and process, not per write: a run writing thousands of frames into one
folder would otherwise list it thousands of times.
"""

from __future__ import annotations

import contextlib
import glob
import hashlib
import os
import re
import secrets
import shutil
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

_HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
# Names of the temporaries this process is writing now (absolute paths).
_OPEN: set[str] = set()
_OPEN_LOCK = threading.Lock()
# Folders this process has already swept of stale parts (absolute paths).
_SWEPT: set[str] = set()
_STALE_NAME = re.compile(r"\..+\.(\d+)\.([0-9a-f]{8})\.[0-9a-f]{12}\.part(\..+)?")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; move it onto `path` when the block succeeds."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    _sweep_once(target.parent)
    with _registered(_part_name(target)) as tmp:
        # Created like open() would (mode 0666 less the umask), and never over an existing file.
        os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        try:
            yield tmp
            os.replace(tmp, target)
        except BaseException:
            _remove(tmp)
            raise


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield an empty temporary folder beside `path`; on success it takes the place of `path`
    (an existing folder there is replaced: the caller decides beforehand whether it may be)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    _sweep_once(target.parent)
    with _registered(_part_name(target)) as tmp:
        tmp.mkdir()
        try:
            yield tmp
            _swap_in(tmp, target)
        except BaseException:
            _remove(tmp)
            raise


def _swap_in(tmp: Path, target: Path) -> None:
    """Rename `tmp` to `target`; an existing folder goes aside first and is deleted after, so
    the target is never missing its complete contents for longer than two renames."""
    if not target.is_dir() or target.is_symlink():
        os.replace(tmp, target)
        return
    with _registered(_part_name(target)) as old:
        os.replace(target, old)
        os.replace(tmp, target)
        _remove(old)


def abandon_open_parts() -> None:
    """Delete every temporary this process is writing, for a process about to end without
    unwinding its `with` blocks (the CLI on SIGTERM). Takes no lock: it may run in a signal
    handler that interrupted a holder of `_OPEN_LOCK`."""
    for name in _OPEN.copy():
        _remove(Path(name))


def _sweep_once(folder: Path) -> None:
    key = str(folder.absolute())
    if key not in _SWEPT:
        _SWEPT.add(key)
        remove_stale_parts(folder)


def remove_stale_parts(folder: Path) -> list[Path]:
    """Delete the temporaries in `folder` whose writer is gone; return what was deleted."""
    removed = []
    with contextlib.suppress(OSError):
        for entry in folder.iterdir():
            found = _STALE_NAME.fullmatch(entry.name)
            if found and not _writer_alive(entry, int(found[1]), found[2]):
                _remove(entry)
                removed.append(entry)
    return removed


def _writer_alive(part: Path, pid: int, host: str) -> bool:
    if host != _HOST or os.name != "posix":
        # Another machine's process: no way to know. Windows: os.kill(pid, 0) would end it.
        return True
    if pid == os.getpid():
        main_part = re.sub(r"(\.part)\..+$", r"\1", str(part.absolute()))
        with _OPEN_LOCK:
            return main_part in _OPEN
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, another user's
    return True


def _part_name(target: Path) -> Path:
    token = secrets.token_hex(6)
    return target.with_name(f".{target.name}.{os.getpid()}.{_HOST}.{token}.part")


@contextlib.contextmanager
def _registered(tmp: Path) -> Iterator[Path]:
    """Mark `tmp` as written by this process for as long as the block runs."""
    key = str(tmp.absolute())
    with _OPEN_LOCK:
        _OPEN.add(key)
    try:
        yield tmp
    finally:
        with _OPEN_LOCK:
            _OPEN.discard(key)


def _remove(path: Path) -> None:
    """Delete a temporary file or folder, and any sidecar a writer made beside it (`NAME.mp4`)."""
    for entry in (path, *path.parent.glob(f"{glob.escape(path.name)}.*")):
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
