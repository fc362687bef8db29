"""Downstream benchmark: does training on pecs's pixel model help a network on real events?

An E2VID-like recurrent U-Net (benches/reconstruction/network.py) learns to reconstruct
intensity from events simulated on the same training frames with three sensors, and is then
tested on the two real DAVIS346 recordings (the road, 59 APS frames, and the Newton's cradle of
emlb, 13 frames; ../shared/data): run recurrently over each recording's real events, one window
per APS frame interval (40 ms at 25 Hz), it reconstructs every frame from the second on, scored
by MSE and SSIM after the frame's best affine intensity fit (the EVREAL protocol,
reconstruction/image_quality.py), mean over frames. Three training seeds a configuration (the
network's initial weights, the batches, and the drawn sensors and their noise); the frames are
the same for every run.

Sensors (one drawn per training sequence, the same draws for every configuration):
(a) "davis346 drawn": the davis346 preset with thresholds drawn around the preset (0.2 / 0.2) and
    the road-calibrated values (0.223 / 0.243, docs/sim-to-real.md, printed by
    `python benches/sim_to_real.py`), refractory period around the preset's 500 us and the
    calibrated lower bound 200 us, mismatch, bandwidth, white level and noise rates drawn around
    the preset's (DRAWN below);
(b) "esim": the ESIM-mode sensor (reference advanced at each crossing, infinite bandwidth, no
    noise) with the same drawn thresholds, what ESIM gives E2VID's training;
(c) "davis346 no noise": (a) with leak, shot noise, hot pixels, threshold noise and timing
    jitter off.

Training data: the E2VID recipe (reconstruction/moving_images.py): natural-image and noise
textures moved by random affine motions, discs crossing them, rendered at 1 kHz and run through
`pecs.frames_to_events`. pecs's procedural scene generator (`pecs dataset`) is not used: it
path-traces every frame with Mitsuba (seconds a frame on a CPU at full size, docs/rendering.md),
where the quick mode alone needs some 35,000 frames at 1 kHz; the test recordings' frames are
never used.

    python benches/downstream.py [-o downstream/] [--long] [--seeds 3] [--jobs 2] [--threads 1]

Quick mode (the default): 128 sequences of 48 x 48 px, 6 windows of 40 ms each, 500 steps of
batch 4, a U-Net 8 channels wide; 21-23 min on 2 shared cores for the 9 trainings, run as 2
jobs of 1 torch thread (on a shared machine 2 threads of one job spin and run several times
slower). `--long`: 512 sequences of 64 px, 8 windows, 5000 steps of batch 8, 16 channels: some
150x the quick mode's compute, hours a training; `--jobs 9` runs all nine at once on a larger
machine. Also printed: a flat image fitted to each frame (the floor: what a network that learnt
nothing scores), and each network on 16 held-out simulated sequences of its own sensor.
Writes results.json (per-frame scores, training losses, times) and table.md into -o.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import lzma
import math
import multiprocessing
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.lib.format import open_memmap
from scipy.ndimage import binary_dilation

try:
    import torch
except ImportError:  # the optional extra: pip install 'pecs[torch]'
    sys.exit("benches/downstream.py needs PyTorch: pip install 'pecs[torch]'")

import pecs
from pecs.config import NOISE_OFF
from reconstruction import moving_images
from reconstruction.image_quality import masked_mse, scores
from reconstruction.network import RecurrentUNet, padded_size, ssim_loss
from reconstruction.voxel_grid import BINS, normalised, voxel_grid

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
RECORDINGS = {
    "road": DATA / "davis346_road" / "davis346_road.aedat4.xz",
    "emlb": DATA / "davis346_emlb" / "demo-01.aedat4.xz",
}
# The table's test sets: the real recordings, and held-out simulated sequences of each
# network's own training sensor (HELD_OUT of them, other frames than the training ones).
TESTS = (*RECORDINGS, "simulated")
HELD_OUT = 16
# The side score "MSE near events": the pixels with an event in the APS interval, grown by this
# many pixels (the moving cars and balls and their edges), fitted and scored alone.
NEAR_EVENTS_PX = 3
CONFIGS = ("davis346 drawn", "esim", "davis346 no noise")
WINDOW_US = 40_000  # both recordings' APS frame interval (25 Hz)
FRAME_US = 1_000  # training frames at 1 kHz


@dataclass(frozen=True)
class Mode:
    sequences: int
    side_px: int
    windows: int
    steps: int
    batch: int
    channels: int = 8  # the U-Net's first width (RecurrentUNet)
    learning_rate: float = 5e-3


QUICK = Mode(sequences=128, side_px=48, windows=6, steps=500, batch=4)
LONG = Mode(
    sequences=512, side_px=64, windows=8, steps=5000, batch=8, channels=16, learning_rate=2e-3
)

# Ranges of the drawn davis346 (config a): each sequence's sensor draws one value of each,
# uniform (log-uniform where marked).
DRAWN = {
    "theta_on": (0.17, 0.28),  # preset 0.2, road-calibrated 0.223
    "theta_off": (0.17, 0.28),  # preset 0.2, road-calibrated 0.243
    "theta_sigma": (0.02, 0.04),  # preset 0.03 (v2e)
    "refractory_us": (150.0, 600.0),  # preset 500, calibrated >= 200
    "cutoff_hz": (100.0, 1000.0),  # log-uniform; preset 300 (v2e)
    "white_lux": (300.0, 20_000.0),  # log-uniform: a dim room to daylight
    "noise_factor": (0.5, 2.0),  # log-uniform, times the preset's leak and shot rates
}
LOG_UNIFORM = {"cutoff_hz", "white_lux", "noise_factor"}


# ---- sensors -----------------------------------------------------------------------------------


def drawn_values(seed: int, sequence: int) -> dict[str, float]:
    """One sequence's draws, the same for every configuration."""
    rng = np.random.default_rng([seed, sequence, 7])
    values = {}
    for name, (low, high) in DRAWN.items():
        if name in LOG_UNIFORM:
            values[name] = float(np.exp(rng.uniform(math.log(low), math.log(high))))
        else:
            values[name] = float(rng.uniform(low, high))
    return values


