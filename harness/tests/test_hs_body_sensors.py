"""Body sensor models: IMU physics, noise statistics, encoder quantisation, fixes, determinism by seed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from reference_body_sensors import ReferenceBodySensors

from pfnav_harness import paths
from pfnav_harness.body_sensors import ADIS16470, AS5047P, BodySensorConfig, BodySensors, quaternion_to_matrix
from pfnav_harness.errors import SimulationError
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario
from pfnav_harness.world import QuadrupedWorld, rotation_to_quaternion

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
CROUCH = ROBOT.crouch

DT = 0.001
IDEAL = BodySensorConfig(imu_noise_scale=0.0, quantize_joints=False)


def _state(quat: np.ndarray | None = None, vel: np.ndarray | None = None, omega: np.ndarray | None = None, q: np.ndarray | None = None) -> np.ndarray:
    state = np.zeros(37)
    state[0:3] = (1.0, 2.0, 0.3)
    state[3:7] = (1.0, 0.0, 0.0, 0.0) if quat is None else quat
    state[7:10] = 0.0 if vel is None else vel
    state[10:13] = 0.0 if omega is None else omega
    state[13:25] = CROUCH if q is None else q
    state[25:37] = np.linspace(-1.0, 1.0, 12)
    return state


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cz, sz, cy, sy, cx, sx = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return rz @ ry @ rx


def test_level_robot_at_rest_reads_gravity_up_and_no_rotation() -> None:
    sensors = BodySensors(IDEAL, DT)
    for k in range(3):
        r = sensors.sample(k * DT, _state())
    np.testing.assert_allclose(r.gyro, 0.0, atol=1e-15)
    np.testing.assert_allclose(r.acc, (0.0, 0.0, 9.81), atol=1e-12)
    np.testing.assert_array_equal(r.joint_q, CROUCH)
    assert not r.fix_valid


def test_known_rotation_puts_world_rates_and_gravity_into_the_body_frame() -> None:
    rot = _rotation(0.7, -0.3, 0.4)
    quat = rotation_to_quaternion(rot)
    np.testing.assert_allclose(quaternion_to_matrix(quat), rot, atol=1e-12)
    omega_world = np.array([0.2, -0.5, 1.1])
    accel_world = np.array([0.8, -0.4, 0.3])
    sensors = BodySensors(IDEAL, DT)
    sensors.sample(0.0, _state(quat, vel=np.zeros(3), omega=omega_world))
    r = sensors.sample(DT, _state(quat, vel=accel_world * DT, omega=omega_world))
    np.testing.assert_allclose(r.gyro, rot.T @ omega_world, atol=1e-12)
    np.testing.assert_allclose(r.acc, rot.T @ (accel_world - np.array([0.0, 0.0, -9.81])), atol=1e-9)
    # Free fall reads zero specific force whatever the attitude.
    r = sensors.sample(2 * DT, _state(quat, vel=accel_world * DT + np.array([0.0, 0.0, -9.81 * DT]), omega=omega_world))
    np.testing.assert_allclose(r.acc, 0.0, atol=1e-9)


def test_readings_saturate_at_the_datasheet_range() -> None:
    sensors = BodySensors(IDEAL, DT)
    sensors.sample(0.0, _state())
    r = sensors.sample(DT, _state(vel=np.array([0.0, 0.0, 10.0]), omega=np.array([100.0, -100.0, 1.0])))
    assert r.gyro[0] == pytest.approx(ADIS16470.gyro_range) and r.gyro[1] == pytest.approx(-ADIS16470.gyro_range)
    assert r.gyro[2] == pytest.approx(1.0)
    assert ADIS16470.gyro_range == pytest.approx(math.radians(2000.0))
    assert r.acc[2] == pytest.approx(40.0 * 9.80665)


def test_white_noise_and_bias_follow_the_datasheet() -> None:
    sensors = BodySensors(BodySensorConfig(seed=11), DT)
    state = _state()
    n = 20_000
    gyro = np.zeros((n, 3))
    acc = np.zeros((n, 3))
    biases = np.zeros((n, 6))
    for k in range(n):
        biases[k] = sensors.bias
        r = sensors.sample(k * DT, state)
        gyro[k], acc[k] = r.gyro, r.acc
    rate_root = math.sqrt(1.0 / DT)
    # Sample standard deviation of 20 000 draws is within ±2 % of sigma with overwhelming odds.
    np.testing.assert_allclose((gyro - biases[:, :3]).std(axis=0), ADIS16470.gyro_noise_density * rate_root, rtol=0.03)
    np.testing.assert_allclose((acc - biases[:, 3:] - (0, 0, 9.81)).std(axis=0), ADIS16470.acc_noise_density * rate_root, rtol=0.03)
    # The bias walks in steps of density·√dt.
    steps = np.diff(biases, axis=0)
    np.testing.assert_allclose(steps[:, :3].std(axis=0), ADIS16470.gyro_bias_walk * math.sqrt(DT), rtol=0.03)
    np.testing.assert_allclose(steps[:, 3:].std(axis=0), ADIS16470.acc_bias_walk * math.sqrt(DT), rtol=0.03)
    # A static gyro averages to its bias: 8 °/h of stability, not the white noise.
    assert np.all(np.abs(gyro.mean(axis=0)) < 5 * ADIS16470.gyro_bias_stability + 3 * ADIS16470.gyro_noise_density * rate_root / math.sqrt(n))


def test_encoders_quantise_to_14_bits_and_pass_velocities_on() -> None:
    q = np.linspace(-2.0, 2.0, 12) + 1e-5
    sensors = BodySensors(BodySensorConfig(imu_noise_scale=0.0), DT)
    r = sensors.sample(0.0, _state(q=q))
    step = AS5047P.resolution
    assert step == pytest.approx(2 * math.pi / 16384)
    np.testing.assert_allclose(r.joint_q / step, np.round(r.joint_q / step), atol=1e-9)
    assert np.max(np.abs(r.joint_q - q)) <= step / 2 + 1e-15
    assert np.any(r.joint_q != q)
    np.testing.assert_array_equal(r.joint_dq, np.linspace(-1.0, 1.0, 12))


def test_fixes_arrive_at_the_rate_with_their_noise_and_are_valid_once() -> None:
    sensors = BodySensors(BodySensorConfig(seed=3, fix_rate=2.0, fix_noise=0.05, imu_noise_scale=0.0), DT)
    state = _state()
    valid_times = []
    fixes = []
    for k in range(4000):
        r = sensors.sample(k * DT, state)
        if r.fix_valid:
            valid_times.append(k * DT)
            fixes.append(r.fix_pos.copy())
    np.testing.assert_allclose(valid_times, np.arange(8) * 0.5, atol=1e-12)
    assert np.all(np.abs(np.array(fixes) - state[0:3]) < 5 * 0.05)
    assert np.any(np.abs(np.array(fixes) - state[0:3]) > 1e-4)
    # Flagged only on arrival, held until the next one.
    arrival = sensors.sample(4.0, state)
    assert arrival.fix_valid
    held = arrival.fix_pos.copy()
    r = sensors.sample(4.001, state)
    assert not r.fix_valid and np.array_equal(r.fix_pos, held)
    # Many fixes have the stated spread.
    many = BodySensors(BodySensorConfig(seed=4, fix_rate=1000.0, fix_noise=0.02, imu_noise_scale=0.0), DT)
    samples = np.array([many.sample(k * DT, state).fix_pos.copy() for k in range(5000)])
    np.testing.assert_allclose((samples - state[0:3]).std(axis=0), 0.02, rtol=0.05)


def test_no_fixes_without_a_rate() -> None:
    sensors = BodySensors(BodySensorConfig(fix_rate=0.0), DT)
    assert not any(sensors.sample(k * DT, _state()).fix_valid for k in range(2000))


def _trace(config: BodySensorConfig, n: int = 300) -> np.ndarray:
    sensors = BodySensors(config, DT)
    rows = []
    for k in range(n):
        state = _state(vel=np.array([0.01 * k, 0.0, 0.0]), omega=np.array([0.0, 0.1, 0.2]))
        r = sensors.sample(k * DT, state)
        rows.append(np.concatenate((r.gyro, r.acc, r.fix_pos, [r.fix_valid])))
    return np.array(rows)


def test_sensor_models_are_deterministic_by_seed() -> None:
    a = _trace(BodySensorConfig(seed=5, fix_rate=10.0))
    b = _trace(BodySensorConfig(seed=5, fix_rate=10.0))
    np.testing.assert_array_equal(a, b)
    c = _trace(BodySensorConfig(seed=6, fix_rate=10.0))
    assert not np.array_equal(a[:, :6], c[:, :6])
    # The IMU's stream does not depend on whether fixes are on.
    d = _trace(BodySensorConfig(seed=5, fix_rate=0.0))
    np.testing.assert_array_equal(a[:, :6], d[:, :6])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fix_rate": -1.0}, "fix rate"),
        ({"fix_rate": math.nan}, "fix rate"),
        ({"fix_noise": -0.1}, "fix noise"),
        ({"seed": -2}, "seed"),
        ({"imu_noise_scale": math.inf}, "noise scale"),
    ],
)
def test_bad_sensor_configs_are_refused(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(SimulationError, match=match):
        BodySensors(BodySensorConfig(**kwargs), DT)  # type: ignore[arg-type]


def test_bad_sample_period_is_refused() -> None:
    with pytest.raises(SimulationError, match="period"):
        BodySensors(BodySensorConfig(), 0.0)


def test_dart_acceleration_equals_the_velocity_difference_the_imu_uses(ramp_scenario: Scenario, tmp_path: Path) -> None:
    """Why the IMU differences velocities: DART's body acceleration after a step is exactly Δv/dt, impacts included."""
    world = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path, DT)
    world.place(1.5, 1.0, 0.2, clearance=0.03)
    impacts = 0
    for _ in range(250):
        q = world.robot.getPositions()[world.joint_dofs]
        dq = world.robot.getVelocities()[world.joint_dofs]
        world.apply_torques(150.0 * (CROUCH - q) - 4.0 * dq)
        before = np.array(world.base.getLinearVelocity())
        world.step()
        after = np.array(world.base.getLinearVelocity())
        np.testing.assert_allclose(np.array(world.base.getLinearAcceleration()), (after - before) / DT, atol=1e-8)
        impacts += int(np.linalg.norm((after - before) / DT - (0.0, 0.0, -9.81)) > 5.0)
    assert impacts > 0, "the check must cover touch-down"


