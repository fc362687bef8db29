"""The `pecs` command. Each subcommand lives in its own module and only calls the Python API."""

from __future__ import annotations

import argparse
import importlib
import sys

# Subcommand modules, each with `register(subparsers)` that adds its parser and sets `func`.
COMMANDS = [
    "frames2events",
    "convert",
    "info",
    "view",
    "compare",
    "lens",
    "simulate",
    "demo",
    "calibrate",
]


def build_parser() -> argparse.ArgumentParser:
    from pecs import __version__

    parser = argparse.ArgumentParser(
        prog="pecs", description="Physically based event-camera simulator"
    )
    parser.add_argument("--version", action="version", version=f"pecs {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"pecs.cli.{name}").register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, OSError) as error:
        print(f"pecs {args.command}: error: {error}", file=sys.stderr)
        return 2
