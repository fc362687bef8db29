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

Only a regular file can be replaced. A symlink is followed: the file it points to is replaced
atomically, the link kept. A stream cannot be replaced, so it is written to: a FIFO or a
character device (a terminal, /dev/null) directly when the writer `streams` (writes front to
back, never seeking back), else through a temporary file copied to it at the end; a Unix socket
is connected to and sent the finished file. One of this process's descriptors named as a path
(/dev/stdout, /dev/fd/N, /proc/self/fd/N) is written through that descriptor, so a shell's
redirection (`> FILE`, `>> FILE`, `| COMMAND`) decides where the output goes. A stream gets what
was written before a failure: it cannot take it back.
"""

from __future__ import annotations

import contextlib
import errno
import glob
import hashlib
import os
import re
import secrets
import shutil
import socket
import stat
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

_HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
# Names of the temporaries this process is writing now (absolute paths).
_OPEN: set[str] = set()
_OPEN_LOCK = threading.Lock()
# Folders this process has already swept of stale parts (absolute paths).
_SWEPT: set[str] = set()
_STALE_NAME = re.compile(r"\..+\.(\d+)\.([0-9a-f]{8})\.[0-9a-f]{12}\.part(\..+)?")
# Paths that name one of this process's descriptors (Linux, macOS).
_DESCRIPTOR_PATH = re.compile(
    r"/dev/(stdin|stdout|stderr)|/dev/fd/(\d+)|/proc/(self|thread-self|\d+)/fd/(\d+)"
)
_STANDARD_STREAMS = {"stdin": 0, "stdout": 1, "stderr": 2}
_COPY_BYTES = 1 << 20


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], *, streams: bool = False) -> Iterator[Path]:
    """Yield the path to write to; what was written there is at `path` when the block succeeds.

    A regular file (new or not) is written beside the target and renamed onto it; a symlink's
    target is; a stream (FIFO, character device, socket, a descriptor of this process) is written
    to as the module says, directly when `streams` (the writer never seeks back)."""
    given = Path(path)
    descriptor = descriptor_of(given)
    if descriptor is not None:
        with to_descriptor(descriptor, streams=streams, name=str(given)) as where:
            yield where
        return
    # A symlink is followed: the file it names is replaced, the link stays.
    target = Path(os.path.realpath(given)) if given.is_symlink() else given
    kind = _stream_kind(target, given)
    if kind == "socket":
        with _spooled(target.name, given, lambda done: _send_to_socket(done, target)) as tmp:
            yield tmp
    elif kind == "device" and streams:
        yield target
    elif kind == "device":
        with _spooled(target.name, given, lambda done: _copy_to_path(done, target)) as tmp:
            yield tmp
    else:
        with _replacing(target, given) as tmp:
            yield tmp


@contextlib.contextmanager
def _replacing(target: Path, given: Path) -> Iterator[Path]:
    """A temporary beside the regular file `target`, renamed onto it when the block succeeds."""
    if target.is_dir():
        raise IsADirectoryError(errno.EISDIR, "a folder is there, not a file", str(given))
    _make_folder(target.parent, given)
    _sweep_once(target.parent)
    with _registered(_part_name(target)) as tmp:
        try:
            # Created like open() would (mode 0666 less the umask), never over an existing file.
            os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        except OSError as error:
            raise _cannot_write(
                given, error, f"creating a file in folder {target.parent}"
            ) from None
        try:
            yield tmp
            try:
                os.replace(tmp, target)
            except OSError as error:
                raise _cannot_write(given, error, f"renaming into folder {target.parent}") from None
        except BaseException:
            _remove(tmp)
            raise


def descriptor_of(path: str | os.PathLike[str]) -> int | None:
    """The descriptor of this process that `path` names (/dev/stdout, /dev/fd/N,
    /proc/self/fd/N, or a symlink to one of them), or None."""
    if os.name != "posix":
        return None
    name = os.path.abspath(os.fspath(path))
    for _ in range(32):  # a chain of symlinks; a loop ends here
        found = _DESCRIPTOR_PATH.fullmatch(name)
        if found:
            standard, dev_fd, process, proc_fd = found.groups()
            if standard:
                return _STANDARD_STREAMS[standard]
            if dev_fd:
                return int(dev_fd)
            own = process in ("self", "thread-self") or int(process) == os.getpid()
            return int(proc_fd) if own else None
        if not os.path.islink(name):
            return None
        name = os.path.normpath(os.path.join(os.path.dirname(name), os.readlink(name)))
    return None


def names_stdout(path: str | os.PathLike[str]) -> bool:
    """Whether output to `path` goes to this process's stdout: `-`, /dev/stdout, /dev/fd/1."""
    return os.fspath(path) == "-" or descriptor_of(path) == 1


