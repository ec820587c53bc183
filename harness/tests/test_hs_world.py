"""DART world: our robot (robot/quadruped.toml) on the triangle-mesh terrain (needs dartpy)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness import paths
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario, Terrain
from pfnav_harness.world import DEFAULT_FRICTION, QuadrupedWorld, quaternion_to_rpy, rotation_to_quaternion

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
CROUCH = ROBOT.crouch


def test_rotation_quaternion_round_trip() -> None:
    rng = np.random.default_rng(5)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w, x, y, z = q
        rot = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
        got = rotation_to_quaternion(rot)
        assert got[0] >= 0
        np.testing.assert_allclose(got, q if q[0] >= 0 else -q, atol=1e-12)


def test_state_vector_matches_the_state(ramp_scenario: Scenario, tmp_path: Path) -> None:
    """`state_vector` (the co-simulation's allocation-free read-out, torques held between
    `apply_torques` calls) agrees with `state` while the robot tumbles through the air."""
    world = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path)
    world.place(1.5, 1.0, 0.7)
    rng = np.random.default_rng(3)
    velocities = rng.normal(scale=2.0, size=world.robot.getNumDofs())
    positions = world.robot.getPositions()
    positions[5] += 1.0  # in the air: nothing stops the tumble
    world.robot.setPositions(positions)
    world.robot.setVelocities(velocities)
    out = np.zeros(37)
    for step in range(300):
        world.apply_torques(rng.normal(scale=3.0, size=12))
        world.step()
        if step % 30 == 0:
            s = world.state()
            world.state_vector(out)
            expected = np.concatenate(
                [s.position, s.quaternion, s.linear_velocity, s.angular_velocity, s.joint_positions, s.joint_velocities]
            )
            np.testing.assert_allclose(out, expected, atol=1e-9)
    assert abs(quaternion_to_rpy(out[3:7])[2] - 0.7) > 1e-3  # it did rotate


def test_placement_puts_the_lowest_foot_on_the_ground(ramp_scenario: Scenario, tmp_path: Path) -> None:
    world = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path)
    world.place(1.5, 1.0, 0.4, clearance=0.002)
    feet = world.foot_positions()
    gaps = feet[:, 2] - world.foot_radius - ramp_scenario.terrain.height(feet[:, 0], feet[:, 1])
    assert min(gaps) == pytest.approx(0.002, abs=1e-9)
    state = world.state()
    roll, pitch, yaw = quaternion_to_rpy(state.quaternion)
    assert yaw == pytest.approx(0.4)
    # Levelled with the ramp (slope 0.2 along x): pitch and roll match the heading's slope components.
    assert pitch == pytest.approx(-math.atan(0.2 * math.cos(0.4)), abs=1e-6)
    assert roll == pytest.approx(math.atan(-0.2 * math.sin(0.4) / math.hypot(1.0, 0.2 * math.cos(0.4))), abs=1e-6)
    # All four feet touch together.
    assert max(gaps) - min(gaps) < 0.01
    np.testing.assert_allclose(state.joint_positions, CROUCH)
    assert world.mass == pytest.approx(12.0)


def test_pd_stance_stands_on_a_sloped_mesh(tmp_path: Path) -> None:
    """Joint PD on the crouched stance holds the 12 kg robot on a 10° mesh slope: no sinking, no falling through."""
    n, res = 40, 0.1
    xs = (np.arange(n) + 0.5) * res
    slope = math.tan(math.radians(10.0))
    terrain = Terrain((0.0, 0.0), res, np.tile(0.2 + slope * xs, (n, 1)))
    world = QuadrupedWorld(terrain, ROBOT, tmp_path, friction=DEFAULT_FRICTION)
    world.place(2.0, 2.0, 0.0)
    kp, kd = 120.0, 3.0
    for _ in range(1500):
        s = world.state()
        world.apply_torques(kp * (CROUCH - s.joint_positions) - kd * s.joint_velocities)
        world.step()
    s = world.state()
    ground = terrain.height_at(float(s.position[0]), float(s.position[1]))
    assert 0.18 < s.position[2] - ground < 0.32
    assert np.hypot(s.position[0] - 2.0, s.position[1] - 2.0) < 0.15
    assert world.foot_contacts().sum() == 4
    # Placed levelled with the slope, it stays so: pitch ≈ −atan(slope) (nose up), no tipping.
    _, pitch, _ = quaternion_to_rpy(s.quaternion)
    assert pitch == pytest.approx(-math.atan(slope), abs=0.05)
    feet = world.foot_positions()
    penetration = terrain.height(feet[:, 0], feet[:, 1]) - (feet[:, 2] - world.foot_radius)
    assert penetration.max() < 0.01


def test_the_fast_state_read_out_is_dart_s_bit_for_bit(ramp_scenario: Scenario, tmp_path: Path) -> None:
    """`state_reader` (base rotation from the free joint's coordinates, Eigen's quaternion in Python,
    one spatial-velocity call) writes exactly what DART's transform and velocity getters give,
    over rotations of every size (both branches of the quaternion formula, tiny angles, half
    turns) and while the robot tumbles and hits the ground."""
    world = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path)
    assert world._fast_state
    world.place(1.5, 1.0, 0.7)
    fast, reference = np.zeros(37), np.zeros(37)
    read = world.state_reader(fast)
    rng = np.random.default_rng(11)
    n = world.robot.getNumDofs()
    negative_trace = 0
    for i in range(3000):
        q = world.robot.getPositions()
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = (rng.uniform(0.0, math.pi), 10.0 ** rng.uniform(-14, -3), math.pi * (1.0 - 1e-15 * rng.uniform()), 0.0)[i % 4]
        q[0:3] = angle * axis
        world.robot.setPositions(q)
        world.robot.setVelocities(rng.normal(scale=2.0, size=n))
        read()
        world.state_vector_reference(reference)
        assert fast.tobytes() == reference.tobytes(), (i, fast - reference)
        negative_trace += 1.0 + 2.0 * math.cos(angle) <= 0.0
    assert negative_trace > 300
    world.place(1.5, 1.0, 2.9)
    positions = world.robot.getPositions()
    positions[5] += 0.3
    world.robot.setPositions(positions)
    world.robot.setVelocities(rng.normal(scale=3.0, size=n))
    touched = 0
    for _ in range(600):
        world.apply_torques(rng.normal(scale=3.0, size=12))
        world.step()
        touched += world.world.getLastCollisionResult().getNumContacts() > 0
        read()
        world.state_vector_reference(reference)
        assert fast.tobytes() == reference.tobytes()
        world.state_vector(reference)
        assert fast.tobytes() == reference.tobytes()
    assert touched > 100  # it landed


def test_torques_are_clamped_as_np_clip_does(ramp_scenario: Scenario, tmp_path: Path) -> None:
    world = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path)
    rng = np.random.default_rng(2)
    limits = world.effort_limits
    for scale in (0.1, 1.0, 10.0):
        torques = rng.normal(scale=scale, size=12) * limits
        torques[0] = limits[0]
        torques[1] = -limits[1]
        torques[2] = -0.0
        world.apply_torques(torques)
        expected = np.clip(torques, -limits, limits)
        assert world._forces[world.joint_dofs].tobytes() == expected.tobytes()
