from __future__ import annotations

import math

import numpy as np
import pytest

from pfnav_harness.errors import PlannerError
from pfnav_harness.planner_client import Plan
from pfnav_harness.reference import T_DZDX, T_HEIGHT, VX, YAW, ReferenceTrajectory, X, Y, Z
from pfnav_harness.reference_source import TrajectorySource
from pfnav_harness.scenario import Scenario


def make_plan(t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> Plan:
    n = len(t)
    vx = np.gradient(x, t)
    vy = np.gradient(y, t)
    return Plan("pf", t, x, y, np.zeros(n), yaw, vx, vy, np.gradient(np.unwrap(yaw), t))


def test_interpolates_and_holds(ramp_scenario: Scenario) -> None:
    t = np.array([0.0, 1.0, 2.0])
    plan = make_plan(t, np.array([0.5, 1.0, 1.5]), np.array([1.0, 1.0, 1.0]), np.zeros(3))
    ref = ReferenceTrajectory(plan, ramp_scenario.terrain)
    row = np.zeros(10)
    ref.sample(0.25, row)
    assert row[X] == pytest.approx(0.625) and row[Y] == pytest.approx(1.0)
    assert row[VX] == pytest.approx(0.5)
    # Heights come from the physics surface (ramp z = 0.1 + 0.2 x), not from the plan's z = 0.
    assert row[Z] == pytest.approx(0.1 + 0.2 * 0.625)
    assert row[T_HEIGHT] == pytest.approx(0.1 + 0.2 * 0.625, abs=1e-9)
    assert row[T_DZDX] == pytest.approx(0.2, abs=1e-9)
    ref.sample(-1.0, row)
    assert row[X] == pytest.approx(0.5) and row[VX] == 0.0
    ref.sample(10.0, row)
    assert row[X] == pytest.approx(1.5) and row[VX] == 0.0


def test_yaw_is_interpolated_across_the_wrap(ramp_scenario: Scenario) -> None:
    t = np.array([0.0, 1.0])
    yaw = np.array([math.pi - 0.1, -math.pi + 0.1])  # 0.2 rad turn through ±π
    plan = make_plan(t, np.array([1.0, 1.1]), np.array([1.0, 1.0]), yaw)
    ref = ReferenceTrajectory(plan, ramp_scenario.terrain)
    row = np.zeros(10)
    ref.sample(0.5, row)
    assert abs(abs(row[YAW]) - math.pi) < 1e-9


def test_invalid_plans_are_rejected(ramp_scenario: Scenario) -> None:
    with pytest.raises(PlannerError, match="at least 2"):
        one = np.ones(1)
        ReferenceTrajectory(Plan("pf", one * 0.0, one, one, one, one, one, one, one), ramp_scenario.terrain)
    bad = make_plan(np.array([0.0, 1.0]), np.array([1.0, 1.2]), np.array([1.0, 1.0]), np.zeros(2))
    bad.x[1] = np.nan
    with pytest.raises(PlannerError, match="NaN"):
        ReferenceTrajectory(bad, ramp_scenario.terrain)
    back = make_plan(np.array([0.0, 1.0]), np.array([1.0, 1.2]), np.array([1.0, 1.0]), np.zeros(2))
    back.t[1] = 0.0
    with pytest.raises(PlannerError, match="increasing"):
        ReferenceTrajectory(back, ramp_scenario.terrain)


def test_heading_smoothing_keeps_positions_and_removes_zig_zag(ramp_scenario: Scenario) -> None:
    # A staircase path alternating heading 0 and 45° every sample, like an 8-connected grid path.
    t = np.arange(0.0, 4.0, 0.1)
    yaw = np.where(np.arange(len(t)) % 2 == 0, 0.0, math.pi / 4)
    step = 0.05 * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    xy = np.vstack([[0.5, 0.5], 0.5 + np.cumsum(step, axis=0)[:-1]])
    plan = make_plan(t, xy[:, 0], xy[:, 1], yaw)
    smooth = ReferenceTrajectory(plan, ramp_scenario.terrain, heading_smoothing=1.0)
    raw = ReferenceTrajectory(plan, ramp_scenario.terrain)
    np.testing.assert_array_equal(smooth.rows[:, [X, Y]], raw.rows[:, [X, Y]])
    middle = slice(10, 30)
    # The mean direction of the zig-zag is 22.5°; smoothed headings stay within a few degrees of it.
    assert np.max(np.abs(smooth.rows[middle, YAW] - math.pi / 8)) < math.radians(5.0)
    assert np.max(np.abs(raw.rows[middle, YAW] - math.pi / 8)) == pytest.approx(math.pi / 8)


def test_a_replanned_trajectory_continues_from_where_it_was_planned(ramp_scenario: Scenario) -> None:
    """Trajectory mode online: the new plan starts at the pose of its map update and is sampled from then on."""
    from pfnav_harness.reference_source import TrajectorySource

    t = np.linspace(0.0, 4.0, 41)
    first = make_plan(t, 0.2 + 0.4 * t, np.full_like(t, 1.0), np.zeros_like(t))
    source = TrajectorySource(first, ramp_scenario.terrain, 0.3, 0.0)
    # A time-indexed reference ignores the pose and the frame offset.
    pose, offset = np.array([5.0, 5.0, 1.0]), np.array([0.3, 0.3, 0.1, 0.0])
    before, after = np.zeros(10), np.zeros(10)
    planned_at, applied_at = 1.0, 1.2
    source.sample(applied_at, pose, offset, True, before)
    # Replanned at t = 1 s from the pose the first plan had then, bending towards y = 1.4 at the same speed.
    second = make_plan(t, 0.6 + 0.4 * t * np.cos(0.3), 1.0 + 0.4 * t * np.sin(0.3), np.full_like(t, 0.3))
    source.replace(second, planned_at)
    source.sample(applied_at, pose, offset, True, after)
    # No jump at the swap beyond what the bend accumulates in the 0.2 s latency (0.08 m at 0.3 rad).
    jump = math.hypot(after[X] - before[X], after[Y] - before[Y])
    assert jump == pytest.approx(math.hypot(0.08 * math.cos(0.3) - 0.08, 0.08 * math.sin(0.3)), abs=1e-9)
    source.sample(planned_at + 2.0, pose, offset, True, after)
    assert after[X] == pytest.approx(0.6 + 0.8 * math.cos(0.3), abs=1e-9)
    assert after[Y] == pytest.approx(1.0 + 0.8 * math.sin(0.3), abs=1e-9)


def test_block_sampling_is_step_sampling_bit_for_bit(ramp_scenario: Scenario) -> None:
    """`sample_block` (the co-simulation samples a trajectory for many steps at once) gives each
    row exactly as `sample` does: before, inside and after the plan, across the yaw wrap, on plan
    sample times, before and after the walk starts, and after a replan."""
    t = np.linspace(0.0, 3.0, 31)
    plan = make_plan(t, 0.5 + 0.3 * t, 1.0 + 0.1 * np.sin(t), np.unwrap(3.0 + 0.4 * t))
    ref = ReferenceTrajectory(plan, ramp_scenario.terrain, heading_smoothing=0.5)
    tau = np.concatenate([np.arange(-500, 3600) * 0.001, t, [-0.0, 0.0, 3.0, 1e9]])
    block = np.zeros((len(tau), 10))
    ref.sample_block(tau, block)
    row = np.zeros(10)
    for i, value in enumerate(tau.tolist()):
        ref.sample(value, row)
        assert block[i].tobytes() == row.tobytes(), (i, value)
    source = TrajectorySource(plan, ramp_scenario.terrain, 0.3, 0.5)
    source.replace(make_plan(t, 1.0 + 0.2 * t, 1.0 + 0.0 * t, 0.1 * t), planned_at=0.7)
    clock = np.arange(0, 4000) * 0.001
    walking = clock >= 1.5
    source.sample_block(clock - 1.5, walking, block[: len(clock)])
    pose, offset = np.zeros(3), np.zeros(4)
    for i in range(len(clock)):
        source.sample(float(clock[i]) - 1.5, pose, offset, bool(walking[i]), row)
        assert block[i].tobytes() == row.tobytes(), i
