"""A robot-centric elevation map: terrain heights with variances, fused from a terrain sensor's
returns in the robot's odometry frame (after Fankhauser et al., RA-L 2018, ANYbotics'
`elevation_mapping`).

The map lives in the frame the state estimator defines: every return is placed with the
*estimated* trunk pose and the sensor's mounting (`TerrainSensorConfig.mount_xyz` and tilt), never
with the truth. Where the estimate has drifted, the map is shifted with it, consistently with
where the robot believes it is.

Per cell: height h and variance σ² (NaN and inf while unknown).
- Each return gets a height variance from the range noise projected on z, d_z²·σ_r(r)², plus the
  trunk's roll/pitch uncertainty carried along the lever arm from the trunk to the point
  (J Σ_θ Jᵀ, J = −(R e_z) × v). Position and yaw uncertainty are common to the map and the robot;
  what matters is how much they grow between a cell's measurement and now (`grow`).
- The returns of one scan that fall in one cell are screened against the cell's median (a return
  more than `gate` robust standard deviations away is a "scan outlier"), then averaged with
  inverse-variance weights; the cell's measurement variance is that of the weighted mean plus the
  spread of the returns in the cell (a slope seen from one side).
- A cell's first measurement is *unconfirmed* unless at least `confirm_returns` screened returns
  back it: a lone return may be a spurious range (a flying pixel, a multipath echo) placed
  anywhere along its ray, often far below the ground behind a flank, and nothing in its scan can
  tell. An unconfirmed cell is known, with variance at least `unconfirmed_variance`, so it tilts
  a fitted slope little and costs the planner its upper bound. The next measurement that agrees
  with it (within the gate) confirms it; one that does not replaces it, still unconfirmed: a
  single return has no claim to outvote the next.
- A 1-D Kalman update fuses the measurement into the cell, unless the Mahalanobis distance
  |z − h| / √(σ² + σ_m²) exceeds `gate`: then the measurement is rejected ("gated") and the
  cell's variance grows by `rejection_inflation`, so a lasting disagreement (the ground changed,
  or the pose drifted) is taken after a few scans instead of never.
- `grow` adds the increase of the estimator's position variance since the last call: vertical,
  plus horizontal times the squared local slope. A cell whose variance passes `max_variance` is
  unknown again. That part (`drift_variances`, carried through each update by its Kalman factor
  1 − gain) is a displacement common to neighbouring cells: it leaves slopes and steps alone.
  `measurement_variances` (the rest) is what sets the uncertainty of the map's relative
  geometry, the planner's confidence bounds; the position's own σ reaches the planner as the
  footprint margin.
- `lower`/`upper` are the confidence bounds h ∓ k·σ (k = `confidence_sigmas`).
- Hazard labels (a sensor with labels, `TerrainSensorConfig.label_error` e): each cell counts net
  hazard votes, +1 per return labelled hazard and −1 per return labelled ground (the cell's
  screened returns, for a measurement that is fused), which is its log-odds of being a hazard in
  steps of log((1 − e)/e); the count is held within ±`hazard_votes_limit` so that a changed label
  can still turn. A known cell is a hazard (`hazards`) from `hazard_votes` net votes on.

Bad input never changes the map: a scan with a non-finite pose or covariance, or captured before
the last fused one, is rejected whole with a reason; non-finite returns, returns beyond
`max_point_range` and returns outside the map are counted per reason and dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .body_sensors import quaternion_to_matrix
from .errors import SimulationError
from .terrain_sensor import SensorScan, TerrainSensorConfig, trunk_pose_problem

FloatArray = NDArray[np.float64]

# Why a return or a cell measurement did not change the map (FuseReport.counts keys).
NO_RETURN = "no return"
NON_FINITE = "non-finite"
OUT_OF_RANGE = "out of range"
OUTSIDE_MAP = "outside map"
SCAN_OUTLIER = "scan outlier"
GATED = "gated"
FUSED = "fused"
# Why a whole scan was rejected (FuseReport.rejected).
BAD_POSE = "pose not finite or not a rotation"
BAD_COVARIANCE = "covariance not finite, not symmetric or negative"
STALE = "captured before the last fused scan"
BAD_SHAPE = "points are not an (n, 3) array"
BAD_LABELS = "hazard labels are not one per point"

# 1.4826 · MAD estimates a Gaussian's standard deviation.
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class PoseBelief:
    """The estimator's trunk pose in its odometry frame and how uncertain it is."""

    position: FloatArray
    # (w, x, y, z), trunk → odometry frame.
    quaternion: FloatArray
    # Position covariance, m² (3 × 3).
    position_covariance: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))
    # Variance of roll, pitch, yaw about the trunk axes, rad².
    attitude_variance: FloatArray = field(default_factory=lambda: np.full(3, 1e-4))

    def problem(self) -> str | None:
        """Why this pose cannot be used, or None."""
        if trunk_pose_problem(self.position, self.quaternion) is not None:
            return BAD_POSE
        c, a = np.asarray(self.position_covariance, dtype=np.float64), np.asarray(self.attitude_variance, dtype=np.float64)
        if c.shape != (3, 3) or a.shape != (3,) or not (np.all(np.isfinite(c)) and np.all(np.isfinite(a))):
            return BAD_COVARIANCE
        if not np.allclose(c, c.T, atol=1e-12) or np.any(np.diag(c) < 0.0) or np.any(a < 0.0):
            return BAD_COVARIANCE
        return None


