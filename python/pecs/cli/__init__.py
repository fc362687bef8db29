"""The `pecs` command. Each subcommand lives in its own module and only calls the Python API."""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings

from pecs.cli._arguments import Parser
from pecs.cli._stop import EXIT_INTERRUPTED, run_stoppable

# Subcommand modules, each with `register(subparsers)` that adds its parser and sets `func`.
COMMANDS = [
    "frames2events",
    "convert",
    "filter",
    "info",
    "view",
    "compare",
    "lens",
    "simulate",
    "demo",
    "calibrate",
    "dataset",
    "bias",
]


def build_parser() -> argparse.ArgumentParser:
    from pecs import __version__

    parser = Parser(prog="pecs", description="Physically based event-camera simulator")
    parser.add_argument("--version", action="version", version=f"pecs {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"pecs.cli.{name}").register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except KeyboardInterrupt:  # while importing the subcommands
        print("pecs: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    # Ctrl-C, SIGTERM and a closed stdout stop a command in one line (pecs.cli._stop).
    with warnings.catch_warnings():
        # A warning from the API (or a library under it) reaches a CLI user as one line naming
        # the command, never with Python's source path and code line.
        warnings.showwarning = _notice_for(args.command)
        return run_stoppable(args.command, lambda: _run_command(args))


def _notice_for(command: str):  # noqa: ANN202 (warnings.showwarning's signature)
    def notice(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
        print(f"pecs {command}: warning: {_one_line(message)}", file=sys.stderr)

    return notice


def _run_command(args: argparse.Namespace) -> int:
    try:
        return int(args.func(args) or 0)
    except OSError as error:
        from pecs.io._write_errors import WRITE_ERRNOS

        if error.errno in WRITE_ERRNOS and error.filename:
            # The data could not be stored (disk full, quota, ...): a failure, not a usage error.
            print(
                f"pecs {args.command}: error: {error.filename}: {error.strerror}", file=sys.stderr
            )
            return 1
        print(f"pecs {args.command}: error: {_one_line(error)}", file=sys.stderr)
        return 2
    except ValueError as error:
        print(f"pecs {args.command}: error: {_one_line(error)}", file=sys.stderr)
        return 2


def _one_line(error: BaseException) -> str:
    """The message on one line: an API message may wrap, an error report must not."""
    return " ".join(str(error).split())
