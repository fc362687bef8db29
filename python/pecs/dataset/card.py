"""A dataset card: the distributions a user checks before training on a dataset (events per
second, ON fraction, flow per 100 ms, depth, illuminance, instances, drawn sensor values), a
summary table and preview event frames, as one self-contained HTML file (figures embedded as
PNG data URIs) or as markdown with its PNGs in a folder beside it.

`write_card(DIR, path)`; `pecs dataset card DIR -o card.html`; `run_dataset` writes
`DIR/card.html` at the end of every run. The numbers are `pecs.dataset.card_stats`'s.
"""

from __future__ import annotations

import base64
import html
import io
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pecs._atomic import atomic_path
from pecs.dataset import layout
from pecs.dataset.card_stats import FLOW_WINDOW_US, DatasetStats, SequenceStats, dataset_stats
from pecs.dataset.distributions import Distribution

#: The card `run_dataset` writes into the dataset folder.
CARD_FILE = "card.html"
_FORMATS = {".html": "html", ".htm": "html", ".md": "markdown"}
_PREVIEWS = 4
# The preview window, around the sequence's middle: long enough for about a quarter as many
# events as pixels (edges, not a filled frame), from 1 to 20 ms, and never past the sequence.
_PREVIEW_FILL = 0.25
_PREVIEW_WINDOW_US = (1_000, 20_000)
_FIGURE_IN = (4.2, 2.6)
_DPI = 80
_RANGE_COLOUR = "#d62728"
_BAR_COLOUR = "#4c72b0"


@dataclass(frozen=True)
class Figure:
    """One PNG of the card, with its title and the note under it."""

    key: str
    title: str
    png: bytes | None
    note: str = ""


def write_card(root: str | os.PathLike[str], path: str | os.PathLike[str] | None = None) -> Path:
    """Write the card of the dataset folder `root` to `path` (default `root/card.html`): HTML
    for `.html`, markdown with its PNGs in `<name>_files/` beside it for `.md`. Returns the
    path; a FileNotFoundError naming the folder when it holds no dataset."""
    target = Path(path) if path is not None else Path(root) / CARD_FILE
    kind = _FORMATS.get(target.suffix.lower())
    if kind is None:
        raise ValueError(
            f"{target}: a card is .html (one self-contained file) or .md (markdown and PNGs); "
            "choose another name with -o"
        )
    stats = dataset_stats(root)
    figures = card_figures(stats)
    previews = preview_frames(stats)
    if kind == "html":
        text = _html(stats, figures, previews)
    else:
        text = _markdown(stats, figures, previews, _write_pngs(target, figures, previews))
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return target


# -- figures ----------------------------------------------------------------------------------


def card_figures(stats: DatasetStats) -> list[Figure]:
    """The card's histograms, in reading order; a figure without data has a note instead."""
    done = len(stats.done)
    figures = [
        _histogram(
            "events_per_s",
            "Events per second (per sequence)",
            stats.per_sequence("events_per_s"),
            "events/s",
            log=True,
            note=f"{done} finished sequences: events / simulated duration.",
        ),
        _histogram(
            "on_fraction",
            "ON fraction (per sequence)",
            stats.per_sequence("on_fraction"),
            "ON events / all events",
            limits=(0.0, 1.0),
        ),
        _pooled(stats, "flow_px_per_100ms", "Flow magnitude per 100 ms", "px", _FLOW_NOTE),
        _pooled(stats, "depth_m", "Depth (valid pixels)", "z-depth, m", "Stored z-depth"),
        _illuminance(stats),
        _instances(stats),
    ]
    figures += [_drawn(stats, key) for key in stats.drawn_fields]
    return figures


_FLOW_NOTE = (
    f"Magnitude of each stored frame-to-frame flow, scaled to {FLOW_WINDOW_US // 1000} ms "
    "(the speed over the frame interval, times 100 ms), pixels with a surface"
)


