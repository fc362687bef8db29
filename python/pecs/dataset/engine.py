"""Where sequences run: one after another in this process, or as Ray tasks (a local Ray started
here, or a running cluster). Both take tasks and hand back outcomes as they finish; retries and
the limit on tasks in flight are the scheduler's (`schedule`), the same for both."""

from __future__ import annotations

import logging
import os
import signal
import threading
from collections import deque
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from typing import Any

from pecs.dataset import scratch
from pecs.dataset.sequence import SequenceOutput, run_sequence
from pecs.dataset.spec import SequenceTask

INSTALL_HINT = 'pip install "pecs[cluster]"'


class RayNotInstalled(ImportError):
    """Ray was asked for (more than one worker, or a cluster address) and is not installed."""

    def __init__(self) -> None:
        super().__init__(
            f"Ray is not installed: {INSTALL_HINT} to run sequences in parallel or on a cluster "
            "(--address), or run them one after another in this process with --workers 1"
        )


@dataclass(frozen=True)
class Outcome:
    """A sequence's last attempt: its output, or the error that ended it."""

    task: SequenceTask
    attempts: int
    output: SequenceOutput | None
    error: str | None


class SequentialEngine:
    """Runs each task in this process when its outcome is asked for."""

    kind = "sequential"

    def __init__(self) -> None:
        self.workers = 1
        self._queue: deque[tuple[int, SequenceTask]] = deque()
        self._next_handle = 0

    def submit(self, task: SequenceTask) -> int:
        self._next_handle += 1
        self._queue.append((self._next_handle, task))
        return self._next_handle

    def next_finished(self, handles: Collection[Any]) -> tuple[Any, SequenceOutput | BaseException]:
        handle, task = self._queue.popleft()
        try:
            return handle, run_sequence(task)
        except Exception as error:  # the sequence failed; the scheduler records or retries it
            return handle, error

    def close(self) -> None:
        pass


class RayEngine:
    """Each task a Ray task of one CPU. Starts a local Ray of `workers` CPUs unless Ray is
    already running in this process or `address` names a cluster; shuts down only what it
    started.

    Ray's start-up messages (token authentication, "Started a local Ray instance") are noise to
    a pecs user, so its driver logger shows errors only; a failed sequence's error is in the
    manifest. A local Ray is started without its dashboard and its processes are recorded
    (`pecs.dataset.scratch`): Ray makes most of them die with this process, and the next run
    ends the rest if this one is killed outright."""

    kind = "ray"

    def __init__(self, workers: int | None, address: str | None) -> None:
        try:
            import ray
        except ImportError:
            raise RayNotInstalled() from None
        self._ray = ray
        self._started = not ray.is_initialized()
        self._processes: scratch.RayProcesses | None = None
        if self._started and address is not None:
            # A cluster's own settings stand; Ray Client (ray://) takes few arguments.
            _init_keeping_sigterm(ray, address=address, logging_level=logging.ERROR)
        elif self._started:
            self._processes = scratch.RayProcesses()
            try:
                _init_keeping_sigterm(
                    ray,
                    num_cpus=workers or os.cpu_count() or 1,
                    include_dashboard=False,
                    log_to_driver=False,
                    logging_level=logging.ERROR,
                )
            except BaseException:
                self._processes.close()
                raise
            self._processes.update()
        cluster_cpus = int(ray.cluster_resources().get("CPU", 1))
        self.workers = workers or cluster_cpus
        self.address = address
        self._remote = ray.remote(num_cpus=1, max_retries=0)(run_sequence)

    def submit(self, task: SequenceTask) -> Any:
        return self._remote.remote(task)

    def next_finished(self, handles: Collection[Any]) -> tuple[Any, SequenceOutput | BaseException]:
        ray = self._ray
        (ref,), _ = ray.wait(list(handles), num_returns=1)
        if self._processes is not None:
            self._processes.update()  # the raylet starts workers and agents as it goes
        try:
            return ref, ray.get(ref)
        except Exception as error:  # a RayTaskError wraps the sequence's own exception
            return ref, getattr(error, "cause", None) or error

    def close(self) -> None:
        if self._started:
            self._ray.shutdown()
        if self._processes is not None:
            self._processes.close()


def schedule(
    engine: SequentialEngine | RayEngine, tasks: list[SequenceTask], retries: int
) -> Iterator[Outcome]:
    """Run `tasks` on `engine`, at most `engine.workers` at a time, each tried up to
    1 + `retries` times; yield each one's outcome as it is known."""
    waiting = deque((task, 1) for task in tasks)
    in_flight: dict[Any, tuple[SequenceTask, int]] = {}
    while waiting or in_flight:
        while waiting and len(in_flight) < engine.workers:
            task, attempt = waiting.popleft()
            in_flight[engine.submit(task)] = (task, attempt)
        handle, result = engine.next_finished(in_flight.keys())
        task, attempt = in_flight.pop(handle)
        if isinstance(result, BaseException):
            if attempt <= retries:
                waiting.appendleft((task, attempt + 1))
                continue
            yield Outcome(task, attempt, None, _describe(result))
        else:
            yield Outcome(task, attempt, result, None)


def make_engine(
    workers: int | None, address: str | None, kind: str | None
) -> SequentialEngine | RayEngine:
    """`kind` "sequential" or "ray"; unset: in this process for one worker and no cluster,
    else Ray."""
    if kind is None:
        kind = "sequential" if workers == 1 and address is None else "ray"
    if kind == "sequential":
        if address is not None:
            raise ValueError("a cluster address needs the Ray engine, not the sequential one")
        return SequentialEngine()
    if kind == "ray":
        return RayEngine(workers, address)
    raise ValueError(f"engine: choose 'sequential' or 'ray', got {kind!r}")


def _init_keeping_sigterm(ray: Any, **options: Any) -> None:
    """`ray.init`, leaving SIGTERM to the handler it found: Ray's own (a stack dump, then
    `sys.exit`) would replace the one-line stop of the pecs command, and a library's caller
    keeps its signal handling. Ray's handlers of crashes (SIGSEGV, SIGABRT...) stay."""
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGTERM) if in_main_thread else None
    try:
        ray.init(**options)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _describe(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return f"{type(error).__name__}: {text}" if text else type(error).__name__
