"""A terrain sensor a robot has: rays cast from a sensor on the trunk against the simulated ground.

Two ray patterns:
- `depth_camera`: a forward-looking camera tilted down by `pitch_deg`, `columns × rows` pixels
  over the horizontal and vertical fields of view (pinhole geometry, like a down-sampled
  RealSense D435: 87° × 58°, 0.2–4 m);
- `lidar`: a spinning multi-beam lidar, `rows` beams between `elevation_min_deg` and
  `elevation_max_deg`, `columns` azimuths over 360° (like a 16-beam Velodyne).

Each ray returns the first point where it meets the terrain surface, the same piecewise-linear
mesh through the cell-centre heights that the physics walks on (`Terrain.height`), so ridges
hide what lies behind them. Rays that leave the mesh (beyond the outermost cell centres) or meet
nothing within `max_range` give no return. The surface is sampled every `step` metres along the
ray, then the crossing is refined by bisection: a ridge thinner than `step` can be missed.

The measured range carries Gaussian noise σ(r) = `sigma0 + sigma_r2 · r²` (stereo and
time-of-flight depth grows like r²); with probability `dropout` a ray gives no return; with
probability `outlier` it gives a spurious range uniform in [`min_range`, `max_range`] (dust,
multipath). Ranges outside [`min_range`, `max_range`] are not returned. All draws come from a
generator seeded by (`seed`, scan index), so the same seed gives the same scans.

Hazard labels (`label_error` < 0.5, the depth camera's default 0.05): an RGB-D camera with a
segmentation network labels each pixel, so each return carries whether it hit a hazard, the
scenario's obstacle mask at the hit point (water, mud, a no-go area: what has no geometry to
measure), flipped with probability `label_error`; a spurious return gets a coin-flip label. A
lidar (`label_error` = 0.5) carries no labels: its hazards are geometry only.

A scan is delivered like a driver delivers it: points in the sensor frame (x along the optical
axis, y left, z up), NaN rows where a ray returned nothing, and the capture time. The sensor's
pose on the trunk (`mount_xyz`, the tilt) is the calibration the mapping uses to bring points
into the robot's frame; the world pose of the trunk is the truth (the physics), never shown to
the map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .body_sensors import quaternion_to_matrix
from .errors import SimulationError
from .scenario import Terrain

FloatArray = NDArray[np.float64]

SENSOR_KINDS = ("depth_camera", "lidar")
# Bisection halvings of the sampling step that brackets a crossing: 2⁻¹⁴ of a few cm, µm.
_BISECTIONS = 14
# Samples along the rays marched at once: rays that met the ground stop after their chunk.
_SAMPLES_PER_CHUNK = 8


@dataclass(frozen=True)
class TerrainSensorConfig:
    """Geometry, noise and rate of a terrain sensor (see the module text)."""

    kind: str = "depth_camera"
    # Sensor origin in the trunk frame (x forward, y left, z up), m.
    mount_xyz: tuple[float, float, float] = (0.28, 0.0, 0.05)
    # Downward tilt of the optical axis (depth camera) or of the spin axis's horizon (lidar), deg.
    pitch_deg: float = 30.0
    fov_horizontal_deg: float = 87.0
    fov_vertical_deg: float = 58.0
    elevation_min_deg: float = -15.0
    elevation_max_deg: float = 15.0
    columns: int = 64
    rows: int = 40
    min_range: float = 0.2
    max_range: float = 4.0
    rate_hz: float = 5.0
    sigma0: float = 0.005
    sigma_r2: float = 0.004
    dropout: float = 0.02
    outlier: float = 0.002
    seed: int = 0
    # Ray-marching step, m; 0: a quarter of the terrain resolution.
    step: float = 0.0
    # Probability that a return's hazard label is wrong; 0.5: the sensor has no labels.
    label_error: float = 0.05

    @property
    def labels(self) -> bool:
        """Whether the returns carry hazard labels."""
        return self.label_error < 0.5

    @staticmethod
    def lidar(**overrides: object) -> TerrainSensorConfig:
        """A 16-beam spinning lidar on top of the trunk (±15°, 2° azimuth, 0.3–10 m, 10 Hz)."""
        values: dict[str, object] = {
            "kind": "lidar",
            "mount_xyz": (0.0, 0.0, 0.12),
            "pitch_deg": 0.0,
            "columns": 180,
            "rows": 16,
            "min_range": 0.3,
            "max_range": 10.0,
            "rate_hz": 10.0,
            "sigma0": 0.02,
            "sigma_r2": 0.0,
            "label_error": 0.5,
        }
        values.update(overrides)
        return TerrainSensorConfig(**values)  # type: ignore[arg-type]

    def sigma(self, ranges: FloatArray) -> FloatArray:
        """Standard deviation of the range noise at `ranges`, m."""
        return self.sigma0 + self.sigma_r2 * ranges * ranges

    def validate(self) -> None:
        def bad(what: str) -> SimulationError:
            return SimulationError(f"terrain sensor: {what}")

        if self.kind not in SENSOR_KINDS:
            raise bad(f"unknown kind '{self.kind}' (choose from {', '.join(SENSOR_KINDS)})")
        if len(self.mount_xyz) != 3 or not all(math.isfinite(v) and abs(v) <= 5.0 for v in self.mount_xyz):
            raise bad(f"mount_xyz must be three finite numbers within 5 m of the trunk, got {self.mount_xyz}")
        if not (math.isfinite(self.pitch_deg) and -90.0 <= self.pitch_deg <= 90.0):
            raise bad(f"pitch_deg must lie in [-90, 90], got {self.pitch_deg}")
        for name in ("fov_horizontal_deg", "fov_vertical_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 < value < 170.0):
                raise bad(f"{name} must lie in (0, 170) degrees, got {value}")
        low, high = self.elevation_min_deg, self.elevation_max_deg
        if not (math.isfinite(low) and math.isfinite(high) and -90.0 <= low <= high <= 90.0):
            raise bad(f"the lidar's elevations must satisfy -90 <= min <= max <= 90, got {low}, {high}")
        for name in ("columns", "rows"):
            value = getattr(self, name)
            if not (isinstance(value, int) and 1 <= value <= 4096):
                raise bad(f"{name} must be an integer in [1, 4096], got {value!r}")
        if self.columns * self.rows > 200_000:
            raise bad(f"{self.columns} × {self.rows} rays per scan is more than 200000")
        if not (math.isfinite(self.min_range) and math.isfinite(self.max_range) and 0.0 <= self.min_range < self.max_range <= 100.0):
            raise bad(f"ranges must satisfy 0 <= min_range < max_range <= 100 m, got {self.min_range}, {self.max_range}")
        if not (math.isfinite(self.rate_hz) and 0.0 < self.rate_hz <= 1000.0):
            raise bad(f"rate_hz must lie in (0, 1000], got {self.rate_hz}")
        if not (math.isfinite(self.sigma0) and math.isfinite(self.sigma_r2) and self.sigma0 >= 0.0 and self.sigma_r2 >= 0.0):
            raise bad(f"noise parameters must be finite and >= 0, got sigma0={self.sigma0}, sigma_r2={self.sigma_r2}")
        for name in ("dropout", "outlier"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value < 1.0):
                raise bad(f"{name} probability must lie in [0, 1), got {value}")
        if not (math.isfinite(self.label_error) and 0.0 <= self.label_error <= 0.5):
            raise bad(f"label_error must lie in [0, 0.5] (0.5: no labels), got {self.label_error}")
        if not (math.isfinite(self.step) and 0.0 <= self.step <= 1.0):
            raise bad(f"step must lie in [0, 1] m (0: a quarter of the terrain resolution), got {self.step}")
        if not (isinstance(self.seed, int) and 0 <= self.seed < 2**63):
            raise bad(f"seed must be a non-negative integer, got {self.seed!r}")

    def rotation_on_trunk(self) -> FloatArray:
        """Sensor frame → trunk frame: a pitch about the trunk's y axis (down positive)."""
        p = math.radians(self.pitch_deg)
        c, s = math.cos(p), math.sin(p)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    def ray_directions(self) -> FloatArray:
        """Unit ray directions in the sensor frame, shape (rows · columns, 3), row-major."""
        if self.kind == "depth_camera":
            # Pinhole: pixel centres on the image plane at unit distance.
            half_w = math.tan(math.radians(self.fov_horizontal_deg) / 2.0)
            half_h = math.tan(math.radians(self.fov_vertical_deg) / 2.0)
            u = ((np.arange(self.columns) + 0.5) / self.columns * 2.0 - 1.0) * half_w
            v = ((np.arange(self.rows) + 0.5) / self.rows * 2.0 - 1.0) * half_h
            gu, gv = np.meshgrid(-u, -v)  # left of the axis is +y, up is +z
            rays = np.stack([np.ones(gu.size), gu.ravel(), gv.ravel()], axis=1)
        else:
            azimuth = np.arange(self.columns) / self.columns * 2.0 * math.pi
            elevation = np.radians(np.linspace(self.elevation_max_deg, self.elevation_min_deg, self.rows))
            ga, ge = np.meshgrid(azimuth, elevation)
            a, e = ga.ravel(), ge.ravel()
            rays = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)


