"""Incline scenarios (issue 19, part 5): the plane, the straight reference, the slip measure, and one
slope per direction walked by the controller FMU.

The closed-loop tests use the steepest angle the current controller passes in every direction
(20°; scripts/bench_slopes.py measures 10/20/30° and docs/slopes.md explains the failures).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness import paths
from pfnav_harness.errors import MissingArtifactError, ScenarioError
from pfnav_harness.incline import (
    DIRECTIONS,
    MIN_WALKED,
    NOMINAL_SPEED,
    WALK_DISTANCE,
    InclineOutcome,
    contacts_between,
    incline_scenario,
    incline_terrain,
    lying_pose,
    run_incline,
    stance_slips,
    straight_plan,
    support_margin,
)
from pfnav_harness.robot import RobotDescription
from pfnav_harness.world import DEFAULT_FRICTION, QuadrupedWorld

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())

# Steepest slope the current controller stands up and walks on in all three directions (with the
# stance slip below 3 cm).
PASSING_ANGLE = 20.0
# The steepest slope of the grid, walked in every direction by the steep-ground rule; stance
# feet slip more there (up to 14 cm while braking at the end of the walk down).
STEEP_ANGLE = 30.0
STEEP_MAX_SLIP = 0.15


def test_the_plane_rises_along_x_at_the_angle_with_heights_from_zero() -> None:
    terrain = incline_terrain(20.0)
    z, dzdx, dzdy = terrain.height_and_gradient(np.array([1.0, 4.0, 7.0]), np.array([2.0, 4.0, 6.0]))
    assert np.allclose(dzdx, math.tan(math.radians(20.0)))
    assert np.allclose(dzdy, 0.0)
    assert terrain.heights.min() >= 0.0
    assert z[2] - z[0] == pytest.approx(6.0 * math.tan(math.radians(20.0)))


@pytest.mark.parametrize("direction", list(DIRECTIONS))
def test_the_walk_is_centred_far_from_the_edges_and_heads_along_its_direction(direction: str) -> None:
    scenario = incline_scenario(30.0, direction)
    (x0, y0), (x1, y1) = scenario.terrain.bounds()
    start, goal = scenario.start, scenario.goal.center
    assert math.hypot(goal[0] - start[0], goal[1] - start[1]) == pytest.approx(WALK_DISTANCE)
    for x, y in (start, goal):
        assert min(x - x0, x1 - x, y - y0, y1 - y) >= 2.0
    rise = scenario.terrain.height_at(*goal) - scenario.terrain.height_at(*start)
    expected = {"up": 1.0, "down": -1.0, "across": 0.0}[direction] * WALK_DISTANCE * math.tan(math.radians(30.0))
    assert rise == pytest.approx(expected, abs=1e-9)


def test_the_straight_plan_is_timed_at_the_nominal_speed() -> None:
    scenario = incline_scenario(10.0, "across")
    plan = straight_plan(scenario)
    assert plan.duration == pytest.approx(WALK_DISTANCE / NOMINAL_SPEED)
    assert np.allclose(np.hypot(plan.vx, plan.vy), NOMINAL_SPEED)
    assert np.allclose(plan.yaw, DIRECTIONS["across"])
    assert (plan.x[-1], plan.y[-1]) == pytest.approx(scenario.goal.center)
    assert np.allclose(plan.z, scenario.terrain.height(plan.x, plan.y))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: incline_terrain(75.0), "angle"),
        (lambda: incline_terrain(float("nan")), "angle"),
        (lambda: incline_scenario(10.0, "sideways"), "direction"),
        (lambda: incline_scenario(10.0, "up", distance=7.5), "distance"),
        (lambda: straight_plan(incline_scenario(10.0, "up"), speed=0.0), "speed"),
    ],
)
def test_bad_input_is_refused_with_the_reason(call: Callable[[], object], message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        call()


def _foot_track(n: int, slide_per_step: float, roll_per_step: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """One foot on flat ground: its centre moves by the roll (r·θ) plus a slide along x."""
    theta = roll_per_step * np.arange(n)
    position = np.zeros((n, 1, 3))
    position[:, 0, 0] = radius * theta + slide_per_step * np.arange(n)
    position[:, 0, 2] = radius
    rotation = np.zeros((n, 1, 3, 3))
    c, s = np.cos(theta), np.sin(theta)
    # Rolling towards +x is a rotation about +y.
    rotation[:, 0] = np.stack([np.stack([c, 0 * c, s], -1), np.stack([0 * c, 1 + 0 * c, 0 * c], -1), np.stack([-s, 0 * c, c], -1)], -2)
    return position, rotation


def test_a_run_passes_only_standing_without_a_fall_and_walking_far_enough() -> None:
    outcome = InclineOutcome(
        30.0, "up", 0.8, "completed", True, 0.26, 0.08, 0.05, MIN_WALKED, False, None, "", False,
        0.01, 0.01, None, 10.0, 3.0, 0.7, "knee", 0.0, 0.05,
    )
    assert outcome.passed
    assert not dataclasses.replace(outcome, walked=MIN_WALKED - 0.01).passed
    assert not dataclasses.replace(outcome, fell=True).passed
    assert not dataclasses.replace(outcome, stood_up=False).passed
    # A thigh on the ground while walking is no pass; while set down lying before the stand-up it is.
    assert not dataclasses.replace(outcome, walk_contacts={"FR_thigh": 2.4}).passed
    assert dataclasses.replace(outcome, non_foot_contacts={"FR_thigh": 0.1}).passed


def test_walk_contacts_are_the_first_touches_between_the_walk_start_and_a_fall() -> None:
    touches = {"trunk": [0.2, 0.3], "FR_calf": [0.5, 2.5, 2.6], "RL_thigh": [4.0]}
    assert contacts_between(touches, 2.0, None) == {"FR_calf": 2.5, "RL_thigh": 4.0}
    assert contacts_between(touches, 2.0, 3.0) == {"FR_calf": 2.5}
    assert contacts_between(touches, 5.0, None) == {}


def test_a_rolling_foot_does_not_slip_and_a_sliding_one_does() -> None:
    n, radius, dt = 200, 0.02, 0.001
    scheduled = np.ones((n, 1), dtype=np.int8)
    touching = np.ones((n, 1), dtype=np.int8)
    rolling = _foot_track(n, 0.0, 0.001, radius)
    sliding = _foot_track(n, 0.0005, 0.0, radius)
    up = np.array([0.0, 0.0, 1.0])
    (rolled,) = stance_slips(scheduled, touching, *rolling, radius, up, dt, ("FR_toe",))
    (slid,) = stance_slips(scheduled, touching, *sliding, radius, up, dt, ("FR_toe",))
    assert rolled.foot == slid.foot == "FR_toe"
    assert rolled.slip < 1e-4
    assert slid.slip == pytest.approx(0.0005 * (n - 1))
    # Once the foot has left the ground (longer than the contact gap) its motion is not slip.
    touching[50:] = 0
    (lifted,) = stance_slips(scheduled, touching, *sliding, radius, up, dt, ("FR_toe",))
    assert lifted.slip == pytest.approx(0.0005 * 49)


def test_the_aligned_pose_leaves_the_support_polygon_on_a_steep_cross_slope(tmp_path: Path) -> None:
    """The pose the robot is placed in (body parallel to the plane) puts its centre of mass
    h·sin θ downhill of its feet: inside their polygon on flat ground, outside it 30° across."""
    margins = {}
    for angle in (0.0, 30.0):
        scenario = incline_scenario(angle, "across")
        world = QuadrupedWorld(scenario.terrain, ROBOT, tmp_path)
        world.place(*scenario.start, scenario.start_yaw)
        margins[angle] = support_margin(world)
    assert 0.1 < margins[0.0] < 0.15
    assert margins[30.0] < 0.0


def test_set_down_lying_the_robot_keeps_its_centre_of_mass_over_its_feet_at_30_across(tmp_path: Path) -> None:
    """The benchmark's start pose: the crouch bent further, inside the joint limits, low enough
    that the centre of mass stays inside the feet's polygon where the crouch leaves it."""
    scenario = incline_scenario(30.0, "across")
    world = QuadrupedWorld(scenario.terrain, ROBOT, tmp_path)
    pose = lying_pose(world)
    crouch = ROBOT.crouch
    np.testing.assert_allclose(pose[0::3], crouch[0::3])
    assert np.all(np.abs(pose[1::3]) > np.abs(crouch[1::3])) and np.all(np.abs(pose[2::3]) > np.abs(crouch[2::3]))
    joints = [world.robot.getJoint(name) for name in ROBOT.joint_names]
    assert all(j.getPositionLowerLimit(0) < q < j.getPositionUpperLimit(0) for j, q in zip(joints, pose, strict=True))
    world.place(*scenario.start, scenario.start_yaw, joint_positions=pose)
    assert support_margin(world) > 0.02


