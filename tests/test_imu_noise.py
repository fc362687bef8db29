"""A real IMU (pecs.ground_truth.imu_noise) against numbers worked out here: the Allan deviation
of a static IMU (written from its definition below, not pecs's), the lever arm's centripetal
and tangential acceleration, the clock offset, the seed, and the plumbing to the run folder."""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from cli_run import run_cli
from pecs.ground_truth.imu import STANDARD_GRAVITY_M_S2, imu_table, imu_times_us
from pecs.ground_truth.imu_noise import IMU_MODELS, MEASURED_COLUMNS, ImuModel
from pecs.render.limits import SettingError
from pecs.render.scene_file import load_scene
from scipy.spatial.transform import Rotation

G = STANDARD_GRAVITY_M_S2
STATIC_ACCEL = np.array([0.0, G, 0.0])  # a camera at rest, +y up: reads +g along y


def overlapping_allan_variance(rates: np.ndarray, rate_hz: float, tau_s: float) -> np.ndarray:
    """Overlapping Allan variance of each column of rate samples (n x axes), from its
    definition on the integrated signal x (IEEE Std 952; Riley, NIST SP 1065):
    sigma^2(tau) = sum_i (x[i + 2m] - 2 x[i + m] + x[i])^2 / (2 tau^2 (n + 1 - 2m)), m = tau r."""
    m = round(tau_s * rate_hz)
    x = np.vstack([np.zeros((1, rates.shape[1])), np.cumsum(rates, axis=0)]) / rate_hz
    second = x[2 * m :] - 2.0 * x[m:-m] + x[: -2 * m]
    return (second**2).sum(axis=0) / (2.0 * (m / rate_hz) ** 2 * second.shape[0])


def static_readings(model: ImuModel, duration_s: float, rate_hz: float) -> tuple[np.ndarray, ...]:
    """(gyro, accel) a static IMU of `model` reads, n x 3 each (the noise model alone: the ideal
    readings of a camera at rest are exact constants)."""
    t_us = _times_us(duration_s, rate_hz)
    gyro = np.zeros((t_us.size, 3))
    accel = np.broadcast_to(STATIC_ACCEL, (t_us.size, 3))
    readings = model.measure(t_us, gyro, accel, None, rate_hz)
    return readings.gyro_rad_s, readings.accel_m_s2


@functools.cache
def _times_us(duration_s: float, rate_hz: float) -> np.ndarray:
    return imu_times_us(duration_s, rate_hz)


# Allan deviation of a static IMU over 10 minutes. N is read on the -1/2 slope:
# sigma(tau) sqrt(tau) at tau = 0.1 s, the value of that line at tau = 1 s (at 0.1 s the random
# walk adds K^2 tau^2 / (3 N^2) < 0.1 % to the variance for both presets, where at 1 s it adds
# 8 % for the BMI160's accelerometer). K is read on the +1/2 slope: sigma(tau) sqrt(3 / tau) at
# tau = 100 s, where the white noise adds at most 1.9 % to the variance (MPU-6500 gyroscope).
# A 10-minute run holds only 6 independent 100 s spans: one axis's sigma(100 s) scatters by
# 33-36 % (measured over 480 axes). So the variances of 160 runs (seeds 0-159) x 3 axes = 480
# axes are pooled: the estimate of K then scatters by 1.8 % (bootstrap over the axes), a fifth
# of the 10 % allowed; N's by 0.04 %. 100 Hz: the densities do not depend on the rate (next
# test), and half of 200 Hz's samples halve the time.
ALLAN_RATE_HZ = 100.0
ALLAN_DURATION_S = 600.0
ALLAN_RUNS = 160
TAU_WHITE_S = 0.1
TAU_WALK_S = 100.0


