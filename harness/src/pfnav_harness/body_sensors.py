"""What a real quadruped measures of itself: an IMU on the trunk, joint encoders, an optional position fix.

The models read the DART trunk state (`QuadrupedWorld.state_vector` layout: pos, quat w-x-y-z,
world velocity, world angular velocity, joint angles, joint velocities) and produce what the
controller FMU's estimator inputs take:

* **IMU** (`imu.gyro[1..3]`, `imu.acc[1..3]`, body frame): gyro = Rᵀ ω_world; accelerometer =
  specific force Rᵀ (a_world − g), g = (0, 0, −9.81) m/s², so a level robot at rest reads +9.81 on z.
  a_world is the velocity difference of the trunk origin over the sampling interval. DART's own
  `BodyNode.getLinearAcceleration()` after a step equals Δv/dt of that step to 1e-13 m/s², contact
  impulses included (checked in test_hs_body_sensors); the difference is used because with a
  communication step longer than the physics step it is the interval's mean, like an IMU's
  delta-velocity output, rather than the last physics step's value. Each axis gets white noise
  of standard deviation `noise density × √(sample rate)` and a bias that starts at N(0, B²) and
  walks (see `ImuSpec`); readings saturate at the data-sheet range.
* **Encoders** (`joint.q[i]`): angles rounded to the resolution of a 14-bit absolute encoder on the
  joint. Joint velocities are passed on as DART gives them: motor drivers report a filtered
  velocity, and a 1 kHz difference of a 14-bit angle would step in 0.38 rad/s quanta that no
  controller consumes unfiltered.
* **Position fix** (`fix.pos[1..3]`, `fix.valid`): at `fix_rate` Hz the true trunk position plus
  N(0, fix_noise²) per axis (GNSS-RTK or motion-capture like); `fix.valid` is true only in the
  sample in which a new fix arrived.
* **Foot contact** (`contact[1..4]`, optional): which feet DART finds touching anything, as an
  ideal binary contact sensor; without it the FMU's estimator trusts its own gait schedule.

Every noise source has its own random stream spawned from one seed (`numpy.random.SeedSequence`,
PCG64), so turning the fix on or off does not change the IMU's noise, and a seed reproduces a run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import SimulationError

FloatArray = NDArray[np.float64]

STANDARD_GRAVITY = 9.80665
# Gravity of the DART world (world.py) and of the specific-force convention of imu.acc.
GRAVITY_WORLD = np.array([0.0, 0.0, -9.81])
_GRAVITY = tuple(GRAVITY_WORLD.tolist())
_DEG = math.pi / 180.0
_NOISE_BLOCK = 4096


@dataclass(frozen=True)
class ImuSpec:
    """A MEMS IMU's noise and range in SI units, per axis.

    The bias random walk is derived from the data sheet's in-run bias stability B (the Allan
    deviation floor): the bias starts at N(0, B²) (what is left after a standstill calibration)
    and walks with density B/√T, so it drifts by about B every `bias_time_constant` T seconds.
    A random walk is a pessimistic stand-in for the flicker noise B describes (it keeps growing).
    """

    name: str
    gyro_noise_density: float  # rad/s/√Hz
    gyro_bias_stability: float  # rad/s
    gyro_range: float  # rad/s
    acc_noise_density: float  # m/s²/√Hz
    acc_bias_stability: float  # m/s²
    acc_range: float  # m/s²
    bias_time_constant: float = 100.0  # s

    @property
    def gyro_bias_walk(self) -> float:
        """Gyro bias random-walk density, rad/s/√s."""
        return self.gyro_bias_stability / math.sqrt(self.bias_time_constant)

    @property
    def acc_bias_walk(self) -> float:
        """Accelerometer bias random-walk density, m/s²/√s."""
        return self.acc_bias_stability / math.sqrt(self.bias_time_constant)


# Analog Devices ADIS16470 "Wide Dynamic Range, Miniature MEMS IMU", data sheet Table 1
# (Specifications, T = 25 °C, typical, 1σ): gyroscope dynamic range ±2000 °/s, in-run bias
# stability 8 °/hr, rate noise density 0.008 °/s/√Hz rms (angular random walk 0.34 °/√hr);
# accelerometer dynamic range ±40 g, in-run bias stability 13 µg, velocity random walk
# 0.037 m/s/√hr. The gyro white noise uses the rate noise density (the larger of the two gyro
# figures); the accelerometer's uses the velocity random walk, 0.037 m/s/√hr = 6.2e-4 m/s²/√Hz.
ADIS16470 = ImuSpec(
    name="ADIS16470",
    gyro_noise_density=0.008 * _DEG,
    gyro_bias_stability=8.0 / 3600.0 * _DEG,
    gyro_range=2000.0 * _DEG,
    acc_noise_density=0.037 / 60.0,
    acc_bias_stability=13e-6 * STANDARD_GRAVITY,
    acc_range=40.0 * STANDARD_GRAVITY,
)


@dataclass(frozen=True)
class EncoderSpec:
    """An absolute joint encoder: `bits` of resolution per revolution of the joint."""

    name: str
    bits: int

    @property
    def resolution(self) -> float:
        """One count, rad."""
        return 2.0 * math.pi / (1 << self.bits)


# ams AS5047P (data sheet "AS5047P 14-Bit On-Axis Magnetic Rotary Position Sensor"): 14-bit
# absolute angle, 2π/16384 = 0.38 mrad. The MIT Mini Cheetah reads it on the motor before a 6:1
# gearbox; here it sits on the joint itself, the coarser (conservative) case.
AS5047P = EncoderSpec(name="AS5047P", bits=14)


@dataclass(frozen=True)
class BodySensorConfig:
    """The body sensors of one run (named apart from `sensing.SensorConfig`, the terrain sensor)."""

    seed: int = 0
    imu: ImuSpec = ADIS16470
    encoder: EncoderSpec = AS5047P
    # Absolute position fixes per second; 0: none.
    fix_rate: float = 0.0
    # Standard deviation of each fix coordinate, m.
    fix_noise: float = 0.02
    # Multiplies every IMU noise and bias (1: the data sheet; 0: ideal readings, for tests).
    imu_noise_scale: float = 1.0
    quantize_joints: bool = True
    # Tell the estimator which feet touch the ground (DART's contacts: an ideal binary foot contact
    # sensor, no delay or threshold); off: the FMU's contact inputs stay −1 and it uses its gait schedule.
    contact_sensor: bool = False

    def validate(self) -> None:
        if not (isinstance(self.seed, int) and self.seed >= 0):
            raise SimulationError(f"the sensor seed must be an integer >= 0, got {self.seed!r}")
        if not (math.isfinite(self.fix_rate) and self.fix_rate >= 0.0):
            raise SimulationError(f"the fix rate must be >= 0 Hz (0 = no fixes), got {self.fix_rate}")
        if not (math.isfinite(self.fix_noise) and self.fix_noise >= 0.0):
            raise SimulationError(f"the fix noise must be >= 0 m, got {self.fix_noise}")
        if not (math.isfinite(self.imu_noise_scale) and self.imu_noise_scale >= 0.0):
            raise SimulationError(f"the IMU noise scale must be >= 0, got {self.imu_noise_scale}")
        if not (1 <= self.encoder.bits <= 32):
            raise SimulationError(f"encoder resolution must be 1..32 bits, got {self.encoder.bits}")


@dataclass
class BodyReadings:
    """One sample of every body sensor (the FMU's estimator inputs)."""

    gyro: FloatArray = field(default_factory=lambda: np.zeros(3))
    acc: FloatArray = field(default_factory=lambda: np.zeros(3))
    joint_q: FloatArray = field(default_factory=lambda: np.zeros(12))
    joint_dq: FloatArray = field(default_factory=lambda: np.zeros(12))
    fix_pos: FloatArray = field(default_factory=lambda: np.zeros(3))
    fix_valid: bool = False


def quaternion_to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrix (body → world) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(q, dtype=np.float64).tolist()
    return np.array(_rotation_rows(w, x, y, z))


def _rotation_rows(w: float, x: float, y: float, z: float) -> tuple[tuple[float, float, float], ...]:
    return (
        (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
        (2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
        (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)),
    )


@dataclass(frozen=True)
class BodySensorsState:
    """Everything a `BodySensors` carries from one sample to the next (copies; picklable).

    The generators' bit-generator states, the drawn but unused noise block, the IMU bias, the last
    velocity (for the next Δv) and the readings (the last fix is repeated until the next one).
    """

    imu_rng: dict[str, Any]
    fix_rng: dict[str, Any]
    noise: FloatArray
    next_noise: int
    bias: FloatArray
    previous_velocity: FloatArray | None
    fixes: int
    readings: BodyReadings


class BodySensors:
    """Seeded IMU, encoder and fix models, sampled every `sample_period` seconds."""

    def __init__(self, config: BodySensorConfig, sample_period: float, readings: BodyReadings | None = None) -> None:
        """`readings`: the arrays `sample` writes into (the estimator's FMU input buffers); fresh ones by default."""
        config.validate()
        if not (math.isfinite(sample_period) and sample_period > 0.0):
            raise SimulationError(f"the sensor sample period must be positive, got {sample_period}")
        self.config = config
        self.sample_period = sample_period
        imu_seq, fix_seq = np.random.SeedSequence(config.seed).spawn(2)
        self._imu_rng = np.random.Generator(np.random.PCG64(imu_seq))
        self._fix_rng = np.random.Generator(np.random.PCG64(fix_seq))
        spec, scale = config.imu, config.imu_noise_scale
        root_rate = math.sqrt(1.0 / sample_period)
        # White noise and bias-step standard deviations per axis: gyro xyz, then accelerometer xyz.
        # Per axis (gyro xyz, then accelerometer xyz) as plain floats: `sample` works on six values,
        # where numpy's per-call overhead would cost more than the arithmetic.
        self._white = (scale * np.repeat([spec.gyro_noise_density * root_rate, spec.acc_noise_density * root_rate], 3)).tolist()
        self._walk = (scale * np.repeat([spec.gyro_bias_walk, spec.acc_bias_walk], 3) * math.sqrt(sample_period)).tolist()
        self._bias = (scale * np.repeat([spec.gyro_bias_stability, spec.acc_bias_stability], 3) * self._imu_rng.standard_normal(6)).tolist()
        self._range = np.repeat([spec.gyro_range, spec.acc_range], 3).tolist()
        self._previous_velocity: tuple[float, float, float] | None = None
        self._fixes = 0
        # Normal draws for the IMU, 12 per sample (6 white, 6 bias steps), drawn in blocks: one
        # generator call per sample would cost more than the rest of the model.
        self._noise = np.zeros((0, 12))
        self._next_noise = 0
        self.readings = readings if readings is not None else BodyReadings()

    @property
    def bias(self) -> FloatArray:
        """The IMU bias now (gyro xyz, accelerometer xyz; a copy)."""
        return np.array(self._bias)

    def save_state(self) -> BodySensorsState:
        r = self.readings
        return BodySensorsState(
            imu_rng=self._imu_rng.bit_generator.state,
            fix_rng=self._fix_rng.bit_generator.state,
            noise=self._noise.copy(),
            next_noise=self._next_noise,
            bias=self.bias,
            previous_velocity=None if self._previous_velocity is None else np.array(self._previous_velocity),
            fixes=self._fixes,
            readings=BodyReadings(r.gyro.copy(), r.acc.copy(), r.joint_q.copy(), r.joint_dq.copy(), r.fix_pos.copy(), r.fix_valid),
        )

    def restore_state(self, state: BodySensorsState) -> None:
        """Continues from `state` (from `save_state` of sensors with the same configuration)."""
        self._imu_rng.bit_generator.state = state.imu_rng
        self._fix_rng.bit_generator.state = state.fix_rng
        self._noise = state.noise.copy()
        self._next_noise = state.next_noise
        self._bias = np.asarray(state.bias, dtype=np.float64).tolist()
        self._previous_velocity = None if state.previous_velocity is None else tuple(np.asarray(state.previous_velocity, dtype=np.float64).tolist())
        self._fixes = state.fixes
        out, saved = self.readings, state.readings
        out.gyro[:] = saved.gyro
        out.acc[:] = saved.acc
        out.joint_q[:] = saved.joint_q
        out.joint_dq[:] = saved.joint_dq
        out.fix_pos[:] = saved.fix_pos
        out.fix_valid = saved.fix_valid

    def _imu_noise(self) -> FloatArray:
        if self._next_noise == len(self._noise):
            self._noise = self._imu_rng.standard_normal((_NOISE_BLOCK, 12))
            self._next_noise = 0
        row = self._noise[self._next_noise]
        self._next_noise += 1
        return row

    def sample(self, t: float, state: FloatArray) -> BodyReadings:
        """The readings at time `t` from the 37-entry trunk and joint state (updates `readings`).

        The IMU model runs on plain floats with the operations (and their order) of the array
        expressions it replaced, so the readings are the same bit for bit (test_hs_body_sensors);
        the frame change stays one numpy product with the same operands, as its rounding is BLAS's.
        """
        out = self.readings
        s = state.tolist()
        vx, vy, vz = s[7], s[8], s[9]
        previous = self._previous_velocity if self._previous_velocity is not None else (vx, vy, vz)
        self._previous_velocity = (vx, vy, vz)
        dt = self.sample_period
        gx, gy, gz = _GRAVITY
        # Angular velocity and specific force ((Δv / Δt) − g) in the world frame, one per column.
        vectors = np.array(
            (
                (s[10], (vx - previous[0]) / dt - gx),
                (s[11], (vy - previous[1]) / dt - gy),
                (s[12], (vz - previous[2]) / dt - gz),
            )
        )
        body = (np.array(_rotation_rows(s[3], s[4], s[5], s[6])).T @ vectors).tolist()
        noise = self._imu_noise().tolist()
        bias, white, walk, limit = self._bias, self._white, self._walk, self._range
        measured = [0.0] * 6
        for i, value in enumerate((body[0][0], body[1][0], body[2][0], body[0][1], body[1][1], body[2][1])):
            m = value + bias[i]
            m += white[i] * noise[i]
            # Saturation; min/max keep a NaN as np.minimum/np.maximum did.
            m = min(m, limit[i])
            measured[i] = max(m, -limit[i])
            bias[i] += walk[i] * noise[6 + i]
        out.gyro[:] = measured[0:3]
        out.acc[:] = measured[3:6]

        joint_q = state[13:25]
        if self.config.quantize_joints:
            step = self.config.encoder.resolution
            np.multiply(joint_q, 1.0 / step, out=out.joint_q)
            np.rint(out.joint_q, out=out.joint_q)
            out.joint_q *= step
        else:
            out.joint_q[:] = joint_q
        out.joint_dq[:] = state[25:37]

        out.fix_valid = False
        rate = self.config.fix_rate
        if rate > 0.0:
            # Fix n arrives at n / rate; a tiny margin keeps sums of steps on the intended side.
            due = math.floor(t * rate + 1e-9) + 1
            if due > self._fixes:
                self._fixes = due
                out.fix_pos[:] = state[0:3] + self.config.fix_noise * self._fix_rng.standard_normal(3)
                out.fix_valid = True
        return out