@pytest.fixture(scope="module")
def fmu() -> Path:
    try:
        return paths.fmu_path()
    except MissingArtifactError as err:
        pytest.fail(str(err), pytrace=False)


def walk_the_slope(angle: float, direction: str, fmu: Path, tmp_path: Path, max_slip: float) -> dict[str, float]:
    """Runs the incline benchmark's case and checks it passed; returns the links other than the feet that touched the ground (first time, s)."""
    run = run_incline(angle, direction, fmu, ROBOT, tmp_path, friction=DEFAULT_FRICTION)
    outcome = run.outcome
    summary = f"{angle:g}° {direction}: {outcome.stop_reason}; walked {outcome.walked:.2f} m; {outcome.fall_reason}"
    assert outcome.stood_up, summary
    assert not outcome.fell, summary
    assert outcome.walked >= MIN_WALKED, summary
    # The feet hold: a stance foot that slides by centimetres is a robot about to slip away.
    assert outcome.max_stance_slip < max_slip, summary
    assert not outcome.walk_contacts, f"{summary}; links on the ground while walking: {outcome.walk_contacts}"
    assert outcome.passed, summary
    return outcome.non_foot_contacts


@pytest.mark.parametrize("direction", list(DIRECTIONS))
def test_the_robot_stands_up_and_walks_the_slope(direction: str, fmu: Path, tmp_path: Path) -> None:
    touching = walk_the_slope(PASSING_ANGLE, direction, fmu, tmp_path, max_slip=0.03)
    assert not touching, f"links on the ground: {touching}"


@pytest.mark.parametrize("direction", list(DIRECTIONS))
def test_the_robot_walks_30_degrees(direction: str, fmu: Path, tmp_path: Path) -> None:
    """On steep ground the MPC keeps `mpc.muSlopeMargin` of friction above tan(slope), lowers the
    body and limits the reference's accelerations; with the margin at 0 (the configured μ 0.6
    alone) it falls up and across and while stopping down (docs/slopes.md). Lying on a 30° plane
    down, the thighs touch the ground as it is set down."""
    walk_the_slope(STEEP_ANGLE, direction, fmu, tmp_path, max_slip=STEEP_MAX_SLIP)
