"""The master loop's fast path against the loop it replaced (reference_loop.py), with the real FMU.

Each case runs the same short co-simulation twice, once with `CoSimulation._advance` and once with
`advance_reference` (the loop of commit 93568a0) in its place, and requires the two logs to be
equal bit for bit. Left out are the two wall-clock measurements a log holds: `mpc_solve_time` (the
MPC solver's own timer) and `replan_latency` (the planner's answer time).

The cases cover what the fast path treats specially: a trajectory sampled in blocks (and resampled
after online replans), the height map sent only when its block moves (or, in the estimated
frame, when the estimate has moved its registration by more than the tolerance), pushes, the
feedback law sampled every step, several communication steps.
"""

from __future__ import annotations

import types
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from reference_loop import advance_reference
from test_hs_navigation_frame import radial_field
from test_hs_online import ScriptedClient

from pfnav_harness import paths
from pfnav_harness.body_sensors import BodySensorConfig
from pfnav_harness.cosim import CoSimConfig, CoSimulation, RunResult
from pfnav_harness.online import OnlineConfig, OnlineNavigator
from pfnav_harness.planner_client import Plan
from pfnav_harness.pushes import PushSchedule, horizontal_push
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
WALL_CLOCK_KEYS = ("mpc_solve_time", "replan_latency")


def walking_plan(speed: float = 0.3, seconds: float = 4.0) -> Plan:
    """From (0.5, 1.0) up the ramp along +x, with a slight turn (the yaw and y columns move too)."""
    t = np.linspace(0.0, seconds, round(seconds / 0.1) + 1)
    x = 0.5 + speed * t
    y = 1.0 + 0.05 * np.sin(t)
    yaw = np.arctan2(np.gradient(y, t), np.gradient(x, t))
    n = len(t)
    return Plan("pf", t, x, y, np.zeros(n), yaw, np.gradient(x, t), np.gradient(y, t), np.gradient(yaw, t))


def run(scenario: Scenario, plan: Plan, config: CoSimConfig, tmp_path: Path, reference: bool, **kwargs: object) -> RunResult:
    with CoSimulation(scenario, plan, paths.fmu_path(), ROBOT, tmp_path, config, **kwargs) as sim:  # type: ignore[arg-type]
        if reference:
            sim._advance = types.MethodType(advance_reference, sim)  # type: ignore[method-assign]
        return sim.run()


def assert_same_log(fast: RunResult, reference: RunResult) -> None:
    assert fast.stop_reason == reference.stop_reason
    assert set(fast.log) == set(reference.log)
    for key, value in reference.log.items():
        if key not in WALL_CLOCK_KEYS:
            assert np.asarray(fast.log[key]).tobytes() == np.asarray(value).tobytes(), key
    assert fast.timing.simulated == reference.timing.simulated


# Factories: a push schedule remembers its heading-relative forces, so each run gets its own.
CASES: dict[str, Callable[[], CoSimConfig]] = {
    "1 ms, ground truth": lambda: CoSimConfig(comm_step=0.001, max_duration=2.6, estimator="groundTruth"),
    "2 ms, kalman, contact sensor, pushes": lambda: CoSimConfig(
        comm_step=0.002,
        max_duration=2.6,
        estimator="kalman",
        body_sensors=BodySensorConfig(seed=3, fix_rate=5.0, fix_noise=0.02, contact_sensor=True),
        pushes=PushSchedule((horizontal_push(25.0, 0.0, 0.3, 0.1), horizontal_push(20.0, 90.0, 0.7, 0.05, heading_relative=True))),
    ),
    "5 ms, ground truth, no height map": lambda: CoSimConfig(comm_step=0.005, max_duration=2.6, height_map=False, estimator="groundTruth"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_fast_loop_logs_what_the_reference_loop_logs(case: str, ramp_scenario: Scenario, tmp_path: Path) -> None:
    plan = walking_plan()
    fast = run(ramp_scenario, plan, CASES[case](), tmp_path, reference=False)
    reference = run(ramp_scenario, plan, CASES[case](), tmp_path, reference=True)
    # The robot walked: the case exercises the walk, not only the stand.
    assert np.ptp(fast.log["base_pos"][:, 0]) > 0.05, case
    assert_same_log(fast, reference)


def test_the_fast_loop_follows_the_feedback_law_as_the_reference_loop(ramp_scenario: Scenario, tmp_path: Path) -> None:
    config = CoSimConfig(comm_step=0.002, max_duration=2.4, follow="feedback", estimator="kalman", body_sensors=BodySensorConfig(seed=4))
    plan = walking_plan()
    field = radial_field(ramp_scenario)
    fast = run(ramp_scenario, plan, config, tmp_path, reference=False, field=field)
    reference = run(ramp_scenario, plan, config, tmp_path, reference=True, field=field)
    assert_same_log(fast, reference)


def test_online_replans_reach_the_fast_loop_as_the_reference_loop(ramp_scenario: Scenario, tmp_path: Path) -> None:
    """Replans swap the plan mid-walk: the block-sampled reference must follow from that step on."""
    config = CoSimConfig(comm_step=0.002, max_duration=3.0, estimator="groundTruth")

    def navigator() -> tuple[OnlineNavigator, Plan]:
        nav = OnlineNavigator(ScriptedClient(), ramp_scenario, OnlineConfig(update_period=0.3, apply_delay=0.1))
        first = nav.start(0.5, 1.0, 0.0, timeout=1.0, retries=0)
        assert first.plan is not None
        return nav, first.plan

    nav, plan = navigator()
    fast = run(ramp_scenario, plan, config, tmp_path, reference=False, online=nav)
    nav, plan = navigator()
    reference = run(ramp_scenario, plan, config, tmp_path, reference=True, online=nav)
    assert int(np.sum(fast.log["replan_in_use"])) >= 3
    assert_same_log(fast, reference)
