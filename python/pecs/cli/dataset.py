"""`pecs dataset example` prints a dataset spec; `pecs dataset run SPEC -o DIR` simulates it;
`pecs dataset card DIR` writes its dataset card."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from pecs.cli._arguments import (
    HelpFormatter,
    add_command,
    add_sensor_config_argument,
    number,
    sensor_config,
)
from pecs.cli._progress import add_progress_arguments, wants_progress


def register(subparsers: argparse._SubParsersAction) -> None:
    p = add_command(
        subparsers,
        "dataset",
        help="simulate a dataset of many sequences (in this process, on local Ray or a cluster)",
        description="A dataset spec (TOML) lists sequences of scenes with sensor parameters drawn "
        "per sequence; 'run' simulates them into a Parquet dataset partitioned by sequence. "
        "See docs/datasets.md.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    example = actions.add_parser(
        "example",
        help="print a small commented dataset spec",
        description="Print a small dataset spec (built-in scenes, drawn sensor parameters).",
        formatter_class=HelpFormatter,
    )
    example.set_defaults(func=print_example)
    run = actions.add_parser(
        "run",
        help="simulate a dataset spec into a folder (a rerun finishes what is missing)",
        description="Simulate every sequence of SPEC into DIR: events/sequence=NAME/*.parquet, "
        "runs/NAME/ (camera poses, preview) and manifest.json. A rerun into the same folder "
        "skips finished sequences; a failing sequence is retried, then recorded as failed.",
        formatter_class=HelpFormatter,
    )
    run.add_argument(
        "spec", metavar="SPEC", help="dataset spec (TOML; 'pecs dataset example' prints one)"
    )
    run.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    add_sensor_config_argument(
        run,
        replaces="the spec's config keys as every sequence's base sensor (the spec's sensor "
        "tables and draws still apply over it; its seed is drawn per sequence)",
    )
    run.add_argument(
        "--workers",
        type=number(int, at_least=1),
        metavar="N",
        help="sequences at a time (1: in this process, no Ray needed; default: every CPU)",
    )
    run.add_argument(
        "--address",
        help="a running Ray cluster: 'auto' on one of its nodes (as in 'ray job submit -- pecs "
        "dataset run ...'), or ray://HOST:PORT (Ray Client: pip install 'ray[client]')",
    )
    run.add_argument(
        "--no-card",
        dest="card",
        action="store_false",
        help="do not write the dataset card (DIR/card.html) at the end of the run",
    )
    add_progress_arguments(run)
    run.set_defaults(func=run_spec)
    card = actions.add_parser(
        "card",
        help="write a dataset's card: distributions to check before training, previews",
        description="Write the card of the dataset in DIR: a summary (sequences done and "
        "failed, events, duration, sizes), histograms of events per second, ON fraction, flow "
        "per 100 ms, depth, illuminance, instances and every drawn sensor field (its spec "
        "range marked), and preview event frames. .html: one self-contained file; .md: "
        "markdown with its PNGs in NAME_files/ beside it. 'pecs dataset run' writes "
        "DIR/card.html at the end of every run.",
        formatter_class=HelpFormatter,
    )
    card.add_argument("folder", metavar="DIR", help="dataset folder (of 'pecs dataset run')")
    card.add_argument(
        "-o",
        "--output",
        metavar="PATH",
        help="card file, .html or .md (default: DIR/card.html)",
    )
    card.set_defaults(func=write_card_file)


def write_card_file(args: argparse.Namespace) -> int:
    from pecs.dataset import write_card

    print(f"dataset card -> {write_card(args.folder, args.output)}")
    return 0


def print_example(args: argparse.Namespace) -> int:
    from pecs.dataset import example_spec_text

    sys.stdout.write(example_spec_text())
    return 0


def run_spec(args: argparse.Namespace) -> int:
    from pecs.dataset import RayNotInstalled, load_spec, run_dataset

    spec = load_spec(args.spec, sensor_config(args))
    bar = _ProgressBar() if wants_progress(args) else None
    try:
        summary = run_dataset(
            spec,
            args.output,
            workers=args.workers,
            address=args.address,
            progress=bar.update if bar else None,
            card=args.card,
        )
    except RayNotInstalled as error:
        print(f"pecs dataset: error: {error}", file=sys.stderr)
        return 2
    finally:
        if bar:
            bar.close()
    print(
        f"{len(summary.done)} sequences simulated, {len(summary.skipped)} already finished, "
        f"{len(summary.failed)} failed; {summary.events} events in {summary.wall_s:.1f} s "
        f"({summary.engine}, {summary.workers} worker{'s' if summary.workers > 1 else ''}) "
        f"-> {summary.out_dir}" + (f" (card: {summary.card.name})" if summary.card else "")
    )
    if summary.failed:
        print(
            f"failed: {', '.join(summary.failed)} (errors in {summary.out_dir}/manifest.json; "
            "a rerun tries them again)",
            file=sys.stderr,
        )
        return 1
    return 0


class _ProgressBar:
    """tqdm over sequences (its rate gives the time left), with events and failures. Sequences
    finished by an earlier run count as done from the start, not in the rate."""

    def __init__(self) -> None:
        self.bar: Any = None

    def update(self, progress: Any) -> None:
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(
                total=progress.total,
                initial=progress.skipped,
                unit="seq",
                dynamic_ncols=True,
                file=sys.stderr,
            )
        self.bar.set_postfix(
            events=str(progress.events), failed=str(progress.failed), refresh=False
        )
        self.bar.update(progress.done + progress.failed + progress.skipped - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
