"""The belief map: prior knowledge plus the cells a height sensor has revealed."""

from __future__ import annotations

import numpy as np
import pytest

from pfnav_harness.errors import SimulationError
from pfnav_harness.scenario import Terrain
from pfnav_harness.sensing import BeliefMap, SensorConfig


def _truth() -> Terrain:
    rng = np.random.default_rng(3)
    heights = rng.uniform(0.0, 0.5, size=(40, 50))
    obstacles = np.zeros((40, 50), dtype=bool)
    obstacles[20:24, 30:34] = True
    return Terrain((0.0, 0.0), 0.1, heights, obstacles)


def test_without_a_prior_nothing_is_known_until_seen() -> None:
    belief = BeliefMap(_truth(), None, SensorConfig(range_m=0.5))
    assert belief.known_fraction == 0.0
    assert belief.terrain().obstacles is None


def test_observation_reveals_exactly_the_cells_in_range() -> None:
    truth = _truth()
    belief = BeliefMap(truth, None, SensorConfig(range_m=0.5))
    changed = belief.observe(1.0, 1.0)
    cx = (np.arange(50) + 0.5) * 0.1
    cy = (np.arange(40) + 0.5) * 0.1
    expected = (cx[None, :] - 1.0) ** 2 + (cy[:, None] - 1.0) ** 2 <= 0.25
    np.testing.assert_array_equal(belief.known, expected)
    assert changed == int(expected.sum())
    np.testing.assert_array_equal(belief.heights[expected], truth.heights[expected])
    # Seeing the same cells again changes nothing.
    assert belief.observe(1.0, 1.0) == 0


def test_obstacles_appear_only_once_seen() -> None:
    truth = _truth()
    belief = BeliefMap(truth, None, SensorConfig(range_m=0.3))
    belief.observe(1.0, 1.0)
    assert belief.terrain().obstacles is None
    belief.observe(3.2, 2.2)
    seen = belief.terrain().obstacles
    assert seen is not None and seen[21, 31] and not seen[0, 0]


def test_a_prior_is_known_and_corrected_by_the_sensor() -> None:
    truth = _truth()
    prior = Terrain(truth.origin, truth.resolution, np.zeros(truth.shape), None)
    belief = BeliefMap(truth, prior, SensorConfig(range_m=0.3))
    assert belief.known_fraction == 1.0 and belief.known_mask() is None
    # The prior shows no obstacle; the sensor finds it and reports the changed cells.
    assert belief.observe(3.2, 2.2) > 0
    terrain = belief.terrain()
    assert terrain.obstacles is not None and terrain.obstacles[21, 31]


def test_far_off_map_observation_is_harmless() -> None:
    belief = BeliefMap(_truth(), None, SensorConfig(range_m=1.0))
    assert belief.observe(100.0, -50.0) == 0
    assert belief.known_fraction == 0.0


@pytest.mark.parametrize(
    "config",
    [SensorConfig(range_m=0.0), SensorConfig(range_m=float("nan")), SensorConfig(unknown_traversability=-0.1), SensorConfig(unknown_traversability=1.5)],
)
def test_bad_sensor_settings_are_refused(config: SensorConfig) -> None:
    with pytest.raises(SimulationError):
        BeliefMap(_truth(), None, config)


def test_a_prior_of_another_shape_is_refused() -> None:
    truth = _truth()
    prior = Terrain(truth.origin, truth.resolution, np.zeros((10, 10)), None)
    with pytest.raises(SimulationError, match="prior map"):
        BeliefMap(truth, prior, SensorConfig())