@dataclass(frozen=True)
class SensorScan:
    """One scan as a driver delivers it (sensor frame), plus what was injected (for evaluation)."""

    capture_time: float
    # (rays, 3) points in the sensor frame; NaN rows: no return.
    points: FloatArray
    # (rays,) measured ranges; NaN: no return.
    ranges: FloatArray
    # Index of this scan since the sensor started (the seed of its draws).
    index: int
    # Ground truth of the simulation, never read by the map: spurious returns and dropped rays.
    injected_outliers: NDArray[np.bool_] = field(repr=False, default_factory=lambda: np.zeros(0, dtype=bool))
    dropped: NDArray[np.bool_] = field(repr=False, default_factory=lambda: np.zeros(0, dtype=bool))
    # (rays,) hazard label of each return (meaningless where there is none); None: no labels.
    hazard: NDArray[np.bool_] | None = None

    @property
    def returns(self) -> int:
        return int(np.count_nonzero(np.isfinite(self.ranges)))


def trunk_pose_problem(position: FloatArray, quaternion: FloatArray) -> str | None:
    """What is wrong with a trunk pose (position, quaternion w, x, y, z), or None."""
    p, q = np.asarray(position, dtype=np.float64), np.asarray(quaternion, dtype=np.float64)
    if p.shape != (3,) or q.shape != (4,) or not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        return "the trunk pose must be a finite position (3) and quaternion (4)"
    norm = float(np.linalg.norm(q))
    if not 0.5 < norm < 2.0:
        return f"the trunk quaternion is not a rotation (norm {norm:.3g})"
    return None


