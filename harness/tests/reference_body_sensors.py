"""The body sensor models as they were before `BodySensors.sample` worked on plain floats: the oracle of
test_hs_body_sensors' bit-for-bit comparison."""

from __future__ import annotations

import math

import numpy as np

from pfnav_harness.body_sensors import _NOISE_BLOCK, GRAVITY_WORLD, BodyReadings, BodySensorConfig, FloatArray
from pfnav_harness.errors import SimulationError


def _quaternion_to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrix (body → world) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(q, dtype=np.float64).tolist()
    return np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )


class ReferenceBodySensors:
    """`BodySensors` as it was before its sample() was rewritten on plain floats (93568a0)."""

    def __init__(self, config: BodySensorConfig, sample_period: float) -> None:
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
        self._white = scale * np.repeat([spec.gyro_noise_density * root_rate, spec.acc_noise_density * root_rate], 3)
        self._walk = scale * np.repeat([spec.gyro_bias_walk, spec.acc_bias_walk], 3) * math.sqrt(sample_period)
        self.bias = scale * np.repeat([spec.gyro_bias_stability, spec.acc_bias_stability], 3) * self._imu_rng.standard_normal(6)
        self._range = np.repeat([spec.gyro_range, spec.acc_range], 3)
        self._previous_velocity: FloatArray | None = None
        self._fixes = 0
        # Normal draws for the IMU, 12 per sample (6 white, 6 bias steps), drawn in blocks: one
        # generator call per sample would cost more than the rest of the model.
        self._noise = np.zeros((0, 12))
        self._next_noise = 0
        self._world_vectors = np.zeros((3, 2))
        self.readings = BodyReadings()

    def _imu_noise(self) -> FloatArray:
        if self._next_noise == len(self._noise):
            self._noise = self._imu_rng.standard_normal((_NOISE_BLOCK, 12))
            self._next_noise = 0
        row = self._noise[self._next_noise]
        self._next_noise += 1
        return row

    def sample(self, t: float, state: FloatArray) -> BodyReadings:
        """The readings at time `t` from the 37-entry trunk and joint state (updates `readings`)."""
        out = self.readings
        velocity = state[7:10]
        if self._previous_velocity is None:
            self._previous_velocity = velocity.copy()
        vectors = self._world_vectors
        vectors[:, 0] = state[10:13]
        # Specific force in the world frame: (Δv / Δt) − g.
        vectors[:, 1] = (velocity - self._previous_velocity) / self.sample_period - GRAVITY_WORLD
        self._previous_velocity[:] = velocity
        body = _quaternion_to_matrix(state[3:7]).T @ vectors
        noise = self._imu_noise()
        measured = np.concatenate((body[:, 0], body[:, 1]))
        measured += self.bias
        measured += self._white * noise[:6]
        # Saturation (np.clip costs several times minimum + maximum on 6 entries).
        np.minimum(measured, self._range, out=measured)
        np.maximum(measured, -self._range, out=measured)
        self.bias += self._walk * noise[6:]
        out.gyro[:] = measured[:3]
        out.acc[:] = measured[3:]

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
