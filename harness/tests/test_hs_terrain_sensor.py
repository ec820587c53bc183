"""The terrain sensor: ray casting against the physics' mesh, occlusion, noise, dropouts, outliers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfnav_harness.errors import SimulationError
from pfnav_harness.scenario import Terrain
from pfnav_harness.terrain_sensor import TerrainSensor, TerrainSensorConfig, ray_cast

LEVEL = np.array([1.0, 0.0, 0.0, 0.0])
NOISELESS = {"sigma0": 0.0, "sigma_r2": 0.0, "dropout": 0.0, "outlier": 0.0}


def flat(height: float = 0.0, n: int = 64, res: float = 0.25) -> Terrain:
    return Terrain((0.0, 0.0), res, np.full((n, n), height))


def to_world(sensor: TerrainSensor, points: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Sensor-frame points → world, for a level trunk at `base`."""
    return points @ sensor.mount_rotation.T + sensor.mount + base


def test_camera_returns_lie_on_the_ground_at_the_geometric_range() -> None:
    terrain = flat(0.4)
    sensor = TerrainSensor(terrain, TerrainSensorConfig(**NOISELESS))
    base = np.array([4.0, 8.0, 0.75])
    scan = sensor.scan(1.5, base, LEVEL)
    assert scan.capture_time == 1.5
    hits = np.isfinite(scan.ranges)
    assert hits.mean() > 0.8
    world = to_world(sensor, scan.points[hits], base)
    assert np.max(np.abs(world[:, 2] - 0.4)) < 1e-5
    # Each ray meets the plane z = 0.4 where geometry says.
    origin_z = base[2] + sensor.mount[2]
    dz = (sensor.directions @ sensor.mount_rotation.T)[hits, 2]
    np.testing.assert_allclose(scan.ranges[hits], (0.4 - origin_z) / dz, rtol=1e-5)


def test_a_wall_hides_the_ground_behind_it() -> None:
    heights = np.zeros((64, 64))
    heights[:, 24:28] = 1.5  # a ridge across the map at x ≈ 6–7 m
    terrain = Terrain((0.0, 0.0), 0.25, heights)
    sensor = TerrainSensor(terrain, TerrainSensorConfig(pitch_deg=10.0, max_range=8.0, **NOISELESS))
    base = np.array([4.0, 8.0, 0.35])
    scan = sensor.scan(0.0, base, LEVEL)
    world = to_world(sensor, scan.points[np.isfinite(scan.ranges)], base)
    assert world[:, 0].max() <= 7.0, "returns from behind the ridge"
    assert (world[:, 2] > 0.3).any(), "the ridge's face is seen"
    # The ideal disc would reveal ground behind the ridge; this sensor cannot.
    assert not ((world[:, 0] > 7.0) & (world[:, 2] < 0.1)).any()


def test_the_lidar_sees_all_around() -> None:
    terrain = flat(0.0, n=96)
    sensor = TerrainSensor(terrain, TerrainSensorConfig.lidar(**NOISELESS))
    base = np.array([12.0, 12.0, 0.35])
    scan = sensor.scan(0.0, base, LEVEL)
    world = to_world(sensor, scan.points[np.isfinite(scan.ranges)], base)
    angles = np.arctan2(world[:, 1] - base[1], world[:, 0] - base[0])
    quadrants = np.unique(np.floor((angles + math.pi) / (math.pi / 2)).astype(int) % 4)
    assert set(quadrants.tolist()) == {0, 1, 2, 3}
    # Beams above the horizon never return on flat ground.
    assert np.isnan(scan.ranges.reshape(16, 180)[:8]).all()


def test_rays_leaving_the_mesh_and_a_sensor_underground() -> None:
    terrain = flat(0.0, n=8)
    # Pointing away from the map at a shallow angle: leaves the mesh first.
    away = np.array([[1.0, 0.0, -0.05]]) / math.hypot(1.0, 0.05)
    assert math.isinf(ray_cast(terrain, np.array([1.0, 1.0, 0.5]), away, 20.0, 0.05)[0])
    down = np.array([[0.0, 0.0, -1.0]])
    assert ray_cast(terrain, np.array([1.0, 1.0, -0.2]), down, 5.0, 0.05)[0] == 0.0
    with pytest.raises(SimulationError, match="origin"):
        ray_cast(terrain, np.array([np.nan, 0.0, 0.0]), down, 5.0, 0.05)


def test_range_noise_follows_its_model() -> None:
    config = TerrainSensorConfig(sigma0=0.01, sigma_r2=0.01, dropout=0.0, outlier=0.0, seed=3)
    terrain = flat(0.0)
    sensor = TerrainSensor(terrain, config)
    ideal = TerrainSensor(terrain, TerrainSensorConfig(**NOISELESS))
    base = np.array([4.0, 8.0, 0.6])
    true = ideal.scan(0.0, base, LEVEL).ranges
    errors, sigmas = [], []
    for k in range(20):
        measured = sensor.scan(0.1 * k, base, LEVEL).ranges
        ok = np.isfinite(measured) & np.isfinite(true)
        errors.append(measured[ok] - true[ok])
        sigmas.append(config.sigma(true[ok]))
    z = np.concatenate(errors) / np.concatenate(sigmas)
    assert abs(z.mean()) < 0.05
    assert 0.95 < z.std() < 1.05