@pytest.mark.parametrize("name", list(IMU_MODELS))
def test_allan_deviation_of_a_static_imu_matches_the_preset(name: str) -> None:
    preset = IMU_MODELS[name]
    avar = {(sensor, tau): 0.0 for sensor in ("gyro", "accel") for tau in (TAU_WHITE_S, TAU_WALK_S)}
    for seed in range(ALLAN_RUNS):
        model = ImuModel.preset(name, seed=seed)
        readings = dict(
            zip(("gyro", "accel"), static_readings(model, ALLAN_DURATION_S, ALLAN_RATE_HZ))
        )
        for (sensor, tau), total in avar.items():
            variances = overlapping_allan_variance(readings[sensor], ALLAN_RATE_HZ, tau)
            avar[sensor, tau] = total + variances.sum() / (3 * ALLAN_RUNS)
    expected = {
        ("gyro", "white"): preset.gyro_noise_density_rad_s_sqrt_hz,
        ("accel", "white"): preset.accel_noise_density_m_s2_sqrt_hz,
        ("gyro", "walk"): preset.gyro_random_walk_rad_s2_sqrt_hz,
        ("accel", "walk"): preset.accel_random_walk_m_s3_sqrt_hz,
    }
    measured = {}
    for sensor in ("gyro", "accel"):
        measured[sensor, "white"] = math.sqrt(avar[sensor, TAU_WHITE_S] * TAU_WHITE_S)
        measured[sensor, "walk"] = math.sqrt(avar[sensor, TAU_WALK_S] * 3.0 / TAU_WALK_S)
    ratios = {key: measured[key] / expected[key] for key in expected}
    print(name, {f"{s} {k}": round(r, 4) for (s, k), r in ratios.items()})
    for key, ratio in ratios.items():
        assert abs(ratio - 1.0) < 0.10, (name, key, measured[key], expected[key])


def test_white_noise_density_does_not_depend_on_the_rate() -> None:
    """sigma_d = N sqrt(rate): the density read back is N at 50 Hz and at 1 kHz alike."""
    density = 2e-3
    model = ImuModel(gyro_noise_density_rad_s_sqrt_hz=density, seed=5)
    for rate_hz in (50.0, 1000.0):
        gyro, _ = static_readings(model, 120.0, rate_hz)
        assert gyro.std() == pytest.approx(density * math.sqrt(rate_hz), rel=0.02)
        variance = overlapping_allan_variance(gyro, rate_hz, 0.2).mean()
        assert math.sqrt(variance * 0.2) == pytest.approx(density, rel=0.03)


def test_bias_random_walk_spreads_as_k_sqrt_t() -> None:
    """b(T) - b(0) of a random walk of density K has standard deviation K sqrt(T), at any rate
    (dt steps of K sqrt(dt)): checked over 400 devices."""
    density, duration_s = 1e-3, 4.0
    ends = []
    for seed in range(400):
        model = ImuModel(gyro_random_walk_rad_s2_sqrt_hz=density, seed=seed)
        t_us = imu_times_us(duration_s, 37.0)  # uneven microsecond steps
        readings = model.measure(
            t_us, np.zeros((t_us.size, 3)), np.zeros((t_us.size, 3)), None, 37.0
        )
        ends.append(readings.gyro_bias_rad_s[-1] - readings.gyro_bias_rad_s[0])
    assert np.std(ends) == pytest.approx(density * math.sqrt(duration_s), rel=0.06)


def test_turn_on_bias_is_drawn_once_per_device() -> None:
    model = ImuModel(accel_turn_on_bias_sigma_m_s2=0.2, gyro_turn_on_bias_sigma_rad_s=0.01)
    starts = []
    for seed in range(600):
        gyro, accel = static_readings(model.with_seed(seed), 0.05, 100.0)
        assert np.ptp(accel, axis=0) == pytest.approx(0.0, abs=1e-12)  # constant in a run
        starts.append(np.concatenate([gyro[0], accel[0] - STATIC_ACCEL]))
    spread = np.std(starts, axis=0)
    np.testing.assert_allclose(spread, [0.01] * 3 + [0.2] * 3, rtol=0.1)


class SpinUp:
    """A camera at the origin turning about its optical axis (+z) from rest: angle a t^2 / 2,
    rate a t, angular acceleration a."""

    def __init__(self, rate_0_rad_s: float, accel_rad_s2: float) -> None:
        self.rate_0, self.accel = rate_0_rad_s, accel_rad_s2

    def pose(self, t_s: float) -> np.ndarray:
        pose = np.eye(4)
        angle = self.rate_0 * t_s + 0.5 * self.accel * t_s**2
        pose[:3, :3] = Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()
        return pose


def columns(table: pa.Table, prefix: str) -> np.ndarray:
    unit = "rad_s" if prefix.startswith("gyro") else "m_s2"
    return np.column_stack([table.column(f"{prefix}_{a}_{unit}").to_numpy() for a in "xyz"])


