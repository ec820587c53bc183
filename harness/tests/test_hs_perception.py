"""The online navigator with a real terrain sensor: scans at the sensor's rate, the map in the believed frame."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_hs_online import ScriptedClient

from pfnav_harness.cosim import believed_trunk_pose
from pfnav_harness.elevation_map import PoseBelief
from pfnav_harness.errors import SimulationError
from pfnav_harness.online import OnlineConfig, OnlineNavigator
from pfnav_harness.perception import PerceptionConfig, SensedMap
from pfnav_harness.planner_client import start_density_belief
from pfnav_harness.scenario import GoalRegion, Scenario, Terrain
from pfnav_harness.terrain_sensor import TerrainSensorConfig
from pfnav_harness.world import quaternion_to_rpy

RES = 0.25
NOISELESS = TerrainSensorConfig(sigma0=0.0, sigma_r2=0.0, dropout=0.0, outlier=0.0)


def step_scenario(prior: bool = False) -> Scenario:
    """Flat ground with a 0.3 m step up at x = 5 m."""
    heights = np.zeros((32, 48))
    heights[:, 20:] = 0.3
    terrain = Terrain((0.0, 0.0), RES, heights)
    prior_map = Terrain((0.0, 0.0), RES, np.zeros((32, 48))) if prior else None
    return Scenario("step", terrain, (2.0, 4.0), 0.0, GoalRegion((10.0, 4.0), 0.5), prior=prior_map)


def trunk(x: float, y: float, yaw: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    return np.array([x, y, 0.32]), np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def test_scans_come_at_the_sensor_rate_and_see_what_lies_ahead() -> None:
    scenario = step_scenario()
    sensed = SensedMap(scenario.terrain, None, PerceptionConfig(sensor=NOISELESS))
    for k in range(100):
        position, quaternion = trunk(2.0 + 0.005 * k, 4.0)
        sensed.sense(0.01 * k, position, quaternion, PoseBelief(position, quaternion))
    assert len(sensed.reports) == 5  # 5 Hz over one second
    known = sensed.known
    xs = (np.arange(48) + 0.5) * RES
    seen_x = np.broadcast_to(xs, known.shape)[known]
    assert seen_x.min() > 2.0, "a forward camera sees nothing behind the trunk"
    heights = sensed.terrain().heights
    x = np.broadcast_to(xs, known.shape)
    # Away from the step's cells (the mesh ramps between the centres either side of x = 5 m).
    assert np.all(np.abs(heights[known & (x < 4.7)]) < 0.02)
    assert np.all(np.abs(heights[known & (x > 5.3)] - 0.3) < 0.02)
    assert sensed.take_changed() > 0 and sensed.take_changed() == 0


def test_the_step_is_mapped_where_the_robot_believes_it_is() -> None:
    scenario = step_scenario()
    sensed = SensedMap(scenario.terrain, None, PerceptionConfig(sensor=NOISELESS))
    position, quaternion = trunk(3.0, 4.0)
    believed = position + np.array([0.5, 0.0, 0.0])  # the estimate is 0.5 m ahead of the truth
    sensed.sense(0.0, position, quaternion, PoseBelief(believed, quaternion))
    heights, known = sensed.terrain().heights, sensed.known
    column = heights[16]
    seen = np.flatnonzero(known[16])
    # The step (true x = 5 m, column 20) appears 0.5 m (two cells) further on.
    first_high = seen[column[seen] > 0.15][0]
    assert first_high == 22


def test_hazard_labels_flag_a_band_without_geometry_and_a_lidar_does_not() -> None:
    heights = np.zeros((32, 48))
    obstacles = np.zeros((32, 48), dtype=bool)
    obstacles[:, 20:24] = True  # flat, flagged (water): x = 5 … 6 m
    terrain = Terrain((0.0, 0.0), RES, heights, obstacles)
    position, quaternion = trunk(3.5, 4.0)

    def sensed_after(sensor: TerrainSensorConfig) -> SensedMap:
        sensed = SensedMap(terrain, None, PerceptionConfig(sensor=sensor))
        for k in range(10):
            sensed.sense(0.2 * k, position, quaternion, PoseBelief(position, quaternion))
        return sensed

    camera = sensed_after(TerrainSensorConfig(seed=5))
    flagged = camera.terrain().obstacles
    assert flagged is not None
    known = camera.known
    assert (known & obstacles).sum() > 20, "the band is in view"
    # Every band cell seen a few times is flagged; label errors (5 %) flag almost nothing else.
    # Range noise carries labelled returns into the next cell along the ray, so the band's
    # far edge may grow by a cell (conservative); beyond that nothing is flagged.
    assert np.mean(flagged[known & obstacles]) > 0.9
    near_band = np.zeros_like(obstacles)
    near_band[:, 19:25] = True
    assert np.mean(flagged[known & ~near_band]) < 0.01
    # A lidar measures geometry only.
    lidar = sensed_after(TerrainSensorConfig.lidar(seed=5))
    assert lidar.terrain().obstacles is None


def test_height_errors_carry_the_map_back_through_the_estimate_offset() -> None:
    # A map made on an estimate that is 0.5 m ahead, 0.05 m high and turned by 0.1 rad.
    scenario = step_scenario()
    sensed = SensedMap(scenario.terrain, None, PerceptionConfig(sensor=NOISELESS))
    position, quaternion = trunk(3.0, 4.0)
    offset = np.array([0.5, 0.0, 0.05, 0.1])
    _, believed_quaternion = trunk(3.0, 4.0, offset[3])
    sensed.sense(0.0, position, quaternion, PoseBelief(position + offset[0:3], believed_quaternion))
    errors, sigmas = sensed.height_errors(position, offset)
    assert len(errors) == sensed.known.sum() > 50 and np.all(sigmas > 0.0)
    # Carried back with the offset, the map is the truth to within its own 2σ: exact on the flat
    # parts, and on the cells across the turned step within the spread of their returns.
    assert np.mean(np.abs(errors) <= 2.0 * sigmas) > 0.95
    assert np.median(np.abs(errors)) < 1e-6
    # Read without the offset, the step sits two cells off and every cell 5 cm high.
    wrong, _ = sensed.height_errors(position, np.zeros(4))
    assert np.mean(np.abs(wrong) <= 2.0 * sigmas) < 0.5


def test_the_prior_map_starts_the_map_and_a_surprise_is_taken_after_a_few_scans() -> None:
    scenario = step_scenario(prior=True)
    config = PerceptionConfig(sensor=NOISELESS, prior_variance=0.001)
    sensed = SensedMap(scenario.terrain, scenario.prior, config)
    assert sensed.known.all() and np.all(sensed.map.variances == 0.001)
    position, quaternion = trunk(4.0, 4.0)
    sensed.sense(0.0, position, quaternion, PoseBelief(position, quaternion))
    assert sensed.reports[0].counts.get("gated", 0) > 0
    assert np.all(sensed.terrain().heights[:, 21:] < 0.05), "one look does not overrule the prior"
    for k in range(1, 10):
        sensed.sense(0.2 * k, position, quaternion, PoseBelief(position, quaternion))
    heights = sensed.terrain().heights
    on_step = heights[:, 22:]
    assert np.count_nonzero(np.abs(on_step - 0.3) < 0.03) > 10, "the step was taken"
    assert np.all(np.abs(heights[:, :18]) < 1e-6)


def test_the_navigator_scans_at_the_start_and_publishes_the_sensed_map() -> None:
    client = ScriptedClient()
    config = OnlineConfig(perception=PerceptionConfig(sensor=NOISELESS))
    navigator = OnlineNavigator(client, step_scenario(), config)  # type: ignore[arg-type]
    assert navigator.senses_terrain
    with pytest.raises(SimulationError, match="trunk height"):
        navigator.start(2.0, 4.0, 0.0, timeout=1.0, retries=0)
    navigator.start(2.0, 4.0, 0.0, timeout=1.0, retries=0, trunk_height=0.32)
    _, _, known, _ = client.maps[0]
    assert known is not None and 0 < known.sum() < known.size
    assert navigator.replans[0].changed_cells == known.sum()
    for k in range(1, 60):
        t = 0.01 * k
        position, quaternion = trunk(2.0 + 0.5 * t, 4.0)
        navigator.sense(t, position, quaternion, PoseBelief(position, quaternion))
        navigator.tick(t, float(position[0]), 4.0, 0.0)
    assert len(client.maps) == 2  # the start and the update at 0.5 s
    assert navigator.replans[1].changed_cells > 0
    assert client.maps[1][2].sum() > known.sum()
    # Each known cell goes out with the map's variance of its height, unknown cells with 0.
    variances = client.variances[1]
    sensed = navigator.belief
    assert isinstance(sensed, SensedMap)
    np.testing.assert_array_equal(variances[client.maps[1][2]], sensed.map.measurement_variances()[client.maps[1][2]])
    assert np.all(variances[~client.maps[1][2]] == 0.0)
    assert np.all(variances[client.maps[1][2]] > 0.0)


@pytest.mark.parametrize("belief_planning", [True, False])
def test_belief_planning_sends_the_position_sigma_and_the_height_variances(belief_planning: bool) -> None:
    client = ScriptedClient()
    config = OnlineConfig(perception=PerceptionConfig(sensor=NOISELESS), belief_planning=belief_planning)
    navigator = OnlineNavigator(client, step_scenario(), config)  # type: ignore[arg-type]
    navigator.start(2.0, 4.0, 0.0, timeout=1.0, retries=0, trunk_height=0.32)
    variance = np.array([0.04, 0.09, 0.01])
    for k in range(1, 60):
        t = 0.01 * k
        position, quaternion = trunk(2.0 + 0.5 * t, 4.0)
        navigator.sense(t, position, quaternion, PoseBelief(position, quaternion))
        navigator.tick(t, float(position[0]), 4.0, 0.0, variance)
    _, update, _ = client.requests[-1]
    if belief_planning:
        assert update.sigma == pytest.approx(0.3)  # the worse horizontal axis
        assert client.variances[-1] is not None
        assert client.options[-1].start_density == start_density_belief()
    else:
        assert update.sigma == 0.0 and client.variances[-1] is None
        assert client.options[-1].start_density == 0  # the service's default


def test_believed_trunk_pose_applies_the_estimate_offset() -> None:
    state = np.zeros(37)
    state[0:3] = [1.0, 2.0, 0.3]
    roll, pitch, yaw = 0.1, -0.05, 0.4
    cr, sr, cp, sp, cy, sy = (math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2), math.cos(yaw / 2), math.sin(yaw / 2))
    state[3:7] = [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy]
    offset = np.array([0.2, -0.1, 0.05, 0.3])
    belief = believed_trunk_pose(state, offset)
    np.testing.assert_allclose(belief.position, [1.2, 1.9, 0.35])
    r, p, y = quaternion_to_rpy(belief.quaternion)
    assert abs(math.remainder(y - (yaw + 0.3), math.tau)) < 1e-9
    assert abs(r - roll) < 0.05 and abs(p - pitch) < 0.05  # yaw rotates about the world vertical
    assert abs(np.linalg.norm(belief.quaternion) - 1.0) < 1e-12


def test_the_map_grows_with_the_estimators_position_variance_between_scans() -> None:
    scenario = step_scenario()
    sensed = SensedMap(scenario.terrain, None, PerceptionConfig(sensor=NOISELESS))
    position, quaternion = trunk(2.0, 4.0)
    sensed.sense(0.0, position, quaternion, PoseBelief(position, quaternion, np.diag([0.0, 0.0, 0.001])))
    seen = sensed.known.copy()
    before = sensed.map.variances[seen].copy()
    # The robot turns away: the cells seen first are not seen again, they only grow.
    away, turned = trunk(2.0, 4.0, yaw=math.pi)
    sensed.sense(0.1, away, turned, PoseBelief(away, turned, np.diag([0.0, 0.0, 0.004])))  # not a scan time: nothing
    np.testing.assert_array_equal(sensed.map.variances[seen], before)
    sensed.sense(0.2, away, turned, PoseBelief(away, turned, np.diag([0.0, 0.0, 0.004])))
    still = seen & sensed.known
    # Flat ground where the first scan looked: the growth is the vertical variance's, 0.003 m².
    grown = sensed.map.variances[still] - before[still[seen]]
    assert still.sum() > 50
    np.testing.assert_allclose(np.median(grown), 0.003, rtol=1e-6)


def test_noise_below_the_lowest_ground_is_clipped_to_the_planners_datum() -> None:
    """Flat ground at h = 0 seen by a noisy sensor: about half the returns lie below 0, which the
    planner's cost h/h_max refuses; the published terrain never goes below 0."""
    scenario = step_scenario()
    noisy = TerrainSensorConfig(sigma0=0.02, sigma_r2=0.0, dropout=0.0, outlier=0.0, seed=3)
    sensed = SensedMap(scenario.terrain, None, PerceptionConfig(sensor=noisy))
    position, quaternion = trunk(2.0, 4.0)
    sensed.sense(0.0, position, quaternion, PoseBelief(position, quaternion))
    assert np.nanmin(sensed.map.heights) < 0.0
    heights = sensed.terrain().heights
    assert heights.min() == 0.0 and np.any(heights[sensed.known] > 0.0)
