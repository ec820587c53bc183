"""The sweep's payload factor in the DART world: the trunk's mass, centre of mass and inertia change, the robot feels it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pfnav_harness import paths
from pfnav_harness.errors import SimulationError
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario
from pfnav_harness.world import Payload, QuadrupedWorld

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
CROUCH = ROBOT.crouch


def _settle(world: QuadrupedWorld, steps: int = 800) -> float:
    """Joint PD on the stance for `steps` physics steps; returns the base height at the end."""
    for _ in range(steps):
        s = world.state()
        world.apply_torques(120.0 * (CROUCH - s.joint_positions) - 3.0 * s.joint_velocities)
        world.step()
    return float(world.state().position[2])


def test_payload_changes_the_simulated_mass_world(ramp_scenario: Scenario, tmp_path: Path) -> None:
    plain = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path)
    offset = (0.05, -0.02, 0.01)
    loaded = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path, payload=Payload(0.2, offset))
    trunk = plain.trunk_mass
    assert loaded.trunk_mass == trunk
    assert loaded.mass == pytest.approx(plain.mass + 0.2 * trunk)
    assert loaded.base.getMass() == pytest.approx(1.2 * trunk)
    # The centre of mass moves towards the payload by m_payload / m_total of its offset.
    shift = np.asarray(loaded.base.getLocalCOM()) - np.asarray(plain.base.getLocalCOM())
    np.testing.assert_allclose(shift, np.asarray(offset) * 0.2 / 1.2, atol=1e-12)
    # Parallel-axis theorem about the new centre of mass: the pitch inertia grows by the point mass and the shift.
    before = np.asarray(plain.base.getInertia().getMoment())
    after = np.asarray(loaded.base.getInertia().getMoment())
    reduced = trunk * 0.2 * trunk / (1.2 * trunk)  # m1·m2 / (m1 + m2)
    d = np.asarray(offset)
    np.testing.assert_allclose(after - before, reduced * (d @ d * np.eye(3) - np.outer(d, d)), atol=1e-12)
    lighter = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path, payload=Payload(-0.2))
    assert lighter.mass == pytest.approx(plain.mass - 0.2 * trunk)
    # The same PD stance sags more under a heavier trunk.
    for world in (plain, loaded, lighter):
        world.place(1.5, 1.0, 0.0)
    heights = [_settle(w) for w in (lighter, plain, loaded)]
    assert heights[0] > heights[1] > heights[2]


def test_impossible_payloads_are_refused_world(ramp_scenario: Scenario, tmp_path: Path) -> None:
    with pytest.raises(SimulationError, match="mass fraction must be finite and > -1"):
        Payload(-1.0)
    with pytest.raises(SimulationError, match="3 finite coordinates"):
        Payload(0.1, (0.0, float("nan"), 0.0))
    with pytest.raises(SimulationError, match="without a positive inertia"):
        QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path, payload=Payload(-0.5, (0.0, 0.0, 0.3)))