def test_the_sample_on_floats_reads_what_the_array_model_read() -> None:
    """`BodySensors.sample` against the array implementation it replaced (reference_body_sensors):
    the same readings bit for bit, step after step, with noise, bias walk, saturation, quantised
    joints, fixes and a NaN in the state."""
    rng = np.random.default_rng(21)
    for config in (
        BodySensorConfig(seed=5, fix_rate=20.0, fix_noise=0.03),
        BodySensorConfig(seed=6, imu_noise_scale=0.0, quantize_joints=False),
        BodySensorConfig(seed=7, imu_noise_scale=300.0),
    ):
        fast, reference = BodySensors(config, 0.002), ReferenceBodySensors(config, 0.002)
        for k in range(1500):
            state = rng.normal(scale=(0.5, 0.5, 0.5, 1, 1, 1, 1, *[2.0] * 6, *[1.0] * 24)[0:37])
            state[3:7] /= np.linalg.norm(state[3:7])
            if k % 97 == 0:
                state[7:13] *= 1e4  # beyond the IMU's range
            if k == 700:
                state[8] = np.nan
            a, b = fast.sample(k * 0.002, state), reference.sample(k * 0.002, state)
            for name in ("gyro", "acc", "joint_q", "joint_dq", "fix_pos"):
                assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), (k, name)
            assert a.fix_valid == b.fix_valid
            assert fast.bias.tobytes() == reference.bias.tobytes()
