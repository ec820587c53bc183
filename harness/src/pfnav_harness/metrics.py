"""Tracking metrics of one co-simulation run, computed from its log.

The traversability p is re-evaluated here from the scenario's own weights with the formula the
planner documents (planner/core/src/traversability.rs): p = clamp((w_h·h/h_max + w_s·min(slope/
slope_ref, 1) + w_r·min(rough/rough_ref, 1)) / (w_h + w_s + w_r), p_floor, 1) per cell centre,
bilinear in between; with `footprint_radius_m` > 0 each cell takes the largest p within that
radius first, obstacle cells counting as p = 1 (the robot footprint the planner service is started
with). Planned and executed paths are integrated with the same field, so their
∫p ds are comparable; a test checks it against the planner's own figure for the planned path.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .scenario import GoalRegion, Terrain

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FallThresholds:
    """A fall: base lower than `min_base_height` above the terrain, roll/pitch beyond the limits (rad), or controller damping."""

    min_base_height: float = 0.12
    max_roll: float = 1.0
    max_pitch: float = 1.0


class TraversabilityField:
    """p per cell centre of the map, bilinear in between, clamped at the map edge."""

    def __init__(self, terrain: Terrain, params: dict[str, Any] | None = None) -> None:
        params = dict(params or {})
        w_h = float(params.get("height_weight", 1.0))
        w_s = float(params.get("slope_weight", 0.0))
        w_r = float(params.get("roughness_weight", 0.0))
        slope_ref = float(params.get("slope_ref_deg", 30.0))
        rough_ref = float(params.get("roughness_ref_m", 0.1))
        p_floor = float(params.get("p_floor", 0.05))
        h_max_param = params.get("h_max")
        if w_h < 0 or w_s < 0 or w_r < 0 or w_h + w_s + w_r <= 0:
            raise ValueError(f"traversability weights must be >= 0 with a positive sum, got {w_h}, {w_s}, {w_r}")
        h = terrain.heights
        h_max = float(h_max_param) if h_max_param is not None else max(float(h.max()), 0.0)
        height_term = np.minimum(h / h_max, 1.0) if h_max > 0 else np.zeros_like(h)
        total = w_h * height_term
        if w_s > 0:
            total = total + w_s * np.minimum(self._slope_deg(h, terrain.resolution) / slope_ref, 1.0)
        if w_r > 0:
            total = total + w_r * np.minimum(self._roughness(h) / rough_ref, 1.0)
        values = np.clip(total / (w_h + w_s + w_r), p_floor, 1.0)
        footprint = float(params.get("footprint_radius_m", 0.0))
        if not (math.isfinite(footprint) and footprint >= 0.0):
            raise ValueError(f"footprint_radius_m must be finite and >= 0, got {footprint}")
        if footprint > 0:
            # As the planner: obstacle cells count as p = 1 within the footprint and keep their own p.
            worst = values if terrain.obstacles is None else np.where(terrain.obstacles, 1.0, values)
            dilated = self._disc_max(worst, footprint / terrain.resolution)
            values = dilated if terrain.obstacles is None else np.where(terrain.obstacles, values, dilated)
        self.values = values
        self.origin = terrain.origin
        self.resolution = terrain.resolution

    @staticmethod
    def _disc_max(values: FloatArray, radius_cells: float) -> FloatArray:
        """Largest value among the cells whose centres lie within `radius_cells` (the planner's filter)."""
        r2 = radius_cells * radius_cells + 1e-9
        reach = math.floor(math.sqrt(r2))
        rows, cols = values.shape
        padded = np.full((rows + 2 * reach, cols + 2 * reach), -np.inf)
        padded[reach : reach + rows, reach : reach + cols] = values
        out = values.copy()
        for dy in range(-reach, reach + 1):
            for dx in range(-reach, reach + 1):
                if dx * dx + dy * dy <= r2:
                    np.maximum(out, padded[reach + dy : reach + dy + rows, reach + dx : reach + dx + cols], out=out)
        return out

    @staticmethod
    def _slope_deg(h: FloatArray, res: float) -> FloatArray:
        ny, nx = h.shape
        ix = np.arange(nx)
        iy = np.arange(ny)
        xl, xh = np.maximum(ix - 1, 0), np.minimum(ix + 1, nx - 1)
        yl, yh = np.maximum(iy - 1, 0), np.minimum(iy + 1, ny - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            dx = (h[:, xh] - h[:, xl]) / ((xh - xl) * res)[None, :]
            dy = (h[yh, :] - h[yl, :]) / ((yh - yl) * res)[:, None]
        dx = np.where(np.isfinite(dx), dx, 0.0)
        dy = np.where(np.isfinite(dy), dy, 0.0)
        return np.degrees(np.arctan(np.hypot(dx, dy)))

    @staticmethod
    def _roughness(h: FloatArray) -> FloatArray:
        ny, nx = h.shape
        out = np.empty_like(h)
        for iy in range(ny):
            y0, y1 = max(iy - 1, 0), min(iy + 1, ny - 1) + 1
            for ix in range(nx):
                x0, x1 = max(ix - 1, 0), min(ix + 1, nx - 1) + 1
                out[iy, ix] = np.std(h[y0:y1, x0:x1])
        return out

    def at(self, x: FloatArray, y: FloatArray) -> FloatArray:
        ny, nx = self.values.shape
        fx = np.clip((np.asarray(x) - self.origin[0]) / self.resolution - 0.5, 0.0, nx - 1.0)
        fy = np.clip((np.asarray(y) - self.origin[1]) / self.resolution - 0.5, 0.0, ny - 1.0)
        x0 = np.floor(fx).astype(np.int64)
        y0 = np.floor(fy).astype(np.int64)
        x1 = np.minimum(x0 + 1, nx - 1)
        y1 = np.minimum(y0 + 1, ny - 1)
        tx = fx - x0
        ty = fy - y0
        v = self.values
        bottom = v[y0, x0] * (1 - tx) + v[y0, x1] * tx
        top = v[y1, x0] * (1 - tx) + v[y1, x1] * tx
        return bottom * (1 - ty) + top * ty


def path_cost(field: TraversabilityField, x: FloatArray, y: FloatArray) -> tuple[float, float]:
    """(∫p ds, length) of a polyline, p at segment midpoints (midpoint rule)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if len(x) < 2:
        return 0.0, 0.0
    ds = np.hypot(np.diff(x), np.diff(y))
    p = field.at(0.5 * (x[1:] + x[:-1]), 0.5 * (y[1:] + y[:-1]))
    return float(np.sum(p * ds)), float(np.sum(ds))


def wrap_angle(a: FloatArray) -> FloatArray:
    """Angle(s) wrapped into (−π, π]."""
    return -((-np.asarray(a) + math.pi) % (2.0 * math.pi) - math.pi)


def roll_pitch_yaw(quat: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """ZYX Euler angles of quaternions (w, x, y, z), shape (N, 4)."""
    w, x, y, z = (quat[:, i] for i in range(4))
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def terrain_pitch_roll(terrain: Terrain, x: FloatArray, y: FloatArray, yaw: FloatArray, radius: float = 0.3, samples: int = 5) -> tuple[FloatArray, FloatArray]:
    """Pitch and roll a body levelled with the local terrain plane would have at heading `yaw`.

    The slope is the mean gradient over a ±`radius` window (about the robot's footprint): one mesh
    triangle under the base can be much steeper than the ground the four feet stand on.
    """
    offsets = np.linspace(-radius, radius, samples)
    gx = np.zeros_like(np.asarray(x, dtype=np.float64))
    gy = np.zeros_like(gx)
    for dx in offsets:
        for dy in offsets:
            _, sx, sy = terrain.height_and_gradient(np.asarray(x) + dx, np.asarray(y) + dy)
            gx = gx + sx
            gy = gy + sy
    gx /= samples * samples
    gy /= samples * samples
    along = gx * np.cos(yaw) + gy * np.sin(yaw)
    across = -gx * np.sin(yaw) + gy * np.cos(yaw)
    # Nose up on an uphill slope is a negative pitch about +y (right-handed, x forward).
    return -np.arctan(along), np.arctan(across)


@dataclass
class RunMetrics:
    scenario: str
    method: str
    duration: float
    walk_start: float
    rms_error: float
    max_error: float
    rms_heading_error_deg: float
    max_heading_error_deg: float
    final_distance_to_goal: float
    goal_reached: bool
    time_to_goal: float | None
    fell: bool
    fall_time: float | None
    fall_reason: str
    effort: float
    executed_cost: float
    executed_length: float
    planned_cost: float
    planned_length: float
    planner_cost: float | None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def compute_metrics(
    log: dict[str, FloatArray],
    terrain: Terrain,
    goal: GoalRegion,
    field: TraversabilityField,
    scenario: str,
    method: str,
    thresholds: FallThresholds | None = None,
    planner_cost: float | None = None,
) -> RunMetrics:
    """Metrics of a run log (see `cosim.CoSimulation.log_arrays` for the keys)."""
    thresholds = thresholds or FallThresholds()
    t = log["t"]
    pos = log["base_pos"]
    quat = log["base_quat"]
    ref = log["ref"]  # columns x, y, z, yaw, vx, vy, yaw_rate
    walk_start = float(log["walk_start"]) if "walk_start" in log else 0.0
    walking = t >= walk_start
    if not np.any(walking):
        walking = np.ones_like(t, dtype=bool)

    err = np.hypot(pos[:, 0] - ref[:, 0], pos[:, 1] - ref[:, 1])
    roll, pitch, yaw = roll_pitch_yaw(quat)
    heading_err = np.abs(wrap_angle(yaw - ref[:, 3]))
    e_walk = err[walking]
    h_walk = heading_err[walking]

    goal_dist = np.hypot(pos[:, 0] - goal.center[0], pos[:, 1] - goal.center[1])
    inside = np.nonzero(goal_dist <= goal.radius)[0]
    goal_reached = bool(len(inside))
    time_to_goal = float(t[inside[0]] - walk_start) if goal_reached else None

    ground = terrain.height(pos[:, 0], pos[:, 1])
    base_height = pos[:, 2] - ground
    too_low = base_height < thresholds.min_base_height
    # Absolute tilt: on rough ground the local slope under the base is too noisy a reference
    # (±0.3 m windows on the scenario meshes reach 30°), and no walkable slope tilts a standing
    # body anywhere near the thresholds.
    too_rolled = np.abs(roll) > thresholds.max_roll
    too_pitched = np.abs(pitch) > thresholds.max_pitch
    # The controller's damping state is its own verdict that the robot is down (the log carries
    # the FMU's code of that state, read from its modelDescription).
    damping = (log["fsm"] == log["fsm_damping"]) if "fsm" in log else np.zeros_like(too_low)
    # Before the controller has stood up the base is legitimately low: only judge after walk start.
    fallen = (too_low | too_rolled | too_pitched | damping) & walking
    fell = bool(np.any(fallen))
    fall_time = None
    reason = ""
    if fell:
        k = int(np.nonzero(fallen)[0][0])
        fall_time = float(t[k])
        reasons = []
        if too_low[k]:
            reasons.append(f"base {base_height[k]:.3f} m above ground")
        if too_rolled[k]:
            reasons.append(f"roll {math.degrees(roll[k]):.0f} deg")
        if too_pitched[k]:
            reasons.append(f"pitch {math.degrees(pitch[k]):.0f} deg")
        if damping[k]:
            reasons.append("controller entered damping")
        reason = ", ".join(reasons)

    tau = log["tau"]
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0] if len(t) > 1 else 0.0))
    effort = float(np.sum(np.sum(tau**2, axis=1) * dt))

    executed_cost, executed_length = path_cost(field, pos[walking, 0], pos[walking, 1])
    planned_cost, planned_length = path_cost(field, log["plan_x"], log["plan_y"])
    return RunMetrics(
        scenario=scenario,
        method=method,
        duration=float(t[-1] - t[0]) if len(t) else 0.0,
        walk_start=walk_start,
        rms_error=float(np.sqrt(np.mean(e_walk**2))),
        max_error=float(np.max(e_walk)),
        rms_heading_error_deg=float(np.degrees(np.sqrt(np.mean(h_walk**2)))),
        max_heading_error_deg=float(np.degrees(np.max(h_walk))),
        final_distance_to_goal=float(goal_dist[-1]),
        goal_reached=goal_reached,
        time_to_goal=time_to_goal,
        fell=fell,
        fall_time=fall_time,
        fall_reason=reason,
        effort=effort,
        executed_cost=executed_cost,
        executed_length=executed_length,
        planned_cost=planned_cost,
        planned_length=planned_length,
        planner_cost=planner_cost,
    )
