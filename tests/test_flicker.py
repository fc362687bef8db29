"""Mains flicker (pecs.render.flicker): the waveforms by hand, a flickering static scene's events
at the flicker's frequency (frames and the 3D path), adaptive steps that sample it, bad input.

Expected values are worked out by hand: w(t) = 1 - d cos(2 pi f t) for the sine (mean 1, depth
(max - min) / (max + min) = d); pi / 2 |sin(pi f t)| for the rectified waveform at depth 1; an
ideal pixel (theta 0.2, no noise) under a light swinging from ln 0.7 to ln 1.3 around its start
crosses two levels each way a period (see the test).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pecs
import pytest
from cli_run import run_cli
from pecs.render.flicker import LAMPS, SAMPLES_PER_PERIOD, Flicker, flickered
from pecs.render.limits import SettingError
from pecs.render.scene_file import TimeStepping, load_scene
from pecs.render.time_stepping import AdaptiveStepper

PERIOD_US = 10_000  # 100 Hz


def rate_spectrum(t_us: np.ndarray, duration_us: int) -> tuple[np.ndarray, np.ndarray]:
    """|FFT| of the event rate in 1 ms bins (mean removed), and its frequencies in Hz."""
    bins = duration_us // 1000
    counts = np.bincount(t_us // 1000, minlength=bins)[:bins].astype(np.float64)
    return np.fft.rfftfreq(bins, 1e-3), np.abs(np.fft.rfft(counts - counts.mean()))


def strongest_hz(t_us: np.ndarray, duration_us: int) -> float:
    frequency, amplitude = rate_spectrum(t_us, duration_us)
    return float(frequency[1 + np.argmax(amplitude[1:])])


def test_waveforms_match_the_formulas_by_hand() -> None:
    sine = Flicker(100.0, 0.3)
    # 1 - 0.3 cos(2 pi 100 t): least at the mains zero crossing, mean a quarter on, most at half.
    assert sine.factor(0.0) == pytest.approx(0.7)
    assert sine.factor(0.0025) == pytest.approx(1.0)
    assert sine.factor(0.005) == pytest.approx(1.3)
    rectified = Flicker(100.0, 1.0, "rectified")
    assert rectified.factor(0.0) == pytest.approx(0.0, abs=1e-12)
    assert rectified.factor(0.0025) == pytest.approx(math.pi / 2 * math.sin(math.pi / 4))
    assert rectified.factor(0.005) == pytest.approx(math.pi / 2)
    # A quarter period of phase moves the least light a quarter period later.
    assert Flicker(100.0, 0.3, phase_deg=90.0).factor(0.0) == pytest.approx(1.0)
    assert Flicker(120.0, 0.3).factor(1 / 240) == pytest.approx(1.3)


@pytest.mark.parametrize("name", sorted(LAMPS))
def test_every_lamp_has_mean_one_and_its_stated_depth(name: str) -> None:
    lamp = Flicker.lamp(name, 120.0)
    t_s = np.arange(100_000) / 100_000 / 120.0  # one period, finely
    light = lamp.factor(t_s)
    assert float(np.mean(light)) == pytest.approx(1.0, abs=1e-6)
    depth = (light.max() - light.min()) / (light.max() + light.min())
    assert depth == pytest.approx(LAMPS[name].depth, abs=1e-6)


def test_sub_frames_are_the_frames_times_the_waveform() -> None:
    """Frames at 25 Hz of a constant 0.5: fed at 20 a period, each 0.5 x (1 - 0.3 cos)."""
    frames = [(t_us, np.full((2, 3), 0.5, np.float32)) for t_us in (0, 40_000, 80_000)]
    fed = list(flickered(iter(frames), Flicker(100.0, 0.3), offset=1e-3))
    times = np.array([t for t, _ in fed])
    assert times[0] == 0 and times[-1] == 80_000
    assert np.all(np.diff(times) == PERIOD_US // SAMPLES_PER_PERIOD)  # 500 us
    light = {t: float(frame[0, 0]) for t, frame in fed}
    assert light[0] == pytest.approx(0.5 * 0.7, rel=1e-6)
    assert light[2500] == pytest.approx(0.5 * 1.0, rel=1e-6)
    assert light[5000] == pytest.approx(0.5 * 1.3, rel=1e-6)
    assert light[40_000] == pytest.approx(0.5 * 0.7, rel=1e-6)  # a footage frame is lit too


def test_sub_frames_follow_the_frames_change_in_log() -> None:
    """Between 1 and 4 the sensor sees 2 at mid-interval (linear in log): 2 x w(t)."""
    frames = [(0, np.ones((1, 1), np.float32)), (20_000, np.full((1, 1), 4.0, np.float32))]
    fed = dict(flickered(iter(frames), Flicker(100.0, 0.3), offset=0.0))
    assert float(fed[10_000][0, 0]) == pytest.approx(2.0 * 0.7, rel=1e-6)
    assert float(fed[12_500][0, 0]) == pytest.approx(2.0 ** (12.5 / 10) * 1.0, rel=1e-6)


def test_a_static_scene_under_100_hz_light_fires_at_100_hz() -> None:
    """A constant frame at 25 fps under 100 Hz light at 30 % depth, 0.2 s, davis346."""
    config = pecs.SensorConfig.preset("davis346", width=16, height=16, seed=1)
    frames = np.full((6, 16, 16), 0.5, np.float32)
    t_us = np.arange(6) * 40_000
    steady = pecs.frames_to_events(frames, t_us, config)
    events = pecs.frames_to_events(frames, t_us, config, flicker=Flicker(100.0, 0.3))
    assert events.num_rows > 50 * max(steady.num_rows, 1)
    t = events.column("t").to_numpy()
    on = events.column("p").to_numpy() == 1
    # Each polarity fires once a period: ON events while the light rises, OFF while it falls.
    assert strongest_hz(t[on], 200_000) == pytest.approx(100.0, abs=5.0)
    assert strongest_hz(t[~on], 200_000) == pytest.approx(100.0, abs=5.0)
    # The total rate, |d ln w / dt| / theta, repeats every half period (the rise mirrors the
    # fall): its strongest line is 200 Hz, and 100 Hz stands far above the floor.
    frequency, amplitude = rate_spectrum(t, 200_000)
    lines = frequency[np.argsort(amplitude)[::-1][:4]]
    assert set(lines) <= {100.0, 200.0, 300.0, 400.0, 500.0}
    assert amplitude[frequency == 100.0][0] > 5 * np.median(amplitude[1:])


def test_an_ideal_pixel_crosses_two_levels_each_way_a_period() -> None:
    """Ideal sensor, theta 0.2, light 1 - 0.3 sin(2 pi f t) starting mid-rise (phase 90 deg):
    ln 1.3 = 0.262 and ln 0.7 = -0.357 around the start, so the levels 0.2, 0.0 and -0.2 are
    crossed: per period 2 ON (rising -0.2 -> 0.0 -> 0.2) and 2 OFF. In 16 whole periods away
    from the ends: 32 of each a pixel."""
    config = pecs.SensorConfig.preset("ideal", width=4, height=4)
    frames = np.full((6, 4, 4), 0.5, np.float32)
    flicker = Flicker(100.0, 0.3, phase_deg=90.0)
    events = pecs.frames_to_events(frames, np.arange(6) * 40_000, config, flicker=flicker)
    t, p = events.column("t").to_numpy(), events.column("p").to_numpy()
    inside = (t >= 21_000) & (t < 181_000)
    assert int(np.sum(inside & (p == 1))) == 2 * 16 * 16
    assert int(np.sum(inside & (p == 0))) == 2 * 16 * 16


def test_frames2events_flicker_options(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    frames = np.full((6, 8, 8), 0.5, np.float32)
    np.save(tmp_path / "frames.npy", frames)
    out = tmp_path / "lit.parquet"
    code, _, err = run_cli(
        capsys,
        *("frames2events", str(tmp_path / "frames.npy"), "-o", str(out), "--fps", "25"),
        *("--preset", "ideal", "--flicker-hz", "100", "--flicker-depth", "0.3", "--quiet"),
    )
    assert code == 0, err
    events = pecs.read_events(out)
    on = events.column("p").to_numpy() == 1
    assert strongest_hz(events.column("t").to_numpy()[on], 200_000) == pytest.approx(100, abs=5)
    code, _, err = run_cli(
        capsys,
        *("frames2events", str(tmp_path / "frames.npy"), "-o", str(tmp_path / "lamp.parquet")),
        *("--fps", "25", "--flicker-hz", "120", "--flicker-lamp", "led_poor", "--quiet"),
    )
    assert code == 0, err


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["--flicker-hz", "-100", "--flicker-depth", "0.3"],
            "argument --flicker-hz: -100: expected",
        ),
        (
            ["--flicker-hz", "100", "--flicker-depth", "1.5"],
            "argument --flicker-depth: 1.5: expected",
        ),
        (["--flicker-hz", "1e6", "--flicker-depth", "0.3"], "at most 50000 Hz"),
        (["--flicker-depth", "0.3"], "--flicker-depth needs --flicker-hz HZ"),
        (["--flicker-hz", "100"], "--flicker-hz needs --flicker-depth D"),
        (
            ["--flicker-hz", "100", "--flicker-lamp", "led_poor", "--flicker-depth", "0.3"],
            "leave out --flicker-depth",
        ),
    ],
)
def test_frames2events_refuses_bad_flicker_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture, options: list[str], message: str
) -> None:
    np.save(tmp_path / "frames.npy", np.full((2, 4, 4), 0.5, np.float32))
    argv = ["frames2events", str(tmp_path / "frames.npy"), "-o", str(tmp_path / "e.parquet")]
    code, out, err = run_cli(capsys, *argv, "--fps", "25", *options, "--quiet")
    assert code == 2
    # One error line, last (argparse's own refusals print the usage above it).
    last = err.strip().splitlines()[-1]
    assert last.startswith("pecs frames2events: error: ") and message in last
    assert err.count("error:") == 1
    assert "Traceback" not in err and not (tmp_path / "e.parquet").exists()


@pytest.mark.parametrize(
    ("frequency_hz", "depth", "message"),
    [
        (-100.0, 0.3, "frequency_hz: must be a positive number of Hz, got -100"),
        (0.0, 0.3, "frequency_hz: must be a positive number of Hz, got 0"),
        (100.0, -0.1, "depth: must be from 0 (steady) to 1"),
        (100.0, 1.5, "depth: must be from 0 (steady) to 1"),
        (1e6, 0.3, "frequency_hz: 1e+06 Hz needs samples"),
    ],
)
def test_flicker_refuses_bad_values(frequency_hz: float, depth: float, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        Flicker(frequency_hz, depth)


# -- the 3D path ----------------------------------------------------------------------------

LAMP_SCENE = {
    "type": "scene",
    "board": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
    "lamp": {"type": "point", "position": [0, 0, 1], "intensity": "$light_spectrum"},
}


def lamp_settings(flicker: dict, time: dict) -> dict:
    """A white board under one lamp at 300 lux (mean), seen from 2 m, 32 x 24 px, spp 1."""
    return {
        "time": time,
        "sensor": {"preset": "davis346", "overrides": {"width": 32, "height": 24}},
        "optics": {"model": "pinhole", "efl_mm": 8.0},
        "render": {"spp": 1, "max_depth": 2},
        "light": {
            "temperature_k": 3200,
            "illuminance_lux": 300,
            "at": [0, 0, 0.001],
            "normal": [0, 0, 1],
            "flicker": flicker,
        },
        "camera": {"keyframes": [{"t_s": 0, "position": [0, 0, 2], "look_at": [0, 0, 0]}]},
    }


def test_a_flickering_lamp_lights_a_static_scene_at_100_hz() -> None:
    """Rendered frames scale with the lamp's level (one emitter, the same samples every frame),
    so frame(t) / frame(0) is w(t) / w(0); the static scene's ON events come at 100 Hz."""
    settings = lamp_settings(
        {"frequency_hz": 100, "depth": 0.3}, {"duration_s": 0.05, "rate_hz": 2000}
    )
    simulation = pecs.Simulation(settings, scene_dict=LAMP_SCENE)
    frames = {frame.t_us: frame.photocurrent_pa.astype(np.float64) for frame in simulation.frames()}
    assert sorted(frames)[:3] == [0, 500, 1000] and len(frames) == 101
    board = frames[0] > 0
    assert np.allclose(frames[2500][board] / frames[0][board], 1.0 / 0.7, rtol=1e-5)
    assert np.allclose(frames[5000][board] / frames[0][board], 1.3 / 0.7, rtol=1e-5)
    # The lamp's mean is what [light] asked: the level at a quarter period is the steady one.
    steady = pecs.Simulation(
        {**settings, "light": {k: v for k, v in settings["light"].items() if k != "flicker"}},
        scene_dict=LAMP_SCENE,
    )
    first = next(iter(steady.frames())).photocurrent_pa.astype(np.float64)
    assert np.allclose(frames[2500][board], first[board], rtol=1e-5)
    events = pa_table(simulation)
    assert events.num_rows > 1000
    on = events.column("p").to_numpy() == 1
    assert strongest_hz(events.column("t").to_numpy()[on], 50_000) == pytest.approx(100, abs=20)
    flicker = simulation.metadata()["pecs.render"]
    assert '"flicker": {"lamp": {"frequency_hz": 100.0, "depth": 0.3' in flicker


