"""Online navigation end to end: sensing, map updates over LCM, replanning, the feedback field, pushes.

Planner service over LCM (udpm, private network namespace) → feedback field → follower → controller
FMU (fmpy) → DART. Short runs; the full-length campaign is `scripts/online_campaign.py`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pfnav_harness.cosim import CoSimConfig
from pfnav_harness.metrics import TraversabilityField
from pfnav_harness.online import OnlineConfig
from pfnav_harness.pipeline import export_scenario, simulate, simulate_online
from pfnav_harness.planner_client import PlannerClient, StartPose
from pfnav_harness.pushes import PushSchedule, parse_push
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario


@pytest.fixture(scope="module")
def surprise(pf_plan_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Scenario:
    return export_scenario(pf_plan_bin, "surprise", tmp_path_factory.mktemp("surprise"))


def test_surprise_trench_is_seen_and_walked_around_while_bad_updates_are_refused(
    planner: PlannerClient,
    surprise: Scenario,
    fmu_file: Path,
    robot: RobotDescription,
    tmp_path: Path,
) -> None:
    config = CoSimConfig(follow="feedback", stand_time=1.5, max_duration=16.0, estimator="groundTruth")
    online = OnlineConfig(bad_updates=("nan", "shape", "stale"))
    outcome = simulate_online(
        planner,
        surprise,
        fmu_file,
        robot,
        tmp_path,
        config,
        online,
        plan_timeout=120.0,
        retries=2,
        show_progress=False,
    )
    log = outcome.result.log
    m = outcome.metrics
    o = outcome.online
    assert o is not None
    assert not m.fell, m.fall_reason

    # Updates at 2 Hz of simulated time, and answers to them (how fast is a benchmark's question:
    # scripts/online_campaign.py reports the latencies).
    assert o.update_rate == pytest.approx(2.0, abs=0.15)
    answered = np.isfinite(log["replan_latency"])
    assert answered.sum() >= 0.8 * len(answered), log["replan_outcome"]

    # Each bad update got an error with its reason and the robot kept the plan it had.
    outcomes = dict(
        zip(log["replan_kind"].tolist(), log["replan_outcome"].tolist(), strict=False)
    )
    assert (
        "not finite" in outcomes["nan"] and "kept the last plan" in outcomes["nan"]
    ), outcomes["nan"]
    assert "grid changed" in outcomes["shape"], outcomes["shape"]
    assert "stale" in outcomes["stale"], outcomes["stale"]
    # ... and kept walking through them (updates 2-4 go out at 1.0, 1.5, 2.0 s of walking).
    t = log["t"] - float(log["walk_start"])
    pos = log["base_pos"]
    during = (t >= 1.0) & (t <= 2.5)
    assert np.hypot(*(pos[during][-1, :2] - pos[during][0, :2])) > 0.3

    # The first plan runs straight through the trench it cannot know about; once the sensor sees
    # the trench the plan in use goes around it.
    field = TraversabilityField(surprise.terrain, surprise.traversability)
    first = field.measure(log["plan_x"], log["plan_y"])
    assert first.length_in_obstacles > 0.5
    lengths = log["replan_path_lengths"]
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    last_used = int(np.nonzero(log["replan_in_use"])[0][-1])
    last_x = log["replan_path_x"][offsets[last_used] : offsets[last_used + 1]]
    last_y = log["replan_path_y"][offsets[last_used] : offsets[last_used + 1]]
    # It turns off the direct line towards one end of the trench.
    (sx, sy), (gx, gy) = surprise.start, surprise.goal.center
    offset = np.abs((gx - sx) * (last_y - sy) - (gy - sy) * (last_x - sx)) / np.hypot(gx - sx, gy - sy)
    assert offset.max() > 1.0
    # The robot itself never stepped into the trench.
    assert not any(
        surprise.terrain.is_obstacle(float(x), float(y)) for x, y in pos[::20, :2]
    )


def test_a_pushed_robot_heads_for_the_goal_from_where_it_landed(
    planner: PlannerClient,
    paper_scenarios: dict[str, Scenario],
    fmu_file: Path,
    robot: RobotDescription,
    tmp_path: Path,
) -> None:
    scenario = paper_scenarios["c_shape"]
    seq = planner.publish_map(scenario.terrain)
    answer = planner.request_answer(
        StartPose(scenario.start[0], scenario.start[1], scenario.start_yaw),
        scenario.goal,
        "pf",
        seq,
        timeout=120.0,
    )
    assert answer.field is not None and answer.plan is not None
    push = parse_push("60@side:3.0+0.2")
    config = CoSimConfig(
        follow="feedback",
        stand_time=1.5,
        max_duration=11.5,
        pushes=PushSchedule([push]),
        estimator="groundTruth",
    )
    outcome = simulate(
        scenario,
        answer.plan,
        fmu_file,
        robot,
        tmp_path,
        config,
        show_progress=False,
        feedback_field=answer.field,
    )
    log = outcome.result.log
    m = outcome.metrics
    assert not m.fell, m.fall_reason
    t = log["t"] - float(log["walk_start"])
    pushed = np.any(log["push_force"] != 0.0, axis=1)
    assert pushed.sum() == 200 and t[pushed][0] == pytest.approx(3.0, abs=1e-6)
    # The push moved the robot off the path ...
    assert m.max_path_deviation > 0.05
    # ... and the field took it on towards the goal from there: cost-to-go falls after the push.
    after = t >= 3.5
    cost = np.array(
        [
            answer.field.sample(float(x), float(y)).cost_to_go
            for x, y in log["base_pos"][after][::100, :2]
        ]
    )  # type: ignore[union-attr]
    assert cost[-1] < 0.85 * cost[0]
    assert np.all(np.diff(cost) < 0.05)
