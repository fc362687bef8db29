"""How the `pecs` command stops early: Ctrl-C, SIGTERM and a closed stdout end it with one line
(or none) and the conventional exit code, and no temporary output left behind.

Neither Ctrl-C nor SIGTERM raises: an exception raised by a signal handler is swallowed when it
lands in a weakref callback, a `__del__` or a native library's callback (a SIGTERM that raised
was lost in about one run of two, and the command went on to the end; the test that
interrupts a write with Ctrl-C failed once under load while KeyboardInterrupt unwound it). The
handler deletes
the temporaries itself (`pecs._atomic.abandon_open_parts`) and ends the process at once.

These handlers are installed by the CLI entry alone and only while a command runs: a library
must not take over the signal handling of the process that imports it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any, TextIO

from pecs._atomic import abandon_open_parts

# 128 + the signal number, as a shell reports a process the signal ended.
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_TERMINATED = 128 + signal.SIGTERM
EXIT_PIPE_CLOSED = 128 + 13  # SIGPIPE (not in the signal module on Windows)


class StdoutClosed(BaseException):
    """The reader of stdout went away (`pecs info f | head -2`); not an OSError, so the error
    handling of a command does not report it as a failed write."""


def run_stoppable(command: str, run: Callable[[], int]) -> int:
    """`run()`, with SIGTERM ending the process cleanly and stdout's broken pipe raising
    `StdoutClosed`; each stop becomes a one-line message (none for the pipe) and its exit code."""
    try:
        with _signals_end(command), _stdout_guarded():
            code = run()
            sys.stdout.flush()
            return code
    except KeyboardInterrupt:  # before the handler is in place
        print(f"pecs {command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except StdoutClosed:
        # Python's recipe: point stdout at /dev/null so the flush at exit has nowhere to fail.
        with contextlib.suppress(OSError, ValueError):  # ValueError: stdout has no descriptor
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_PIPE_CLOSED


@contextlib.contextmanager
def _signals_end(command: str) -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield  # only the main thread may set handlers (pecs.cli.main called from a thread)
        return
    words = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated"}
    codes = {signal.SIGINT: EXIT_INTERRUPTED, signal.SIGTERM: EXIT_TERMINATED}

    def end(signum: int, frame: Any) -> None:
        for each in words:  # one clean-up, not two at once
            signal.signal(each, signal.SIG_IGN)
        abandon_open_parts()
        # A progress bar may hold the line; start a fresh one on a terminal.
        newline = "\n" if sys.stderr.isatty() else ""
        os.write(2, f"{newline}pecs {command}: {words[signum]}\n".encode())
        os._exit(codes[signum])

    previous = {each: signal.signal(each, end) for each in words}
    try:
        yield
    finally:
        for each, handler in previous.items():
            signal.signal(each, handler)


@contextlib.contextmanager
def _stdout_guarded() -> Iterator[None]:
    original = sys.stdout
    sys.stdout = _GuardedStream(original)
    try:
        yield
    finally:
        sys.stdout = original


class _GuardedStream:
    """A text stream whose writes turn BrokenPipeError into `StdoutClosed`."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            raise StdoutClosed from None

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            raise StdoutClosed from None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)