def pa_table(simulation: pecs.Simulation):  # noqa: ANN201 (a pyarrow Table)
    import pyarrow as pa

    return pa.Table.from_batches(list(simulation.event_batches()))


def test_adaptive_steps_sample_the_flicker() -> None:
    """A static scene would step at the minimum rate (10 Hz); under a 100 Hz lamp every step is
    at most 1 / (20 x 100 Hz) = 500 us."""
    stepping = TimeStepping(0.1, None, 10.0, 100_000.0)
    assert AdaptiveStepper(stepping, 0.2).next_step_us(0.0, 50_000) == 100_000
    stepper = AdaptiveStepper(stepping, 0.2, periodic_hz=100.0)
    assert stepper.max_step_us == 500
    assert stepper.next_step_us(0.0, 500) == 500
    settings = lamp_settings(
        {"frequency_hz": 120, "lamp": "fluorescent_magnetic"},
        {"duration_s": 0.02, "adaptive": True, "min_rate_hz": 10, "max_rate_hz": 100_000},
    )
    times = [frame.t_us for frame in pecs.Simulation(settings, scene_dict=LAMP_SCENE).frames()]
    assert times[-1] == 20_000
    assert max(np.diff(times)) <= math.floor(1e6 / (20 * 120))  # 416 us


def test_scene_rates_that_cannot_follow_the_flicker_are_refused() -> None:
    settings = lamp_settings(
        {"frequency_hz": 100, "depth": 0.3}, {"duration_s": 0.05, "rate_hz": 1000}
    )
    with pytest.raises(
        SettingError, match=r"time\.rate_hz: 1000 frames a second cannot follow"
    ) as error:
        pecs.Simulation(settings, scene_dict=LAMP_SCENE)
    assert "at least 2000 Hz" in str(error.value) and "\n" not in str(error.value)
    fine = lamp_settings({"frequency_hz": 100, "depth": 0.3}, {"duration_s": 0.05, "rate_hz": 2000})
    with pytest.raises(SettingError, match=r"^rate_hz: 500 frames a second"):
        pecs.Simulation(fine, scene_dict=LAMP_SCENE, rate_hz=500)
    adaptive = lamp_settings(
        {"frequency_hz": 100, "depth": 0.3},
        {"duration_s": 0.05, "adaptive": True, "min_rate_hz": 10, "max_rate_hz": 1000},
    )
    with pytest.raises(SettingError, match=r"time\.max_rate_hz: 1000 frames a second"):
        pecs.Simulation(adaptive, scene_dict=LAMP_SCENE)