def sensor(config: str, values: dict[str, float], side_px: int, seed: int) -> pecs.SensorConfig:
    """Configuration (a), (b) or (c) with one sequence's drawn values."""
    size = {"width": side_px, "height": side_px, "seed": seed}
    thresholds = {"theta_on": values["theta_on"], "theta_off": values["theta_off"]}
    if config == "esim":
        return pecs.SensorConfig.preset("esim", **size, **thresholds)
    preset = pecs.SensorConfig.preset("davis346")
    factor = values["noise_factor"]
    drawn = {
        **thresholds,
        "theta_sigma": values["theta_sigma"],
        "refractory_us": values["refractory_us"],
        "cutoff_hz": values["cutoff_hz"],
        "white_lux": values["white_lux"],
        "leak_rate_hz": preset.leak_rate_hz * factor,
        "leak_light_rate_hz": preset.leak_light_rate_hz * factor,
        "shot_rate_hz": preset.shot_rate_hz * factor,
    }
    if config == "davis346 no noise":
        drawn.update(NOISE_OFF, jitter_us=0.0)
    return pecs.SensorConfig.preset("davis346", **size, **drawn)


# ---- events to voxel grids -------------------------------------------------------------------


def window_voxels(
    events: dict[str, np.ndarray], ends_us: np.ndarray, start_us: int, width: int, height: int
) -> np.ndarray:
    """Normalised voxel grids (len(ends_us), BINS, height, width) of the windows (start, end_0],
    (end_0, end_1], ..."""
    bounds = np.concatenate([[start_us], ends_us])
    cuts = np.searchsorted(events["t"], bounds, side="right")
    grids = []
    for k in range(len(ends_us)):
        part = slice(cuts[k], cuts[k + 1])
        grid = voxel_grid(
            events["t"][part],
            events["x"][part],
            events["y"][part],
            events["p"][part],
            (int(bounds[k]), int(bounds[k + 1])),
            width,
            height,
        )
        grids.append(normalised(grid))
    return np.stack(grids)


