"""Datasets: many sequences (scenes, sensors with parameters drawn per sequence) simulated in
this process or on Ray into a Parquet dataset partitioned by sequence, and read back in windows
of events for training. See docs/datasets.md."""

from pecs.dataset.card import write_card
from pecs.dataset.engine import RayNotInstalled
from pecs.dataset.on_the_fly import GeneratedWindows
from pecs.dataset.run import DatasetSummary, Progress, run_dataset
from pecs.dataset.spec import DatasetSpec, SequenceTask, example_spec_text, load_spec, parse_spec
from pecs.dataset.windows import EventDataset, EventWindow, EventWindows, open_dataset

__all__ = [
    "DatasetSpec",
    "DatasetSummary",
    "EventDataset",
    "EventWindow",
    "EventWindows",
    "GeneratedWindows",
    "Progress",
    "RayNotInstalled",
    "SequenceTask",
    "example_spec_text",
    "load_spec",
    "open_dataset",
    "parse_spec",
    "run_dataset",
    "write_card",
]