def _pooled(stats: DatasetStats, attribute: str, title: str, unit: str, what: str) -> Figure:
    values = stats.pooled(attribute)
    having = sum(getattr(s, attribute) is not None for s in stats.done)
    if having == 0:
        kind = "flow" if attribute.startswith("flow") else "depth"
        return Figure(
            attribute,
            title,
            None,
            f'Skipped: no sequence stored {kind} ground truth (spec: ground_truth = "{kind}").',
        )
    note = f"{what}: {having} of {len(stats.done)} sequences, {values.size} pixels (thinned)."
    log = attribute == "depth_m"
    return _histogram(attribute, title, values, unit, log=log, counted="pixels", note=note)


def _illuminance(stats: DatasetStats) -> Figure:
    values = stats.per_sequence("illuminance_lux")
    title = "Illuminance at the scene (per sequence)"
    if values.size == 0:
        return Figure(
            "illuminance_lux",
            title,
            None,
            "Skipped: no sequence's scene has a [light] table stating its illuminance.",
        )
    ranges = [tuple(r) for r in stats.scene_ranges.get("illuminance_lux", [])]
    missing = len(stats.done) - values.size
    note = "The scene's [light] illuminance_lux" + (
        f"; {missing} sequences have no [light] table." if missing else "."
    )
    if ranges:
        note += " Red: the generator's drawn range."
    return _histogram("illuminance_lux", title, values, "lux", log=True, ranges=ranges, note=note)


def _instances(stats: DatasetStats) -> Figure:
    values = stats.per_sequence("instances")
    title = "Instances per sequence"
    if values.size == 0:
        return Figure(
            "instances",
            title,
            None,
            'Skipped: no sequence stored instance ground truth (spec: ground_truth = "instances").',
        )
    return _histogram(
        "instances",
        title,
        values,
        "instances seen",
        integers=True,
        note="Shapes seen in the stored instance frames, background shapes included.",
    )


def _drawn(stats: DatasetStats, key: str) -> Figure:
    values = stats.drawn_values(key)
    distributions = stats.draw_ranges.get(key, [])
    title = f"Drawn: {key}"
    note = "Red: " + "; ".join(_described(d) for d in distributions) if distributions else ""
    if any(d.kind == "choice" for d in distributions) or not all(map(_is_number, values)):
        return Figure(f"drawn_{key}", title, _bars(values, distributions), note)
    ranges = [_marked_range(d) for d in distributions]
    log = any(d.kind == "log_uniform" for d in distributions)
    return _histogram(
        f"drawn_{key}", title, np.asarray(values, float), key, log=log, ranges=ranges, note=note
    )


def _described(distribution: Distribution) -> str:
    a, b = distribution.arguments[:2] if len(distribution.arguments) >= 2 else (None, None)
    if distribution.kind == "normal":
        return f"normal, mean {a:g} +- std {b:g}"
    if distribution.kind == "choice":
        return "choice of " + ", ".join(map(str, distribution.arguments))
    return f"{distribution.kind} [{a:g}, {b:g}]"


def _marked_range(distribution: Distribution) -> tuple[float, float]:
    """The span a drawn value should lie in: [min, max], or mean +- std for a normal."""
    a, b = distribution.arguments
    return (a - b, a + b) if distribution.kind == "normal" else (a, b)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _histogram(
    key: str,
    title: str,
    values: np.ndarray,
    unit: str,
    *,
    log: bool = False,
    limits: tuple[float, float] | None = None,
    ranges: list[tuple[float, float]] | None = None,
    integers: bool = False,
    counted: str = "sequences",
    note: str = "",
) -> Figure:
    """A histogram of `values` (counted in `counted`); `ranges` marked in red, and the bins
    spread over them too, so that a draw that fills only part of its range shows it."""
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return Figure(key, title, None, note or "Skipped: no finished sequence has this value.")
    ranges = ranges or []
    span = limits or _span(values, ranges)
    log = log and span[0] > 0 and span[1] > 10 * span[0]
    figure, axes = _figure()
    if integers:
        bins: Any = np.arange(math.floor(span[0]) - 0.5, math.ceil(span[1]) + 1.0)
    else:
        bins = _bins(span, log, values.size)
    axes.hist(
        values, bins=bins, color=_BAR_COLOUR, edgecolor="white", rwidth=0.85 if integers else None
    )
    for low, high in ranges:
        axes.axvspan(low, high, color=_RANGE_COLOUR, alpha=0.12, lw=0)
        for edge in (low, high):
            axes.axvline(edge, color=_RANGE_COLOUR, lw=1.2)
    if limits is not None:
        axes.set_xlim(*limits)
    _compact_ticks(axes, log, integers)
    axes.set_xlabel(unit)
    axes.set_ylabel(counted)
    return Figure(key, title, _png(figure), note)


