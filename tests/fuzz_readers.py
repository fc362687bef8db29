"""Mutation fuzzing of every pecs reader, in a child process so that a native crash is caught.

    python tests/fuzz_readers.py --seconds 3600 [--seed 1] [--save DIR]

Seeds are small valid files of every format (tests/bad_inputs.py). Each round mutates one seed
(bit flips, byte insertions and deletions, truncation, overwritten runs, splices with another
seed, a foreign suffix), and a worker process reads it with `pecs.io.iter_events`. A read
must either give events of the pecs schema (integer t, x, y, p) or raise EventFileError or
ValueError; anything else (another exception, a crash of the worker, a read over
--timeout seconds) is a finding: the input is saved to the --save folder (a temporary folder
by default) with what happened, and the worker is restarted. The exit status is the number
of findings (capped at 100). CI runs it for a bounded time through tests/test_fuzz_readers.py
(PECS_FUZZ_SECONDS, 40 by default).
"""

from __future__ import annotations

import argparse
import gc
import json
import random
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bad_inputs  # noqa: E402

_WORKER_MEMORY_BYTES = 4 << 30  # a read that needs more is a finding (MemoryError)


# --- the worker: reads one file per request line, answers one JSON line -------------------------


def worker() -> None:
    import resource

    import numpy as np
    import pecs.io
    import pyarrow as pa

    resource.setrlimit(resource.RLIMIT_AS, (_WORKER_MEMORY_BYTES, _WORKER_MEMORY_BYTES))
    expected = {"t": pa.int64(), "x": pa.uint16(), "y": pa.uint16(), "p": pa.int8()}
    for line in sys.stdin:
        request = json.loads(line)
        try:
            rows = 0
            for batch in pecs.io.iter_events(request["path"], batch_size=request["batch_size"]):
                for name, kind in expected.items():
                    if batch.schema.field(name).type != kind:
                        raise AssertionError(f"column {name} is {batch.schema.field(name).type}")
                p = batch.column("p").to_numpy()
                if len(p) and not np.isin(p, [0, 1]).all():
                    raise AssertionError("p outside {0, 1}")
                if batch.num_rows > request["batch_size"]:
                    raise AssertionError(f"batch of {batch.num_rows} > {request['batch_size']}")
                rows += batch.num_rows
            answer = {"outcome": "events", "rows": rows}
        except (pecs.io.EventFileError, ValueError) as error:
            answer = {"outcome": "refused", "type": type(error).__name__, "message": str(error)}
        except BaseException as error:  # noqa: BLE001 (every other exception is a finding)
            answer = {"outcome": "finding", "type": type(error).__name__, "message": str(error)}
        # Destructors of this read's native objects run now, so a crash in one is charged to
        # this input and not to a later one.
        gc.collect()
        print(json.dumps(answer), flush=True)


# --- mutations ----------------------------------------------------------------------------------


def mutate(data: bytes, other: bytes, rng: random.Random) -> bytes:
    """One to four random edits of `data`; `other` is another seed for splices."""
    buffer = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        kind = rng.choice(
            ["flip", "flip", "byte", "insert", "delete", "truncate", "run", "splice", "copy"]
        )
        _edit(buffer, other, kind, rng)
    return bytes(buffer)


