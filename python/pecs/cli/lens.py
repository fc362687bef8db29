"""`pecs lens info NAME|FILE [--sensor PRESET]`, `pecs lens plot NAME|FILE -o lens.png` and
`pecs lens ghosts NAME|FILE [--cover-glass]`."""

from __future__ import annotations

import argparse

from pecs.cli._arguments import add_command, number
from pecs.lens.lens import SENSOR_FILM_MM, Lens

#: Slowest f-number taken. At f/1000 diffraction blurs a point over 2.44 lambda N = 1.4 mm at
#: 587.6 nm, more than any sensor, and the ray model has no diffraction: past it, nothing it
#: computes means anything.
MAX_F_NUMBER = 1000.0
# Lens.with_f_number's tolerance: this close to wide open (a nominal f/2 lens may be f/2.03 from
# its prescription) is wide open.
_NOMINAL = 0.98
_POSITIVE = number(float, above=0)


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
        "sensor's film (--sensor).",
    )
    _common(info)
    info.add_argument(
        "--sensor",
        default="davis346",
        choices=tuple(SENSOR_FILM_MM),
        help="sensor whose film the field of view is worked out on: "
        + ", ".join(f"{name} ({w:.2f} x {h:.2f} mm)" for name, (w, h) in SENSOR_FILM_MM.items())
        + "; the ideal and esim presets have no physical pixel size",
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
    ghosts = add_command(
        sub,
        "ghosts",
        help="the lens's two-reflection ghosts, first-order",
        description="List every two-reflection ghost path (reflect back at one surface, forward "
        "again at an earlier one) with its paraxial image: centre per degree of field, radius "
        "and focus relative to the film, and energy R_i R_j at normal incidence (single-layer "
        "quarter-wave coatings at 550 nm), brightest first.",
    )
    _common(ghosts)
    ghosts.add_argument(
        "--cover-glass", action="store_true", help="add the sensor's cover glass (two faces)"
    )
    ghosts.add_argument(
        "--uncoated", action="store_true", help="bare glass: plain Fresnel reflection"
    )
    ghosts.set_defaults(func=run_ghosts)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "lens",
        help=f"built-in lens ({', '.join(Lens.builtin_names())}) or prescription file",
    )
    parser.add_argument(
        "--efl-mm", type=number(float, above=0), help="scale the lens to this focal length, mm"
    )
    parser.add_argument(
        "--f-number",
        type=f_number,
        help="close the stop to this f-number, from the lens's widest (within 2 %%: a nominal "
        f"f/2 lens may be f/2.03) to {MAX_F_NUMBER:g} (the lens wide open if unset)",
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
        _check_f_number(args.f_number, lens)
        # Within 2 % of wide open the lens is taken wide open (clamp), without a word.
        lens = lens.with_f_number(args.f_number, clamp=True)
    return lens.focused(args.focus_m)


def f_number(text: str) -> float:
    """An f-number > 0 and at most MAX_F_NUMBER (argparse type)."""
    value = _POSITIVE(text)
    if value > MAX_F_NUMBER:
        raise argparse.ArgumentTypeError(
            f"{text}: expected at most f/{MAX_F_NUMBER:g} (past it diffraction blurs a point over "
            "more than a sensor, and the ray model has none)"
        )
    return value


def _check_f_number(value: float, lens: Lens) -> None:
    """Refuse an f-number faster than the lens opens (by more than 2 %: a nominal f/2 lens
    may be f/2.03), which the lens cannot have: it used to be taken wide open with a Python
    warning."""
    widest = lens.f_number()
    if value < _NOMINAL * widest:
        raise ValueError(
            f"--f-number {value:g}: {lens.name} opens to f/{widest:.3g} at most; give "
            f"f/{widest:.3g} to f/{MAX_F_NUMBER:g}, or no --f-number for the lens wide open"
        )


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
    for i, line in enumerate(_glass_lines(lens)):
        print(f"{'glass' if i == 0 else '':<19}{line}")
    print(
        f"field of view      {fov['horizontal']:.2f} x {fov['vertical']:.2f} deg, "
        f"{fov['diagonal']:.2f} deg diagonal ({args.sensor})"
    )
    return 0


def _glass_lines(lens: Lens) -> list[str]:
    """One line per distinct glass: its name, n_d, V_d and where its index is defined."""
    lines: dict[str, str] = {}
    for s in lens.surfaces:
        g = s.glass
        if g.kind == "catalogue" and g.range_nm is not None:
            lo, hi = g.range_nm
            lines[g.name] = f"{g.name}  n_d {g.n_d:.5f}, V_d {g.v_d:.2f}, {lo:.0f}-{hi:.0f} nm"
        elif g.kind == "abbe":
            lines[f"{g.n_d}/{g.v_d}"] = f"n_d {g.n_d:g}, V_d {g.v_d:g} (Cauchy fit)"
    return list(lines.values())


def run_plot(args: argparse.Namespace) -> int:
    lens = _load(args)
    lens.plot(path=args.output, field_deg=args.field_deg)
    print(f"wrote {args.output}")
    return 0


def run_ghosts(args: argparse.Namespace) -> int:
    import math

    from pecs.lens.ghosts import CoverGlass, GhostOptions
    from pecs.lens.paraxial_ghosts import ghost_table

    lens = _load(args)
    options = GhostOptions(
        coatings=None if args.uncoated else GhostOptions().coatings,
        cover_glass=CoverGlass() if args.cover_glass else None,
    )
    table = ghost_table(lens, options)
    print(f"{lens.name}: {len(table)} two-reflection ghosts (reflect at A, then at B)")
    print(f"{'A':>18} {'B':>18} {'energy':>9} {'centre/deg':>10} {'radius':>8} {'focus':>9}")
    per_degree = math.tan(math.radians(1.0))
    for g in table:
        radius = f"{g.radius_mm:8.3f}" if g.stop_crossings == 1 else "       -"
        print(
            f"{g.names[0]:>18} {g.names[1]:>18} {g.energy:9.2e} "
            f"{g.centre_per_slope_mm * per_degree:10.4f} {radius} {g.focus_from_film_mm:9.2f}"
        )
    print("mm on the film; centre: for a source 1 deg off axis; radius: of the stop's ghost")
    print("image ('-': the stop crossed three times); focus: where it is sharp, film at 0")
    return 0
