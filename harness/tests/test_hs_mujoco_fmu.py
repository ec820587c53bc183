"""The real controller FMU in the MuJoCo world: it stands up from a drop and trots on flat ground.

The controller was tuned in DART; these runs check that it does not depend on DART's contact
model to stand and walk. The terrain and the straight reference come from the incline benchmark
at 0° (an 8 m flat map, a walk at the planner's nominal 0.5 m/s).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pfnav_harness import paths
from pfnav_harness.cosim import CoSimConfig, CoSimulation
from pfnav_harness.incline import incline_scenario, straight_plan
from pfnav_harness.metrics import rms_tracking_error, roll_pitch_yaw
from pfnav_harness.robot import RobotDescription

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
# The robot is dropped from this height (lowest foot above the ground, m).
DROP_CLEARANCE = 0.08


def test_the_fmu_stands_up_after_a_drop_in_mujoco(tmp_path: Path) -> None:
    """Dropped 8 cm in its crouch, asked to stand for 2.5 s: it lands, stands at its stand height, level, on four feet."""
    scenario = incline_scenario(0.0, "up")
    plan = straight_plan(scenario)
    stand = 2.5
    config = CoSimConfig(engine="mujoco", stand_time=stand, max_duration=stand, estimator="groundTruth")
    with CoSimulation(scenario, plan, paths.fmu_path(), ROBOT, tmp_path, config) as sim:
        sim.world.place(float(plan.x[0]), float(plan.y[0]), float(plan.yaw[0]), clearance=DROP_CLEARANCE)
        stand_code = int(sim.fmu.contract.fsm.Stand)
        nominal = float(sim.fmu.contract.stand_height)
        result = sim.run()
    log = result.log
    assert result.fall_step is None
    pos = log["base_pos"]
    # It fell freely first: no foot touched during the first 0.1 s (√(2·0.08/9.81) ≈ 0.13 s of fall).
    assert not log["contact_actual"][:100].any()
    last = slice(-200, None)
    assert np.all(log["fsm"][last] == stand_code)
    assert np.all(log["contact_actual"][last] == 1)
    height = pos[last, 2] - scenario.terrain.height(pos[last, 0], pos[last, 1])
    assert np.abs(height - nominal).max() < 0.03
    roll, pitch, _ = roll_pitch_yaw(log["base_quat"][last])
    assert np.degrees(np.abs(roll)).max() < 3.0 and np.degrees(np.abs(pitch)).max() < 3.0
    assert math.hypot(*(pos[-1, :2] - pos[0, :2])) < 0.05


def test_the_fmu_trots_forward_for_3_s_in_mujoco(tmp_path: Path) -> None:
    """After the stand-up, 3 s of walking at 0.5 m/s along a straight reference: no fall, ≥ 1.2 m forward, on the line."""
    scenario = incline_scenario(0.0, "up")
    plan = straight_plan(scenario)
    walk = 3.0
    config = CoSimConfig(engine="mujoco", max_duration=CoSimConfig().stand_time + walk, estimator="groundTruth")
    with CoSimulation(scenario, plan, paths.fmu_path(), ROBOT, tmp_path, config) as sim:
        locomotion = int(sim.fmu.contract.fsm.Locomotion)
        result = sim.run()
    log = result.log
    assert result.fall_step is None, result.stop_reason
    pos = log["base_pos"]
    k_walk = round(config.stand_time / config.physics_dt)
    forward = float(pos[-1, 0] - pos[k_walk, 0])
    assert forward > 1.2
    assert abs(float(pos[-1, 1] - plan.y[0])) < 0.1
    assert rms_tracking_error(log) < 0.1
    # A trot: the controller is in locomotion and feet leave and touch the ground.
    walking = slice(k_walk + 500, None)
    assert np.all(log["fsm"][walking] == locomotion)
    swings = np.diff(log["contact_actual"][walking].astype(np.int8), axis=0)
    assert (swings == -1).sum(axis=0).min() >= 4
    roll, pitch, _ = roll_pitch_yaw(log["base_quat"][walking])
    assert np.degrees(np.abs(roll)).max() < 10.0 and np.degrees(np.abs(pitch)).max() < 10.0