def is_terminal(path: str | os.PathLike[str]) -> bool:
    """Whether `path` (`-` for stdout) is a terminal, where binary output would garble the
    screen."""
    descriptor = 1 if os.fspath(path) == "-" else descriptor_of(path)
    if descriptor is not None:
        return os.isatty(descriptor)
    try:
        if not stat.S_ISCHR(os.stat(path).st_mode):
            return False
        # O_NOCTTY: looking must not make it this process's controlling terminal.
        probe = os.open(path, os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        return os.isatty(probe)
    finally:
        os.close(probe)


@contextlib.contextmanager
def to_descriptor(descriptor: int, *, streams: bool = False, name: str = "-") -> Iterator[Path]:
    """Yield a path whose content goes to `descriptor` (1 for stdout; `name` in errors): the
    descriptor's own pipe or device when the writer `streams`, else a temporary file that is
    copied through the descriptor at the end. A regular file behind it gets the copy too, so a
    shell's `>> FILE` appends and nothing replaces the file."""
    for stream in (sys.stdout, sys.stderr):  # what was printed comes first
        with contextlib.suppress(OSError, ValueError, AttributeError):
            stream.flush()
    try:
        mode = os.fstat(descriptor).st_mode
    except OSError as error:
        raise _cannot_write(Path(name), error, f"descriptor {descriptor}") from None
    direct = Path(f"/dev/fd/{descriptor}")
    if streams and (stat.S_ISFIFO(mode) or stat.S_ISCHR(mode)) and direct.exists():
        yield direct
        return
    deliver = lambda done: _copy_to_descriptor(done, descriptor)  # noqa: E731
    with _spooled(f"fd{descriptor}", Path(name), deliver) as tmp:
        yield tmp


def _stream_kind(target: Path, given: Path) -> str | None:
    """ "device" (FIFO, character device), "socket", or None for a regular file or none."""
    try:
        mode = target.stat().st_mode
    except OSError:
        return None
    if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode):
        return "device"
    if stat.S_ISSOCK(mode):
        return "socket"
    if stat.S_ISBLK(mode):
        raise ValueError(f"{given} is a block device (a disk), not a file: write to a file")
    return None


@contextlib.contextmanager
def _spooled(name: str, given: Path, deliver: Callable[[Path], None]) -> Iterator[Path]:
    """A temporary file in the system's temporary folder; `deliver(it)` when the block succeeds,
    and it is deleted either way."""
    folder = Path(tempfile.gettempdir())
    _sweep_once(folder)
    with _registered(_part_name(folder / name)) as tmp:
        os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        try:
            yield tmp
            try:
                deliver(tmp)
            except OSError as error:
                raise _cannot_write(given, error, "sending the output") from None
        finally:
            _remove(tmp)


def _copy_to_descriptor(source: Path, descriptor: int) -> None:
    with open(source, "rb") as file:
        while chunk := file.read(_COPY_BYTES):
            view = memoryview(chunk)
            while view:
                view = view[os.write(descriptor, view) :]


def _copy_to_path(source: Path, target: Path) -> None:
    with open(source, "rb") as file, open(target, "wb") as out:
        shutil.copyfileobj(file, out, _COPY_BYTES)


def _send_to_socket(source: Path, target: Path) -> None:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as connection:
        connection.connect(str(target))
        with open(source, "rb") as file:
            while chunk := file.read(_COPY_BYTES):
                connection.sendall(chunk)


def _make_folder(folder: Path, given: Path) -> None:
    """Create the target's folder; a file in the way is named, not just "File exists"."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as error:
        blocker = next((p for p in (folder, *folder.parents) if p.is_file()), None)
        if blocker is None:
            raise _cannot_write(given, error, f"creating folder {folder}") from None
        raise NotADirectoryError(
            errno.ENOTDIR, f"{blocker} is a file, not a folder", str(given)
        ) from None
    except OSError as error:
        raise _cannot_write(given, error, f"creating folder {error.filename or folder}") from None


def _cannot_write(given: Path, error: OSError, doing: str) -> OSError:
    """The same failure (same OSError subclass, same errno) naming the target the user gave,
    not the hidden temporary, and saying what failed."""
    if error.errno is None:
        return OSError(errno.EIO, f"{error} ({doing})", str(given))
    reason = os.strerror(error.errno)
    if error.errno in (errno.EACCES, errno.EPERM):
        reason = "Permission denied"
    return OSError(error.errno, f"{reason} ({doing})", str(given))


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
