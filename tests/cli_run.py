"""Running the CLI in-process in tests, and what its messages must not show."""

from __future__ import annotations

import re

import pytest
from pecs.cli import main

# Python's words and reprs that a user should never read: True/False/None, quoted strings in
# brackets or braces, a class repr.
PYTHON_SYNTAX = re.compile(r"\b(True|False|None)\b|\['|'\]|\{'|<class |\(default: \)")


def run_cli(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    """`pecs ARGV` in-process: (exit code, stdout, stderr); argparse's exit counts too."""
    try:
        code = main(list(argv))
    except SystemExit as stop:
        code = int(stop.code or 0)
    out, err = capsys.readouterr()
    return code, out, err
