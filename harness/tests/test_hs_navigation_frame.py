"""The robot navigates in the frame of its own estimate.

With an estimator the reference, the feedback law, the replans and the elevation map are all
taken at the pose the robot believes it has (truth + the estimate's offset), and the terrain it is
given is the ground actually under it, moved into that frame — as a body-relative perception
would give it. A stand-in controller reports a known, constant estimate error here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_hs_cosim import PdStandIn, standing_plan

from pfnav_harness import fmu_runner as fr
from pfnav_harness import paths
from pfnav_harness.body_sensors import BodySensorConfig
from pfnav_harness.cosim import MAP_REGISTRATION_TOLERANCE, CoSimConfig, CoSimulation, RunResult
from pfnav_harness.feedback_field import FeedbackField
from pfnav_harness.reference import N_COLUMNS, T_HEIGHT, VX, VY, X, Y, Z
from pfnav_harness.reference_source import FieldSource, yaw_of
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())

# Estimate − truth the stand-in reports: dx, dy, dz [m], dyaw [rad].
OFFSET = np.array([0.12, -0.07, 0.03, 0.2])
GOAL = (2.5, 1.0, 0.2)


def radial_field(scenario: Scenario) -> FeedbackField:
    """Straight at the goal centre from every cell of the scenario's map (the optimal law of p ≡ 1)."""
    terrain = scenario.terrain
    ny, nx = terrain.shape
    res = terrain.resolution
    x = terrain.origin[0] + (np.arange(nx)[None, :] + 0.5) * res
    y = terrain.origin[1] + (np.arange(ny)[:, None] + 0.5) * res
    dx, dy = GOAL[0] - x, GOAL[1] - y
    dist = np.hypot(dx, dy)
    inside = dist <= GOAL[2]
    safe = np.where(dist > 0.0, dist, 1.0)
    zero = np.zeros_like(dist)
    return FeedbackField(
        terrain.origin,
        res,
        np.where(inside, zero, dx / safe),
        np.where(inside, zero, dy / safe),
        np.where(inside, zero, 0.4),
        np.where(inside, zero, dist - GOAL[2]),
        GOAL,
    )


def ramp_height(x: float) -> float:
    """The `ramp_scenario` fixture's surface: 0.1 m + 0.2 m per metre along x."""
    return 0.1 + 0.2 * x


def test_the_field_is_sampled_at_the_believed_pose_over_the_true_ground(ramp_scenario: Scenario) -> None:
    field = radial_field(ramp_scenario)
    source = FieldSource(field, ramp_scenario.terrain, 0.3, 0.001, start_yaw=0.0)
    # Believed (1.22, 1.12): the robot is at (1.10, 1.19), where the plane cache's 0.05 m quantum puts no rounding.
    believed = np.array([1.22, 1.12, 0.0])
    out = np.zeros(N_COLUMNS)
    source.sample(0.0, believed, OFFSET, True, out)
    assert (out[X], out[Y]) == (1.22, 1.12)
    # The ground under the robot (x = 1.10), in the estimated frame; under the believed x it is 0.024 m higher.
    assert out[T_HEIGHT] == pytest.approx(ramp_height(1.10) + 0.03, abs=1e-9)
    assert out[Z] == out[T_HEIGHT]
    # The law's direction at the believed position: the goal lies at (+1.28, −0.12) from there
    # (from the true position it would be (+1.40, −0.19): 0.05 rad further south).
    heading = math.atan2(out[VY], out[VX])
    assert heading == pytest.approx(math.atan2(-0.12, 1.28), abs=0.01)
    assert math.hypot(out[VX], out[VY]) > 0.0


class OffsetEstimateStandIn(PdStandIn):
    """Holds the stance by joint PD; its estimate is the truth plus `OFFSET`; records the map it is given."""

    def __init__(self, contract: fr.FmuContract) -> None:
        super().__init__(contract)
        self.estimation: fr.EstimationIo | None = None
        # Per doStep: time; base x, y, z and yaw as given; map origin x, y; the map's first height.
        self.seen: list[tuple[float, ...]] = []

    def enable_estimation(self, mode: str) -> fr.EstimationIo:
        self.estimation = fr.EstimationIo.detached()
        return self.estimation

    def do_step(self, time: float, step: float) -> None:
        super().do_step(time, step)
        base = self.inputs.view(fr.BASE_POS)
        yaw = yaw_of(self.inputs.view(fr.BASE_QUAT))
        origin = self.inputs.view(fr.HEIGHT_MAP_ORIGIN)
        first_height = self.inputs.view(self.contract.height_map_heights)[0]
        self.seen.append((time, base[0], base[1], base[2], yaw, origin[0], origin[1], first_height))
        est = self.estimation
        assert est is not None
        est.est_pos[:] = base + OFFSET[:3]
        est.est_rpy[:] = (0.0, 0.0, yaw + OFFSET[3])


