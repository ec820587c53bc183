from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness.errors import MissingArtifactError
from pfnav_harness.fmu_runner import FmuContract
from pfnav_harness.metrics import (
    CostModelError,
    FallThresholds,
    TraversabilityField,
    compute_metrics,
    path_cost,
    roll_pitch_yaw,
    wrap_angle,
)
from pfnav_harness.scenario import GoalRegion, Scenario, Terrain


def quat_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def straight_log(scenario: Scenario, offset: float, n: int = 2001, dt: float = 0.001, height: float = 0.28) -> dict[str, np.ndarray]:
    """Reference along y = 1 from x = 0.5 at 0.5 m/s; the base walks `offset` m to its left."""
    t = np.arange(n) * dt
    x = 0.5 + 0.5 * t
    ref = np.zeros((n, 10))
    ref[:, 0] = x
    ref[:, 1] = 1.0
    ref[:, 4] = 0.5
    pos = np.stack([x, np.full(n, 1.0 + offset), scenario.terrain.height(x, 1.0 + offset) + height], axis=1)
    quat = np.tile(quat_from_rpy(0.0, 0.0, 0.0), (n, 1))
    tau = np.full((n, 12), 2.0)
    return {
        "t": t,
        "base_pos": pos,
        "base_quat": quat,
        "ref": ref,
        "tau": tau,
        "walk_start": np.array(0.0),
        "plan_x": np.array([0.5, 1.5]),
        "plan_y": np.array([1.0, 1.0]),
    }