def as_arrays(table: object) -> dict[str, np.ndarray]:
    return {name: table.column(name).to_numpy() for name in ("t", "x", "y", "p")}  # type: ignore[attr-defined]


# ---- training and testing --------------------------------------------------------------------


def train(
    voxels: np.ndarray,
    targets: np.ndarray,
    seed: int,
    steps: int,
    batch: int,
    losses: list[float] | None = None,
    channels: int = 8,
    learning_rate: float = 5e-3,
) -> RecurrentUNet:
    """Adam, L1 + (1 - SSIM) on every window but the first, back-propagated through the whole
    sequence (truncated BPTT at the sequence's length); batches of random sequences, each
    turned by a random multiple of 90 degrees and mirrored at random. Each step's loss is
    appended to `losses` where given."""
    torch.manual_seed(seed)
    rng = np.random.default_rng([seed, 11])
    model = RecurrentUNet(bins=BINS, channels=channels)
    optimiser = torch.optim.Adam(model.parameters(), lr=learning_rate)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, steps)
    windows = voxels.shape[1]
    model.train()
    for _ in range(steps):
        chosen = rng.choice(len(voxels), batch, replace=False)
        x = torch.from_numpy(voxels[chosen])
        y = torch.from_numpy(targets[chosen])[:, :, None]
        turns = int(rng.integers(4))
        x, y = torch.rot90(x, turns, (-2, -1)), torch.rot90(y, turns, (-2, -1))
        if rng.uniform() < 0.5:
            x, y = x.flip(-1), y.flip(-1)
        state, loss = None, torch.zeros(())
        for w in range(windows):
            image, state = model(x[:, w], state)
            if w > 0:
                loss = loss + (image - y[:, w]).abs().mean() + ssim_loss(image, y[:, w])
        optimiser.zero_grad()
        loss = loss / (windows - 1)
        loss.backward()
        if losses is not None:
            losses.append(float(loss.detach()))
        optimiser.step()
        schedule.step()
    return model


@dataclass(frozen=True)
class RealRecording:
    times_us: np.ndarray
    frames: np.ndarray
    events: dict[str, np.ndarray]


def unpacked(path: Path, scratch: Path) -> Path:
    """The AEDAT4 file, unpacked into `scratch` where it is .xz."""
    if not path.exists():
        raise SystemExit(f"no recording at {path}: the shared data sits beside the checkout")
    if path.suffix != ".xz":
        return path
    target_path = scratch / path.stem
    with lzma.open(path) as source, open(target_path, "wb") as target:
        shutil.copyfileobj(source, target)
    return target_path


def load_recording(path: Path) -> RealRecording:
    """APS frames (exposure midpoints, DN / 255) and events of an AEDAT4 file."""
    pairs = list(pecs.open_frames(path))
    times = np.array([t for t, _ in pairs], np.int64)
    frames = np.stack([np.asarray(f, np.float64) for _, f in pairs])
    return RealRecording(times, frames, as_arrays(pecs.read_events(path)))


def near_events(grid: np.ndarray) -> np.ndarray:
    """The pixels with an event in a window, grown by NEAR_EVENTS_PX: where the scene moved."""
    return binary_dilation(np.abs(grid).sum(0) > 0, iterations=NEAR_EVENTS_PX)


def test(
    model: RecurrentUNet, recording: RealRecording
) -> tuple[list[float], list[float], list[float]]:
    """Per-frame MSE and SSIM of frames 1..N-1, each reconstructed from the events of its APS
    interval with the state carried from the first frame on; and the MSE near the interval's
    events (`near_events`, fitted there: `masked_mse`)."""
    height, width = recording.frames.shape[1:]
    padded_h, padded_w = padded_size(height, width)
    voxels = window_voxels(
        recording.events, recording.times_us[1:], int(recording.times_us[0]), width, height
    )
    model.eval()
    mse, ssim, mse_near = [], [], []
    state = None
    with torch.no_grad():
        for k, grid in enumerate(voxels, start=1):
            x = torch.zeros(1, BINS, padded_h, padded_w)
            x[0, :, :height, :width] = torch.from_numpy(grid)
            image, state = model(x, state)
            prediction = image[0, 0, :height, :width].numpy().astype(np.float64)
            m, s = scores(prediction, recording.frames[k])
            mse.append(m)
            ssim.append(s)
            mse_near.append(masked_mse(prediction, recording.frames[k], near_events(grid)))
    return mse, ssim, mse_near