def _edit(buffer: bytearray, other: bytes, kind: str, rng: random.Random) -> None:
    at = rng.randrange(len(buffer) + 1)
    if kind == "flip" and buffer:
        at = min(at, len(buffer) - 1)
        buffer[at] ^= 1 << rng.randrange(8)
    elif kind == "byte" and buffer:
        at = min(at, len(buffer) - 1)
        buffer[at] = rng.choice([0x00, 0xFF, 0x7F, 0x80, 0x01, rng.randrange(256)])
    elif kind == "insert":
        buffer[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    elif kind == "delete":
        del buffer[at : at + rng.randint(1, 16)]
    elif kind == "truncate":
        del buffer[at:]
    elif kind == "run":
        value = rng.choice([0x00, 0xFF, rng.randrange(256)])
        buffer[at : at + rng.randint(1, 64)] = bytes([value]) * rng.randint(1, 64)
    elif kind == "splice" and other:
        cut = rng.randrange(len(other))
        buffer[at:] = other[cut:]
    elif kind == "copy" and buffer:
        start = rng.randrange(len(buffer))
        buffer[at:at] = buffer[start : start + rng.randint(1, 256)]


# --- the parent: mutates, sends, watches --------------------------------------------------------


@dataclass
class Report:
    rounds: dict[str, int] = field(default_factory=dict)
    outcomes: dict[str, int] = field(default_factory=dict)
    findings: list[dict[str, str]] = field(default_factory=list)


def _panic_lines(stderr: str) -> str:
    """The lines that say what crashed (Rust panics, Python fatal errors), else the tail."""
    lines = stderr.splitlines()
    keep = [
        " ".join(lines[i : i + 2])
        for i, line in enumerate(lines)
        if any(mark in line for mark in ("panicked at", "Fatal Python error", "memory allocation"))
    ]
    return "\n".join(keep)[:2000] if keep else stderr[-2000:]


class Worker:
    """The child that reads; restarted after a crash or a hang."""

    def __init__(self, stderr_path: Path) -> None:
        self.process: subprocess.Popen[str] | None = None
        # stderr goes to a file: a pipe nobody reads would fill and stall the worker.
        self._stderr_path = stderr_path

    def read(self, path: Path, batch_size: int, timeout_s: float) -> dict[str, object]:
        if self.process is None or self.process.poll() is not None:
            if self.process is not None:
                self.process.communicate()  # the crashed worker's pipes closed, it reaped
            with self._stderr_path.open("w") as stderr:  # the child keeps its own copy
                self.process = subprocess.Popen(
                    [sys.executable, __file__, "--worker"],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=stderr,
                    text=True,
                )
        assert self.process.stdin is not None and self.process.stdout is not None
        request = {"path": str(path), "batch_size": batch_size}
        try:
            self.process.stdin.write(json.dumps(request) + "\n")
            self.process.stdin.flush()
        except BrokenPipeError:
            return self._crashed()
        import selectors

        with selectors.DefaultSelector() as selector:
            selector.register(self.process.stdout, selectors.EVENT_READ)
            if not selector.select(timeout_s):
                self.process.kill()
                self.process.communicate()  # reaped, its pipes closed
                self.process = None
                return {"outcome": "finding", "type": "hang", "message": f"> {timeout_s} s"}
        line = self.process.stdout.readline()
        if not line:
            return self._crashed()
        return json.loads(line)

    def _crashed(self) -> dict[str, object]:
        assert self.process is not None
        self.process.communicate()  # reaped, its pipes closed
        code = self.process.returncode
        stderr = _panic_lines(self._stderr_path.read_text(errors="replace"))
        self.process = None
        return {"outcome": "finding", "type": f"crash (exit {code})", "message": stderr}

    def close(self) -> None:
        if self.process is not None:
            if self.process.poll() is None:
                self.process.kill()
            self.process.communicate()  # reaped, its pipes closed


def fuzz(
    seconds: float, seed: int, save: Path, timeout_s: float = 20.0, only: str | None = None
) -> Report:
    rng = random.Random(seed)
    report = Report()
    with tempfile.TemporaryDirectory(prefix="pecs-fuzz-") as scratch:
        seeds = bad_inputs.valid_files(Path(scratch) / "seeds")
        contents = {name: path.read_bytes() for name, path in seeds.items()}
        names = [only] if only else sorted(contents)
        worker = Worker(Path(scratch) / "worker-stderr.txt")
        deadline = time.monotonic() + seconds
        try:
            round_number = 0
            while time.monotonic() < deadline:
                name = names[round_number % len(names)]  # formats share the time evenly
                round_number += 1
                other = contents[rng.choice(names)]
                data = mutate(contents[name], other, rng)
                suffix = seeds[name].suffix
                if rng.random() < 0.1:
                    suffix = rng.choice(bad_inputs.SUFFIXES)
                path = Path(scratch) / f"input{suffix}"
                path.write_bytes(data)
                batch_size = rng.choice([1, 7, 1 << 20])
                answer = worker.read(path, batch_size, timeout_s)
                report.rounds[name] = report.rounds.get(name, 0) + 1
                key = f"{answer['outcome']}:{answer.get('type', '')}"
                report.outcomes[key] = report.outcomes.get(key, 0) + 1
                if answer["outcome"] == "finding":
                    report.findings.append(_save(save, name, suffix, data, batch_size, answer))
        finally:
            worker.close()
    return report


def _save(
    folder: Path, seed: str, suffix: str, data: bytes, batch_size: int, answer: dict
) -> dict[str, str]:
    folder.mkdir(parents=True, exist_ok=True)
    index = len(list(folder.glob("finding-*.json")))
    stem = folder / f"finding-{index:04d}-{seed}"
    input_path = stem.with_suffix(suffix)
    input_path.write_bytes(data)
    finding = {
        "seed": seed,
        "input": str(input_path),
        "batch_size": str(batch_size),
        "type": str(answer.get("type")),
        "message": str(answer.get("message"))[:2000],
    }
    stem.with_suffix(".json").write_text(json.dumps(finding, indent=1))
    return finding


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="how long to fuzz")
    parser.add_argument("--seed", type=int, default=int(time.time()), help="random seed")
    parser.add_argument("--save", type=Path, help="folder for findings (default: temporary)")
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds one read may take")
    parser.add_argument("--only", choices=sorted(bad_inputs.SEEDS), help="fuzz one seed only")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker()
        return 0
    save = args.save or Path(tempfile.mkdtemp(prefix="pecs-fuzz-findings-"))
    start = time.monotonic()
    report = fuzz(args.seconds, args.seed, save, args.timeout, args.only)
    print(
        f"seed {args.seed}: {sum(report.rounds.values())} reads in {time.monotonic() - start:.0f} s"
    )
    print("rounds per seed:", json.dumps(report.rounds))
    print("outcomes:", json.dumps(report.outcomes, indent=1))
    for finding in report.findings:
        print(f"FINDING {finding['type']}: {finding['input']}: {finding['message'][:300]}")
    print(f"{len(report.findings)} finding(s), saved in {save}")
    return min(len(report.findings), 100)


if __name__ == "__main__":
    sys.exit(main())