def test_constant_offset_gives_that_error(ramp_scenario: Scenario) -> None:
    field = TraversabilityField(ramp_scenario.terrain, ramp_scenario.traversability)
    log = straight_log(ramp_scenario, 0.07)
    m = compute_metrics(log, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf")
    assert m.rms_error == pytest.approx(0.07, abs=1e-12)
    assert m.max_error == pytest.approx(0.07, abs=1e-12)
    assert m.rms_heading_error_deg == pytest.approx(0.0, abs=1e-9)
    assert not m.fell
    # 12 joints × 2² N²m² × 2.001 s (the first sample counts one dt as well).
    assert m.effort == pytest.approx(12 * 4.0 * 2.001, rel=1e-9)
    assert m.executed_length == pytest.approx(1.0, abs=1e-9)
    assert m.planned_length == pytest.approx(1.0, abs=1e-12)
    assert not m.goal_reached  # ends at x = 1.5, goal at 2.5 ± 0.3
    assert m.final_distance_to_goal == pytest.approx(math.hypot(1.0, 0.07), abs=1e-9)


def test_goal_time_and_heading_error(ramp_scenario: Scenario) -> None:
    field = TraversabilityField(ramp_scenario.terrain, ramp_scenario.traversability)
    log = straight_log(ramp_scenario, 0.0, n=5001)
    log["base_quat"] = np.tile(quat_from_rpy(0.0, 0.0, math.radians(10.0)), (len(log["t"]), 1))
    log["walk_start"] = np.array(0.5)
    m = compute_metrics(log, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf")
    assert m.goal_reached
    # The base enters the disc of radius 0.3 around x = 2.5 at x = 2.2, i.e. t = 3.4 s; walking started at 0.5 s.
    assert m.time_to_goal == pytest.approx(2.9, abs=2e-3)
    assert m.rms_heading_error_deg == pytest.approx(10.0, abs=1e-9)


def test_falls_are_detected_by_height_and_tilt(ramp_scenario: Scenario, fmu_contract: FmuContract) -> None:
    field = TraversabilityField(ramp_scenario.terrain, ramp_scenario.traversability)
    low = straight_log(ramp_scenario, 0.0, height=0.05)
    m = compute_metrics(low, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf", FallThresholds(min_base_height=0.12))
    assert m.fell and m.fall_time == pytest.approx(0.0) and "above ground" in m.fall_reason

    tilted = straight_log(ramp_scenario, 0.0)
    n = len(tilted["t"])
    tilted["base_quat"][n // 2 :] = quat_from_rpy(1.4, 0.0, 0.0)
    m = compute_metrics(tilted, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf")
    assert m.fell and m.fall_time == pytest.approx(tilted["t"][n // 2]) and "roll" in m.fall_reason
    # Judged where the co-simulation looks: a tilt from a step between two looks counts at the next.
    tilted["base_quat"][:] = quat_from_rpy(0.0, 0.0, 0.0)
    tilted["base_quat"][n // 2 + 3 :] = quat_from_rpy(0.0, -1.4, 0.0)
    m = compute_metrics(tilted, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf")
    assert m.fell and m.fall_time == pytest.approx(tilted["t"][n // 2 + 10]) and "pitch" in m.fall_reason
    # 1.2 rad: a steep slope's tilt on top of 1 rad, still standing.
    tilted["base_quat"][:] = quat_from_rpy(1.2, 0.0, 0.0)
    assert not compute_metrics(tilted, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf").fell

    # Pitched like the 0.2 slope (≈ 11.3° nose up), levelled with the terrain: not a fall.
    levelled = straight_log(ramp_scenario, 0.0)
    levelled["base_quat"][:] = quat_from_rpy(0.0, -math.atan(0.2), 0.0)
    m = compute_metrics(levelled, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf")
    assert not m.fell

    # The controller's damping state counts as a fall.
    damped = straight_log(ramp_scenario, 0.0)
    fsm = fmu_contract.fsm
    damped["fsm"] = np.full(len(damped["t"]), fsm.Locomotion)
    damped["fsm"][1500:] = fsm.Damping
    damped["fsm_damping"] = np.array(int(fsm.Damping))
    m = compute_metrics(damped, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf")
    assert m.fell and m.fall_time == pytest.approx(1.5) and "damping" in m.fall_reason


def test_traversability_matches_the_documented_formula() -> None:
    heights = np.array([[0.0, 1.0, 2.0, 4.0]])
    heights = np.vstack([heights, heights])
    terrain = Terrain((0.0, 0.0), 1.0, heights)
    field = TraversabilityField(terrain, {"height_weight": 1.0, "p_floor": 0.05})
    np.testing.assert_allclose(field.values[0], [0.05, 0.25, 0.5, 1.0])
    # Slope only: the 1:1 central difference at ix=1 ((2-0)/2 = 1) is 45°, with slope_ref 60° → 0.75.
    field = TraversabilityField(terrain, {"height_weight": 0.0, "slope_weight": 1.0, "slope_ref_deg": 60.0})
    assert field.values[0, 1] == pytest.approx(45.0 / 60.0)
    # Constant p integrates to p × length.
    flat = Terrain((0.0, 0.0), 0.5, np.full((6, 6), 2.0))
    f = TraversabilityField(flat, {"h_max": 4.0})
    cost, length = path_cost(f, np.array([0.5, 1.5, 1.5]), np.array([0.5, 0.5, 2.5]))
    assert length == pytest.approx(3.0)
    assert cost == pytest.approx(0.5 * 3.0)
    with pytest.raises(ValueError):
        TraversabilityField(flat, {"height_weight": 0.0})


def test_footprint_takes_the_largest_p_within_the_radius() -> None:
    heights = np.zeros((7, 9))
    heights[3, 4] = 1.0
    heights[6, 8] = 0.5
    terrain = Terrain((0.0, 0.0), 0.5, heights)
    point = TraversabilityField(terrain, {}).values
    for radius in (0.0, 0.4, 0.5, 0.75, 1.0, 1.2, 2.0):
        values = TraversabilityField(terrain, {"footprint_radius_m": radius}).values
        # Cells beyond the map edge count as p = 1 (the ground ends there).
        padded = np.pad(point, heights.shape[0], constant_values=1.0)
        for iy, ix in np.ndindex(heights.shape):
            sy, sx = np.indices(padded.shape) - heights.shape[0]
            within = np.hypot(sx - ix, sy - iy) * 0.5 <= radius + 1e-12
            assert values[iy, ix] == padded[within].max(), (radius, ix, iy)
    with pytest.raises(ValueError):
        TraversabilityField(terrain, {"footprint_radius_m": -0.1})
    # Obstacle cells count as p = 1 around them and keep their own p; so do the cells beyond the edge.
    pit = np.zeros((5, 7), dtype=bool)
    pit[2, 3] = True
    flat = Terrain((0.0, 0.0), 1.0, np.full((5, 7), 0.5), pit)
    values = TraversabilityField(flat, {"footprint_radius_m": 1.0, "h_max": 1.0}).values
    for iy, ix in np.ndindex(pit.shape):
        near = math.hypot(ix - 3, iy - 2) <= 1.0 and (ix, iy) != (3, 2)
        on_edge = ix in (0, 6) or iy in (0, 4)
        assert values[iy, ix] == (1.0 if near or on_edge else 0.5), (ix, iy)


def test_angle_helpers() -> None:
    np.testing.assert_allclose(wrap_angle(np.array([3 * math.pi / 2, -3 * math.pi / 2, 0.1])), [-math.pi / 2, math.pi / 2, 0.1])
    q = np.array([quat_from_rpy(0.1, -0.2, 2.5)])
    r, p, y = roll_pitch_yaw(q)
    assert (r[0], p[0], y[0]) == pytest.approx((0.1, -0.2, 2.5))


def test_the_goal_disc_includes_its_boundary(ramp_scenario: Scenario) -> None:
    # The walk ends on y = 1 at x = 1.5; a goal of radius 0.4 centred 0.4 m ahead is reached
    # exactly at the end, one 1e-9 m further it is not.
    log = straight_log(ramp_scenario, 0.0)
    field = TraversabilityField(ramp_scenario.terrain, ramp_scenario.traversability)
    on_edge = compute_metrics(log, ramp_scenario.terrain, GoalRegion((1.9, 1.0), 0.4), field, "ramp", "pf")
    assert on_edge.goal_reached and on_edge.time_to_goal == pytest.approx(2.0)
    assert on_edge.final_distance_to_goal == pytest.approx(0.4, abs=1e-12)
    beyond = compute_metrics(log, ramp_scenario.terrain, GoalRegion((1.9 + 1e-9, 1.0), 0.4), field, "ramp", "pf")
    assert not beyond.goal_reached and beyond.time_to_goal is None


def test_path_cost_is_the_planners_measurement(tmp_path: Path) -> None:
    # A pit (obstacle) across the middle row: the planner reports the length inside it, the
    # clearance and exactly the cost the documented model gives (p = 0.5 everywhere, h_max = 1).
    pit = np.zeros((5, 8), dtype=bool)
    pit[2, 3:5] = True
    terrain = Terrain((0.0, 0.0), 1.0, np.full((5, 8), 0.5), pit)
    field = TraversabilityField(terrain, {"h_max": 1.0})
    through = field.measure(np.array([0.5, 7.5]), np.array([2.5, 2.5]))
    assert through.length == pytest.approx(7.0) and through.cost_integral == pytest.approx(3.5)
    assert through.length_in_obstacles == pytest.approx(2.0) and through.min_clearance == 0.0
    beside = field.measure(np.array([0.5, 7.5]), np.array([0.5, 0.5]))
    assert beside.length_in_obstacles == 0.0 and beside.min_clearance == pytest.approx(1.5)
    # Points reach the planner bit for bit (a 1e-13 m step would vanish at fewer digits).
    x = np.array([0.1, 0.1 + 1e-13, 6.3])
    assert field.measure(x, np.full(3, 0.7)).length == (x[1] - x[0]) + (x[2] - x[1])
    # Bad paths are refused with the planner's reason.
    with pytest.raises(CostModelError, match="not finite"):
        field.measure(np.array([0.5, np.nan]), np.array([0.5, 0.5]))
    with pytest.raises(ValueError, match="differ in length"):
        field.measure(np.array([0.5, 1.0]), np.array([0.5]))
    assert path_cost(field, np.array([0.5]), np.array([0.5])) == (0.0, 0.0)
    # A binary that cannot run is a missing artefact, not a crash.
    missing = TraversabilityField.__new__(TraversabilityField)
    missing.__dict__.update(field.__dict__, _pf_plan=tmp_path / "no-pf-plan")
    with pytest.raises(MissingArtifactError):
        missing.measure(np.array([0.5, 1.0]), np.array([0.5, 0.5]))
