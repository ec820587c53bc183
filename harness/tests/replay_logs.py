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
        "fsm_state_names": np.array(["Passive", "Stand", "Locomotion", "Damping"]),
        "fsm_state_codes": np.array([0, 1, 2, 4]),
        "mpc_solve_time": np.where(np.arange(n) % 97 == 0, 0.004, 0.001),
        "walk_start": np.array(0.5),
        "plan_x": np.linspace(scenario.start[0], scenario.goal.center[0], 20),
        "plan_y": np.linspace(scenario.start[1], scenario.goal.center[1], 20),
        "est_pos": base_pos + np.array([0.01, -0.01, 0.0]),
        "est_rpy": np.zeros((n, 3)),
        "push_force": np.where((t > 1.0) & (t < 1.2), 1.0, 0.0)[:, None] * [0.0, 60.0, 0.0],
    }
    if online:
        # Three updates: the first and the third put in use, each with its field; the map as each sent it.
        log["replan_t_publish"] = np.array([0.2, 1.2, 1.3])
        log["replan_t_apply"] = np.array([0.7, np.nan, 1.4])
        log["replan_in_use"] = np.array([True, False, True])
        log["replan_path_lengths"] = np.array([5, 3, 4])
        log["replan_path_x"] = np.linspace(0.5, 2.5, 12)
        log["replan_path_y"] = np.full(12, 1.0)
        heights = scenario.terrain.heights.copy()
        heights[:, 15:] = np.nan
        log["map_heights_final"] = heights
        log["map_variances_final"] = np.where(np.isfinite(heights), 0.01, np.inf)
        ny, nx = heights.shape
        log["replan_field_rows"] = np.array([0, 2])
        log["replan_field_origin"] = np.array(scenario.origin)
        log["replan_field_resolution"] = np.array(scenario.resolution)
        log["replan_field_goal"] = np.array([*scenario.goal.center, scenario.goal.radius])
        # First field along +x, second along +y.
        log["replan_field_dir_x"] = np.stack([np.ones((ny, nx)), np.zeros((ny, nx))]).astype(np.float16)
        log["replan_field_dir_y"] = np.stack([np.zeros((ny, nx)), np.ones((ny, nx))]).astype(np.float16)
        log["replan_field_speed"] = np.full((2, ny, nx), 0.3, dtype=np.float16)
        log["replan_field_cost_to_go"] = np.ones((2, ny, nx), dtype=np.float32)
        # Snapshots at 0.2 s (columns < 5 known), 1.2 s (< 10) and 1.3 s (< 12); the last is closer
        # than the recording's period to the one before and is left out there.
        known_columns = [5, 10, 12]
        snapshot_heights = np.stack([np.where(np.arange(nx) < c, scenario.terrain.heights, np.nan) for c in known_columns])
        log["map_snapshot_rows"] = np.array([0, 1, 2])
        log["map_snapshot_heights"] = snapshot_heights.astype(np.float32)
        log["map_snapshot_variances"] = np.where(np.isfinite(snapshot_heights), 0.02, np.nan).astype(np.float32)
    return log
