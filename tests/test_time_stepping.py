"""Adaptive time steps: the motion statistic on synthetic frames whose motion and noise are known,
and the stepping of a rendered edge whose image speed follows from the camera geometry.

Expected values are derived here: the shift of a sampled grating, the statistics of Gaussian
noise, the pinhole projection f v / Z.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pecs.render.scene_file import TimeStepping
from pecs.render.time_stepping import (
    AdaptiveStepper,
    common_change,
    exact_step_us,
    max_log_change,
    motion_px,
)

HEIGHT, WIDTH = 128, 192
PERIOD_PX = 32.0
THETA = 0.2
STEPPING = TimeStepping(0.1, None, min_rate_hz=100.0, max_rate_hz=10_000.0, threshold_fraction=0.5)


def grating(shift_px: float, amplitude: float = 0.5, angle_deg: float = 0.0) -> np.ndarray:
    """log I = amplitude sin(2 pi x' / P) at pixel centres, x' across the stripes, moved by shift."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH] + 0.5
    a = math.radians(angle_deg)
    across = x * math.cos(a) + y * math.sin(a) - shift_px
    return amplitude * np.sin(2 * math.pi * across / PERIOD_PX)


def grating_motion(shift_px: float) -> float:
    """sum g dL / sum g^2 for a sampled sinusoid with central differences: with k = 2 pi / P,
    g = A sin(k) cos(kx) and dL = A (sin(k(x - d)) - sin(kx)), so over whole periods
    sum g dL / sum g^2 = sin(k d) / sin(k)."""
    k = 2 * math.pi / PERIOD_PX
    return math.sin(k * shift_px) / math.sin(k)


@pytest.mark.parametrize("shift_px", [0.05, 0.25, 0.8])
@pytest.mark.parametrize("angle_deg", [0.0, 90.0])
def test_a_shifted_grating_moves_by_its_shift(shift_px: float, angle_deg: float) -> None:
    measured = motion_px(grating(0.0, angle_deg=angle_deg), grating(shift_px, angle_deg=angle_deg))
    # the frame's border blocks use one-sided differences: allow 2 %
    assert measured == pytest.approx(grating_motion(shift_px), rel=0.02)


def test_motion_does_not_depend_on_the_contrast_or_a_common_change() -> None:
    low = motion_px(grating(0.0, amplitude=0.05), grating(0.3, amplitude=0.05))
    high = motion_px(grating(0.0, amplitude=2.0), grating(0.3, amplitude=2.0) + 0.7)
    assert low == pytest.approx(grating_motion(0.3), rel=0.02)
    assert high == pytest.approx(grating_motion(0.3), rel=0.02)


def test_noise_alone_does_not_push_to_the_max_rate() -> None:
    # Independent noise of sigma 0.05 in log: ESIM's largest |Delta L| over 24,576 pixels is
    # about 4.4 sqrt(2) sigma = 0.31, three times the limit 0.5 theta = 0.1, so it pins the step to
    # the max rate. In the motion statistic b = sum g Delta L is a sum of 256 products of
    # uncorrelated terms, |b|^2 exponential with mean s^2 trace(M) (s = sqrt(2) sigma): removing
    # 7 times that mean leaves a block moving with probability e^-7 (of 96 blocks, the 99th
    # percentile needs two), and the step doubles up to the longest (1 / min rate). On a static
    # texture the same.
    stepper = AdaptiveStepper(STEPPING, THETA)
    texture = grating(0.0, angle_deg=30.0)
    for seed, background in ((1, 0.0), (2, texture)):
        first, second = np.random.default_rng(seed).normal(0, 0.05, (2, HEIGHT, WIDTH))
        first, second = first + background, second + background
        esim = max_log_change(first, second)
        assert esim > 0.25
        assert stepper.next_step_us(esim, stepper.min_step_us) == stepper.min_step_us
        measured = stepper.change(first, second)
        assert measured <= 0.4 * stepper.limit  # SAFETY 0.8 / 0.4 = GROWTH: each step doubles
        step_us = stepper.min_step_us
        for _ in range(12):
            assert stepper.accept(measured, step_us)
            step_us = stepper.next_step_us(measured, step_us)
        assert step_us == stepper.max_step_us


def test_a_known_motion_under_noise_sets_the_step() -> None:
    # 0.25 px per 1000 us under sigma 0.01 noise. Per block the noise moves the estimate by
    # N(0, s / sqrt(lambda)), s = sqrt(2) sigma (noise of Delta L), lambda = sum g^2 =
    # 256 A^2 sin^2(k) / 2; the 99th percentile of 96 blocks sits 2.33 of those above the motion.
    # The step is then SAFETY * fraction px / (motion per ms).
    rng = np.random.default_rng(2)
    sigma, amplitude, k = 0.01, 0.5, 2 * math.pi / PERIOD_PX
    noise = rng.normal(0, sigma, (2, HEIGHT, WIDTH))
    first, second = grating(0.0) + noise[0], grating(0.25) + noise[1]
    stepper = AdaptiveStepper(STEPPING, THETA)
    block_lambda = 256 * amplitude**2 * math.sin(k) ** 2 / 2
    expected_px = grating_motion(0.25) + 2.33 * math.sqrt(2) * sigma / math.sqrt(block_lambda)
    change = stepper.change(first, second)
    assert change == pytest.approx(THETA * expected_px, rel=0.05)
    expected_us = 0.8 * 0.5 / expected_px * 1000
    assert stepper.next_step_us(change, 1000) == pytest.approx(expected_us, rel=0.05)
    # four times the motion per step does not pass; 1.5 px per shortest step asks for the max rate
    assert not stepper.accept(stepper.change(first, grating(1.0) + noise[1]), 1000)
    fast = stepper.change(first, grating(1.5) + noise[1])
    assert fast == pytest.approx(THETA * grating_motion(1.5), rel=0.05)
    assert stepper.next_step_us(fast, stepper.min_step_us) == stepper.min_step_us


def test_a_small_moving_object_sets_the_step_and_fireflies_do_not() -> None:
    # A grating patch of 64 x 64 pixels (2 x 2 blocks inside it, of 96: more than the 1 % the
    # percentile leaves out) moves 0.4 px on a static grating of the other direction, where 20
    # single pixels jump by 5 log units (fireflies): ESIM's maximum sees 5, the motion 0.4 px.
    static = grating(0.0, angle_deg=90.0)
    first, second = static.copy(), static.copy()
    first[32:96, 64:128] = grating(0.0)[32:96, 64:128]
    second[32:96, 64:128] = grating(0.4)[32:96, 64:128]
    rng = np.random.default_rng(3)
    rows, cols = rng.integers(1, HEIGHT - 1, 40), rng.integers(1, WIDTH - 1, 40)
    outside = (rows < 30) | (rows > 98) | (cols < 62) | (cols > 130)
    second[rows[outside][:20], cols[outside][:20]] += 5.0
    assert max_log_change(first, second) >= 5.0
    assert motion_px(first, second) == pytest.approx(grating_motion(0.4), rel=0.03)
    assert motion_px(first, first + 0.0) == 0.0


def test_a_common_change_counts_as_it_is() -> None:
    first = grating(0.0)
    stepper = AdaptiveStepper(STEPPING, THETA)
    assert common_change(first, first + 0.3) == pytest.approx(0.3)
    assert stepper.change(first, first + 0.3) == pytest.approx(0.3)
    assert stepper.next_step_us(0.3, 1000) == math.floor(0.8 * 0.1 / 0.3 * 1000)


RAMP_XML = """<scene version="3.0.0">
<sensor type="perspective">
  <transform name="to_world"><lookat origin="0, 0, 1" target="0, 0, 0" up="0, 1, 0"/></transform>
</sensor>
<shape type="rectangle" id="board">
  <bsdf type="diffuse">
    <texture type="bitmap" name="reflectance">
      <string name="filename" value="ramp.exr"/>
      <boolean name="raw" value="true"/>
      <string name="wrap_mode" value="clamp"/>
    </texture>
  </bsdf>
</shape>
<emitter type="constant"><spectrum name="radiance" value="400:0.01, 1000:0.01"/></emitter>
</scene>"""


def _write_ramp_scene(folder: Path) -> None:
    """A 2 m board 1 m in front of a pinhole (f = 8 mm, 140 um pixels: f = 57.14 px), its
    reflectance ramping from 0.05 to 0.8 over 10 cm, moving 10 cm in x over 0.05 s (2 m/s)."""
    import mitsuba as mi
    from pecs._mitsuba import mitsuba

    mitsuba()
    u = (np.arange(400) + 0.5) / 400
    ramp = np.clip((u - 0.475) / 0.05, 0, 1) * 0.75 + 0.05
    mi.Bitmap(np.repeat(ramp[None, :, None], 4, axis=0).astype(np.float32)).write(
        str(folder / "ramp.exr")
    )
    (folder / "scene.xml").write_text(RAMP_XML)
    (folder / "scene.toml").write_text(
        '[scene]\nmitsuba = "scene.xml"\n'
        "[time]\nduration_s = 0.05\nadaptive = true\nmin_rate_hz = 100\nmax_rate_hz = 20000\n"
        'threshold_fraction = 0.5\n[sensor]\npreset = "davis346"\n'
        "overrides = { width = 64, height = 48, pixel_pitch_um = 140.0 }\n"
        '[optics]\nmodel = "pinhole"\nefl_mm = 8.0\n[render]\nspp = 4\nmax_depth = 2\n'
        '[[objects]]\nid = "board"\nkeyframes = [{ t_s = 0.0, position = [0, 0, 0] },'
        " { t_s = 0.05, position = [0.1, 0, 0] }]\n"
    )


def test_rendered_steps_keep_the_image_motion_under_the_fraction(tmp_path: Path) -> None:
    # A 2 m board 1 m in front of a pinhole (f = 8 mm, 140 um pixels: f = 57.14 px), its
    # reflectance ramping from 0.05 to 0.8 over 10 cm (an edge 5.7 px wide), moving at 2 m/s:
    # the image moves f v / Z = 114.3 px/s, so fraction 0.5 allows 4.4 ms steps, while ESIM's
    # per-pixel bound (a change of 0.1 at 0.49 log units per pixel) would allow 1.8 ms.
    from pecs.render import Simulation

    _write_ramp_scene(tmp_path)
    frames = list(Simulation(tmp_path / "scene.toml").frames())
    times = np.array([f.t_us for f in frames])
    assert times[0] == 0 and times[-1] == 50_000 and np.all(np.diff(times) > 0)
    speed_px_per_us = 8.0 / 0.140 * 2.0 / 1.0 * 1e-6
    motion = np.diff(times) * speed_px_per_us
    assert np.all(motion <= 0.5 * 1.1)  # every step within the fraction (10 %: the estimate)
    # not needlessly short: after the first steps (from 50 us, doubling), about SAFETY x 0.5 px
    assert np.median(motion[8:-1]) == pytest.approx(0.8 * 0.5, rel=0.15)
    assert len(frames) < 0.05 / 0.0018  # fewer than ESIM's per-pixel bound would take


# -- the exact-motion rule: steps from the image motion the animation gives ----------------


def test_a_point_moving_at_v_px_per_s_gives_steps_of_k_over_v() -> None:
    # 0.5 px at 200 px/s: 2.5 ms; twice as fast, half as long; no motion, no bound
    assert exact_step_us(0.02, 100, 0.5) == pytest.approx(2500.0)
    assert exact_step_us(0.04, 100, 0.5) == pytest.approx(1250.0)
    assert exact_step_us(0.0, 100, 0.5) == math.inf
    stepper = AdaptiveStepper(STEPPING, THETA)  # k = 0.5 px, steps 100 us to 10 ms
    for speed_px_s, expected_us in ((200.0, 2500), (400.0, 1250), (20.0, 10_000), (1e5, 100)):
        assert stepper.exact_step(lambda step_us, v=speed_px_s: v * step_us * 1e-6) == expected_us
    assert stepper.exact_step(lambda step_us: 0.0) == stepper.max_step_us


def test_the_fastest_of_independent_motions_sets_the_exact_step() -> None:
    # Three objects at 50, 300 and 120 px/s: the largest motion is the 300 px/s one's, so
    # 0.5 / 300 s = 1666 us (whole µs, rounded down); a 100 Hz flicker still caps it at 500 us.
    speeds_px_s = (50.0, 300.0, 120.0)

    def largest_px(step_us: int) -> float:
        return max(v * step_us * 1e-6 for v in speeds_px_s)

    assert AdaptiveStepper(STEPPING, THETA).exact_step(largest_px) == 1666
    assert AdaptiveStepper(STEPPING, THETA, periodic_hz=100.0).exact_step(largest_px) == 500


def test_an_exact_motion_that_speeds_up_is_checked_over_the_step() -> None:
    # x(s) = v0 s + a s^2 / 2 with v0 = 100 px/s and a = 1e5 px/s^2: the finest step (100 us)
    # sees 105 px/s, so k / v asks for 4761 us, over which the point moves 0.476 + 1.133 px.
    # The step is searched for; the longest within 0.5 px solves v0 s + a s^2 / 2 = 0.5:
    # s = (-v0 + sqrt(v0^2 + a)) / a = 2.317 ms.
    v0, a = 100.0, 1e5
    stepper = AdaptiveStepper(STEPPING, THETA)

    def moved_px(step_us: int) -> float:
        s = step_us * 1e-6
        return v0 * s + 0.5 * a * s * s

    step_us = stepper.exact_step(moved_px)
    assert moved_px(step_us) <= 0.5
    longest_us = (-v0 + math.sqrt(v0 * v0 + a)) / a * 1e6
    assert 0.95 * longest_us <= step_us <= longest_us


def test_a_common_change_still_shortens_an_exact_step() -> None:
    # light fading by 0.05 in 1 ms: SAFETY 0.8 x limit 0.1 / 0.05 per ms = 1.6 ms, under the
    # exact 2.5 ms; without a common change the exact step stands
    stepper = AdaptiveStepper(STEPPING, THETA)
    assert stepper.exact_next_step_us(0.05, 1000, 2500) == 1600
    assert stepper.exact_next_step_us(0.0, 1000, 2500) == 2500


def test_rendered_exact_steps_move_the_image_by_the_fraction(tmp_path: Path) -> None:
    # The ramp board of the test above at 2 m/s, 1 m away (f = 57.14 px): the image moves
    # f v / Z = 114.29 px/s, so every step is 0.5 / 114.29 s = 4375 us, from the first frame
    # on (the measured rule starts at 50 us and doubles), and none is rendered twice. The motion
    # comes from float32 surface points projected by the camera model (the ground truth's flow,
    # exact to about 1e-3 px): a step may fall short of 4375 us by 0.5 %, never exceed it.
    from pecs.render import Simulation

    _write_ramp_scene(tmp_path)
    simulation = Simulation(tmp_path / "scene.toml")
    renders = 0
    render = simulation.renderer.render

    def counted(t_s: float) -> np.ndarray:
        nonlocal renders
        renders += 1
        return render(t_s)

    simulation.renderer.render = counted  # type: ignore[method-assign]
    times = np.array([f.t_us for f in simulation._adaptive_frames(exact_motion=True)])
    assert times[0] == 0 and times[-1] == 50_000
    steps = np.diff(times)
    assert np.all((steps[:-1] >= 4375 * 0.995) & (steps[:-1] <= 4375))
    assert steps[-1] <= 4375
    assert renders == len(times) == 13  # 11 steps of 4375 us and the last 1875 us, plus t = 0


def test_a_scene_file_asks_for_exact_motion_steps_and_a_bad_motion_is_refused(
    tmp_path: Path,
) -> None:
    # `[time] motion = "exact"`: Simulation.frames() takes the exact rule's steps, the same
    # 4375 us (0.5 / 114.29 px/s) the test above works out by hand for this board.
    from pecs.render import Simulation

    _write_ramp_scene(tmp_path)
    text = (tmp_path / "scene.toml").read_text()
    (tmp_path / "scene.toml").write_text(
        text.replace("threshold_fraction = 0.5\n", 'threshold_fraction = 0.5\nmotion = "exact"\n')
    )
    simulation = Simulation(tmp_path / "scene.toml")
    assert simulation.spec.time.motion == "exact"
    steps = np.diff([f.t_us for f in simulation.frames()])
    assert np.all((steps[:-1] >= 4375 * 0.995) & (steps[:-1] <= 4375))
    (tmp_path / "scene.toml").write_text(
        text.replace("threshold_fraction = 0.5\n", 'motion = "guess"\n')
    )
    with pytest.raises(ValueError, match=r"time\.motion.*'guess'.*measured, exact"):
        Simulation(tmp_path / "scene.toml")