def test_lever_arm_reads_the_centripetal_acceleration_of_a_spinning_camera() -> None:
    # An IMU 10 cm to the camera's +x of a camera spinning at w = 5 rad/s about +z:
    # omega x (omega x r) = (0, 0, 5) x ((0, 0, 5) x (0.1, 0, 0)) = (0, 0, 5) x (0, 0.5, 0)
    # = (-2.5, 0, 0) m/s^2: w^2 |r| = 2.5 towards the axis. No angular acceleration.
    model = ImuModel(lever_arm_m=(0.1, 0.0, 0.0), seed=0)
    table = imu_table(SpinUp(5.0, 0.0).pose, 0.5, 100.0, model=model)
    extra = columns(table, "accel_meas") - columns(table, "accel")
    np.testing.assert_allclose(extra, [[-2.5, 0.0, 0.0]] * table.num_rows, atol=1e-6)
    np.testing.assert_allclose(columns(table, "gyro_meas"), columns(table, "gyro"), atol=0)


def test_lever_arm_reads_the_tangential_acceleration_of_a_spin_up() -> None:
    # Rate a t, a = 4 rad/s^2; IMU at r = (0, 0.05, 0.02): alpha x r = (0, 0, 4) x (0, 0.05, 0.02)
    # = (-0.2, 0, 0); omega x (omega x r) = -(a t)^2 (0, 0.05, 0) (the part of r across the axis).
    a, r = 4.0, (0.0, 0.05, 0.02)
    model = ImuModel(lever_arm_m=r, seed=0)
    duration_s = 0.5
    table = imu_table(SpinUp(0.0, a).pose, duration_s, 100.0, model=model)
    # The ideal IMU's samples within 0.1 ms of an end are taken 0.1 ms inside (its stencil).
    t_s = np.clip(table.column("t_us").to_numpy() * 1e-6, 1e-4, duration_s - 1e-4)
    expected = np.column_stack([np.full_like(t_s, -0.2), -((a * t_s) ** 2) * 0.05, 0.0 * t_s])
    extra = columns(table, "accel_meas") - columns(table, "accel")
    np.testing.assert_allclose(extra, expected, atol=1e-5)


def test_time_offset_shifts_the_signal() -> None:
    # Rate a t: an IMU whose clock runs 5 ms ahead (t_imu = t_camera + 5 ms) stamps the
    # motion of t - 5 ms at t, so it reads a (t - 0.005); the ideal columns read a t.
    a, offset_s, duration_s = 4.0, 0.005, 0.5
    for offset in (offset_s, -offset_s):
        model = ImuModel(time_offset_s=offset, seed=0)
        table = imu_table(SpinUp(0.0, a).pose, duration_s, 200.0, model=model)
        t_s = table.column("t_us").to_numpy() * 1e-6
        inside = (t_s - offset > 1e-3) & (t_s - offset < duration_s - 1e-3)
        assert inside.sum() > 90
        gyro_z = table.column("gyro_meas_z_rad_s").to_numpy()
        np.testing.assert_allclose(gyro_z[inside], a * (t_s[inside] - offset), atol=1e-7)
        ideal_z = table.column("gyro_z_rad_s").to_numpy()
        ideal_inside = (t_s > 1e-3) & (t_s < duration_s - 1e-3)
        np.testing.assert_allclose(ideal_z[ideal_inside], a * t_s[ideal_inside], atol=1e-7)


def test_rotation_turns_the_readings_into_the_imus_axes() -> None:
    # x_imu = R x_camera with R a quarter turn about x: the camera's +z (the spin) is the
    # IMU's -y, and the camera's +y (gravity's reading at rest) the IMU's +z.
    quarter = Rotation.from_rotvec([math.pi / 2, 0.0, 0.0]).as_matrix()
    model = ImuModel(rotation=quarter, seed=0)
    table = imu_table(SpinUp(3.0, 0.0).pose, 0.2, 100.0, model=model)
    np.testing.assert_allclose(columns(table, "gyro_meas"), [[0.0, -3.0, 0.0]] * 21, atol=1e-9)
    # The first sample is taken 0.1 ms in (0.3 mrad turned): gravity reads (g sin, g cos, 0).
    first = [G * math.sin(3e-4), 0.0, G * math.cos(3e-4)]
    np.testing.assert_allclose(columns(table, "accel_meas")[0], first, atol=1e-6)
    np.testing.assert_allclose(columns(table, "accel_meas"), columns(table, "accel") @ quarter.T)