# ---- the table -----------------------------------------------------------------------------


def summary(values: list[float]) -> dict[str, float]:
    array = np.asarray(values)
    return {
        "mean": float(array.mean()),
        "std": float(array.std()),
        "range": float(array.max() - array.min()),
    }


def flat_scores(recording: RealRecording) -> dict[str, float]:
    """The floor: a flat image (what a network that learnt nothing from events gives), fitted
    to each frame 1..N-1: MSE = the frame's variance; near the events, their pixels' variance."""
    pairs = [scores(np.zeros_like(frame), frame) for frame in recording.frames[1:]]
    height, width = recording.frames.shape[1:]
    voxels = window_voxels(
        recording.events, recording.times_us[1:], int(recording.times_us[0]), width, height
    )
    near = [
        masked_mse(np.zeros_like(frame), frame, near_events(grid))
        for frame, grid in zip(recording.frames[1:], voxels)
    ]
    return {
        "mse": float(np.mean([m for m, _ in pairs])),
        "ssim": float(np.mean([s for _, s in pairs])),
        "mse_near_events": float(np.mean(near)),
    }


def table(results: dict, flat: dict[str, dict[str, float]]) -> str:
    """Config x test set, mean +- std over seeds (range in brackets), then (a) against (b) on
    the real recordings."""
    lines = [
        "| sensor | test | MSE (mean +- std [range]) | SSIM (mean +- std [range]) |",
        "|---|---|---|---|",
    ]
    for name in TESTS:
        lines.append(
            f"| flat image (floor) | {name} | {flat[name]['mse']:.4f} | {flat[name]['ssim']:.3f} |"
        )
    for config in CONFIGS:
        for name in TESTS:
            mse = summary([r["mse"] for r in results[config][name]])
            ssim = summary([r["ssim"] for r in results[config][name]])
            lines.append(
                f"| {config} | {name} | {mse['mean']:.4f} +- {mse['std']:.4f} "
                f"[{mse['range']:.4f}] | {ssim['mean']:.3f} +- {ssim['std']:.3f} "
                f"[{ssim['range']:.3f}] |"
            )
    lines += ["", "| MSE near events (mean +- std [range]) | " + " | ".join(RECORDINGS) + " |"]
    lines.append("|---|" + "---|" * len(RECORDINGS))
    lines.append(
        "| flat image (floor) | "
        + " | ".join(f"{flat[name]['mse_near_events']:.4f}" for name in RECORDINGS)
        + " |"
    )
    for config in CONFIGS:
        cells = []
        for name in RECORDINGS:
            near = summary([r["mse_near_events"] for r in results[config][name]])
            cells.append(f"{near['mean']:.4f} +- {near['std']:.4f} [{near['range']:.4f}]")
        lines.append(f"| {config} | " + " | ".join(cells) + " |")
    lines += ["", "| recording | MSE a / b | SSIM a / b | a beats b beyond the seeds' range |"]
    lines.append("|---|---|---|---|")
    a, b = CONFIGS[0], CONFIGS[1]
    for name in RECORDINGS:
        ma, mb = (summary([r["mse"] for r in results[c][name]]) for c in (a, b))
        sa, sb = (summary([r["ssim"] for r in results[c][name]]) for c in (a, b))
        mse_margin = mb["mean"] - ma["mean"]
        ssim_margin = sa["mean"] - sb["mean"]
        mse_wins = mse_margin > max(ma["range"], mb["range"], 0.0)
        ssim_wins = ssim_margin > max(sa["range"], sb["range"], 0.0)
        verdict = f"MSE {'yes' if mse_wins else 'no'}, SSIM {'yes' if ssim_wins else 'no'}"
        if len(results[a][name]) < 2:
            verdict = "n/a: one seed"
        lines.append(
            f"| {name} | {ma['mean'] / mb['mean']:.3f} | {sa['mean'] / sb['mean']:.3f} | {verdict} |"
        )
    return "\n".join(lines)


