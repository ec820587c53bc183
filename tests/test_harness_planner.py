"""The harness's LCM client against the real pf-planner-service (private network namespace)."""

from __future__ import annotations

from collections.abc import Callable

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
    # The planner's own ∫p ds and the harness's re-evaluation of it on the same map agree: the metric
    # the report compares executed against planned paths with is the planner's metric.
    field = TraversabilityField(scenario.terrain, {**scenario.traversability, "footprint_radius_m": ROBOT_FOOTPRINT_RADIUS})
    cost, length = path_cost(field, plan.x, plan.y)
    assert length == pytest.approx(plan.metrics["length"], rel=0.02)
    assert cost == pytest.approx(plan.metrics["cost"], rel=0.03)


def test_pf_is_cheaper_than_astar_on_c_shape(
    plan_for: Callable[[str, str], Plan],
) -> None:
    # The paper's claim, seen through the wire: ∫p ds of P-F well below A*'s on c_shape.
    assert (
        plan_for("c_shape", "pf").metrics["cost"]
        < 0.9 * plan_for("c_shape", "astar").metrics["cost"]
    )
