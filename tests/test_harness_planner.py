"""The harness's LCM client against the real pf-planner-service (private network namespace)."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from pfnav_harness.metrics import TraversabilityField, path_cost
from pfnav_harness.planner_client import ROBOT_FOOTPRINT_RADIUS, Plan
from pfnav_harness.scenario import Scenario


@pytest.mark.parametrize("method", ["pf", "astar"])
def test_c_shape_plans_over_lcm(
    method: str,
    plan_for: Callable[[str, str], Plan],
    paper_scenarios: dict[str, Scenario],
) -> None:
    scenario = paper_scenarios["c_shape"]
    plan = plan_for("c_shape", method)
    assert plan.method == method
    assert len(plan) >= 10
    assert np.hypot(plan.x[0] - scenario.start[0], plan.y[0] - scenario.start[1]) < 0.3
    goal_distance = np.hypot(
        plan.x[-1] - scenario.goal.center[0], plan.y[-1] - scenario.goal.center[1]
    )
    assert goal_distance <= scenario.goal.radius + 1e-6
    assert plan.metrics["reached_goal"] == 1.0
    # Path never enters a hard obstacle.
    assert not any(
        scenario.terrain.is_obstacle(float(x), float(y))
        for x, y in zip(plan.x, plan.y, strict=True)
    )
    # The reply's ∫p ds is of the planner's path; the harness measures the re-timed trajectory
    # through it (corners rounded by the sampling), with the planner's cost model: close, not equal.
    field = TraversabilityField(
        scenario.terrain,
        {**scenario.traversability, "footprint_radius_m": ROBOT_FOOTPRINT_RADIUS},
    )
    cost, length = path_cost(field, plan.x, plan.y)
    assert length == pytest.approx(plan.metrics["length"], rel=0.01)
    assert cost == pytest.approx(plan.metrics["cost"], rel=0.01)


@pytest.mark.parametrize("footprint", [0.0, ROBOT_FOOTPRINT_RADIUS])
def test_the_harness_reports_the_planners_cost_of_every_plan(
    footprint: float,
    paper_scenarios: dict[str, Scenario],
    pf_plan_bin: Path,
    tmp_path: Path,
) -> None:
    # One cost model: on every paper scenario and for every method, the ∫p ds the harness reports
    # for a planned path is the planner's own figure for that plan (`pf-plan plan` on the exported
    # map, footprint as the service is started with).
    for name, scenario in paper_scenarios.items():
        assert scenario.source is not None
        out = tmp_path / f"{name}_{footprint}"
        subprocess.run(
            [
                str(pf_plan_bin),
                "plan",
                "--map",
                str(scenario.source),
                "--method",
                "all",
                f"--footprint-radius={footprint}",
                "--out",
                str(out),
            ],
            check=True,
            capture_output=True,
            timeout=600,
        )
        field = TraversabilityField(
            scenario.terrain,
            {**scenario.traversability, "footprint_radius_m": footprint},
        )
        plans = sorted(out.glob(f"{name}_*.json"))
        assert [p.stem.removeprefix(f"{name}_") for p in plans] == [
            "astar-admissible",
            "astar",
            "dijkstra",
            "pf",
        ]
        for plan_file in plans:
            planned = json.loads(plan_file.read_text())
            path = np.array(planned["path"], dtype=np.float64)
            cost, length = path_cost(field, path[:, 0], path[:, 1])
            expected = planned["metrics"]
            assert cost == pytest.approx(
                expected["cost_integral"], rel=1e-9, abs=0.0
            ), plan_file.name
            assert length == pytest.approx(expected["length"], rel=1e-9, abs=0.0), (
                plan_file.name
            )


def test_pf_is_cheaper_than_astar_on_c_shape(
    plan_for: Callable[[str, str], Plan],
) -> None:
    # The paper's claim, seen through the wire: ∫p ds of P-F well below A*'s on c_shape.
    assert (
        plan_for("c_shape", "pf").metrics["cost"]
        < 0.9 * plan_for("c_shape", "astar").metrics["cost"]
    )
