"""`pecs frames2events --input-noise-sigma READ[,GAIN] [--deadband-sigmas K]`: the frames'
noise stated on the command line gives the events of the Python API's
`frames_to_file(..., input_noise=InputNoise(READ, GAIN, K))`, and bad values are refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pecs
import pyarrow as pa
import pytest
from cli_run import PYTHON_SYNTAX, run_cli
from pecs.cli import main as cli_main
from pecs.config import SensorConfig
from pecs.footage.input_noise import InputNoise

H, W, N = 24, 40, 12
READ_SIGMA = 0.01


@pytest.fixture
def noisy_npy(tmp_path: Path) -> Path:
    """Still frames from 0.02 to 0.5 across x with Gaussian read noise of 0.01 (2.5 DN of 255)
    drawn anew each frame, and a step x2 in the left half at frame 6: in the dark columns the
    noise alone is a log change of up to 0.5, well above the 0.2 threshold."""
    rng = np.random.default_rng(4)
    levels = np.tile(np.linspace(0.02, 0.5, W, dtype=np.float32), (N, H, 1))
    levels[6:, :, : W // 2] *= 2.0
    frames = levels + READ_SIGMA * rng.standard_normal((N, H, W)).astype(np.float32)
    path = tmp_path / "frames.npy"
    np.save(path, np.clip(frames, 0.0, 1.0))
    return path


def frames2events(npy: Path, out: Path, *options: str) -> pa.Table:
    args = ["frames2events", str(npy), "--fps", "25", "--preset", "ideal", "-o", str(out)]
    assert cli_main([*args, "--quiet", *options]) == 0
    return pecs.read_events(out)


def same_events(a: pa.Table, b: pa.Table) -> bool:
    return a.num_rows == b.num_rows and all(
        np.array_equal(a[name].to_numpy(), b[name].to_numpy()) for name in ("t", "x", "y", "p")
    )


def test_a_stated_noise_gives_the_python_apis_events(noisy_npy: Path, tmp_path: Path) -> None:
    stated = ["--input-noise-sigma", "0.008,0.0002", "--deadband-sigmas", "4"]
    cli = frames2events(noisy_npy, tmp_path / "cli.parquet", *stated)
    api_out = tmp_path / "api.parquet"
    config = SensorConfig.preset("ideal", width=W, height=H)
    noise = InputNoise(0.008, 0.0002, 4.0)
    pecs.frames_to_file(noisy_npy, api_out, config, fps=25, input_noise=noise)
    assert same_events(cli, pecs.read_events(api_out))
    # frames from arrays have input noise off by default: stating it turned it on
    raw = frames2events(noisy_npy, tmp_path / "raw.parquet")
    assert raw.num_rows > 1.5 * cli.num_rows
    # a band wider than any change (sigma 1.0 of frames in [0, 1]) holds every pixel at its
    # first frame: constant input, no events from the ideal sensor
    held = frames2events(noisy_npy, tmp_path / "held.parquet", "--input-noise-sigma", "1")
    assert held.num_rows == 0


def test_a_stated_sigma_changes_the_events_against_the_estimate(
    noisy_npy: Path, tmp_path: Path
) -> None:
    # The estimate finds ~0.01; a stated 0.002 makes a band of 5 x 0.002 = 1 sigma of the real
    # noise, which a still pixel leaves on 32 % of frames: far more events than the estimate
    # (the step's 1440 events and ~1100 of noise unfiltered: ~2300 against ~1200).
    estimated = frames2events(noisy_npy, tmp_path / "estimated.parquet", "--input-noise", "on")
    low = frames2events(noisy_npy, tmp_path / "low.parquet", "--input-noise-sigma", "0.002")
    assert low.num_rows > 1.5 * estimated.num_rows
    # the stated noise at its true value is about the estimate's result (the estimate is within
    # 10 % of the truth: test_input_noise)
    true = frames2events(noisy_npy, tmp_path / "true.parquet", "--input-noise-sigma", "0.01")
    assert abs(true.num_rows - estimated.num_rows) <= 0.1 * estimated.num_rows


def test_a_deadband_alone_holds_back_the_estimated_noise(noisy_npy: Path, tmp_path: Path) -> None:
    # --deadband-sigmas without a stated noise: the noise is estimated (~0.01) and the band is K
    # of its sigma. K = 0 holds nothing back: the raw frames' events; K = 100, the most allowed
    # (a band of ~1, wider than any change of these frames: at most 0.26 and the noise) holds
    # every pixel at its first frame: none; K = 5 is the estimated default's events.
    raw = frames2events(noisy_npy, tmp_path / "raw.parquet")
    none = frames2events(noisy_npy, tmp_path / "k0.parquet", "--deadband-sigmas", "0")
    assert same_events(none, raw) and raw.num_rows > 1000
    held = frames2events(noisy_npy, tmp_path / "k100.parquet", "--deadband-sigmas", "100")
    assert held.num_rows == 0
    five = frames2events(noisy_npy, tmp_path / "k5.parquet", "--deadband-sigmas", "5")
    on = frames2events(noisy_npy, tmp_path / "on.parquet", "--input-noise", "on")
    assert same_events(five, on)
    three = frames2events(noisy_npy, tmp_path / "k3.parquet", "--deadband-sigmas", "3")
    assert on.num_rows < three.num_rows < raw.num_rows


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--input-noise-sigma", "-0.01"], "-0.01: expected a number >= 0"),
        (["--input-noise-sigma", "nan"], "nan: expected a number >= 0"),
        (["--input-noise-sigma", "0.01,inf"], "inf: expected a number >= 0"),
        (["--input-noise-sigma", "0.01,0.1,3"], "0.01,0.1,3: expected READ or READ,GAIN"),
        (["--input-noise-sigma", "low"], "low: expected a number >= 0"),
        (["--input-noise-sigma", "0.01", "--deadband-sigmas", "-1"], ">= 0"),
        (["--input-noise-sigma", "0.01", "--input-noise", "off"], "cannot go with"),
        (["--deadband-sigmas", "3", "--input-noise", "off"], "cannot go with --input-noise off"),
    ],
)
def test_bad_stated_noise_is_refused_with_its_reason(
    noisy_npy: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    options: list[str],
    message: str,
) -> None:
    out = tmp_path / "events.parquet"
    code, _, err = run_cli(
        capsys, "frames2events", str(noisy_npy), "--fps", "25", "-o", str(out), *options
    )
    assert code == 2
    assert message in err
    assert not PYTHON_SYNTAX.search(err)
    assert not out.exists()
