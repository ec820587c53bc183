"""Short synthetic run logs in the co-simulation's format, for the replay tests (no FMU, no physics)."""

from __future__ import annotations

import numpy as np

from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario

DURATION = 2.0
DT = 0.001


def synthetic_log(scenario: Scenario, robot: RobotDescription, online: bool = False) -> dict[str, np.ndarray]:
    """A short log in the co-simulation's format: the robot in its crouch, sliding along x over the terrain with a gait-like contact pattern."""
    t = np.arange(0.0, DURATION, DT)
    n = len(t)
    x = scenario.start[0] + 0.3 * t
    y = np.full(n, scenario.start[1])
    base_pos = np.stack([x, y, scenario.terrain.height(x, y) + 0.3], axis=1)
    base_quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    q = np.tile(robot.crouch, (n, 1)) + 0.1 * np.sin(2.0 * np.pi * t)[:, None]
    contact = ((np.floor(t / 0.25)[:, None] + np.arange(4)) % 2).astype(np.int8)
    log: dict[str, np.ndarray] = {
        "t": t,
        "base_pos": base_pos,
        "base_quat": base_quat,
        "base_vel": np.zeros((n, 3)),
        "base_omega": np.zeros((n, 3)),
        "q": q,
        "dq": np.zeros((n, 12)),
        "tau": np.sin(t)[:, None] * np.arange(1, 13),
        "ref": np.concatenate([base_pos + np.array([0.05, 0.0, 0.0]), np.zeros((n, 7))], axis=1),
        "forces": np.tile([0.0, 0.0, 30.0], (n, 4)) * contact.repeat(3, axis=1),
        "contact_scheduled": contact,
        "contact_actual": contact,
        "fsm": np.where(t < 0.5, 1, 2).astype(np.int8),
        "fsm_damping": np.array(4),
        "mpc_solve_time": np.where(np.arange(n) % 97 == 0, 0.004, 0.001),
        "walk_start": np.array(0.5),
        "plan_x": np.linspace(scenario.start[0], scenario.goal.center[0], 20),
        "plan_y": np.linspace(scenario.start[1], scenario.goal.center[1], 20),
        "est_pos": base_pos + np.array([0.01, -0.01, 0.0]),
        "est_rpy": np.zeros((n, 3)),
        "push_force": np.where((t > 1.0) & (t < 1.2), 1.0, 0.0)[:, None] * [0.0, 60.0, 0.0],
    }
    if online:
        log["replan_t_apply"] = np.array([0.7, np.nan, 1.4])
        log["replan_in_use"] = np.array([True, False, True])
        log["replan_path_lengths"] = np.array([5, 3, 4])
        log["replan_path_x"] = np.linspace(0.5, 2.5, 12)
        log["replan_path_y"] = np.full(12, 1.0)
        heights = scenario.terrain.heights.copy()
        heights[:, 15:] = np.nan
        log["map_heights_final"] = heights
        log["map_variances_final"] = np.where(np.isfinite(heights), 0.01, np.inf)
    return log
