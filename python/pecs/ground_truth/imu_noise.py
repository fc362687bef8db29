"""A real IMU on the camera: what a MEMS IMU of a named datasheet reads where the ideal IMU
(pecs.ground_truth.imu) reads exact angular velocity and specific force.

Per axis of each sensor (gyroscope in rad/s, accelerometer in m/s^2), sample k stamped t_k (the
events' clock), samples dt_k apart at the nominal rate r = imu_rate_hz:

    y_k = C R u(t_k - delta) + b_k + n_k

- u: the ideal reading in the camera body frame, at t_k - delta. `time_offset_s` delta is
  t_imu - t_camera for one instant (Kalibr's timeshift_cam_imu): a sample stamped t_k saw the
  motion of t_k - delta. The accelerometer sits at the lever arm r (the IMU's origin in the
  camera frame, metres), so it reads f + alpha x r + omega x (omega x r): the specific force at
  the camera origin plus the tangential and centripetal acceleration of a point of the rigid
  body (omega the body rate, alpha = d omega / dt, both in the body frame).
- R: camera-to-IMU rotation (x_imu = R x_camera); the readings are in the IMU's axes.
- C = I + diag(s) + M, drawn once per device: scale-factor errors s_i ~ N(0, sigma_s^2) and axis
  misalignment (cross-axis sensitivity) M_ij ~ N(0, sigma_m^2) for i != j.
- b_k: bias = turn-on bias b_0 ~ N(0, sigma_b0^2), drawn once, plus a random walk (rate random
  walk) of continuous density K, dB = K dW. Its exact discretisation over a step dt_k:
  b_k = b_{k-1} + K sqrt(dt_k) w_k.
- n_k: white noise of continuous density N. A sample that averages it over the band up to the
  Nyquist frequency r / 2 (an ideal anti-alias filter) has variance N^2 r: n_k = N sqrt(r) v_k.
  w_k, v_k are standard normal.

On the Allan deviation of a static IMU the white noise is sigma(tau) = N / sqrt(tau) (slope -1/2,
N read at tau = 1 s) and the random walk sigma(tau) = K sqrt(tau / 3) (slope +1/2); the turn-on
bias is a constant and does not show. tests/test_imu_noise.py checks both against the presets.

Every draw derives from `seed`, one independent stream per component (overriding one density
leaves the others' draws as they were): the same seed gives the same readings.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Standard gravity (CGPM 1901), m/s^2: datasheets give accelerations in g.
_G_M_S2 = 9.80665
_DEG = math.pi / 180.0
_MICRO_G = 1e-6 * _G_M_S2
_MILLI_G = 1e-3 * _G_M_S2
#: Separates the IMU's random streams from every other user of the same seed.
_STREAM = 0x494D55  # "IMU"
#: Each component's stream: this + 0 for the gyroscope, + 1 for the accelerometer.
_WHITE, _WALK, _TURN_ON, _SCALE, _MISALIGNMENT = 0, 2, 4, 6, 8
_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
#: The most an IMU clock may be off the events' clock: beyond it, a mistake (milliseconds is
#: what a USB-stamped IMU shows).
MAX_TIME_OFFSET_S = 1.0
#: Columns added to the ideal IMU table: readings, then the bias inside them (IMU axes).
MEASURED_COLUMNS = tuple(
    f"{sensor}_{kind}_{axis}_{unit}"
    for kind in ("meas", "bias")
    for sensor, unit in (("gyro", "rad_s"), ("accel", "m_s2"))
    for axis in "xyz"
)

# The densities (N, K) and the spreads of the per-device draws. Names: the scene file's [imu] keys.
_NONNEGATIVE = (
    "gyro_noise_density_rad_s_sqrt_hz",
    "accel_noise_density_m_s2_sqrt_hz",
    "gyro_random_walk_rad_s2_sqrt_hz",
    "accel_random_walk_m_s3_sqrt_hz",
    "gyro_turn_on_bias_sigma_rad_s",
    "accel_turn_on_bias_sigma_m_s2",
    "gyro_scale_sigma",
    "accel_scale_sigma",
    "gyro_misalignment_sigma_rad",
    "accel_misalignment_sigma_rad",
)


@dataclass(frozen=True)
class ImuModel:
    """A real IMU: noise densities, bias, scale and misalignment spreads, mounting, clock offset.

    The zero model is the ideal IMU. `ImuModel.preset("mpu6500", seed=3)` is a named datasheet's
    (`IMU_MODELS`); every field can be overridden. Sigmas are one standard deviation of a draw
    made once per device (per seed); `seed` None takes the simulation's seed.
    """

    name: str = "custom"
    gyro_noise_density_rad_s_sqrt_hz: float = 0.0
    accel_noise_density_m_s2_sqrt_hz: float = 0.0
    gyro_random_walk_rad_s2_sqrt_hz: float = 0.0
    accel_random_walk_m_s3_sqrt_hz: float = 0.0
    gyro_turn_on_bias_sigma_rad_s: float = 0.0
    accel_turn_on_bias_sigma_m_s2: float = 0.0
    #: Scale-factor error (fraction: 0.01 reads 1 % high or low) and cross-axis sensitivity.
    gyro_scale_sigma: float = 0.0
    accel_scale_sigma: float = 0.0
    gyro_misalignment_sigma_rad: float = 0.0
    accel_misalignment_sigma_rad: float = 0.0
    #: Camera-to-IMU rotation, rows of the 3x3: x_imu = rotation @ x_camera.
    rotation: tuple[tuple[float, float, float], ...] = _IDENTITY
    #: Where the IMU sits in the camera frame (+x left, +y up, +z forward), metres.
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: t_imu - t_camera for one instant, seconds: a sample stamped t saw the motion of t - offset.
    time_offset_s: float = 0.0
    seed: int | None = None

    def __post_init__(self) -> None:
        for name in _NONNEGATIVE:
            object.__setattr__(self, name, _number(name, getattr(self, name)))
        offset = _number("time_offset_s", self.time_offset_s, within_s=MAX_TIME_OFFSET_S)
        object.__setattr__(self, "time_offset_s", offset)
        object.__setattr__(self, "rotation", _rotation(self.rotation))
        object.__setattr__(self, "lever_arm_m", _vector("lever_arm_m", self.lever_arm_m))
        object.__setattr__(self, "seed", _seed(self.seed))

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> ImuModel:
        """The named IMU's model (`IMU_MODELS`), with fields replaced by `overrides`."""
        if name not in IMU_MODELS:
            raise ValueError(f"model: unknown IMU model {name!r}; known: {', '.join(IMU_MODELS)}")
        return dataclasses.replace(IMU_MODELS[name], **overrides)

    @classmethod
    def from_settings(cls, settings: dict[str, Any], where: str = "") -> ImuModel:
        """A model from a scene file's `[imu]` table (or the same as a dict): `model` (a preset,
        none: every field from zero) and any field; errors start with `where` and name the key."""
        known = ("model", *(f.name for f in dataclasses.fields(cls) if f.name != "name"))
        unknown = sorted(set(settings) - set(known))
        if unknown:
            raise ValueError(f"{where}{unknown[0]}: unknown key (known: {', '.join(known)})")
        fields = {k: v for k, v in settings.items() if k != "model"}
        name = settings.get("model")
        try:
            if name is None:
                return cls(**fields)
            if not isinstance(name, str):
                raise ValueError(f"model: expected the name of an IMU model, got {name!r}")
            return cls.preset(name, **fields)
        except ValueError as error:
            raise ValueError(f"{where}{error}") from None

    def with_seed(self, default_seed: int) -> ImuModel:
        """This model with `default_seed` where it has no seed of its own."""
        return self if self.seed is not None else dataclasses.replace(self, seed=default_seed)

    def as_dict(self) -> dict[str, Any]:
        """Every field, JSON-ready (the IMU table's metadata records the model used)."""
        out = dataclasses.asdict(self)
        out["rotation"] = [list(row) for row in self.rotation]
        out["lever_arm_m"] = list(self.lever_arm_m)
        return out

    def measure(
        self,
        t_us: np.ndarray,
        gyro_rad_s: np.ndarray,
        specific_force_m_s2: np.ndarray,
        angular_acceleration_rad_s2: np.ndarray | None,
        rate_hz: float,
    ) -> ImuReadings:
        """What this IMU reads at `t_us` (n samples) given the ideal readings (n x 3, camera body
        frame, at the camera origin) at t_us - time_offset_s. `angular_acceleration_rad_s2` (n x
        3) is needed only with a lever arm."""
        if self.seed is None:
            raise ValueError("seed: the IMU model needs a seed (with_seed gives the default)")
        gyro = np.asarray(gyro_rad_s, np.float64)
        force = self._force_at_imu(gyro, specific_force_m_s2, angular_acceleration_rad_s2)
        sqrt_dt = np.sqrt(np.diff(np.asarray(t_us, np.int64)) * 1e-6)
        rotation = np.array(self.rotation)
        readings = []
        for index, (sensor, true) in enumerate((("gyro", gyro), ("accel", force))):
            error_matrix = self._error_matrix(sensor, index) @ rotation
            bias = self._bias(sensor, index, sqrt_dt)
            reading = self._white(sensor, index, true.shape[0], rate_hz)
            reading += bias
            # The identity (an ideal mounting) is skipped: n x 3 @ 3 x 3 is slow in numpy.
            reading += true if np.array_equal(error_matrix, np.eye(3)) else true @ error_matrix.T
            readings.append((reading, bias))
        (gyro_meas, gyro_bias), (accel_meas, accel_bias) = readings
        return ImuReadings(gyro_meas, accel_meas, gyro_bias, accel_bias)

    def _force_at_imu(
        self, gyro: np.ndarray, force: np.ndarray, alpha: np.ndarray | None
    ) -> np.ndarray:
        """The specific force at the lever arm: f + alpha x r + omega x (omega x r)."""
        force = np.asarray(force, np.float64)
        if not any(self.lever_arm_m):
            return force
        if alpha is None:
            raise ValueError("lever_arm_m: needs the angular acceleration of the motion")
        alpha = np.asarray(alpha, np.float64)
        r = np.broadcast_to(np.array(self.lever_arm_m), gyro.shape)
        return force + np.cross(alpha, r) + np.cross(gyro, np.cross(gyro, r))

    # -- the components: each from its own stream ----------------------------------------------

    def _stream(self, component: int) -> np.random.Generator:
        assert self.seed is not None
        return np.random.default_rng(np.random.SeedSequence([self.seed, _STREAM, component]))

    def _density(self, sensor: str, kind: str) -> float:
        """The field of `sensor` ("gyro", "accel") for `kind` ("noise", "random_walk", "turn_on",
        "scale", "misalignment")."""
        return float(
            getattr(self, next(n for n in _NONNEGATIVE if n.startswith(f"{sensor}_{kind}")))
        )

    def _white(self, sensor: str, index: int, count: int, rate_hz: float) -> np.ndarray:
        """n_k = N sqrt(r) v_k: the band-limited white noise's variance per sample is N^2 r."""
        sigma = self._density(sensor, "noise") * math.sqrt(rate_hz)
        return sigma * self._stream(_WHITE + index).standard_normal((count, 3))

    def _bias(self, sensor: str, index: int, sqrt_dt: np.ndarray) -> np.ndarray:
        """b_0 ~ N(0, sigma_b0^2), then b_k = b_{k-1} + K sqrt(dt_k) w_k."""
        bias = np.empty((sqrt_dt.size + 1, 3))
        turn_on = self._stream(_TURN_ON + index).standard_normal(3)
        bias[0] = self._density(sensor, "turn_on") * turn_on
        steps = self._stream(_WALK + index).standard_normal((sqrt_dt.size, 3))
        steps *= self._density(sensor, "random_walk") * sqrt_dt[:, None]
        np.cumsum(steps, axis=0, out=bias[1:])
        bias[1:] += bias[0]
        return bias

    def _error_matrix(self, sensor: str, index: int) -> np.ndarray:
        """C = I + diag(s) + M (M off the diagonal): scale and misalignment of this device."""
        scale = self._density(sensor, "scale") * self._stream(_SCALE + index).standard_normal(3)
        cross = self._stream(_MISALIGNMENT + index).standard_normal((3, 3))
        cross *= self._density(sensor, "misalignment")
        np.fill_diagonal(cross, 0.0)
        return np.eye(3) + np.diag(scale) + cross