@pytest.mark.parametrize(
    ("flicker", "message"),
    [
        ({"frequency_hz": -100, "depth": 0.3}, "light.flicker.frequency_hz: must be a positive"),
        ({"frequency_hz": 100, "depth": 1.2}, "light.flicker.depth: must be from 0"),
        ({"depth": 0.3}, "light.flicker.frequency_hz: missing required key"),
        ({"frequency_hz": 100}, "light.flicker.depth: missing required key"),
        ({"frequency_hz": 100, "lamp": "candle"}, "light.flicker.lamp: unknown lamp 'candle'"),
        ({"frequency_hz": 100, "lamp": "led_poor", "depth": 1}, "give lamp or depth, not both"),
        ({"frequency_hz": 100, "depth": 0.3, "waveform": "square"}, "light.flicker.waveform"),
        ({"frequency_hz": 100, "depth": 0.3, "hz": 1}, "light.flicker.hz: unknown key"),
    ],
)
def test_scene_files_refuse_bad_flicker(flicker: dict, message: str) -> None:
    settings = lamp_settings(flicker, {"duration_s": 0.05, "rate_hz": 2000})
    with pytest.raises(ValueError, match=re.escape(message)):
        load_scene(settings, LAMP_SCENE)


def test_lights_entries_take_a_flicker_of_their_own() -> None:
    settings = lamp_settings(
        {"frequency_hz": 100, "depth": 0.3}, {"duration_s": 0.05, "rate_hz": 2400}
    )
    settings["lights"] = [
        {"id": "sky", "scale": 1.0, "flicker": {"frequency_hz": 120, "lamp": "led_poor"}}
    ]
    spec = load_scene(settings, LAMP_SCENE)
    assert spec.lights[0].flicker == Flicker(120.0, 1.0, "rectified")
    assert spec.light is not None and spec.light.flicker == Flicker(100.0, 0.3)


