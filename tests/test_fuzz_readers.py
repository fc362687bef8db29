"""The bounded mutation fuzz of every reader (tests/fuzz_readers.py) that CI runs: for
PECS_FUZZ_SECONDS (40 by default), every mutated input must read as events or be refused with
EventFileError/ValueError; no other exception, no crash of the reading process, no hang."""

from __future__ import annotations

import os

import fuzz_readers


def test_mutated_files_of_every_format_read_or_are_refused(tmp_path):
    seconds = float(os.environ.get("PECS_FUZZ_SECONDS", "40"))
    seed = int(os.environ.get("PECS_FUZZ_SEED", "12"))
    report = fuzz_readers.fuzz(seconds, seed, tmp_path / "findings")
    assert set(report.rounds) == set(fuzz_readers.bad_inputs.SEEDS)  # every reader was fuzzed
    assert min(report.rounds.values()) >= 10, report.rounds
    found = [f"{f['type']} on {f['input']}: {f['message'][:500]}" for f in report.findings]
    assert not found, "\n".join(found)
