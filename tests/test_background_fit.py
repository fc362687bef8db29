"""The noise-only fit's light (pecs.calibrate_noise, `pecs calibrate --noise-only`): a frame
value is the photocurrent value * white_lux / 1000 (config.py), so the shot law's dark rate is
recovered from a scene simulated at a white_lux other than 1000."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pecs
import pytest
from pecs.calibration.background_fit import dark_shot_rate_hz
from pecs.cli import main as cli_main
from pecs.config import SensorConfig

SIZE = 64
DURATION_US = 10_000_000
FRAME_VALUE, DARK, WHITE_LUX = 0.1, 0.01, 10_000.0
SHOT_DARK_HZ = 200.0


def static_scene(tmp_path: Path) -> tuple[Path, SensorConfig]:
    """Shot noise alone on a constant frame at white_lux 10000: photocurrent 0.1 * 10 = 1.0, so
    the scene's rate is 200 * 0.01 / 1.01 = 1.98 Hz per pixel (at white_lux 1000 it would be
    200 * 0.01 / 0.11 = 18 Hz): ~81 k events on 4096 pixels in 10 s, Poisson error 0.4 %."""
    truth = SensorConfig.preset(
        "ideal",
        width=SIZE,
        height=SIZE,
        dark_current=DARK,
        white_lux=WHITE_LUX,
        shot_rate_hz=SHOT_DARK_HZ,
        seed=5,
    )
    frames = np.full((2, SIZE, SIZE), FRAME_VALUE, np.float32)
    events = pecs.frames_to_events(frames, np.array([0, DURATION_US]), truth)
    path = tmp_path / "static.parquet"
    pecs.write_events(events, path)
    return path, truth


def fit_static_scene(tmp_path: Path, **law: float) -> pecs.calibration.background_fit.NoiseFit:
    """The noise fit of `static_scene`'s events, told its light (and any shot law given)."""
    path, _ = static_scene(tmp_path)
    return pecs.calibrate_noise(
        path,
        window_us=(0, DURATION_US),
        photocurrent=FRAME_VALUE,
        dark_current=DARK,
        white_lux=WHITE_LUX,
        **law,
    )


def test_the_shot_law_is_inverted_at_the_frames_white_lux() -> None:
    # r = S I_dark / (v white_lux / 1000 + I_dark): 2 Hz at v = 0.1, 10 klux, I_dark 0.01
    scene_hz = SHOT_DARK_HZ * DARK / (FRAME_VALUE * 10 + DARK)
    assert dark_shot_rate_hz(scene_hz, FRAME_VALUE, DARK, WHITE_LUX) == pytest.approx(200.0)
    assert dark_shot_rate_hz(scene_hz, FRAME_VALUE, DARK) == pytest.approx(200.0 * 11 / 101)
    with pytest.raises(ValueError, match="white_lux > 0"):
        dark_shot_rate_hz(scene_hz, FRAME_VALUE, DARK, 0.0)
    # The square law, r = S (I_dark / x)^2: 200 (0.01 / 1.01)^2 = 0.0196 Hz at the same light.
    square_hz = SHOT_DARK_HZ * (DARK / (FRAME_VALUE * 10 + DARK)) ** 2
    assert dark_shot_rate_hz(square_hz, FRAME_VALUE, DARK, WHITE_LUX, 2.0) == pytest.approx(200.0)
    for bad_exponent in (1.5, 0.0):
        with pytest.raises(ValueError, match="shot_light_exponent must be 1 or 2"):
            dark_shot_rate_hz(square_hz, FRAME_VALUE, DARK, WHITE_LUX, bad_exponent)
    with pytest.raises(ValueError, match="finite"):
        dark_shot_rate_hz(scene_hz, FRAME_VALUE, DARK, float("inf"))


def test_a_fit_keeps_the_law_its_dark_rate_belongs_to(tmp_path: Path) -> None:
    # Fitted with n = 2, the fit's configuration says n = 2 whatever its base says, so that its
    # dark rate gives the scene's rate back: S (I_dark / x)^2 at the fitted light.
    fit = fit_static_scene(tmp_path, shot_light_exponent=2)
    config = fit.config(SensorConfig(dark_current=DARK, white_lux=WHITE_LUX))
    assert config.shot_light_exponent == 2
    x = FRAME_VALUE * WHITE_LUX / 1000 + DARK
    assert config.shot_rate_hz * (DARK / x) ** 2 == pytest.approx(fit.scene_shot_rate_hz)


def test_a_fit_at_10_klux_recovers_the_dark_shot_rate_within_10_percent(tmp_path: Path) -> None:
    fit = fit_static_scene(tmp_path)
    assert fit.scene_shot_rate_hz == pytest.approx(SHOT_DARK_HZ * DARK / 1.01, rel=0.05)
    assert fit.shot_rate_hz == pytest.approx(SHOT_DARK_HZ, rel=0.10)


def test_cli_noise_only_takes_white_lux_from_the_config(tmp_path: Path) -> None:
    path, truth = static_scene(tmp_path)
    base, output = tmp_path / "base.toml", tmp_path / "fitted.toml"
    truth.replace(shot_rate_hz=0.0).to_file(base)
    args = ["calibrate", "--noise-only", str(path), "--config", str(base)]
    assert cli_main([*args, "--photocurrent", str(FRAME_VALUE), "-o", str(output)]) == 0
    fitted = SensorConfig.from_file(output)
    assert fitted.white_lux == WHITE_LUX
    assert fitted.shot_rate_hz == pytest.approx(SHOT_DARK_HZ, rel=0.10)
