"""One sequence of a dataset: `pecs.Simulation` run in a scratch folder of the worker, its files
returned as bytes, so that the worker needs no storage shared with the driver (a Ray cluster's
nodes rarely share one) and only the driver writes the dataset."""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pecs.dataset import scratch
from pecs.dataset.spec import SequenceTask
from pecs.render.limits import SettingError


@dataclass(frozen=True)
class SequenceOutput:
    """What a worker sends back for one finished sequence."""

    name: str
    #: Every file `Simulation.run` wrote, by its path relative to the run folder.
    files: dict[str, bytes]
    events: int
    frames: int
    simulated_s: float
    wall_s: float
    #: The sensor configuration actually simulated (preset, overrides and draws merged).
    config: dict[str, Any]
    host: str


def build_simulation(task: SequenceTask, scene_dir: Path | None = None) -> Any:
    """The `pecs.Simulation` of a sequence: its scene and settings, fixed and drawn sensor fields,
    and its seed (render and sensor). A generated scene (`task.generator`) is drawn and written
    into `scene_dir` first (scene file, Mitsuba XML, meshes, textures), and simulated from there:
    what the dataset keeps is what it rendered."""
    from pecs.render import Simulation

    scene = task.scene
    if task.generator:
        if scene_dir is None:
            raise ValueError(
                f"sequence {task.name}: its scene is drawn by the {task.generator!r} generator; "
                "give a folder to write it in (scene_dir)"
            )
        from pecs.dataset import generators

        scene = str(generators.write_task_scene(task, scene_dir))
    try:
        return Simulation(
            scene,
            seed=task.seed,
            sensor={**task.sensor, **task.drawn},
            **task.settings,
        )
    except SettingError as error:
        raise ValueError(_in_spec_words(task, error)) from None


def _in_spec_words(task: SequenceTask, error: SettingError) -> str:
    """A `SettingError` blamed on the spec key that gave the value (a draw, a sensor table, a
    setting), not on the scene file: "spec.toml: draw.theta_on: drew -0.03 for seq-2: ..."."""
    key = error.field if error.setting == "sensor" else error.setting
    if error.source is not None or key not in task.origins:
        return str(error)
    reason = error.reason.removeprefix(f"{key}: ")
    if key in task.drawn:
        value = task.drawn[key]
        shown = f"{value:.6g}" if isinstance(value, float) else str(value)
        return f"{task.origins[key]}: drew {shown} for {task.name}: {key} {reason}"
    return f"{task.origins[key]}: {reason} (sequence {task.name})"


def run_sequence(task: SequenceTask) -> SequenceOutput:
    """Simulate one sequence and return its files; any error propagates to the caller."""
    from pecs.dataset.generators import SCENE_FOLDER

    started = time.perf_counter()
    # A folder named after this process: if it is killed, the next run removes it.
    with scratch.sequence_folder() as folder:
        simulation = build_simulation(task, folder / SCENE_FOLDER)
        summary = simulation.run(folder / "run")
        files = {
            str(path.relative_to(summary.out_dir)): path.read_bytes()
            for path in sorted(summary.out_dir.rglob("*"))
            if path.is_file()
        }
        # A generated scene is kept with the sequence (runs/NAME/scene/): `pecs simulate
        # runs/NAME/scene/scene.toml` renders it alone.
        files.update(
            {
                str(path.relative_to(folder)): path.read_bytes()
                for path in sorted((folder / SCENE_FOLDER).rglob("*"))
                if path.is_file()
            }
        )
    return SequenceOutput(
        name=task.name,
        files=files,
        events=summary.events,
        frames=summary.frames,
        simulated_s=summary.simulated_s,
        wall_s=time.perf_counter() - started,
        config=simulation.sensor_config.to_dict(),
        host=platform.node(),
    )