def test_dropouts_and_outliers_at_their_rates_and_seeded() -> None:
    config = TerrainSensorConfig(dropout=0.1, outlier=0.05, seed=11)
    terrain = flat(0.0)
    base = np.array([4.0, 8.0, 0.6])
    a = TerrainSensor(terrain, config)
    b = TerrainSensor(terrain, config)
    scans_a = [a.scan(0.2 * k, base, LEVEL) for k in range(10)]
    scans_b = [b.scan(0.2 * k, base, LEVEL) for k in range(10)]
    for sa, sb in zip(scans_a, scans_b, strict=True):
        np.testing.assert_array_equal(sa.ranges, sb.ranges)
    dropped = np.concatenate([s.dropped for s in scans_a]).mean()
    outliers = np.concatenate([s.injected_outliers for s in scans_a]).mean()
    assert 0.08 < dropped < 0.12
    assert 0.03 < outliers < 0.06
    other = TerrainSensor(terrain, TerrainSensorConfig(dropout=0.1, outlier=0.05, seed=12)).scan(0.0, base, LEVEL)
    assert not np.array_equal(np.nan_to_num(other.ranges), np.nan_to_num(scans_a[0].ranges))


def test_camera_labels_hazards_at_their_error_rate_and_leaves_the_ranges_alone() -> None:
    # A hazard band without geometry (water, mud) across the flat ground at x = 5 … 6 m.
    obstacles = np.zeros((64, 64), dtype=bool)
    obstacles[:, 20:24] = True
    terrain = Terrain((0.0, 0.0), 0.25, np.zeros((64, 64)), obstacles)
    base = np.array([4.0, 8.0, 0.6])
    config = TerrainSensorConfig(seed=3, label_error=0.1)
    sensor = TerrainSensor(terrain, config)
    scans = [sensor.scan(0.2 * k, base, LEVEL) for k in range(5)]
    hits = [np.isfinite(s.ranges) & ~s.injected_outliers for s in scans]
    truth = [terrain.obstacles_at(*to_world(sensor, s.points[h], base)[:, :2].T) for s, h in zip(scans, hits, strict=True)]
    labels = [s.hazard[h] for s, h in zip(scans, hits, strict=True) if s.hazard is not None]
    assert len(labels) == 5
    truth_all, labels_all = np.concatenate(truth), np.concatenate(labels)
    assert truth_all.sum() > 100, "the band is in view"
    assert 0.08 < np.mean(truth_all != labels_all) < 0.12
    # The label draws come after the range draws: the ranges are those of a sensor without labels.
    unlabelled = TerrainSensor(terrain, TerrainSensorConfig(seed=3, label_error=0.5)).scan(0.0, base, LEVEL)
    assert unlabelled.hazard is None
    np.testing.assert_array_equal(np.nan_to_num(unlabelled.ranges), np.nan_to_num(scans[0].ranges))
    assert TerrainSensor(terrain, TerrainSensorConfig.lidar()).scan(0.0, base, LEVEL).hazard is None


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"kind": "sonar"}, "unknown kind"),
        ({"fov_horizontal_deg": math.nan}, "fov_horizontal_deg"),
        ({"max_range": 0.1}, "ranges"),
        ({"dropout": 1.0}, "dropout"),
        ({"columns": 0}, "columns"),
        ({"columns": 4096, "rows": 4096}, "rays per scan"),
        ({"mount_xyz": (0.0, math.inf, 0.0)}, "mount_xyz"),
        ({"seed": -1}, "seed"),
        ({"label_error": 0.6}, "label_error"),
        ({"label_error": math.nan}, "label_error"),
    ],
)
def test_bad_configurations_are_refused_with_the_reason(overrides: dict[str, object], message: str) -> None:
    with pytest.raises(SimulationError, match=message):
        TerrainSensor(flat(), TerrainSensorConfig(**overrides))  # type: ignore[arg-type]


def test_a_non_finite_trunk_pose_is_refused() -> None:
    sensor = TerrainSensor(flat(), TerrainSensorConfig())
    with pytest.raises(SimulationError, match="finite"):
        sensor.scan(0.0, np.array([1.0, np.nan, 0.5]), LEVEL)
    with pytest.raises(SimulationError, match="rotation"):
        sensor.scan(0.0, np.array([1.0, 1.0, 0.5]), np.zeros(4))


def test_height_is_the_height_of_height_and_gradient_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    terrain = Terrain((-1.0, 2.0), 0.3, rng.normal(0.0, 0.4, (20, 30)))
    x = rng.uniform(-3.0, 12.0, 5000)
    y = rng.uniform(0.0, 10.0, 5000)
    np.testing.assert_array_equal(terrain.height(x, y), terrain.height_and_gradient(x, y)[0])