def _compact_ticks(axes: Any, log: bool, integers: bool) -> None:
    """Few ticks, whole counts, and large or small numbers as a power of ten above the axis."""
    from matplotlib.ticker import MaxNLocator

    axes.yaxis.set_major_locator(MaxNLocator(nbins=5, integer=True))
    axes.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4), useMathText=True)
    if log:
        from matplotlib.ticker import LogFormatterSciNotation, LogLocator

        axes.set_xscale("log")
        # Labels at 1, 2 and 5 per decade: every minor tick's label overlapped.
        axes.xaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
        axes.xaxis.set_minor_formatter(LogFormatterSciNotation(labelOnlyBase=False))
        return
    axes.xaxis.set_major_locator(MaxNLocator(nbins=6, integer=integers))
    axes.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4), useMathText=True)


def _span(values: np.ndarray, ranges: list[tuple[float, float]]) -> tuple[float, float]:
    low = min([float(values.min())] + [r[0] for r in ranges])
    high = max([float(values.max())] + [r[1] for r in ranges])
    if high == low:  # one value: a visible bar around it
        spread = abs(low) * 0.05 or 0.5
        return low - spread, high + spread
    return low, high


def _bins(span: tuple[float, float], log: bool, count: int) -> np.ndarray:
    """Edges over `span`: about sqrt(count) of them, 10 to 40."""
    edges = int(min(40, max(10, math.ceil(math.sqrt(count))))) + 1
    if log:
        return np.geomspace(span[0], span[1], edges)
    return np.linspace(span[0], span[1], edges)


def _bars(values: list[Any], distributions: list[Distribution]) -> bytes:
    """A drawn choice: how many sequences drew each value (every possible value shown)."""
    labels = [str(v) for d in distributions for v in d.arguments if d.kind == "choice"]
    labels = list(dict.fromkeys(labels + [str(v) for v in values]))
    counts = [sum(str(v) == label for v in values) for label in labels]
    figure, axes = _figure()
    axes.bar(range(len(labels)), counts, color=_BAR_COLOUR)
    axes.set_xticks(range(len(labels)), labels, rotation=20, fontsize=8)
    axes.set_ylabel("sequences")
    return _png(figure)


def _figure() -> tuple[Any, Any]:
    # The object API, not pyplot: drawn by Agg whatever the user's backend, which stays as it is;
    # no global state, nothing kept open between cards.
    from matplotlib.figure import Figure as MatplotlibFigure

    figure = MatplotlibFigure(figsize=_FIGURE_IN, dpi=_DPI)
    # Fixed margins: a constrained layout took half of a card's time.
    figure.subplots_adjust(left=0.16, right=0.97, bottom=0.2, top=0.9)
    return figure, figure.add_subplot()


def _png(figure: Any) -> bytes:
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        # A card is a report: matplotlib's layout notes must not reach a dataset run's user.
        warnings.simplefilter("ignore")
        figure.savefig(buffer, format="png", dpi=_DPI)
    return buffer.getvalue()


# -- preview frames ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Preview:
    sequence: str
    start_us: int
    end_us: int
    png: bytes


