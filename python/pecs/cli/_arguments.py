"""Argument parsing shared by the subcommands: help that shows defaults in plain words, and the
argument types that refuse impossible numbers before any work starts."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from pecs.config import SensorConfig


class Parser(argparse.ArgumentParser):
    """argparse's parser, with a choice error in plain words: argparse quotes each choice as a
    Python string ("invalid choice: 'x' (choose from 'a', 'b')")."""

    def _check_value(self, action: argparse.Action, value: object) -> None:
        choices = action.choices
        if choices is not None and value not in choices:
            names = ", ".join(str(choice) for choice in choices)
            raise argparse.ArgumentError(action, f"{value}: choose one of {names}")


class HelpFormatter(argparse.HelpFormatter):
    """Adds "(default: X)" to each option that has a default worth showing. Unlike argparse's
    ArgumentDefaultsHelpFormatter it says nothing for None and False (the option is off unless
    given), which would print Python's words."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        # A flag (--quiet, --no-card) takes no value: its default is its meaning, not a value.
        if "default" in text or not action.option_strings or action.nargs == 0:
            return text
        shown = plain_default(action.default)
        return f"{text} (default: {shown})" if shown else text


def plain_default(value: object) -> str:
    """A default as a user would type it; '' when there is nothing to show."""
    if value is None or value is False or value is argparse.SUPPRESS or value == []:
        return ""
    if isinstance(value, float):
        return "infinity" if math.isinf(value) else f"{value:g}"
    if isinstance(value, (list, tuple)):
        return " ".join(plain_default(v) for v in value)
    return str(value).replace("%", "%%")


def add_command(
    subparsers: argparse._SubParsersAction, name: str, *, help: str, description: str
) -> argparse.ArgumentParser:
    """A subcommand parser with the shared help format."""
    return subparsers.add_parser(
        name, help=help, description=description, formatter_class=HelpFormatter
    )


def _whole_number(text: str) -> int:
    """An integer as people write one: `4000000000`, or `4e9` and `1e12` (a float that is whole,
    so that its range check, not the parse, answers an absurd count)."""
    try:
        return int(text)
    except ValueError:
        value = float(text)
        if not value.is_integer():  # also NaN and the infinities
            raise ValueError(text) from None
        return int(value)


def number(
    kind: type[float] | type[int],
    *,
    above: float | None = None,
    at_least: float | None = None,
    below: float | None = None,
    finite: bool = True,
) -> Callable[[str], float]:
    """An argparse type: `kind` parsed from the text, refused outside the stated range."""
    limits = []
    if above is not None:
        limits.append(f"> {above:g}")
    if at_least is not None:
        limits.append(f">= {at_least:g}")
    if below is not None:
        limits.append(f"< {below:g}")
    noun = "an integer" if kind is int else "a number"
    wanted = f"{noun} {' and '.join(limits)}".strip()

    def parse(text: str) -> float:
        try:
            value = _whole_number(text) if kind is int else kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text}: expected {wanted}") from None
        bad = (
            (finite and not math.isfinite(value))
            or math.isnan(value)
            or (above is not None and not value > above)
            or (at_least is not None and not value >= at_least)
            or (below is not None and not value < below)
        )
        if bad:
            raise argparse.ArgumentTypeError(f"{text}: expected {wanted}")
        return value

    parse.__name__ = noun  # argparse names the type in "invalid <name> value" messages
    return parse


def add_sensor_config_argument(parser: argparse.ArgumentParser, *, replaces: str) -> None:
    """`--config SENSOR.toml`, the same in every command that simulates: a sensor config file
    (SensorConfig.from_file; `pecs calibrate` writes one) in place of `replaces`."""
    parser.add_argument(
        "--config",
        metavar="SENSOR.toml",
        help="sensor config file (TOML of SensorConfig fields, e.g. from pecs calibrate); "
        f"replaces {replaces}",
    )


def sensor_config(args: argparse.Namespace) -> SensorConfig | None:
    """The sensor of `--config`, None when it is not given."""
    return SensorConfig.from_file(args.config) if args.config else None
