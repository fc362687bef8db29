"""The report of a calibration (`pecs calibrate --report DIR`): the fitted values and which of
them the data pinned down (`pecs.calibration.profile`), the measures
of the starting preset and of the calibrated sensor on the fitted and held-out spans (a
Markdown table), and a figure: real | preset | calibrated count maps, and the rate curves."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa

from pecs._atomic import atomic_path
from pecs.calibration.fit import CalibrationResult, Recording
from pecs.calibration.profile import NOISE_FLOOR, PINNED
from pecs.calibration.realism import RATE_BIN_US, blurred_count_map, rate_curve

__all__ = ["markdown", "write_report"]

# (measure key, label, format) rows of the table.
ROWS = (
    ("events_sim", "events", "{:.0f}"),
    ("count_ratio", "count ratio (sim / real)", "{:.3f}"),
    ("on_fraction_sim", "ON fraction", "{:.3f}"),
    ("count_map_correlation", "count-map r (3 x 3)", "{:.3f}"),
    ("rate_correlation", "rate r (5 ms)", "{:.3f}"),
    ("chamfer_sensor", "chamfer (sensor)", "{:.3f}"),
    ("gaussian_sensor", "Gaussian (sensor)", "{:.3f}"),
    ("chamfer_pecs", "chamfer (pecs)", "{:.3f}"),
    ("gaussian_pecs", "Gaussian (pecs)", "{:.3f}"),
    ("objective", "objective", "{:.3f}"),
)


def markdown(result: CalibrationResult) -> str:
    """The fitted values and the measures table, as Markdown."""
    preset = result.start_config.preset_name or "start"
    lines = [
        "# pecs calibration",
        "",
        f"{result.evaluations} evaluations (and {result.profile_evaluations} for the profile) "
        f"in {result.seconds:.0f} s; fitted span "
        f"{_span([result.fit_window_us])}, held out {_span(result.holdout_windows_us)}.",
        "",
        _verdict(result, preset),
        "",
        _light_model(result),
        "",
        *_parameter_table(result, preset),
    ]
    spans = [("fitted", result.start_fit, result.fit)]
    if result.holdout is not None and result.start_holdout is not None:
        spans.append(("held out", result.start_holdout, result.holdout))
    header = "| measure |" + "".join(
        f" real ({span}) | {preset} ({span}) | calibrated ({span}) |" for span, _, _ in spans
    )
    lines += ["", header, "|---" * (1 + 3 * len(spans)) + "|"]
    for key, label, fmt in ROWS:
        cells = []
        for _, start, fitted in spans:
            real = _real_value(key, start)
            cells += [real, fmt.format(start[key]), fmt.format(fitted[key])]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _verdict(result: CalibrationResult, preset: str) -> str:
    """Whether the fit beat the start, and its promise (`pecs.calibration.fit`'s NO_WORSE)."""
    if not result.improved:
        return (
            f"Nothing the search tried beat {preset} without worsening the chamfer or Gaussian "
            f"distance, the count, the count-map r or the rate r on the fitted span: the "
            f"calibrated sensor is {preset} itself."
        )
    return (
        f"The calibrated sensor is no worse than {preset} as frames2events simulates it by "
        "default on the chamfer and Gaussian distances, the count, the count-map r and the rate "
        "r over the fitted span (the fit keeps only such candidates)."
    )


def _light_model(result: CalibrationResult) -> str:
    """Which light model (interpolation between frames) the fit chose, and what each reached."""
    reached = ", ".join(
        f"{model} {objective:.3f}" if math.isfinite(objective) else f"{model} none"
        for model, objective in result.light_models.items()
    )
    return (
        f"Light between frames: **{result.interpolation}**; use the file with `pecs "
        f"frames2events --interpolation {result.interpolation} --config FILE`. Lowest "
        f"objective no worse than the reference, per light model tried: {reached or 'none'}."
    )


def _parameter_table(result: CalibrationResult, preset: str) -> list[str]:
    """The fitted values, with what the profile says the data decided of each."""
    profiles = {p.name: p for p in result.profiles}
    if not profiles:
        lines = [f"| parameter | {preset} | calibrated |", "|---|---|---|"]
        for name, value in result.fitted.items():
            lines.append(f"| {name} | {getattr(result.start_config, name):.5g} | {value:.5g} |")
        return lines
    lines = [
        f"| parameter | {preset} | calibrated | the data | values that fit as well |",
        "|---|---|---|---|---|",
    ]
    for name, value in result.fitted.items():
        profile = profiles[name]
        shown = f"{value:.5g}" if profile.status == PINNED else f"({value:.3g})"
        lines.append(
            f"| {name} | {getattr(result.start_config, name):.5g} | {shown} | {profile.status} "
            f"| {profile.interval()} |"
        )
    threshold = next(iter(profiles.values())).threshold
    lines += [
        "",
        "Each parameter moved alone (x 1/2, x 0.71, x 1.41, x 2; linear ones +-1/8, +-1/4 of "
        "their range), the others held: a value fits as well when the objective rises no more "
        f"than {threshold:.3g}, the objective's difference between two simulation seeds "
        f"({result.objective_noise:.3g}; at least {NOISE_FLOOR:g}). Pinned: ruled out on both "
        "sides; a value in brackets is one the data did not decide, kept for the file.",
    ]
    return lines


def write_report(
    result: CalibrationResult, recording: Recording, folder: str | os.PathLike[str]
) -> list[Path]:
    """report.md and calibration.png in `folder` (created); returns their paths."""
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    report = target / "report.md"
    with atomic_path(report) as tmp:
        tmp.write_text(markdown(result) + "\n![count maps and rates](calibration.png)\n")
    figure_path = target / "calibration.png"
    # The streams the held-out score compared (the fitted span's when nothing is held out).
    windows = result.holdout_windows_us or [result.fit_window_us]
    # The start as frames2events simulates it by default, the fit with its light model.
    reference = recording.with_interpolation("auto")
    real, start, window = reference.scored_streams(result.start_config, windows)
    chosen = recording.with_interpolation(result.interpolation)
    streams = {
        "real": real,
        result.start_config.preset_name or "start": start,
        "calibrated": chosen.scored_streams(result.config, windows)[1],
    }
    with atomic_path(figure_path) as tmp:
        figure(streams, window, recording.size, tmp, joined=len(windows) > 1)
    return [report, figure_path]


def figure(
    streams: dict[str, pa.Table],
    window_us: tuple[int, int],
    size: tuple[int, int],
    path: Path,
    *,
    joined: bool = False,
) -> None:
    """Count maps (log(1 + events per pixel), 3 x 3 mean) side by side over rate curves;
    `joined`: the streams are spans put end to end (`Recording.scored_streams`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(3.4 * len(streams), 6.0), layout="constrained")
    grid = fig.add_gridspec(2, len(streams))
    rates = fig.add_subplot(grid[1, :])
    for column, (name, table) in enumerate(streams.items()):
        t, x, y = (table.column(c).to_numpy() for c in ("t", "x", "y"))
        inside = (t >= window_us[0]) & (t < window_us[1])
        counts = blurred_count_map(x[inside], y[inside], *size) / 9
        axis = fig.add_subplot(grid[0, column])
        axis.imshow(np.log1p(counts), cmap="magma")
        axis.set_title(f"{name}: {int(inside.sum())} events", fontsize=9)
        axis.set_axis_off()
        curve = rate_curve(t, *window_us, RATE_BIN_US) / (RATE_BIN_US * 1e-6)
        rates.plot(np.arange(len(curve)) * RATE_BIN_US / 1e3, curve, label=name)
    seam = ", held-out parts end to end" if joined else ""
    rates.set_xlabel(f"time from {window_us[0]} us{seam} (ms)")
    rates.set_ylabel("events / s (5 ms bins)")
    rates.legend(fontsize=8)
    fig.savefig(path, dpi=100, format="png")
    plt.close(fig)


def _real_value(key: str, measures: dict[str, float]) -> str:
    real = {"events_sim": "events_real", "on_fraction_sim": "on_fraction_real"}
    if key in real:
        return ROWS_FORMAT[key].format(measures[real[key]])
    return "1" if key in ("count_ratio", "count_map_correlation", "rate_correlation") else "0"


ROWS_FORMAT = {key: fmt for key, _, fmt in ROWS}


def _span(windows: Sequence[tuple[int, int]]) -> str:
    """Absolute windows as "a..b us", joined by " + "; "none" for none."""
    return " + ".join(f"{a}..{b} us" for a, b in windows) or "none"