def ray_cast(terrain: Terrain, origin: FloatArray, directions: FloatArray, max_range: float, step: float) -> FloatArray:
    """Distance along each unit direction from `origin` to the terrain surface; inf: no hit.

    A ray starting below the surface hits at 0. Rays that leave the mesh (beyond the outermost
    cell centres) before meeting it give inf.
    """
    origin = np.asarray(origin, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise SimulationError(f"ray_cast: the origin must be a finite 3-vector, got {origin}")
    if directions.ndim != 2 or directions.shape[1] != 3 or not np.all(np.isfinite(directions)):
        raise SimulationError("ray_cast: directions must be finite, shape (n, 3)")
    if not (math.isfinite(max_range) and max_range > 0.0 and math.isfinite(step) and step > 0.0):
        raise SimulationError(f"ray_cast: max_range and step must be positive, got {max_range}, {step}")
    res = terrain.resolution
    ny, nx = terrain.shape
    x_lo, y_lo = terrain.origin[0] + 0.5 * res, terrain.origin[1] + 0.5 * res
    x_hi, y_hi = terrain.origin[0] + (nx - 0.5) * res, terrain.origin[1] + (ny - 0.5) * res
    samples = np.arange(0.0, max_range + step, step)
    samples[-1] = min(samples[-1], max_range)
    out = np.full(len(directions), np.inf)
    # Rays still marching. Most rays of a down-looking sensor meet the ground within a metre:
    # marching in chunks stops them early.
    active = np.arange(len(directions))
    top = float(terrain.heights.max())
    # The brackets of the rays that crossed, refined together at the end: one bisection over
    # every hit instead of one per chunk (the bisection was half the cost of a scan).
    crossed: list[tuple[NDArray[np.intp], FloatArray, FloatArray]] = []
    for chunk_start in range(0, len(samples), _SAMPLES_PER_CHUNK):
        if active.size == 0:
            break
        s = samples[chunk_start : chunk_start + _SAMPLES_PER_CHUNK]
        d = directions[active]
        x = origin[0] + s[None, :] * d[:, 0:1]
        y = origin[1] + s[None, :] * d[:, 1:2]
        z = origin[2] + s[None, :] * d[:, 2:3]
        on_mesh = (x >= x_lo) & (x <= x_hi) & (y >= y_lo) & (y <= y_hi)
        below = (z <= terrain.height(x, y)) & on_mesh
        # A ray is lost once it leaves the mesh: only crossings before that count.
        below &= np.cumsum(~on_mesh, axis=1) == 0
        hit = below.any(axis=1)
        # Lost: left the mesh, or above the highest vertex and not descending.
        lost = ~hit & (~on_mesh.all(axis=1) | ((z[:, -1] > top) & (d[:, 2] >= 0.0)))
        k = chunk_start + np.argmax(below[hit], axis=1)
        hit_rays = active[hit]
        at_start = k == 0
        out[hit_rays[at_start]] = 0.0
        crossed.append((hit_rays[~at_start], samples[k[~at_start] - 1], samples[k[~at_start]]))
        active = active[~hit & ~lost]
    if crossed:
        rays, above, below = (np.concatenate(parts) for parts in zip(*crossed, strict=True))
        _refine(terrain, origin, directions, rays, above, below, out)
    return out


def _refine(
    terrain: Terrain, origin: FloatArray, directions: FloatArray, rays: NDArray[np.intp], above: FloatArray, below: FloatArray, out: FloatArray
) -> None:
    """Bisection of each ray's bracket [above, below] around its crossing; the midpoint into `out`."""
    if rays.size == 0:
        return
    d = directions[rays]
    a, b = above, below
    for _ in range(_BISECTIONS):
        mid = 0.5 * (a + b)
        p = origin[None, :] + mid[:, None] * d
        under = p[:, 2] <= terrain.height(p[:, 0], p[:, 1])
        b = np.where(under, mid, b)
        a = np.where(under, a, mid)
    out[rays] = 0.5 * (a + b)


class TerrainSensor:
    """Scans the true terrain from the trunk's true pose (the simulation's side of a sensor)."""

    def __init__(self, terrain: Terrain, config: TerrainSensorConfig) -> None:
        config.validate()
        self.terrain = terrain
        self.config = config
        self.directions = config.ray_directions()
        self.mount = np.asarray(config.mount_xyz, dtype=np.float64)
        self.mount_rotation = config.rotation_on_trunk()
        self.step = config.step if config.step > 0.0 else 0.25 * terrain.resolution
        self.period = 1.0 / config.rate_hz
        self._index = 0

    @property
    def scans_taken(self) -> int:
        return self._index

    def scan(self, t: float, base_position: FloatArray, base_quaternion: FloatArray) -> SensorScan:
        """A scan captured at time `t` with the trunk at `base_position`, `base_quaternion` (w, x, y, z)."""
        problem = trunk_pose_problem(base_position, base_quaternion)
        if problem is not None:
            raise SimulationError(f"terrain sensor: {problem}")
        position = np.asarray(base_position, dtype=np.float64)
        quaternion = np.asarray(base_quaternion, dtype=np.float64)
        norm = float(np.linalg.norm(quaternion))
        c = self.config
        trunk = quaternion_to_matrix(quaternion / norm)
        sensor_rotation = trunk @ self.mount_rotation
        origin = position + trunk @ self.mount
        true_range = ray_cast(self.terrain, origin, self.directions @ sensor_rotation.T, c.max_range, self.step)

        rng = np.random.default_rng(np.random.SeedSequence((c.seed, self._index)))
        n = len(true_range)
        noise = rng.standard_normal(n)
        outlier = rng.random(n) < c.outlier
        dropped = rng.random(n) < c.dropout
        spurious = rng.uniform(c.min_range, c.max_range, n)
        measured = np.where(np.isfinite(true_range), true_range + c.sigma(np.where(np.isfinite(true_range), true_range, 0.0)) * noise, np.inf)
        measured = np.where(outlier, spurious, measured)
        valid = np.isfinite(measured) & (measured >= c.min_range) & (measured <= c.max_range) & ~dropped
        ranges = np.where(valid, measured, np.nan)
        hazard = None
        if c.labels:
            # Drawn after the range draws, so labels leave a seed's ranges as they were.
            flip = rng.random(n) < c.label_error
            coin = rng.random(n) < 0.5
            hit = origin + (self.directions @ sensor_rotation.T) * np.where(np.isfinite(true_range), true_range, 0.0)[:, None]
            truth = self.terrain.obstacles_at(hit[:, 0], hit[:, 1]) & np.isfinite(true_range)
            hazard = np.where(outlier, coin, truth ^ flip)
        scan = SensorScan(
            capture_time=float(t),
            points=self.directions * ranges[:, None],
            ranges=ranges,
            index=self._index,
            injected_outliers=outlier & valid,
            dropped=dropped,
            hazard=hazard,
        )
        self._index += 1
        return scan
