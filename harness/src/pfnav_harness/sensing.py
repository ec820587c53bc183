"""What the robot knows of the terrain: a prior map and the cells a height sensor has seen.

The physics world always walks on the true terrain. The planner only ever sees the belief: cells
in the prior map (if the scenario declares one) or revealed by the sensor carry heights and
obstacle flags; all other cells are unknown and the planner gives them a prior traversability
(unknown pits are not obstacles until seen). The sensor is a disc of `range_m` around the base,
like a ring of depth cameras or a lidar elevation map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .errors import SimulationError
from .scenario import Terrain

DEFAULT_SENSOR_RANGE = 3.0
# terrain_map_t.unknown_traversability = 0: the planner service's own default applies.
PLANNER_DEFAULT = 0.0


@dataclass(frozen=True)
class SensorConfig:
    range_m: float = DEFAULT_SENSOR_RANGE
    # Traversability p the planner gives cells nobody has seen, in (0, 1]; 0: the planner's default.
    unknown_traversability: float = PLANNER_DEFAULT

    def validate(self) -> None:
        if not (math.isfinite(self.range_m) and self.range_m > 0.0):
            raise SimulationError(f"the sensor range must be a positive number of metres, got {self.range_m}")
        check_unknown_traversability(self.unknown_traversability)


def check_unknown_traversability(p: float) -> None:
    """The traversability of unknown cells: in (0, 1], or 0 for the planner's default."""
    if not (p == PLANNER_DEFAULT or (math.isfinite(p) and 0.0 < p <= 1.0)):
        raise SimulationError(f"the traversability of unknown cells must lie in (0, 1] (or be 0: the planner's default), got {p}")


def check_prior_covers(prior: Terrain, truth: Terrain) -> None:
    """A prior map must lie on the true map's grid."""
    if prior.shape != truth.shape or prior.origin != truth.origin or prior.resolution != truth.resolution:
        raise SimulationError(f"the prior map ({prior.shape}, origin {prior.origin}) does not cover the terrain ({truth.shape}, origin {truth.origin})")


class BeliefMap:
    """The robot's map: prior knowledge plus every cell the sensor has revealed."""

    def __init__(self, truth: Terrain, prior: Terrain | None, config: SensorConfig) -> None:
        config.validate()
        if prior is not None:
            check_prior_covers(prior, truth)
        self.truth = truth
        self.config = config
        ny, nx = truth.shape
        if prior is None:
            self.heights = np.zeros((ny, nx))
            self.obstacles = np.zeros((ny, nx), dtype=bool)
            self.known = np.zeros((ny, nx), dtype=bool)
        else:
            self.heights = prior.heights.copy()
            self.obstacles = np.zeros((ny, nx), dtype=bool) if prior.obstacles is None else prior.obstacles.copy()
            self.known = np.ones((ny, nx), dtype=bool)
        self.seen = np.zeros((ny, nx), dtype=bool)
        self._true_obstacles = np.zeros((ny, nx), dtype=bool) if truth.obstacles is None else truth.obstacles
        res = truth.resolution
        self._centre_x = truth.origin[0] + (np.arange(nx) + 0.5) * res
        self._centre_y = truth.origin[1] + (np.arange(ny) + 0.5) * res

    def observe(self, x: float, y: float) -> int:
        """Reveals the true cells within the sensor range of (x, y); returns how many cells changed."""
        r = self.config.range_m
        res = self.truth.resolution
        ny, nx = self.truth.shape
        ix0 = max(0, math.floor((x - r - self.truth.origin[0]) / res))
        ix1 = min(nx, math.ceil((x + r - self.truth.origin[0]) / res) + 1)
        iy0 = max(0, math.floor((y - r - self.truth.origin[1]) / res))
        iy1 = min(ny, math.ceil((y + r - self.truth.origin[1]) / res) + 1)
        if ix0 >= ix1 or iy0 >= iy1:
            return 0
        dx = self._centre_x[ix0:ix1][None, :] - x
        dy = self._centre_y[iy0:iy1][:, None] - y
        in_range = dx * dx + dy * dy <= r * r
        window = (slice(iy0, iy1), slice(ix0, ix1))
        true_heights = self.truth.heights[window]
        true_obstacles = self._true_obstacles[window]
        changed = in_range & (~self.known[window] | (self.heights[window] != true_heights) | (self.obstacles[window] != true_obstacles))
        self.heights[window][in_range] = true_heights[in_range]
        self.obstacles[window][in_range] = true_obstacles[in_range]
        self.known[window] |= in_range
        self.seen[window] |= in_range
        return int(changed.sum())

    def terrain(self) -> Terrain:
        """The believed terrain (unknown cells at height 0, never obstacles); a copy."""
        obstacles = self.obstacles & self.known
        return Terrain(self.truth.origin, self.truth.resolution, self.heights.copy(), obstacles if obstacles.any() else None)

    @property
    def unknown_traversability(self) -> float:
        return self.config.unknown_traversability

    @property
    def known_fraction(self) -> float:
        return float(self.known.mean())

    def known_mask(self) -> NDArray[np.bool_] | None:
        """The known cells, or None when every cell is known (the map message then sends no mask)."""
        return None if bool(self.known.all()) else self.known.copy()

    def height_variances(self) -> NDArray[np.float64] | None:
        """None: the ideal sensor's heights are exact."""
        return None