def stand_on_the_estimate(scenario: Scenario, controller: OffsetEstimateStandIn, tmp_path: Path) -> RunResult:
    """0.4 s standing on the ramp with the kalman estimator in the loop (the stand-in reports the estimate)."""
    plan = standing_plan(1.2, 1.0)
    config = CoSimConfig(stand_time=0.2, max_duration=0.4, follow="feedback", estimator="kalman", body_sensors=BodySensorConfig(seed=1))
    with CoSimulation(scenario, plan, None, ROBOT, tmp_path, config, controller=controller, field=radial_field(scenario)) as sim:  # type: ignore[arg-type]
        return sim.run()


def test_with_an_estimator_reference_and_map_are_in_the_estimated_frame(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    controller = OffsetEstimateStandIn(fmu_contract)
    result = stand_on_the_estimate(ramp_scenario, controller, tmp_path)
    truth, ref = result.log["base_pos"], result.log["ref"]
    assert len(truth) == 400
    # From the second step on the offset is known: the reference position is the believed one.
    np.testing.assert_allclose(ref[1:, 0] - truth[1:, 0], OFFSET[0], atol=1e-12)
    np.testing.assert_allclose(ref[1:, 1] - truth[1:, 1], OFFSET[1], atol=1e-12)
    seen = np.array(controller.seen[1:])
    terrain = ramp_scenario.terrain
    for _, x, y, _, _, origin_x, origin_y, first_height in seen[::37]:
        grid = terrain.local_grid(x, y, fmu_contract.height_map_size)
        assert grid is not None
        # The block of ground around the true base, shifted into the estimated frame.
        assert (origin_x, origin_y) == pytest.approx((grid[0] + OFFSET[0], grid[1] + OFFSET[1]), abs=1e-12)
        assert first_height == pytest.approx(grid[2][0, 0] + OFFSET[2], abs=1e-12)


def test_without_an_estimator_nothing_is_shifted(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    plan = standing_plan(1.2, 1.0)
    config = CoSimConfig(stand_time=0.2, max_duration=0.3, follow="feedback", estimator="groundTruth")
    controller = OffsetEstimateStandIn(fmu_contract)
    controller.estimation = fr.EstimationIo.detached()  # written by the stand-in, never read by the harness
    with CoSimulation(ramp_scenario, plan, None, ROBOT, tmp_path, config, controller=controller, field=radial_field(ramp_scenario)) as sim:  # type: ignore[arg-type]
        result = sim.run()
    np.testing.assert_array_equal(result.log["ref"][:, 0], result.log["base_pos"][:, 0])
    for _, x, y, _, _, origin_x, _, _ in controller.seen[::50]:
        grid = ramp_scenario.terrain.local_grid(x, y, fmu_contract.height_map_size)
        assert grid is not None
        assert origin_x == grid[0]


class DriftingEstimateStandIn(OffsetEstimateStandIn):
    """As `OffsetEstimateStandIn`, but its estimate drifts along x by `DRIFT_PER_STEP` each doStep."""

    DRIFT_PER_STEP = 0.25e-3

    def do_step(self, time: float, step: float) -> None:
        super().do_step(time, step)
        est = self.estimation
        assert est is not None
        est.est_pos[0] += self.DRIFT_PER_STEP * len(self.seen)


def test_the_map_follows_a_drifting_estimate_within_the_registration_tolerance(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    controller = DriftingEstimateStandIn(fmu_contract)
    result = stand_on_the_estimate(ramp_scenario, controller, tmp_path)
    assert result.stop_reason.startswith("completed")
    seen = np.array(controller.seen[2:])
    terrain = ramp_scenario.terrain
    deviations = []
    for step, (_, x, y, _, _, origin_x, origin_y, first_height) in enumerate(seen, start=2):
        grid = terrain.local_grid(x, y, fmu_contract.height_map_size)
        assert grid is not None
        # The offset the loop last knew: that of the estimate after the previous doStep.
        believed_dx = OFFSET[0] + DriftingEstimateStandIn.DRIFT_PER_STEP * step
        deviations.append(abs(origin_x - (grid[0] + believed_dx)))
        assert origin_y == pytest.approx(grid[1] + OFFSET[1], abs=1e-12)
        assert first_height == pytest.approx(grid[2][0, 0] + OFFSET[2], abs=1e-12)
    # Never further from the estimate than the tolerance, and moved with it in steps of about the
    # tolerance (0.1 m of drift over the run), not re-registered at every step.
    assert max(deviations) <= MAP_REGISTRATION_TOLERANCE + 1e-9
    moves = np.count_nonzero(np.diff(seen[:, 5]))
    drift = DriftingEstimateStandIn.DRIFT_PER_STEP * len(seen)
    assert 0.8 * drift / MAP_REGISTRATION_TOLERANCE <= moves <= 1.2 * drift / MAP_REGISTRATION_TOLERANCE