def preview_frames(stats: DatasetStats, count: int = _PREVIEWS) -> list[Preview]:
    """Event frames (`pecs.viz.event_frame`) of up to `count` finished sequences spread over the
    dataset, each over a window of 1 to 20 ms around the sequence's middle (`_window_us`)."""
    done = [s for s in stats.done if s.events > 0]
    if not done:
        return []
    picks = sorted({round(k) for k in np.linspace(0, len(done) - 1, min(count, len(done)))})
    return [_preview(stats.root, done[k]) for k in picks]


def _preview(root: Path, sequence: SequenceStats) -> Preview:
    import pyarrow.parquet as pq

    from pecs.viz import event_frame

    duration_us = max(1, round(sequence.duration_s * 1e6))
    window_us = _window_us(sequence, duration_us)
    start_us = max(0, duration_us // 2 - window_us // 2)
    path = layout.events_partition(root, sequence.name) / layout.EVENTS_FILE
    events = pq.read_table(
        path,
        columns=["t", "x", "y", "p"],
        filters=[("t", ">=", start_us), ("t", "<", start_us + window_us)],
    )
    image = event_frame(
        events,
        sequence.width or None,
        sequence.height or None,
        t_start_us=start_us,
        t_end_us=start_us + window_us,
    )
    return Preview(sequence.name, start_us, start_us + window_us, _image_png(image))


def _window_us(sequence: SequenceStats, duration_us: int) -> int:
    """The preview's window: about `_PREVIEW_FILL` events per pixel at the sequence's mean rate,
    within `_PREVIEW_WINDOW_US` and the sequence."""
    pixels = max(1, sequence.width * sequence.height)
    low, high = _PREVIEW_WINDOW_US
    wanted = _PREVIEW_FILL * pixels / max(sequence.events_per_s, 1e-9) * 1e6
    return int(min(duration_us, max(low, min(high, round(wanted, -2)))))


def _image_png(image: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


# -- the summary ------------------------------------------------------------------------------


def summary_rows(stats: DatasetStats) -> list[tuple[str, str]]:
    """The summary table: (what, value) rows."""
    sizes = ", ".join(f"{w} x {h} ({n})" for (w, h), n in sorted(stats.sensor_sizes.items())) or "-"
    total = len(stats.sequences)
    return [
        ("Dataset", stats.name),
        (
            "Sequences",
            f"{total}: {stats.count('done')} done, {stats.count('failed')} failed, "
            f"{stats.count('pending')} pending",
        ),
        ("Events", f"{stats.total_events:,}"),
        ("Simulated duration", f"{stats.total_duration_s:.3f} s"),
        ("Mean event rate", _rate(stats)),
        ("Sensor sizes (sequences)", sizes),
        ("Size on disk", _bytes(stats.size_bytes)),
        ("pecs", str(stats.versions.get("pecs", "?"))),
    ]


def _rate(stats: DatasetStats) -> str:
    duration_s = stats.total_duration_s
    return f"{stats.total_events / duration_s:,.0f} events/s" if duration_s > 0 else "-"


def _bytes(size: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if size < 1024 or unit == "GB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{size} B"  # pragma: no cover


def _failures(stats: DatasetStats, limit: int = 20) -> list[tuple[str, str]]:
    failed = [s for s in stats.sequences if s.status == "failed"]
    rows = [(s.name, " ".join((s.error or "").split())) for s in failed[:limit]]
    if len(failed) > limit:
        rows.append(("...", f"{len(failed) - limit} more (manifest.json)"))
    return rows


# -- HTML -------------------------------------------------------------------------------------

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 72em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
td, th { border-bottom: 1px solid #ddd; padding: 0.25em 0.8em; text-align: left; }
.grid { display: flex; flex-wrap: wrap; gap: 1.2em; }
figure { margin: 0; width: 336px; }
figcaption { font-size: 0.85em; color: #555; }
.preview img { width: 320px; image-rendering: pixelated; border: 1px solid #ccc; }
.note { color: #777; font-size: 0.9em; }
"""


def _html(stats: DatasetStats, figures: list[Figure], previews: list[Preview]) -> str:
    escape = html.escape
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>Dataset card: {escape(stats.name)}</title>",
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>Dataset card: {escape(stats.name)}</h1>",
        _html_table(summary_rows(stats)),
    ]
    failures = _failures(stats)
    if failures:
        parts += ["<h2>Failed sequences</h2>", _html_table(failures)]
    parts += ["<h2>Distributions</h2>", '<div class="grid">']
    parts += [_html_figure(f) for f in figures]
    parts += ["</div>", "<h2>Preview event frames</h2>", '<div class="grid preview">']
    parts += [_html_preview(p) for p in previews] or ['<p class="note">No events to show.</p>']
    parts += ["</div>", "</body></html>", ""]
    return "\n".join(parts)


def _html_table(rows: list[tuple[str, str]]) -> str:
    body = "".join(f"<tr><th>{html.escape(a)}</th><td>{html.escape(b)}</td></tr>" for a, b in rows)
    return f"<table>{body}</table>"


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _html_figure(figure: Figure) -> str:
    title = html.escape(figure.title)
    note = html.escape(figure.note)
    if figure.png is None:
        return f'<figure><h3>{title}</h3><p class="note">{note}</p></figure>'
    image = f'<img src="{_data_uri(figure.png)}" alt="{title}">'
    return f"<figure><h3>{title}</h3>{image}<figcaption>{note}</figcaption></figure>"


def _html_preview(preview: Preview) -> str:
    caption = _preview_caption(preview)
    image = f'<img src="{_data_uri(preview.png)}" alt="{html.escape(caption)}">'
    return f"<figure>{image}<figcaption>{html.escape(caption)}</figcaption></figure>"


def _preview_caption(preview: Preview) -> str:
    return (
        f"{preview.sequence}: {preview.start_us / 1000:g} to {preview.end_us / 1000:g} ms "
        "(ON blue, OFF red: each pixel's latest event)"
    )


# -- markdown ---------------------------------------------------------------------------------


def _write_pngs(target: Path, figures: list[Figure], previews: list[Preview]) -> dict[str, str]:
    """The PNGs of a markdown card, in `<name>_files/` beside it; key -> relative path."""
    folder = target.with_name(f"{target.stem}_files")
    folder.mkdir(parents=True, exist_ok=True)
    pngs = {f.key: f.png for f in figures if f.png is not None}
    pngs.update({f"preview_{p.sequence}": p.png for p in previews})
    paths = {}
    for key, png in pngs.items():
        with atomic_path(folder / f"{key}.png") as tmp:
            tmp.write_bytes(png)
        paths[key] = f"{folder.name}/{key}.png"
    return paths


def _markdown(
    stats: DatasetStats, figures: list[Figure], previews: list[Preview], paths: dict[str, str]
) -> str:
    lines = [f"# Dataset card: {stats.name}", "", "| | |", "|---|---|"]
    lines += [f"| {a} | {_cell(b)} |" for a, b in summary_rows(stats)]
    failures = _failures(stats)
    if failures:
        lines += ["", "## Failed sequences", "", "| sequence | error |", "|---|---|"]
        lines += [f"| {a} | {_cell(b)} |" for a, b in failures]
    lines += ["", "## Distributions", ""]
    for figure in figures:
        lines += [f"### {figure.title}", ""]
        if figure.key in paths:
            lines += [f"![{figure.title}]({paths[figure.key]})", ""]
        lines += [figure.note, ""] if figure.note else []
    lines += ["## Preview event frames", ""]
    for preview in previews:
        caption = _preview_caption(preview)
        lines += [f"![{caption}]({paths[f'preview_{preview.sequence}']})", "", caption, ""]
    return "\n".join(lines)


def _cell(text: str) -> str:
    return text.replace("|", "\\|")