def test_scale_and_misalignment_spread_as_asked() -> None:
    # Spin about +z at 2 rad/s: C (0, 0, 2) = 2 (M_xz, M_yz, 1 + s_z). Over 500 devices the
    # z reading's relative error spreads by the scale sigma, x and y by the misalignment sigma.
    readings = []
    for seed in range(500):
        model = ImuModel(gyro_scale_sigma=0.03, gyro_misalignment_sigma_rad=0.02, seed=seed)
        t_us = np.array([0, 10_000])
        gyro = np.array([[0.0, 0.0, 2.0]] * 2)
        readings.append(model.measure(t_us, gyro, np.zeros((2, 3)), None, 100.0).gyro_rad_s[0])
    relative = np.array(readings) / 2.0 - [0.0, 0.0, 1.0]
    np.testing.assert_allclose(relative.std(axis=0), [0.02, 0.02, 0.03], rtol=0.12)


def test_same_seed_same_noise_and_the_ideal_columns_stay() -> None:
    def pose(t_s: float) -> np.ndarray:  # a slow turn and drift
        matrix = np.eye(4)
        matrix[:3, :3] = Rotation.from_rotvec([0.1 * t_s, 0.2 * t_s**2, 0.0]).as_matrix()
        matrix[:3, 3] = [0.3 * t_s**2, 0.0, 0.1 * t_s]
        return matrix

    ideal = imu_table(pose, 0.3, 200.0)
    first, again, other = (
        imu_table(pose, 0.3, 200.0, model=ImuModel.preset("bmi160", seed=seed))
        for seed in (7, 7, 8)
    )
    assert first.equals(again)
    assert not first.column("gyro_meas_x_rad_s").equals(other.column("gyro_meas_x_rad_s"))
    assert first.select(ideal.column_names).equals(ideal)  # bit for bit
    assert first.column_names == ideal.column_names + list(MEASURED_COLUMNS)
    # One stream per component: no random walk leaves the white noise's draws as they were.
    calm = imu_table(
        pose, 0.3, 200.0, model=ImuModel.preset("bmi160", seed=7, gyro_random_walk_rad_s2_sqrt_hz=0)
    )
    white = columns(first, "gyro_meas") - columns(first, "gyro_bias")
    np.testing.assert_allclose(columns(calm, "gyro_meas") - columns(calm, "gyro_bias"), white)


def test_presets_carry_their_datasheet_densities() -> None:
    """The datasheets' figures in SI units, converted here by hand."""
    mpu, bmi = IMU_MODELS["mpu6500"], IMU_MODELS["bmi160"]
    assert mpu.gyro_noise_density_rad_s_sqrt_hz == pytest.approx(0.01 * math.pi / 180)
    assert mpu.accel_noise_density_m_s2_sqrt_hz == pytest.approx(300e-6 * 9.80665)
    assert bmi.gyro_noise_density_rad_s_sqrt_hz == pytest.approx(1.2217e-4, rel=1e-4)
    assert bmi.accel_noise_density_m_s2_sqrt_hz == pytest.approx(1.7652e-3, rel=1e-4)


def test_scene_file_imu_table_and_its_errors(tmp_path: Path) -> None:
    scene = tmp_path / "scene.toml"
    (tmp_path / "scene.xml").write_text('<scene version="3.0.0"/>')
    base = """[scene]\nmitsuba = "scene.xml"\n[time]\nduration_s = 0.1\nrate_hz = 100\n
[sensor]\npreset = "davis346"\n[optics]\nmodel = "pinhole"\nfov_deg = 40\n"""
    scene.write_text(
        base + '[imu]\nmodel = "mpu6500"\nseed = 4\nlever_arm_m = [0.01, 0, 0.02]\n'
        "gyro_noise_density_rad_s_sqrt_hz = 1e-3\n"
    )
    imu = load_scene(scene).imu
    assert imu is not None and imu.name == "mpu6500" and imu.seed == 4
    assert imu.lever_arm_m == (0.01, 0.0, 0.02)
    assert imu.gyro_noise_density_rad_s_sqrt_hz == 1e-3
    assert (
        imu.accel_noise_density_m_s2_sqrt_hz
        == IMU_MODELS["mpu6500"].accel_noise_density_m_s2_sqrt_hz
    )
    for table, message in [
        (
            'model = "mpu9999"',
            r"scene.toml: imu.model: unknown IMU model 'mpu9999'; known: mpu6500",
        ),
        ("gyro_noise = 1", r"scene.toml: imu.gyro_noise: unknown key \(known: model, gyro_noise_"),
        ("accel_scale_sigma = -0.1", r"imu.accel_scale_sigma: must be a finite number >= 0"),
        ("rotation = [[1, 0, 0], [0, 1, 0], [0, 0, -1]]", r"imu.rotation: not a rotation"),
        ("time_offset_s = 5", r"imu.time_offset_s: must be within \+-1 s"),
    ]:
        scene.write_text(base + "[imu]\n" + table + "\n")
        with pytest.raises(ValueError, match=message):
            load_scene(scene)


