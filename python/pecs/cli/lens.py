"""`pecs lens info NAME|FILE [--sensor PRESET]` and `pecs lens plot NAME|FILE -o lens.png`."""

from __future__ import annotations

import argparse

from pecs.cli._arguments import add_command, number
from pecs.lens.lens import SENSOR_FILM_MM


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "lens",
        help="inspect a lens prescription",
        description="First-order numbers and ray-traced plots of a built-in lens or a "
        "prescription file (surfaces from the scene side, lengths in mm).",
    )
    sub = parser.add_subparsers(dest="lens_command", metavar="ACTION", required=True)
    info = add_command(
        sub,
        "info",
        help="focal length, back focus, f-number, pupils, field of view",
        description="Print the lens's first-order numbers (d line) and its field of view on a "
        "sensor preset.",
    )
    _common(info)
    info.add_argument(
        "--sensor",
        default="davis346",
        choices=tuple(SENSOR_FILM_MM),
        help="sensor preset for the field of view",
    )
    info.set_defaults(func=run_info)
    plot = add_command(
        sub,
        "plot",
        help="layout with traced rays and spot diagrams",
        description="Draw the lens layout with traced rays and spot diagrams to an image file.",
    )
    _common(plot)
    plot.add_argument("-o", "--output", required=True, help="image file to write (png, pdf, svg)")
    plot.add_argument(
        "--field-deg",
        type=number(float, at_least=0, below=90),
        help="off-axis field angle drawn, degrees",
    )
    plot.set_defaults(func=run_plot)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("lens", help="built-in lens name or prescription file")
    parser.add_argument(
        "--efl-mm", type=number(float, above=0), help="scale the lens to this focal length, mm"
    )
    parser.add_argument(
        "--f-number",
        type=number(float, above=0),
        help="close the stop to this f-number (the lens wide open if unset or faster)",
    )
    parser.add_argument(
        "--focus-m",
        type=number(float, above=0, finite=False),
        default=float("inf"),
        help="focus distance from the film, m",
    )


def _load(args: argparse.Namespace):  # noqa: ANN202
    from pecs.lens import Lens

    lens = Lens.load(args.lens)
    if args.efl_mm is not None:
        lens = lens.scaled_to(args.efl_mm)
    if args.f_number is not None:
        lens = lens.with_f_number(args.f_number, clamp=True)
    return lens.focused(args.focus_m)


def run_info(args: argparse.Namespace) -> int:
    lens = _load(args)
    fo = lens.first_order()
    fov = lens.field_of_view_deg(args.sensor)
    lca = lens.longitudinal_chromatic_aberration_mm()
    print(
        f"lens               {lens.name} ({len(lens.surfaces)} surfaces, stop = surface {lens.stop_index})"
    )
    print(f"EFL                {fo.efl_mm:.4f} mm (d line, 587.6 nm)")
    print(f"BFL                {fo.bfl_mm:.4f} mm")
    print(f"f-number           {fo.f_number:.3f}")
    print(
        f"entrance pupil     z = {fo.entrance_pupil_z_mm:.3f} mm, diameter {fo.entrance_pupil_diameter_mm:.3f} mm"
    )
    print(
        f"exit pupil         z = {fo.exit_pupil_z_mm:.3f} mm, diameter {fo.exit_pupil_diameter_mm:.3f} mm"
    )
    print(
        f"film distance      {lens.film_distance_mm:.4f} mm (focus {args.focus_m:g} m), total track {lens.total_track_mm:.3f} mm"
    )
    print(f"focal shift F, C   {lca[0] * 1e3:+.1f} um, {lca[2] * 1e3:+.1f} um (against d)")
    print(
        f"field of view      {fov['horizontal']:.2f} x {fov['vertical']:.2f} deg, "
        f"{fov['diagonal']:.2f} deg diagonal ({args.sensor})"
    )
    return 0


def run_plot(args: argparse.Namespace) -> int:
    lens = _load(args)
    lens.plot(path=args.output, field_deg=args.field_deg)
    print(f"wrote {args.output}")
    return 0
