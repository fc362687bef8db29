"""The Fig. S1 protocol of PECS (supplement): how the chamfer (CD) and Gaussian (GD) distances
grow under a time-bias stretch and under added uniform noise.

On the first `--window-us` of a stream (shifted to start at 0):
- time bias: event i gets t += bias * i / N, bias in 0, 10, 100, 1e3, 1e4, 1e5 µs; the stretched
  stream is compared on the same window, so late events leave it;
- noise: n events added, n in 0, 10, ..., 1e5, with uniform x, y over the sensor, timestamps of
  the stream's events at a stride, and alternating polarity.
Each distorted stream is compared with the original (first_us = window). Writes fig_s1.csv,
fig_s1.md (with the paper's numbers beside ours) and fig_s1.png (both curves per sweep).

Run: .venv/bin/python benches/fig_s1.py [--events FILE] [--window-us 10000] [--out out/fig_s1]
Without --events, a synthetic stream (edge sweep plus noise, see event_streams.py) is used.
(needs matplotlib: pip install -e '.[bench]')
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
from event_streams import HEIGHT, WIDTH, edge_sweep  # noqa: E402
from pecs._atomic import atomic_path  # noqa: E402
from pecs.events import record_batch, schema, sensor_size, to_table  # noqa: E402
from pecs.metrics import compare  # noqa: E402

LEVELS = [0, 10, 100, 1_000, 10_000, 100_000]
# The paper's Fig. S1 (a real recording, 10 ms window), for the shape.
PAPER = {
    ("time bias", "CD"): [0, 0.0936, 0.1163, 0.4653, 2.0746, 3.1891],
    ("time bias", "GD"): [0, 0.0859, 0.1068, 0.4271, 1.4980, 1.6689],
    ("noise", "CD"): [0, 0.00021, 0.00197, 0.0332, 0.1966, 1.4592],
    ("noise", "GD"): [0, 2.85e-5, 0.00032, 0.0152, 0.0423, 0.2481],
}


def window(events: pa.Table, window_us: int) -> dict[str, np.ndarray]:
    """The first `window_us` of the stream, shifted to start at 0, sorted by t."""
    cols = {c: events.column(c).to_numpy() for c in ("t", "x", "y", "p")}
    t = cols["t"] - cols["t"].min()
    keep = t < window_us
    order = np.argsort(t[keep], kind="stable")
    return {"t": t[keep][order], **{c: cols[c][keep][order] for c in ("x", "y", "p")}}


def stretched(cols: dict[str, np.ndarray], bias_us: float) -> dict[str, np.ndarray]:
    n = len(cols["t"])
    return {**cols, "t": cols["t"] + np.floor(bias_us * np.arange(n) / n).astype(np.int64)}


def with_noise(cols, n: int, width: int, height: int, rng) -> dict[str, np.ndarray]:
    if n == 0:
        return cols
    stride_index = np.linspace(0, len(cols["t"]) - 1, n).astype(np.int64)
    noise = {
        "t": cols["t"][stride_index],
        "x": rng.integers(0, width, n),
        "y": rng.integers(0, height, n),
        "p": np.arange(n) % 2,
    }
    merged = {c: np.concatenate([cols[c], noise[c]]) for c in cols}
    order = np.argsort(merged["t"], kind="stable")
    return {c: v[order] for c, v in merged.items()}


def sweep(events: pa.Table, window_us: int, seed: int) -> list[dict]:
    width, height = sensor_size(events.schema) or (WIDTH, HEIGHT)
    event_schema = schema(width, height)
    base = window(events, window_us)
    original = record_batch(base, event_schema)
    rng = np.random.default_rng(seed)
    rows = []
    for kind, distort in (
        ("time bias", lambda level: stretched(base, level)),
        ("noise", lambda level: with_noise(base, level, width, height, rng)),
    ):
        for level in LEVELS:
            result = compare(
                original, record_batch(distort(level), event_schema), first_us=window_us
            )
            rows.append(
                {
                    "sweep": kind,
                    "level": level,
                    "CD": result.chamfer,
                    "GD": result.gaussian,
                    "events": result.events_a,
                    "events_distorted": result.events_b,
                }
            )
            print(f"{kind:9s} {level:>7d}  CD {result.chamfer:10.5f}  GD {result.gaussian:9.5f}")
    return rows


def write_table(rows: list[dict], out: Path) -> None:
    with atomic_path(out / "fig_s1.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lines = [
        "| bias (µs) or added noise events | " + " | ".join(map(str, LEVELS)) + " |",
        "|---" * (len(LEVELS) + 1) + "|",
    ]
    for kind in ("time bias", "noise"):
        for metric in ("CD", "GD"):
            ours = [r[metric] for r in rows if r["sweep"] == kind]
            lines.append(
                f"| {kind}: {metric} (pecs) | " + " | ".join(f"{v:.4g}" for v in ours) + " |"
            )
            lines.append(
                f"| {kind}: {metric} (paper) | "
                + " | ".join(f"{v:.4g}" for v in PAPER[kind, metric])
                + " |"
            )
    with atomic_path(out / "fig_s1.md") as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def plot(rows: list[dict], out: Path, title: str) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    levels = np.array(LEVELS[1:], dtype=float)
    for ax, kind, label in zip(
        axes, ("time bias", "noise"), ("time bias (µs)", "added noise events")
    ):
        for metric, color in (("CD", "tab:blue"), ("GD", "tab:orange")):
            ours = [r[metric] for r in rows if r["sweep"] == kind][1:]
            ax.loglog(levels, ours, "o-", color=color, label=f"{metric} (pecs)")
            ax.loglog(
                levels,
                PAPER[kind, metric][1:],
                "--",
                color=color,
                alpha=0.5,
                label=f"{metric} (paper)",
            )
        ax.set_xlabel(label)
        ax.set_ylabel("distance")
        ax.set_title(kind)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title)
    with atomic_path(out / "fig_s1.png") as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", help="event file to distort (default: a synthetic edge sweep)")
    parser.add_argument("--window-us", type=int, default=10_000, help="evaluation window (µs)")
    parser.add_argument(
        "--synthetic-events", type=int, default=300_000, help="synthetic stream size in the window"
    )
    parser.add_argument("--out", type=Path, default=Path("out/fig_s1"), help="output folder")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.events:
        events, title = to_table(args.events), f"Fig. S1 protocol on {Path(args.events).name}"
    else:
        events = edge_sweep(args.synthetic_events, duration_us=args.window_us, seed=args.seed)
        title = "Fig. S1 protocol on a synthetic edge sweep (346 x 260)"
    rows = sweep(events, args.window_us, args.seed)
    write_table(rows, args.out)
    plot(rows, args.out, f"{title}, {args.window_us} µs window")
    print(f"wrote {args.out / 'fig_s1.csv'}, {args.out / 'fig_s1.md'}, {args.out / 'fig_s1.png'}")


if __name__ == "__main__":
    main()