@dataclass(frozen=True)
class ElevationMapConfig:
    mahalanobis_gate: float = 3.0
    # m² added to a cell's variance each time a measurement of it is gated.
    rejection_inflation: float = 0.01
    # m²: a cell more uncertain than this is unknown again.
    max_variance: float = 1.0
    # m²: floor of a measurement's variance (a noiseless sensor still has rounding).
    min_variance: float = 1e-8
    confidence_sigmas: float = 2.0
    # m: returns farther than this from the sensor are not physical (hostile or corrupt data).
    max_point_range: float = 100.0
    # Net hazard-labelled returns that make a cell a hazard, and the most the evidence holds.
    hazard_votes: float = 2.0
    hazard_votes_limit: float = 6.0
    # Screened returns of one scan that make a new cell's measurement confirmed at once.
    confirm_returns: int = 3
    # m²: the least variance of an unconfirmed cell (σ 0.5 m; at most `max_variance`).
    unconfirmed_variance: float = 0.25

    def validate(self) -> None:
        checks = {
            "mahalanobis_gate": self.mahalanobis_gate > 0.0,
            "rejection_inflation": self.rejection_inflation >= 0.0,
            "max_variance": self.max_variance > 0.0,
            "min_variance": 0.0 < self.min_variance < self.max_variance,
            "confidence_sigmas": self.confidence_sigmas >= 0.0,
            "max_point_range": self.max_point_range > 0.0,
            "hazard_votes": self.hazard_votes > 0.0,
            "hazard_votes_limit": self.hazard_votes_limit >= self.hazard_votes,
            "confirm_returns": self.confirm_returns >= 1,
            "unconfirmed_variance": self.unconfirmed_variance >= self.min_variance,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (math.isfinite(value) and ok):
                raise SimulationError(f"elevation map: invalid {name} = {value}")


@dataclass
class FuseReport:
    """What one `fuse` call did: returns and cells per outcome, or why the scan was rejected."""

    capture_time: float
    rejected: str | None = None
    counts: dict[str, int] = field(default_factory=dict)
    # Cells whose height or variance changed.
    changed_cells: int = 0


class ElevationMap:
    """Heights and variances on a grid of the odometry frame (see the module text)."""

    def __init__(
        self,
        origin: tuple[float, float],
        resolution: float,
        shape: tuple[int, int],
        sensor: TerrainSensorConfig,
        config: ElevationMapConfig | None = None,
    ) -> None:
        self.config = config or ElevationMapConfig()
        self.config.validate()
        sensor.validate()
        if not (all(math.isfinite(v) for v in origin) and math.isfinite(resolution) and resolution > 0.0):
            raise SimulationError(f"elevation map: invalid origin {origin} or resolution {resolution}")
        ny, nx = shape
        if not (1 <= ny <= 8192 and 1 <= nx <= 8192):
            raise SimulationError(f"elevation map: invalid shape {shape}")
        self.origin = (float(origin[0]), float(origin[1]))
        self.resolution = float(resolution)
        self.shape = (int(ny), int(nx))
        self.mount = np.asarray(sensor.mount_xyz, dtype=np.float64)
        self.mount_rotation = sensor.rotation_on_trunk()
        self.sensor = sensor
        self.heights = np.full(self.shape, np.nan)
        self.variances = np.full(self.shape, np.inf)
        # The part of `variances` that `grow` added (0 where unknown).
        self.drift_variances = np.zeros(self.shape)
        # Evidence that a cell is a hazard, in label votes (0: none either way).
        self.net_hazard_votes = np.zeros(self.shape)
        # Known cells whose height more than one return has backed (module text).
        self.confirmed = np.zeros(self.shape, dtype=bool)
        self.last_capture_time = -math.inf
        self.totals: dict[str, int] = {}

    @property
    def known(self) -> NDArray[np.bool_]:
        return np.isfinite(self.heights)

    @property
    def hazards(self) -> NDArray[np.bool_]:
        """Known cells whose labels say hazard (`ElevationMapConfig.hazard_votes` net votes)."""
        return self.known & (self.net_hazard_votes >= self.config.hazard_votes)

    def measurement_variances(self) -> FloatArray:
        """`variances` less the pose drift's share: the uncertainty of a cell relative to its
        neighbours (inf where unknown)."""
        return np.maximum(self.variances - self.drift_variances, self.config.min_variance)

    def lower(self) -> FloatArray:
        """Lower confidence bound h − k σ (NaN where unknown)."""
        return self.heights - self.config.confidence_sigmas * np.sqrt(self.variances)

    def upper(self) -> FloatArray:
        """Upper confidence bound h + k σ (NaN where unknown)."""
        return self.heights + self.config.confidence_sigmas * np.sqrt(self.variances)

    def cell_centres(self) -> tuple[FloatArray, FloatArray]:
        ny, nx = self.shape
        xs = self.origin[0] + (np.arange(nx) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(ny) + 0.5) * self.resolution
        return xs, ys

    def _count(self, report: FuseReport, reason: str, n: int) -> None:
        if n:
            report.counts[reason] = report.counts.get(reason, 0) + int(n)
            self.totals[reason] = self.totals.get(reason, 0) + int(n)

    def _reject(self, report: FuseReport, reason: str) -> FuseReport:
        report.rejected = reason
        self.totals["rejected scans"] = self.totals.get("rejected scans", 0) + 1
        return report

    def fuse(self, scan: SensorScan, pose: PoseBelief) -> FuseReport:
        """Fuses one scan taken at the estimated trunk pose `pose`."""
        report = FuseReport(capture_time=scan.capture_time)
        if not math.isfinite(scan.capture_time) or scan.capture_time < self.last_capture_time:
            return self._reject(report, STALE)
        points = np.asarray(scan.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            return self._reject(report, BAD_SHAPE)
        labels = None if scan.hazard is None or not self.sensor.labels else np.asarray(scan.hazard, dtype=bool)
        if labels is not None and labels.shape != (len(points),):
            return self._reject(report, BAD_LABELS)
        problem = pose.problem()
        if problem is not None:
            return self._reject(report, problem)
        self.last_capture_time = scan.capture_time
        c = self.config

        nan_rows = np.all(np.isnan(points), axis=1)
        self._count(report, NO_RETURN, int(nan_rows.sum()))
        finite = np.all(np.isfinite(points), axis=1)
        self._count(report, NON_FINITE, int((~finite & ~nan_rows).sum()))
        points = points[finite]
        ranges = np.linalg.norm(points, axis=1)
        in_range = ranges <= c.max_point_range
        self._count(report, OUT_OF_RANGE, int((~in_range).sum()))
        points, ranges = points[in_range], ranges[in_range]
        if labels is not None:
            labels = labels[finite][in_range]
        if points.size == 0:
            return report

        quaternion = np.asarray(pose.quaternion, dtype=np.float64)
        trunk = quaternion_to_matrix(quaternion / np.linalg.norm(quaternion))
        # Points in the trunk frame (lever arms from the trunk origin), then the odometry frame.
        lever = points @ self.mount_rotation.T + self.mount
        world = lever @ trunk.T + np.asarray(pose.position, dtype=np.float64)
        ix = np.floor((world[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        iy = np.floor((world[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        ny, nx = self.shape
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        self._count(report, OUTSIDE_MAP, int((~inside).sum()))
        if not inside.any():
            return report
        world, lever, ranges, ix, iy = world[inside], lever[inside], ranges[inside], ix[inside], iy[inside]
        if labels is not None:
            labels = labels[inside]

        # Height variance of each return: range noise along the ray's vertical component, plus
        # roll/pitch/yaw uncertainty along the lever arm.
        ray_z = (world[:, 2] - (trunk @ self.mount + pose.position)[2]) / np.maximum(ranges, 1e-9)
        sigma_r = self.sensor.sigma(ranges)
        jacobian = -np.cross(trunk[2, :], lever)
        variance = ray_z**2 * sigma_r**2 + (jacobian**2) @ np.asarray(pose.attitude_variance, dtype=np.float64)
        variance = np.maximum(variance, c.min_variance)

        cell = iy * nx + ix
        z = world[:, 2]
        # Screen each cell's returns against its median (robust scale: MAD, at least the returns' own σ).
        order = np.lexsort((z, cell))
        cell, z, variance = cell[order], z[order], variance[order]
        if labels is not None:
            labels = labels[order]
        starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
        counts = np.diff(np.r_[starts, len(cell)])
        group = np.repeat(np.arange(len(starts)), counts)
        median = 0.5 * (z[starts + (counts - 1) // 2] + z[starts + counts // 2])
        deviation = np.abs(z - median[group])
        dev_order = np.lexsort((deviation, group))
        sorted_dev = deviation[dev_order]
        mad = 0.5 * (sorted_dev[starts + (counts - 1) // 2] + sorted_dev[starts + counts // 2])
        scale = np.sqrt((_MAD_TO_SIGMA * mad[group]) ** 2 + variance)
        keep = deviation <= c.mahalanobis_gate * scale
        self._count(report, SCAN_OUTLIER, int((~keep).sum()))
        cell, z, variance, group = cell[keep], z[keep], variance[keep], group[keep]
        if labels is not None:
            labels = labels[keep]

        # Inverse-variance mean per cell, its variance plus the spread of the cell's returns.
        n_groups = len(starts)
        weight = 1.0 / variance
        w_sum = np.bincount(group, weight, n_groups)
        used = w_sum > 0.0
        w_sum_safe = np.where(used, w_sum, 1.0)
        mean = np.bincount(group, weight * z, n_groups) / w_sum_safe
        spread = np.bincount(group, weight * (z - mean[group]) ** 2, n_groups) / w_sum_safe
        measured = mean[used]
        measured_variance = 1.0 / w_sum[used] + spread[used]
        returns_per_group = np.bincount(group, None, n_groups)
        support = returns_per_group[used]
        cells = np.zeros(n_groups, dtype=np.int64)
        cells[group] = cell
        cells = cells[used]

        h = self.heights.reshape(-1)
        v = self.variances.reshape(-1)
        confirmed = self.confirmed.reshape(-1)
        prior_h, prior_v = h[cells], v[cells]
        unknown = ~np.isfinite(prior_h)
        # Unknown cells take the measurement as it is (gain 1); placeholders keep the arithmetic finite.
        known_h = np.where(unknown, measured, prior_h)
        known_v = np.where(unknown, 1.0, prior_v)
        distance = np.abs(measured - known_h) / np.sqrt(known_v + measured_variance)
        disagrees = ~unknown & (distance > c.mahalanobis_gate)
        # An unconfirmed cell's disagreeing measurement replaces it (module text).
        replaced = disagrees & ~confirmed[cells]
        gated = disagrees & ~replaced
        fresh = unknown | replaced
        accept = ~gated
        gain = np.where(fresh, 1.0, known_v / (known_v + measured_variance))
        new_h = np.where(fresh, measured, known_h + gain * (measured - known_h))
        new_v = np.where(fresh, measured_variance, (1.0 - gain) * known_v)
        backed = support >= c.confirm_returns
        # A fresh cell without the returns to back it stays unconfirmed; a known one that agreed is confirmed.
        new_confirmed = np.where(fresh, backed, True)
        new_v = np.where(new_confirmed, new_v, np.maximum(new_v, min(c.unconfirmed_variance, c.max_variance)))
        h[cells[accept]] = new_h[accept]
        v[cells[accept]] = np.maximum(new_v[accept], c.min_variance)
        confirmed[cells[accept]] = new_confirmed[accept]
        drift = self.drift_variances.reshape(-1)
        # An unknown cell starts without drift; a known one keeps the share the update leaves.
        drift[cells[accept]] = np.where(fresh, 0.0, (1.0 - gain) * drift[cells])[accept]
        if labels is not None:
            # Net hazard votes of each cell's screened returns, for the measurements fused.
            net = (2.0 * np.bincount(group, labels.astype(np.float64), n_groups) - returns_per_group)[used]
            votes = self.net_hazard_votes.reshape(-1)
            limit = c.hazard_votes_limit
            votes[cells[accept]] = np.clip(np.where(fresh, 0.0, votes[cells])[accept] + net[accept], -limit, limit)
        v[cells[gated]] = prior_v[gated] + c.rejection_inflation
        self._forget(cells[gated])
        self._count(report, GATED, int(gated.sum()))
        self._count(report, FUSED, int(accept.sum()))
        report.changed_cells = len(cells)
        return report

    def grow(self, position_variance_increase: FloatArray) -> None:
        """Adds the growth of the estimator's position variance (x, y, z; m²) since the last call."""
        increase = np.asarray(position_variance_increase, dtype=np.float64)
        if increase.shape != (3,) or not np.all(np.isfinite(increase)):
            raise SimulationError(f"elevation map: the variance increase must be three finite numbers, got {increase}")
        increase = np.maximum(increase, 0.0)
        if not increase.any():
            return
        with np.errstate(invalid="ignore"):
            gy, gx = np.gradient(self.heights, self.resolution) if min(self.shape) >= 2 else (np.zeros(self.shape), np.zeros(self.shape))
        gx = np.nan_to_num(gx, nan=0.0)
        gy = np.nan_to_num(gy, nan=0.0)
        known = self.known
        added = increase[2] + gx[known] ** 2 * increase[0] + gy[known] ** 2 * increase[1]
        self.variances[known] += added
        self.drift_variances[known] += added
        self._forget(np.flatnonzero((self.variances > self.config.max_variance) & known))

    def _forget(self, cells: NDArray[np.int64]) -> None:
        """Cells past `max_variance` become unknown."""
        v = self.variances.reshape(-1)
        gone = cells[v[cells] > self.config.max_variance]
        if gone.size:
            self.heights.reshape(-1)[gone] = np.nan
            v[gone] = np.inf
            self.drift_variances.reshape(-1)[gone] = 0.0
            self.net_hazard_votes.reshape(-1)[gone] = 0.0
            self.confirmed.reshape(-1)[gone] = False