@dataclass(frozen=True)
class ImuReadings:
    """What a real IMU read (n x 3 each, its own axes) and the bias inside each reading."""

    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    gyro_bias_rad_s: np.ndarray
    accel_bias_m_s2: np.ndarray

    def columns(self) -> dict[str, np.ndarray]:
        """The arrays by `MEASURED_COLUMNS` name."""
        arrays = (self.gyro_rad_s, self.accel_m_s2, self.gyro_bias_rad_s, self.accel_bias_m_s2)
        return {name: arrays[i // 3][:, i % 3] for i, name in enumerate(MEASURED_COLUMNS)}


def _number(name: str, value: Any, within_s: float | None = None) -> float:
    """A finite float: >= 0, or a time within +-`within_s` seconds when that is given."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    number = float(value)
    if within_s is None and not (math.isfinite(number) and number >= 0):
        raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")
    if within_s is not None and not (math.isfinite(number) and abs(number) <= within_s):
        raise ValueError(f"{name}: must be within +-{within_s:g} s, got {value!r}")
    return number


def _seed(value: Any) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {value!r}")
    return int(value)


def _rotation(value: Any) -> tuple[tuple[float, float, float], ...]:
    """A 3x3 proper rotation (orthonormal to 1e-6, determinant +1) as a tuple of rows."""
    try:
        matrix = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        matrix = np.zeros(0)
    if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
        raise ValueError(f"rotation: expected a 3x3 matrix (three rows of three), got {value!r}")
    if not np.allclose(matrix @ matrix.T, np.eye(3), atol=1e-6) or np.linalg.det(matrix) < 0:
        raise ValueError(
            "rotation: not a rotation (rows must be orthonormal, determinant +1), got "
            f"{matrix.tolist()}"
        )
    return tuple(tuple(float(v) for v in row) for row in matrix)  # type: ignore[return-value]


def _vector(name: str, value: Any) -> tuple[float, float, float]:
    try:
        vector = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        vector = np.zeros(0)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise ValueError(f"{name}: expected three numbers (metres), got {value!r}")
    return (float(vector[0]), float(vector[1]), float(vector[2]))


# Presets. White-noise densities are the datasheets' typical values. Datasheets give no bias
# random walk: where a published Allan-variance characterisation of the part exists it is used,
# else the value is marked assumed. Turn-on bias: datasheets give a +- tolerance, not a
# distribution; it is read here as 3 sigma (assumed), so sigma = tolerance / 3.

#: The IMU of the DAVIS346: TDK InvenSense MPU-6500 (iniVation's documentation, "IMU": "The IMU
#: used in our DAVIS346 camera is the TDK InvenSense MPU-6500"; all other iniVation cameras carry
#: a Bosch BMI160).
MPU6500 = ImuModel(
    name="mpu6500",
    # MPU-6500 Product Specification PS-MPU-6500A-01 rev 1.1, section 3.1 (Gyroscope
    # Specifications): rate noise spectral density 0.01 deg/s/sqrt(Hz).
    gyro_noise_density_rad_s_sqrt_hz=0.01 * _DEG,
    # Same document, section 3.2 (Accelerometer Specifications): noise power spectral density,
    # low-noise mode, 300 ug/sqrt(Hz).
    accel_noise_density_m_s2_sqrt_hz=300.0 * _MICRO_G,
    # Assumed: no published Allan characterisation of the MPU-6500 found; the BMI160's (below,
    # TUM VI), a part of the same consumer-MEMS class with a white noise within 1.7x of it.
    gyro_random_walk_rad_s2_sqrt_hz=2.2e-5,
    accel_random_walk_m_s3_sqrt_hz=8.6e-4,
    # Section 3.1: initial zero-rate output tolerance +-5 deg/s; section 3.2: zero-g initial
    # calibration tolerance +-60 mg (x, y; z: +-80 mg). The same figures are in the MPU-9250
    # specification PS-MPU-9250A-01 rev 1.0, tables 1 and 2 (its gyro/accelerometer die is the
    # MPU-6500's).
    gyro_turn_on_bias_sigma_rad_s=5.0 * _DEG / 3.0,
    accel_turn_on_bias_sigma_m_s2=60.0 * _MILLI_G / 3.0,
)

#: The IMU of the DVXplorer (and iniVation's other cameras but the DAVIS346): Bosch BMI160.
BMI160 = ImuModel(
    name="bmi160",
    # BMI160 data sheet BST-BMI160-DS000, section 1.2 (specification, table 1): gyroscope
    # output noise density 0.007 deg/s/sqrt(Hz), accelerometer 180 ug/sqrt(Hz) (normal mode).
    gyro_noise_density_rad_s_sqrt_hz=0.007 * _DEG,
    accel_noise_density_m_s2_sqrt_hz=180.0 * _MICRO_G,
    # Allan-deviation characterisation of a BMI160: Schubert et al., "The TUM VI Benchmark for
    # Evaluating Visual-Inertial Odometry", IROS 2018 (arXiv:1804.06120), its IMU noise
    # parameters (as shipped in the dataset's imu_config.yaml): gyroscope random walk
    # 2.2e-5 rad/s^2/sqrt(Hz), accelerometer 8.6e-4 m/s^3/sqrt(Hz).
    gyro_random_walk_rad_s2_sqrt_hz=2.2e-5,
    accel_random_walk_m_s3_sqrt_hz=8.6e-4,
    # Same section: zero-rate offset +-10 deg/s, zero-g offset +-40 mg.
    gyro_turn_on_bias_sigma_rad_s=10.0 * _DEG / 3.0,
    accel_turn_on_bias_sigma_m_s2=40.0 * _MILLI_G / 3.0,
)

#: Named IMUs for `ImuModel.preset`, `Simulation(imu_model=...)`, `pecs simulate --imu-model`.
IMU_MODELS: dict[str, ImuModel] = {"mpu6500": MPU6500, "bmi160": BMI160}
#: The event cameras that carry each (for messages and docs).
IMU_CAMERAS = {"mpu6500": "DAVIS346", "bmi160": "DVXplorer"}
