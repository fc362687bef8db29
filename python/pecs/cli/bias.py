"""`pecs bias SENSOR`: a camera's biases mapped to the pixel model's parameters, each with the
range the mapping's constants allow; `-o sensor.toml` writes them as a sensor file."""

from __future__ import annotations

import argparse
import json

from pecs.biases import (
    BIAS_SENSORS,
    IMX636_RANGES,
    BiasMapping,
    coarse_fine_current_pa,
    map_biases,
    write_bias_file,
)
from pecs.biases.davis import parse_coarse_fine
from pecs.cli._arguments import add_command


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "bias",
        help="map a camera's biases to thresholds, bandwidth and refractory period",
        description="Map the biases of a DAVIS346 (libcaer's coarse/fine biases) or an IMX636 / "
        "Prophesee EVK4 (OpenEB's bias offsets) to the pixel model's theta_on, theta_off, "
        "cutoff_hz and refractory_us, each with the range the mapping's constants allow. Biases "
        "not given take the camera's defaults. The relations and their sources: docs/biases.md.",
    )
    parser.add_argument("sensor", choices=BIAS_SENSORS, help="the camera")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="BIAS=VALUE",
        help="a bias: davis346 COARSE/FINE (OnBn=5/255), imx636 an offset (bias_diff_on=20); "
        "repeat for more",
    )
    for name, (low, high) in IMX636_RANGES.items():
        parser.add_argument(
            "--" + name.replace("_", "-"),
            type=_offset(low, high),
            metavar="N",
            help=f"imx636: {name} offset, {low}..{high}",
        )
    parser.add_argument("-o", "--output", metavar="SENSOR.toml", help="write a sensor file")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=run)


def _offset(low: int, high: int):  # noqa: ANN202 (an argparse type)
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text}: expected a whole number in {low}..{high}")
        return value

    parse.__name__ = "offset"
    return parse


def biases_from_args(args: argparse.Namespace) -> dict[str, object]:
    """The biases of --set and the --bias-* options, as `map_biases` takes them."""
    options = {name: getattr(args, name) for name in IMX636_RANGES}
    given = {name: value for name, value in options.items() if value is not None}
    if given and args.sensor != "imx636":
        option = "--" + next(iter(given)).replace("_", "-")
        raise ValueError(f"{option} is an imx636 bias; a davis346 takes --set NAME=COARSE/FINE")
    biases: dict[str, object] = {}
    for item in args.set:
        name, sep, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name:
            raise ValueError(f"--set {item}: expected BIAS=VALUE, e.g. {_example(args.sensor)}")
        biases[name] = _offset_text(name, text) if args.sensor == "imx636" else text
    return {**biases, **given}


def _example(sensor: str) -> str:
    return "OnBn=5/255" if sensor == "davis346" else "bias_diff_on=20"


def _offset_text(name: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"--set {name}={text}: an imx636 bias is a whole-number offset") from None


def run(args: argparse.Namespace) -> int:
    mapping = map_biases(args.sensor, biases_from_args(args))
    if args.output:
        write_bias_file(mapping, args.output)
    if args.json:
        print(json.dumps(mapping.to_dict(), indent=2))
    else:
        print("\n".join(describe(mapping)))
    if args.output:
        print(f"sensor -> {args.output}")
    return 0


def describe(mapping: BiasMapping) -> list[str]:
    """The mapping as lines of text: the biases, each field with its range, the unmapped."""
    lines = [f"{mapping.sensor} biases: {', '.join(_bias_texts(mapping))}", ""]
    lines.append(f"{'field':<14} {'value':>10}   {'range':<21} relation")
    for name, e in mapping.parameters.items():
        span = f"{e.low:.4g} to {e.high:.4g}"
        lines.append(f"{name:<14} {e.value:>10.4g}   {span:<21} {e.relation}")
    for name, why in mapping.unmapped.items():
        lines.append(f"not mapped: {name}: {why}")
    return lines


def _bias_texts(mapping: BiasMapping) -> list[str]:
    if mapping.sensor != "davis346":
        return [f"{name} {value:+d}" for name, value in mapping.biases.items()]
    texts = []
    for name, value in mapping.biases.items():
        current_pa = coarse_fine_current_pa(*parse_coarse_fine(name, value))
        texts.append(f"{name} {value} ({_amps(current_pa)})")
    return texts


def _amps(pa: float) -> str:
    return f"{pa / 1000:.3g} nA" if pa >= 1000 else f"{pa:.3g} pA"
