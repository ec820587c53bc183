"""The elevation map: fusion in the estimated frame, variances that hold, rejection of bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfnav_harness.elevation_map import (
    BAD_COVARIANCE,
    BAD_LABELS,
    BAD_POSE,
    FUSED,
    GATED,
    NO_RETURN,
    NON_FINITE,
    OUT_OF_RANGE,
    OUTSIDE_MAP,
    STALE,
    ElevationMap,
    ElevationMapConfig,
    PoseBelief,
)
from pfnav_harness.errors import SimulationError
from pfnav_harness.scenario import Terrain
from pfnav_harness.terrain_sensor import SensorScan, TerrainSensor, TerrainSensorConfig

LEVEL = np.array([1.0, 0.0, 0.0, 0.0])
NOISELESS = {"sigma0": 0.0, "sigma_r2": 0.0, "dropout": 0.0, "outlier": 0.0}


def rough(seed: int = 0, n: int = 64, res: float = 0.25) -> Terrain:
    """Smooth hills (σ ≈ 0.1 m) on a 16 m square."""
    rng = np.random.default_rng(seed)
    coarse = rng.normal(0.0, 0.15, (n // 8 + 2, n // 8 + 2))
    fine = np.kron(coarse, np.ones((8, 8)))[:n, :n]
    kernel = np.ones(9) / 9.0
    smooth = np.apply_along_axis(lambda r: np.convolve(r, kernel, "same"), 0, fine)
    smooth = np.apply_along_axis(lambda r: np.convolve(r, kernel, "same"), 1, smooth)
    return Terrain((0.0, 0.0), res, smooth)


def new_map(terrain: Terrain, sensor: TerrainSensorConfig, config: ElevationMapConfig | None = None) -> ElevationMap:
    return ElevationMap(terrain.origin, terrain.resolution, terrain.shape, sensor, config)


def standing(terrain: Terrain, x: float, y: float, yaw: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    position = np.array([x, y, float(terrain.height(x, y)) + 0.32])
    return position, np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def sweep(terrain: Terrain, config: TerrainSensorConfig, offset: np.ndarray, emap: ElevationMap) -> None:
    """The robot turns on the spot at (8, 8), scanning; its estimate is off by `offset` (x, y, z)."""
    sensor = TerrainSensor(terrain, config)
    for k in range(12):
        position, quaternion = standing(terrain, 8.0, 8.0, yaw=k * math.pi / 6)
        scan = sensor.scan(0.2 * k, position, quaternion)
        report = emap.fuse(scan, PoseBelief(position + offset, quaternion))
        assert report.rejected is None


def cell_centres_truth(emap: ElevationMap, terrain: Terrain, shift: np.ndarray) -> np.ndarray:
    xs, ys = emap.cell_centres()
    gx, gy = np.meshgrid(xs, ys)
    return terrain.height(gx - shift[0], gy - shift[1]) + shift[2]


def test_noiseless_scans_map_the_ground_to_within_the_cell_discretisation() -> None:
    terrain = rough()
    emap = new_map(terrain, TerrainSensorConfig(**NOISELESS))
    sweep(terrain, TerrainSensorConfig(**NOISELESS), np.zeros(3), emap)
    known = emap.known
    assert known.sum() > 300
    error = np.abs(emap.heights - cell_centres_truth(emap, terrain, np.zeros(3)))[known]
    # A point anywhere in a 0.25 m cell, on slopes of these hills (< 30 %), is within a few cm.
    assert np.percentile(error, 95) < 0.04


def test_the_map_lives_in_the_estimated_frame() -> None:
    terrain = rough(1)
    offset = np.array([0.5, -0.25, 0.1])
    emap = new_map(terrain, TerrainSensorConfig(**NOISELESS))
    sweep(terrain, TerrainSensorConfig(**NOISELESS), offset, emap)
    known = emap.known
    shifted = np.abs(emap.heights - cell_centres_truth(emap, terrain, offset))[known]
    unshifted = np.abs(emap.heights - cell_centres_truth(emap, terrain, np.zeros(3)))[known]
    assert np.median(shifted) < 0.02
    assert np.median(unshifted) > 0.05


def test_variances_are_honest_with_sensor_noise_and_outliers() -> None:
    terrain = rough(2)
    sensor = TerrainSensorConfig(sigma0=0.01, sigma_r2=0.01, dropout=0.05, outlier=0.01, seed=5)
    emap = new_map(terrain, sensor)
    sweep(terrain, sensor, np.zeros(3), emap)
    known = emap.known
    error = np.abs(emap.heights - cell_centres_truth(emap, terrain, np.zeros(3)))[known]
    sigma = np.sqrt(emap.variances[known])
    assert known.sum() > 300
    assert np.mean(error <= 2.0 * sigma) >= 0.9
    assert emap.totals.get(NO_RETURN, 0) > 0


def returns_below_the_sensor(sensor: TerrainSensorConfig, pose: PoseBelief, t: float, heights: list[float]) -> SensorScan:
    """A scan whose returns lie straight below the sensor at `heights` (all in one cell)."""
    world = np.array([[pose.position[0] + sensor.mount_xyz[0], pose.position[1], z] for z in heights])
    lever = world - pose.position
    # The sensor frame is pitched down: rotate back.
    points = (lever - np.array(sensor.mount_xyz)) @ sensor.rotation_on_trunk()
    return SensorScan(t, points, np.linalg.norm(points, axis=1), 0)


def test_an_outlier_against_a_known_cell_is_gated_and_a_lasting_change_is_taken() -> None:
    terrain = Terrain((0.0, 0.0), 0.25, np.zeros((16, 16)))
    sensor = TerrainSensorConfig(**NOISELESS)
    emap = new_map(terrain, sensor, ElevationMapConfig(rejection_inflation=0.05))
    pose = PoseBelief(np.array([2.0, 2.0, 0.32]), LEVEL)

    def one_point(t: float, z: float) -> SensorScan:
        return returns_below_the_sensor(sensor, pose, t, [z])

    for k in range(5):
        assert emap.fuse(one_point(0.1 * k, 0.0), pose).counts.get(FUSED) == 1
    i, j = int(2.0 / 0.25), int((2.0 + sensor.mount_xyz[0]) / 0.25)
    before = emap.variances[i, j]
    report = emap.fuse(one_point(1.0, 0.5), pose)
    assert report.counts.get(GATED) == 1
    assert abs(emap.heights[i, j]) < 1e-9
    assert emap.variances[i, j] > before
    t = 1.1
    while emap.heights[i, j] < 0.25:
        emap.fuse(one_point(t, 0.5), pose)
        t += 0.1
        assert t < 3.0, "a lasting change was never taken"


def test_a_lone_return_is_unconfirmed_until_the_next_look_and_cannot_outvote_it() -> None:
    # A spurious range lands far below the ground in a cell nothing else has seen yet (as behind
    # the flank of a ridge). Taken at its own small variance it would gate every true return after it.
    terrain = Terrain((0.0, 0.0), 0.25, np.zeros((16, 16)))
    sensor = TerrainSensorConfig(**NOISELESS)
    emap = new_map(terrain, sensor)
    pose = PoseBelief(np.array([2.0, 2.0, 0.32]), LEVEL)
    i, j = int(2.0 / 0.25), int((2.0 + sensor.mount_xyz[0]) / 0.25)
    assert emap.fuse(returns_below_the_sensor(sensor, pose, 0.0, [-0.8]), pose).counts.get(FUSED) == 1
    assert emap.known[i, j] and not emap.confirmed[i, j]
    assert emap.variances[i, j] >= ElevationMapConfig().unconfirmed_variance
    # The next look outweighs it (gain ≈ 1) and confirms the cell.
    assert emap.fuse(returns_below_the_sensor(sensor, pose, 0.2, [0.0]), pose).counts.get(FUSED) == 1
    assert abs(emap.heights[i, j]) < 1e-4 and emap.confirmed[i, j]
    assert emap.variances[i, j] < 1e-4
    # Confirmed, the cell gates a lone outlier as any known cell does.
    assert emap.fuse(returns_below_the_sensor(sensor, pose, 0.6, [-0.8]), pose).counts.get(GATED) == 1
    assert abs(emap.heights[i, j]) < 1e-4
    # A lone return so far off that even its widened variance gates the next look is replaced
    # by it (no claim to outvote it), which the look after that confirms.
    replaced = new_map(terrain, sensor)
    replaced.fuse(returns_below_the_sensor(sensor, pose, 0.0, [-3.0]), pose)
    assert replaced.fuse(returns_below_the_sensor(sensor, pose, 0.2, [0.0]), pose).counts.get(FUSED) == 1
    assert abs(replaced.heights[i, j]) < 1e-9 and not replaced.confirmed[i, j]
    replaced.fuse(returns_below_the_sensor(sensor, pose, 0.4, [0.0]), pose)
    assert abs(replaced.heights[i, j]) < 1e-9 and replaced.confirmed[i, j]
    # Three returns in one scan back a new cell at once, at their own variance.
    fresh = new_map(terrain, sensor)
    assert fresh.fuse(returns_below_the_sensor(sensor, pose, 0.0, [0.0, 0.0, 0.0]), pose).counts.get(FUSED) == 1
    assert fresh.confirmed[i, j] and fresh.variances[i, j] < 1e-4


def test_variance_grows_with_the_pose_and_old_cells_are_forgotten() -> None:
    terrain = rough(3)
    sensor = TerrainSensorConfig(**NOISELESS)
    emap = new_map(terrain, sensor, ElevationMapConfig(max_variance=0.05))
    sweep(terrain, sensor, np.zeros(3), emap)
    # Unconfirmed cells sit at max_variance here (0.05 < unconfirmed_variance): any growth forgets them.
    known = emap.confirmed.copy()
    assert known.sum() > 0.5 * emap.known.sum()
    before = emap.variances[known].copy()
    measured = emap.measurement_variances()[known].copy()
    emap.grow(np.array([0.0, 0.0, 0.01]))
    np.testing.assert_allclose(emap.variances[known], before + 0.01)
    # The drift moves every cell alike: the cells' relative uncertainty stays what was measured.
    np.testing.assert_allclose(emap.measurement_variances()[known], measured)
    np.testing.assert_allclose(emap.drift_variances[known], 0.01)
    # A new look shrinks the drift's share by the update's factor 1 − gain.
    total = emap.variances.copy()
    position, quaternion = standing(terrain, 8.0, 8.0)
    assert emap.fuse(TerrainSensor(terrain, sensor).scan(10.0, position, quaternion), PoseBelief(position, quaternion)).rejected is None
    updated = known & (emap.variances < total)
    assert updated.any()
    np.testing.assert_allclose(emap.drift_variances[updated], 0.01 * emap.variances[updated] / total[updated])
    emap.grow(np.array([0.0, 0.0, 0.05]))
    assert not emap.known.any()
    with pytest.raises(SimulationError, match="finite"):
        emap.grow(np.array([np.nan, 0.0, 0.0]))


def test_bad_input_is_counted_or_refused_and_changes_nothing() -> None:
    terrain = rough(4)
    sensor_config = TerrainSensorConfig(**NOISELESS)
    emap = new_map(terrain, sensor_config)
    sweep(terrain, sensor_config, np.zeros(3), emap)
    heights, variances = emap.heights.copy(), emap.variances.copy()
    position, quaternion = standing(terrain, 8.0, 8.0)
    scan = TerrainSensor(terrain, sensor_config).scan(5.0, position, quaternion)

    def unchanged() -> None:
        np.testing.assert_array_equal(emap.heights, heights)
        np.testing.assert_array_equal(emap.variances, variances)

    assert emap.fuse(scan, PoseBelief(np.array([np.nan, 8.0, 0.3]), quaternion)).rejected == BAD_POSE
    assert emap.fuse(scan, PoseBelief(position, np.zeros(4))).rejected == BAD_POSE
    bad_cov = PoseBelief(position, quaternion, position_covariance=np.diag([1.0, -1.0, 1.0]))
    assert emap.fuse(scan, bad_cov).rejected == BAD_COVARIANCE
    assert emap.fuse(SensorScan(0.1, scan.points, scan.ranges, 0), PoseBelief(position, quaternion)).rejected == STALE
    short_labels = SensorScan(5.5, scan.points, scan.ranges, 0, hazard=np.zeros(3, dtype=bool))
    assert emap.fuse(short_labels, PoseBelief(position, quaternion)).rejected == BAD_LABELS
    unchanged()

    hostile = np.array([[np.inf, 0.0, 0.0], [1e9, 0.0, 0.0], [50.0, 0.0, -5.0], [np.nan, np.nan, np.nan]])
    report = emap.fuse(SensorScan(6.0, hostile, np.full(4, np.nan), 1), PoseBelief(position, quaternion))
    assert report.rejected is None
    assert report.counts == {NON_FINITE: 1, OUT_OF_RANGE: 1, OUTSIDE_MAP: 1, NO_RETURN: 1}
    unchanged()
    empty = SensorScan(7.0, np.zeros((0, 3)), np.zeros(0), 2)
    assert emap.fuse(empty, PoseBelief(position, quaternion)).counts == {}
    unchanged()


def test_confidence_bounds_bracket_the_height() -> None:
    terrain = rough(5)
    sensor = TerrainSensorConfig(sigma0=0.02, sigma_r2=0.0, dropout=0.0, outlier=0.0, seed=1)
    emap = new_map(terrain, sensor, ElevationMapConfig(confidence_sigmas=2.0))
    sweep(terrain, sensor, np.zeros(3), emap)
    known = emap.known
    np.testing.assert_allclose((emap.upper() - emap.heights)[known], 2.0 * np.sqrt(emap.variances[known]))
    assert np.all(emap.lower()[known] < emap.upper()[known])
    assert np.isnan(emap.lower()[~known]).all()