def test_a_tabulated_lamp_flickering_fully_renders_at_its_dark_moment(tmp_path: Path) -> None:
    # depth 1 takes the lamp to zero at t = 0; Mitsuba refuses a tabulated spectrum scaled to 0
    # ("IrregularContinuousDistribution: no probability mass found"), so the frame there failed.
    (tmp_path / "scene.xml").write_text(
        '<scene version="3.0.0"><sensor type="perspective"><transform name="to_world">'
        '<lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>'
        '<shape type="rectangle" id="lamp"><emitter type="area" id="e">'
        '<spectrum name="radiance" value="540:0, 545:1, 555:1, 560:0"/></emitter></shape></scene>'
    )
    (tmp_path / "scene.toml").write_text(
        '[scene]\nmitsuba = "scene.xml"\n[time]\nduration_s = 0.01\nrate_hz = 2000\n'
        '[sensor]\npreset = "ideal"\noverrides = { width = 8, height = 6 }\n'
        '[optics]\nmodel = "pinhole"\nefl_mm = 50.0\nf_number = 2.0\n'
        "[render]\nspp = 1\nmax_depth = 1\n"
        '[[lights]]\nid = "lamp"\nscale = 1.0\n'
        'flicker = { frequency_hz = 100, depth = 1.0, waveform = "sine" }\n'
    )
    renderer = pecs.Simulation(tmp_path / "scene.toml").renderer
    dark, full = renderer.render(0.0), renderer.render(0.005)
    assert full.max() > 0
    # Held at 1e-9 of the mean at the trough: the full frame is 2x the mean.
    assert dark.max() <= 1e-8 * full.max()