def simulate_all(
    mode: Mode, seeds: int, scratch: Path, held_out: bool = False
) -> tuple[Path, dict[tuple[str, int], Path], dict[tuple[str, int], int]]:
    """Draws the training frames (or, `held_out`, HELD_OUT other sequences) one sequence at a
    time and simulates each with every (configuration, seed)'s sensor; the voxel grids and
    targets go to .npy files in `scratch` (the frames themselves are not kept). Returns the
    targets' file, each run's voxel file and its event count."""
    count, frames_seed, first = (HELD_OUT, 4048, 10**6) if held_out else (mode.sequences, 2024, 0)
    prefix = "held_out_" if held_out else ""
    shape = (count, mode.windows, BINS, mode.side_px, mode.side_px)
    runs = [(config, seed) for seed in range(seeds) for config in CONFIGS]
    files = {
        run: scratch / f"{prefix}voxels_{run[0].replace(' ', '_')}_{run[1]}.npy" for run in runs
    }
    voxels = {run: open_memmap(files[run], "w+", np.float32, shape) for run in runs}
    targets_file = scratch / f"{prefix}targets.npy"
    targets = open_memmap(targets_file, "w+", np.float32, shape[:2] + shape[3:])
    counts = dict.fromkeys(runs, 0)
    rng = np.random.default_rng(frames_seed)
    for index in range(first, first + count):
        sequence = moving_images.sequence(rng, mode.side_px, mode.windows, WINDOW_US, FRAME_US)
        targets[index - first] = sequence.targets
        for config, seed in runs:
            values = drawn_values(seed, index)
            settings = sensor(config, values, mode.side_px, seed * 100_003 + index)
            table = pecs.frames_to_events(sequence.frames, sequence.frame_times_us, settings)
            counts[config, seed] += table.num_rows
            voxels[config, seed][index - first] = window_voxels(
                as_arrays(table), sequence.target_times_us, 0, mode.side_px, mode.side_px
            )
    for array in (*voxels.values(), targets):
        array.flush()
    return targets_file, files, counts


def simulated_scores(
    model: RecurrentUNet, voxels: np.ndarray, targets: np.ndarray
) -> tuple[float, float]:
    """Mean MSE and SSIM (after the affine fit) over held-out simulated sequences, every window
    but the first."""
    model.eval()
    pairs = []
    with torch.no_grad():
        state = None
        for w in range(voxels.shape[1]):
            images, state = model(torch.from_numpy(np.array(voxels[:, w])), state)
            if w > 0:
                pairs += [
                    scores(image[0].numpy().astype(np.float64), target)
                    for image, target in zip(images, targets[:, w])
                ]
    return float(np.mean([m for m, _ in pairs])), float(np.mean([s for _, s in pairs]))