def test_simulation_takes_the_model_and_seeds_it() -> None:
    from pecs.render import Simulation

    simulation = Simulation("room", ground_truth="imu", imu_model="bmi160", seed=11)
    assert simulation.imu_model == ImuModel.preset("bmi160", seed=11)
    own = Simulation("room", ground_truth="imu", imu_model={"model": "mpu6500", "seed": 2})
    assert own.imu_model is not None and own.imu_model.seed == 2
    assert Simulation("room", ground_truth="imu").imu_model is None
    with pytest.raises(SettingError, match="imu_model: a real IMU needs the IMU ground truth"):
        Simulation("room", ground_truth="depth", imu_model="bmi160")
    with pytest.raises(SettingError, match="imu_model: unknown IMU model 'adis'"):
        Simulation("room", ground_truth="imu", imu_model="adis")


def test_cli_writes_the_real_imu_next_to_the_ideal_one(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    import pecs

    out = tmp_path / "run"
    small = ["--duration", "0.004", "--spp", "1", "--rate", "1000", "--quiet"]
    film = ["--set", "width=16", "--set", "height=12", "--imu-rate", "5000"]
    args = ["simulate", "room", "-o", str(out), *small, *film, "--ground-truth", "imu"]
    code, _, err = run_cli(capsys, *args, "--imu-model", "mpu6500", "--seed", "3")
    assert code == 0, err
    truth = pecs.read_ground_truth(out)
    assert truth.imu.column_names[7:] == list(MEASURED_COLUMNS)
    assert truth.imu_model is not None and truth.imu_model["name"] == "mpu6500"
    assert truth.imu_model["seed"] == 3
    # What a DAVIS346's MPU-6500 reads differs from the ideal by its noise and bias only.
    noise = (
        columns(truth.imu, "gyro_meas")
        - columns(truth.imu, "gyro")
        - columns(truth.imu, "gyro_bias")
    )
    expected_sigma = IMU_MODELS["mpu6500"].gyro_noise_density_rad_s_sqrt_hz * math.sqrt(5000.0)
    assert 0.3 * expected_sigma < noise.std() < 3.0 * expected_sigma
    code, _, err = run_cli(
        capsys, "simulate", "room", "-o", str(tmp_path / "no"), "--imu-model", "bmi160"
    )
    assert code == 2
    assert err.strip().splitlines()[-1] == (
        "pecs simulate: error: --imu-model bmi160: a real IMU needs the IMU ground truth "
        "(kind imu, or all)"
    )


def test_dataset_spec_names_the_imu_and_each_sequence_seeds_it() -> None:
    from pecs.dataset.sequence import build_simulation
    from pecs.dataset.spec import parse_spec

    text = """[defaults]\nground_truth = "imu"\nimu_model = "mpu6500"\n
[[sequences]]\nscene = "room"\ncount = 2\n"""
    tasks = parse_spec(text).sequences
    models = [build_simulation(task).imu_model for task in tasks]
    assert [m.seed if m else None for m in models] == [task.seed for task in tasks]
    assert models[0] == ImuModel.preset("mpu6500", seed=tasks[0].seed)
    assert tasks[0].seed != tasks[1].seed  # each sequence's IMU has its own noise
    with pytest.raises(ValueError, match=r"defaults.imu_model: unknown IMU model 'adis16448'"):
        parse_spec(text.replace("mpu6500", "adis16448"))
