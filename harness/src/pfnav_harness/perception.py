"""What a robot with a real terrain sensor knows: an elevation map fused, at the sensor's rate,
from scans taken at the true trunk pose and placed with the estimated one.

`SensedMap` stands beside `sensing.BeliefMap` (the ideal disc sensor, kept for comparison) and
answers the online navigator the same questions: the terrain to plan on, which cells are known,
how many cells the last update changed. The map lives in the estimator's frame (`elevation_map`),
so the map, the plan and the feedback field sampled at the estimate agree with each other even
where the estimate has drifted from the truth.

The planner gets each known cell's height; unknown cells (never seen, or forgotten when their
variance passed the map's limit) carry the prior traversability. A scenario's prior map starts
the elevation map at `prior_variance`: a surprise in it is gated first, then taken once it has
been seen a few times (the map's variance inflation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .elevation_map import ElevationMap, ElevationMapConfig, FuseReport, PoseBelief
from .errors import SimulationError
from .scenario import Terrain
from .sensing import PLANNER_DEFAULT, check_prior_covers, check_unknown_traversability
from .terrain_sensor import TerrainSensor, TerrainSensorConfig

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PerceptionConfig:
    sensor: TerrainSensorConfig = field(default_factory=TerrainSensorConfig)
    elevation_map: ElevationMapConfig = field(default_factory=ElevationMapConfig)
    # m²: variance of a scenario's prior map heights.
    prior_variance: float = 0.01
    # Traversability p the planner gives unknown cells, in (0, 1]; 0: the planner's default.
    unknown_traversability: float = PLANNER_DEFAULT

    def validate(self) -> None:
        self.sensor.validate()
        self.elevation_map.validate()
        if not (math.isfinite(self.prior_variance) and 0.0 < self.prior_variance < self.elevation_map.max_variance):
            raise SimulationError(f"the prior map's variance must lie in (0, max_variance), got {self.prior_variance}")
        check_unknown_traversability(self.unknown_traversability)


class SensedMap:
    """The terrain sensor and the elevation map of one run."""

    def __init__(self, truth: Terrain, prior: Terrain | None, config: PerceptionConfig) -> None:
        config.validate()
        self.config = config
        self.truth = truth
        self.sensor = TerrainSensor(truth, config.sensor)
        self.map = ElevationMap(truth.origin, truth.resolution, truth.shape, config.sensor, config.elevation_map)
        if prior is not None:
            check_prior_covers(prior, truth)
            self.map.heights[:] = prior.heights
            self.map.variances[:] = config.prior_variance
            # A given map is no lone return: its cells are confirmed (ElevationMap's module text).
            self.map.confirmed[:] = True
        self._next_scan = -math.inf
        self._last_position_variance = np.zeros(3)
        self.reports: list[FuseReport] = []
        self._changed_since_update = 0

    def sense(self, t: float, true_position: FloatArray, true_quaternion: FloatArray, belief: PoseBelief) -> None:
        """Takes the scan due by time `t` (at the sensor's rate) and fuses it at `belief`, after
        growing the map's variances by the estimator's growth since the last scan."""
        if not self.scan_due(t):
            return
        self._next_scan = (math.floor(t / self.sensor.period + 1e-9) + 1) * self.sensor.period
        variance = np.diag(np.asarray(belief.position_covariance, dtype=np.float64))
        if np.all(np.isfinite(variance)):
            self.map.grow(variance - self._last_position_variance)
            self._last_position_variance = variance
        scan = self.sensor.scan(t, true_position, true_quaternion)
        report = self.map.fuse(scan, belief)
        self.reports.append(report)
        self._changed_since_update += report.changed_cells

    def scan_due(self, t: float) -> bool:
        """Whether a scan is due at time `t`: scans come at multiples of the sensor period."""
        return t + 1e-9 >= self._next_scan

    def take_changed(self) -> int:
        """Cells changed since the last call (a map update's "changed cells")."""
        changed, self._changed_since_update = self._changed_since_update, 0
        return changed

    def terrain(self) -> Terrain:
        """The believed terrain: known heights, unknown cells at 0 (their mask goes with them),
        and the cells a labelling sensor calls hazards as obstacles.

        Heights are clipped at 0, the datum of the planner's cost h/h_max (which refuses a map
        with a negative cell): range noise puts returns from the lowest ground a little below it.
        """
        hazards = self.map.hazards
        heights = np.clip(np.nan_to_num(self.map.heights, nan=0.0), 0.0, None)
        return Terrain(self.truth.origin, self.truth.resolution, heights, hazards if hazards.any() else None)

    @property
    def known(self) -> NDArray[np.bool_]:
        return self.map.known

    def known_mask(self) -> NDArray[np.bool_] | None:
        known = self.map.known
        return None if bool(known.all()) else known.copy()

    def height_variances(self) -> FloatArray:
        """Each cell's height variance for the planner, m² (0 where unknown, ignored there): the
        measurement's share, which sets the map's slopes and steps. The drift's share moves
        neighbouring cells together; the planner covers it with the footprint margin of the
        position's σ (see `elevation_map`)."""
        return np.where(self.map.known, self.map.measurement_variances(), 0.0)

    @property
    def known_fraction(self) -> float:
        return float(self.map.known.mean())

    def height_errors(self, true_position: FloatArray, offset: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Each known cell's mapped height minus the true height at the same place, and the
        map's σ of that height: the honesty check of the map's variance.

        The map lives in the estimator's frame. `offset` (x, y, z, yaw: estimate − truth) and the
        robot's true position now give the rigid motion between the two frames; a cell centre of
        the map is carried back into the true frame with it, and the offset's z is removed from
        its height. The map's variances have grown with the estimate's drift since each cell was
        seen, so the offset of now is the one they answer for.
        """
        known = self.map.known
        xs, ys = self.map.cell_centres()
        bx, by = np.meshgrid(xs, ys)
        bx, by = bx[known], by[known]
        px, py = float(true_position[0]), float(true_position[1])
        # Believed = R(δψ)(true − p) + p + offset: invert for the true place of a believed point.
        c, s = math.cos(float(offset[3])), math.sin(float(offset[3]))
        dx, dy = bx - px - float(offset[0]), by - py - float(offset[1])
        tx, ty = px + c * dx + s * dy, py - s * dx + c * dy
        (x0, y0), (x1, y1) = self.truth.bounds()
        inside = (tx >= x0) & (tx < x1) & (ty >= y0) & (ty < y1)
        errors = self.map.heights[known][inside] - float(offset[2]) - self.truth.height(tx[inside], ty[inside])
        return errors, np.sqrt(self.map.variances[known][inside])

    @property
    def unknown_traversability(self) -> float:
        return self.config.unknown_traversability