def test_anti_flicker_in_band_stop_removes_nine_tenths_of_a_lamps_100_hz_events() -> None:
    # Issue 36's target, end to end: a static scene under a lamp at 100 Hz with 30 % modulation,
    # through the imx636 (readout and rate controller included), then the chip's anti-flicker
    # filter in band-stop over 50-520 Hz. AFK needs about 3.5 periods a 4 x 4 region to call it
    # flickering (its hysteresis), so half a second (50 periods) leaves it the rest.
    from pecs.filters import FilterSettings

    config = pecs.SensorConfig.preset("imx636", width=32, height=32, seed=4)
    frames = np.full((51, 32, 32), 0.5, np.float32)
    times = np.arange(51, dtype=np.int64) * 10_000  # footage frames 10 ms apart, over 0.5 s
    flicker = Flicker(100.0, 0.3)
    lit = pecs.frames_to_events(frames, times, config, flicker=flicker)
    kept = pecs.frames_to_events(
        frames, times, config, flicker=flicker, filters=FilterSettings(afk_band_hz=(50, 520))
    )
    assert lit.num_rows > 20 * 32 * 32  # the flicker's events: several a pixel a period
    assert kept.num_rows <= 0.1 * lit.num_rows
    # An out-of-band setting removes none of them: it is the 100 Hz that AFK takes out.
    above = pecs.frames_to_events(
        frames, times, config, flicker=flicker, filters=FilterSettings(afk_band_hz=(300, 520))
    )
    assert above.num_rows >= 0.95 * lit.num_rows
