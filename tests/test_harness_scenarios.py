"""The planner's exported scenarios become a DART world the URDF robot can stand in."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from pfnav_harness.pipeline import export_scenario
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import (
    Scenario,
    paper_scenario_names,
    planner_scenario_names,
)
from pfnav_harness.world import QuadrupedWorld


def test_the_paper_scenarios_are_the_planners(
    pf_plan_bin: Path, paper_scenarios: dict[str, Scenario]
) -> None:
    # The scenarios are defined once, in the planner: the harness's names are its list, and what
    # the harness loads is the planner's export (seed, start, goal, map size), field for field.
    names = planner_scenario_names(pf_plan_bin)
    assert paper_scenario_names() == names
    listed = json.loads(
        subprocess.run(
            [str(pf_plan_bin), "scenario", "list", "--json"],
            capture_output=True,
            text=True,
            check=True,
            timeout=120,
        ).stdout
    )
    for entry in listed:
        scenario = paper_scenarios[entry["name"]]
        assert scenario.seed == entry["seed"]
        assert (
            scenario.start == tuple(entry["start"])
            and scenario.start_yaw == entry["start_yaw"]
        )
        assert (
            scenario.goal.center == tuple(entry["goal"]["center"])
            and scenario.goal.radius == entry["goal"]["radius"]
        )
        assert scenario.terrain.shape == (entry["height"], entry["width"])
        assert (
            scenario.terrain.origin == tuple(entry["origin"])
            and scenario.resolution == entry["resolution"]
        )
        assert scenario.traversability == entry["traversability"]


@pytest.mark.parametrize("name", paper_scenario_names())
def test_exported_scenario_is_a_standable_world(
    name: str,
    paper_scenarios: dict[str, Scenario],
    robot: RobotDescription,
    tmp_path: Path,
) -> None:
    scenario = paper_scenarios[name]
    terrain = scenario.terrain
    (x0, y0), (x1, y1) = terrain.bounds()
    assert x1 - x0 >= 8.0 and y1 - y0 >= 8.0, "the paper's scenarios are 10-20 m across"
    assert x0 < scenario.start[0] < x1 and y0 < scenario.start[1] < y1
    assert not terrain.is_obstacle(*scenario.start)
    assert not terrain.is_obstacle(*scenario.goal.center)
    # The physics mesh is the planner's map: every cell centre is a mesh vertex at the map's height.
    vertices = terrain.vertices()
    np.testing.assert_array_equal(vertices[:, 2], terrain.heights.ravel())

    world = QuadrupedWorld(terrain, robot, tmp_path)
    world.place(scenario.start[0], scenario.start[1], scenario.start_yaw)
    for _ in range(800):
        s = world.state()
        world.apply_torques(
            150.0 * (robot.crouch - s.joint_positions) - 3.0 * s.joint_velocities
        )
        world.step()
    s = world.state()
    ground = terrain.height_at(float(s.position[0]), float(s.position[1]))
    assert 0.15 < s.position[2] - ground < 0.4
    assert (
        np.hypot(s.position[0] - scenario.start[0], s.position[1] - scenario.start[1])
        < 0.15
    )
    assert world.foot_contacts().sum() >= 3


def test_surprise_is_exported_by_name_with_its_prior(
    pf_plan_bin: Path, paper_scenarios: dict[str, Scenario], tmp_path: Path
) -> None:
    # `surprise` is a built-in scenario but not one of the paper's: the demo's default list
    # leaves it out, `--all` lists it, and it exports by name with the map the robot is told
    # beforehand (the prior) beside the true one.
    assert "surprise" not in paper_scenario_names()
    assert planner_scenario_names(pf_plan_bin, every=True) == (
        *paper_scenario_names(),
        "surprise",
    )
    assert all(s.prior is None for s in paper_scenarios.values())
    listed = json.loads(
        subprocess.run(
            [str(pf_plan_bin), "scenario", "list", "--all", "--json"],
            capture_output=True,
            text=True,
            check=True,
            timeout=120,
        ).stdout
    )
    assert {e["name"]: (e["paper"], e["prior"]) for e in listed}["surprise"] == (
        False,
        True,
    )

    scenario = export_scenario(pf_plan_bin, "surprise", tmp_path)
    assert scenario.seed == 4
    prior, truth = scenario.prior, scenario.terrain
    assert prior is not None and truth.obstacles is not None
    assert prior.shape == truth.shape and prior.origin == truth.origin
    assert prior.resolution == truth.resolution == 0.125
    assert prior.obstacles is None
    # The prior shows flat ground where the true map has its trench, and agrees elsewhere.
    np.testing.assert_array_equal(
        prior.heights[~truth.obstacles], truth.heights[~truth.obstacles]
    )
    assert np.all(truth.heights[truth.obstacles] < prior.heights[truth.obstacles])
    # The trench crosses the straight line start -> goal, at least 4 m from the start.
    (sx, sy), (gx, gy) = scenario.start, scenario.goal.center
    ts = np.linspace(0.0, 1.0, 2000)
    on_line = [(sx + t * (gx - sx), sy + t * (gy - sy)) for t in ts]
    blocked = [np.hypot(x - sx, y - sy) for x, y in on_line if truth.is_obstacle(x, y)]
    assert blocked and min(blocked) >= 4.0