def run(task: tuple) -> dict:
    """One training and its tests, in a worker process with `threads` torch threads: the real
    recordings, and held-out simulated sequences of its own sensor (is anything learnt?)."""
    config, seed, voxel_file, targets_file, held_out, mode, recordings, threads, output = task
    torch.set_num_threads(threads)
    clock = time.perf_counter()
    voxels = np.load(voxel_file, mmap_mode="r")
    targets = np.load(targets_file, mmap_mode="r")
    losses: list[float] = []
    model = train(
        voxels, targets, seed, mode.steps, mode.batch, losses, mode.channels, mode.learning_rate
    )
    trained = time.perf_counter() - clock
    tests = {}
    for name, path in recordings.items():
        mse, ssim, mse_near = test(model, load_recording(path))
        tests[name] = {
            "seed": seed,
            "mse": float(np.mean(mse)),
            "ssim": float(np.mean(ssim)),
            "mse_near_events": float(np.mean(mse_near)),
            "mse_frames": mse,
            "ssim_frames": ssim,
        }
    held_out_mse, held_out_ssim = simulated_scores(
        model, np.load(held_out[0], mmap_mode="r"), np.load(held_out[1], mmap_mode="r")
    )
    tests["simulated"] = {"seed": seed, "mse": held_out_mse, "ssim": held_out_ssim}
    torch.save(model.state_dict(), output / f"model_{config.replace(' ', '_')}_{seed}.pt")
    return {
        "config": config,
        "seed": seed,
        "train_s": trained,
        "test_s": time.perf_counter() - clock - trained,
        # The training loss, mean over the first and the last tenth of the steps.
        "loss_first": float(np.mean(losses[: max(1, len(losses) // 10)])),
        "loss_last": float(np.mean(losses[-max(1, len(losses) // 10) :])),
        "tests": tests,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default="downstream", help="folder for the results")
    parser.add_argument("--long", action="store_true", help="the long mode (hours a training)")
    parser.add_argument("--seeds", type=int, default=3, help="training seeds a configuration")
    parser.add_argument("--jobs", type=int, default=2, help="trainings at once (processes)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads a training")
    parser.add_argument("--steps", type=int, help="training steps (overrides the mode's)")
    parser.add_argument("--sequences", type=int, help="training sequences (overrides the mode's)")
    args = parser.parse_args()
    mode = LONG if args.long else QUICK
    mode = dataclasses.replace(
        mode, sequences=args.sequences or mode.sequences, steps=args.steps or mode.steps
    )
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as name:
        scratch = Path(name)
        recordings = {key: unpacked(path, scratch) for key, path in RECORDINGS.items()}
        flat = {key: flat_scores(load_recording(path)) for key, path in recordings.items()}
        targets_file, files, counts = simulate_all(mode, args.seeds, scratch)
        held_out_targets, held_out_files, _ = simulate_all(mode, args.seeds, scratch, True)
        held_out_floor = [
            scores(np.zeros_like(target), target)
            for target in np.load(held_out_targets)[:, 1:].reshape(-1, mode.side_px, mode.side_px)
        ]
        flat["simulated"] = {
            "mse": float(np.mean([m for m, _ in held_out_floor])),
            "ssim": float(np.mean([s for _, s in held_out_floor])),
        }
        simulated = time.perf_counter() - started
        print(f"{mode}: frames drawn and simulated in {simulated:.0f} s", flush=True)
        tasks = [
            (
                config,
                seed,
                file,
                targets_file,
                (held_out_files[config, seed], held_out_targets),
                mode,
                recordings,
                args.threads,
                output,
            )
            for (config, seed), file in files.items()
        ]
        results: dict = {config: {name: [] for name in TESTS} for config in CONFIGS}
        runs = []
        with multiprocessing.get_context("spawn").Pool(args.jobs) as pool:
            for done in pool.imap_unordered(run, tasks):
                config, seed = done["config"], done["seed"]
                for name, scored in done.pop("tests").items():
                    results[config][name].append(scored)
                runs.append({**done, "events": counts[config, seed]})
                print(
                    f"seed {seed} {config}: {counts[config, seed]:,} training events, trained "
                    f"{done['train_s']:.0f} s (loss {done['loss_first']:.3f} -> "
                    f"{done['loss_last']:.3f}), tested {done['test_s']:.0f} s; "
                    + ", ".join(
                        f"{n} MSE {results[config][n][-1]['mse']:.4f} "
                        f"SSIM {results[config][n][-1]['ssim']:.3f}"
                        for n in TESTS
                    ),
                    flush=True,
                )
    text = table(results, flat)
    total = time.perf_counter() - started
    print(text)
    print(
        f"total {total / 60:.1f} min ({simulated:.0f} s drawing and simulating), {args.jobs} jobs "
        f"x {args.threads} torch threads, {time.strftime('%Y-%m-%d')}"
    )
    (output / "table.md").write_text(text + "\n")
    summary_json = {
        "mode": mode.__dict__,
        "results": results,
        "flat": flat,
        "runs": runs,
        "total_s": total,
    }
    (output / "results.json").write_text(json.dumps(summary_json, indent=1))


if __name__ == "__main__":
    main()
