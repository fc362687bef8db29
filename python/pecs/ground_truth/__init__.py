"""Ground truth aligned with the events: z-depth, motion field, instances, normals, boxes,
classes, intrinsics, poses and IMU per run, and flow between any two times
(`Simulation(ground_truth=...)`, `pecs simulate --ground-truth`), read back with
`pecs.read_ground_truth(run_dir)`. Conventions: docs/ground-truth.md."""

from pecs.ground_truth.boxes import Boxes
from pecs.ground_truth.flow import FlowBetween
from pecs.ground_truth.layout import KINDS, parse_kinds
from pecs.ground_truth.reader import GroundTruth, read_ground_truth

__all__ = ["KINDS", "Boxes", "FlowBetween", "GroundTruth", "parse_kinds", "read_ground_truth"]
