"""Tracking metrics of one co-simulation run, computed from its log.

∫p ds comes from the planner itself: `TraversabilityField` writes the terrain and the scenario's
traversability model (with the robot footprint the planner service is started with) as a map file
and `path_cost` asks `pf-plan path-cost` to measure a polyline on it, with the very traversability
field, footprint filter and quadrature (bilinear p, trapezoid rule, steps ≤ resolution/8) that the
planner reports for its own plans (`planner/core/src/metrics.rs`). There is no second copy of the
cost model here; a test checks that the harness's ∫p ds of a planned path equals the planner's.
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import paths
from .errors import PlannerError
from .scenario import GoalRegion, Terrain, write_map
from .tools import run_tool

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class FallThresholds:
    """The harness's fall rule: while walking, the base lower than `min_base_height` above the
    terrain, roll or pitch beyond the limits (rad), or the controller in its damping state, looked
    at every `every_steps`-th physics step. The co-simulation stops on it (`fallen`) and the
    metrics judge a log by it (`judge_fall`): both name the same fall time."""

    min_base_height: float = 0.12
    # Absolute tilt: on rough ground the local slope under the base is too noisy a reference
    # (±0.3 m windows on the scenario meshes reach 30°); 1 rad plus a margin for the slope a
    # walkable route tilts a standing body by (≤ ~15°).
    max_roll: float = 1.3
    max_pitch: float = 1.3
    # A look costs a height lookup and a quaternion's angles; a fall lasts far longer than 10 ms.
    every_steps: int = 10

    def too_low(self, base_height: FloatArray | float) -> BoolArray | bool:
        return base_height < self.min_base_height

    def too_rolled(self, roll: FloatArray | float) -> BoolArray | bool:
        return abs(roll) > self.max_roll

    def too_pitched(self, pitch: FloatArray | float) -> BoolArray | bool:
        return abs(pitch) > self.max_pitch

    def fallen(self, base_height: float, roll: float, pitch: float) -> bool:
        """Height and tilt at one sample (the caller adds the damping state and when to look)."""
        return bool(self.too_low(base_height) or self.too_rolled(roll) or self.too_pitched(pitch))

    def looks_at(self, steps: NDArray[np.intp]) -> BoolArray:
        """Which physics steps (log rows) the rule is applied at."""
        return steps % self.every_steps == 0


class CostModelError(PlannerError, ValueError):
    """`pf-plan` refused the terrain, the traversability parameters or a path (bad input)."""


@dataclass(frozen=True)
class PathCost:
    """The planner's measurement of a polyline (`pf-plan path-cost`)."""

    cost_integral: float
    length: float
    length_in_obstacles: float
    min_clearance: float | None
    max_slope_deg: float


class TraversabilityField:
    """The planner's traversability model on one terrain; `pf-plan` evaluates it.

    The map file lives in a private temporary folder for the lifetime of this object. Invalid
    parameters (negative footprint, zero weights, negative heights, ...) are refused by the planner
    with its reason (`CostModelError`, a `ValueError`), when the field is made.
    """

    def __init__(self, terrain: Terrain, params: dict[str, Any] | None = None, pf_plan: Path | None = None, timeout: float = 120.0) -> None:
        self.terrain = terrain
        self.params = dict(params or {})
        self.timeout = timeout
        self._pf_plan = pf_plan
        self._folder = tempfile.TemporaryDirectory(prefix="pfnav-field-")
        self.map_file = write_map(terrain, Path(self._folder.name), "field", self.params)
        self._values: FloatArray | None = None
        self.values  # noqa: B018 - evaluate once now: bad parameters fail here, not at the first path

    def _run(self, command: str, args: list[str], stdin: str | None = None) -> str:
        binary = self._pf_plan or paths.pf_plan_path()
        return run_tool(
            binary,
            [command, "--map", str(self.map_file), *args],
            what=f"pf-plan {command} refused the map, the traversability parameters or the path",
            failure=CostModelError,
            timeout=self.timeout,
            stdin=stdin,
        )

    @property
    def values(self) -> FloatArray:
        """p per map cell, shape (rows along y, columns along x), as the planner evaluates it."""
        if self._values is None:
            out = Path(self._folder.name) / "p.npy"
            self._run("traversability", ["--out", str(out)])
            self._values = np.load(out, allow_pickle=False)
        return self._values

    def measure(self, x: FloatArray, y: FloatArray) -> PathCost:
        """The planner's ∫p ds, length, obstacle length, clearance and steepest slope of a polyline."""
        x = np.asarray(x, dtype=np.float64).ravel()
        y = np.asarray(y, dtype=np.float64).ravel()
        if len(x) != len(y):
            raise ValueError(f"path x and y differ in length ({len(x)} vs {len(y)})")
        # %.17g reads back to the same double: the planner measures exactly these points.
        rows = "\n".join(f"{a:.17g},{b:.17g}" for a, b in zip(x.tolist(), y.tolist(), strict=True))
        reply = json.loads(self._run("path-cost", ["--path", "-"], stdin=f"x,y\n{rows}\n"))
        clearance = reply.get("min_clearance")
        return PathCost(
            cost_integral=float(reply["cost_integral"]),
            length=float(reply["length"]),
            length_in_obstacles=float(reply["length_in_obstacles"]),
            min_clearance=None if clearance is None else float(clearance),
            max_slope_deg=float(reply["max_slope_deg"]),
        )


def path_cost(field: TraversabilityField, x: FloatArray, y: FloatArray) -> tuple[float, float]:
    """(∫p ds, length) of a polyline as the planner measures it; (0, 0) without a segment."""
    if len(x) < 2:
        return 0.0, 0.0
    cost = field.measure(x, y)
    return cost.cost_integral, cost.length


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
    # Largest horizontal distance of the walked path from the plan's path (in feedback mode the
    # reference is the robot's own position, so this, not the tracking error, says how far it strayed).
    max_path_deviation: float = 0.0
    # The steepest terrain under the planned path, as the planner measures it, degrees.
    planned_max_slope_deg: float = 0.0
    # Wall-clock time the planner service spent on the plan, s (None: not from the service).
    planner_solve_time: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class FallVerdict:
    """Whether and when a run fell, and by which rule."""

    fell: bool
    fall_time: float | None
    reason: str


def walking_mask(log: dict[str, FloatArray]) -> NDArray[np.bool_]:
    """The log rows from the walk start on (every row when the walk never started)."""
    t = log["t"]
    walking = t >= (float(log["walk_start"]) if "walk_start" in log else 0.0)
    return walking if np.any(walking) else np.ones_like(t, dtype=bool)


def judge_fall(log: dict[str, FloatArray], terrain: Terrain, thresholds: FallThresholds, tilt_from: float | None = None) -> FallVerdict:
    """The fall rule (`FallThresholds`) applied to a log, at the steps the co-simulation looks at.

    Height is judged from the walk start on (the robot starts crouched); tilt and damping from
    `tilt_from` (default: the walk start too), so a caller can also judge the stand-up.
    """
    t = log["t"]
    pos = log["base_pos"]
    looked = thresholds.looks_at(np.arange(len(t)))
    walking = walking_mask(log) & looked
    tilt_judged = (walking if tilt_from is None else t >= tilt_from) & looked
    roll, pitch, _ = roll_pitch_yaw(log["base_quat"])
    base_height = pos[:, 2] - terrain.height(pos[:, 0], pos[:, 1])
    too_low = thresholds.too_low(base_height) & walking
    too_rolled = thresholds.too_rolled(roll) & tilt_judged
    too_pitched = thresholds.too_pitched(pitch) & tilt_judged
    # The controller's damping state is its own verdict that the robot is down (the log carries
    # the FMU's code of that state, read from its modelDescription).
    damping = ((log["fsm"] == log["fsm_damping"]) if "fsm" in log else np.zeros_like(too_low)) & tilt_judged
    fallen = too_low | too_rolled | too_pitched | damping
    if not np.any(fallen):
        return FallVerdict(False, None, "")
    k = int(np.nonzero(fallen)[0][0])
    reasons = []
    if too_low[k]:
        reasons.append(f"base {base_height[k]:.3f} m above ground")
    if too_rolled[k]:
        reasons.append(f"roll {math.degrees(roll[k]):.0f} deg")
    if too_pitched[k]:
        reasons.append(f"pitch {math.degrees(pitch[k]):.0f} deg")
    if damping[k]:
        reasons.append("controller entered damping")
    return FallVerdict(True, float(t[k]), ", ".join(reasons))


def rms_tracking_error(log: dict[str, FloatArray]) -> float:
    """Horizontal RMS distance of the base from the reference while walking, m."""
    pos, ref = log["base_pos"], log["ref"]
    err = np.hypot(pos[:, 0] - ref[:, 0], pos[:, 1] - ref[:, 1])[walking_mask(log)]
    return float(np.sqrt(np.mean(err**2)))


def compute_metrics(
    log: dict[str, FloatArray],
    terrain: Terrain,
    goal: GoalRegion,
    field: TraversabilityField,
    scenario: str,
    method: str,
    thresholds: FallThresholds | None = None,
    planner_cost: float | None = None,
    planner_solve_time: float | None = None,
) -> RunMetrics:
    """Metrics of a run log (see `cosim.CoSimulation.log_arrays` for the keys)."""
    thresholds = thresholds or FallThresholds()
    t = log["t"]
    pos = log["base_pos"]
    quat = log["base_quat"]
    ref = log["ref"]  # columns x, y, z, yaw, vx, vy, yaw_rate
    walk_start = float(log["walk_start"]) if "walk_start" in log else 0.0
    walking = walking_mask(log)

    err = np.hypot(pos[:, 0] - ref[:, 0], pos[:, 1] - ref[:, 1])
    _, _, yaw = roll_pitch_yaw(quat)
    heading_err = np.abs(wrap_angle(yaw - ref[:, 3]))
    e_walk = err[walking]
    h_walk = heading_err[walking]

    goal_dist = np.hypot(pos[:, 0] - goal.center[0], pos[:, 1] - goal.center[1])
    inside = np.nonzero(goal_dist <= goal.radius)[0]
    goal_reached = bool(len(inside))
    time_to_goal = float(t[inside[0]] - walk_start) if goal_reached else None

    verdict = judge_fall(log, terrain, thresholds)

    tau = log["tau"]
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0] if len(t) > 1 else 0.0))
    effort = float(np.sum(np.sum(tau**2, axis=1) * dt))

    executed_cost, executed_length = path_cost(field, pos[walking, 0], pos[walking, 1])
    planned = field.measure(log["plan_x"], log["plan_y"]) if len(log["plan_x"]) >= 2 else None
    planned_cost, planned_length = (planned.cost_integral, planned.length) if planned is not None else (0.0, 0.0)
    walked = pos[walking][::10]
    deviation = distance_to_polyline(walked[:, 0], walked[:, 1], np.asarray(log["plan_x"]), np.asarray(log["plan_y"]))
    return RunMetrics(
        scenario=scenario,
        method=method,
        duration=float(t[-1] - t[0]) if len(t) else 0.0,
        walk_start=walk_start,
        rms_error=rms_tracking_error(log),
        max_error=float(np.max(e_walk)),
        rms_heading_error_deg=float(np.degrees(np.sqrt(np.mean(h_walk**2)))),
        max_heading_error_deg=float(np.degrees(np.max(h_walk))),
        final_distance_to_goal=float(goal_dist[-1]),
        goal_reached=goal_reached,
        time_to_goal=time_to_goal,
        fell=verdict.fell,
        fall_time=verdict.fall_time,
        fall_reason=verdict.reason,
        effort=effort,
        executed_cost=executed_cost,
        executed_length=executed_length,
        planned_cost=planned_cost,
        planned_length=planned_length,
        planner_cost=planner_cost,
        max_path_deviation=float(deviation.max()) if len(deviation) else 0.0,
        planned_max_slope_deg=planned.max_slope_deg if planned is not None else 0.0,
        planner_solve_time=planner_solve_time,
    )


@dataclass
class OnlineMetrics:
    """What online navigation adds to a run's metrics."""

    map_updates: int
    replans_in_use: int
    # Why answers were not used (bad updates, lost fields, timeouts).
    rejected: list[str]
    # Map published → reply sent by the service, wall seconds, over the regular updates.
    latency_p50: float | None
    latency_p99: float | None
    latency_max: float | None
    # Simulated seconds the simulation allowed for a replan (a latency above it would have been late).
    latency_budget: float
    # Map updates per simulated second while updates went out (they stop at the goal).
    update_rate: float
    # ∫p ds on the true map of the walked path and of the full-knowledge plan.
    executed_cost: float
    full_knowledge_cost: float
    # Largest horizontal distance of the walked path from the first plan's path, m.
    max_deviation: float
    known_fraction: float
    pushes: int
    # A sensed map's known cells at the end of the run: how many lie on the true map, and the
    # share whose height error (after the estimate's offset) is within twice the map's own σ.
    map_cells: int = 0
    map_within_2sigma: float | None = None

    @property
    def cost_ratio(self) -> float:
        return self.executed_cost / self.full_knowledge_cost if self.full_knowledge_cost > 0 else math.inf

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "cost_ratio": self.cost_ratio}


def distance_to_polyline(px: FloatArray, py: FloatArray, x: FloatArray, y: FloatArray) -> FloatArray:
    """Horizontal distance of each point (px, py) to the polyline (x, y)."""
    ax, ay = x[:-1], y[:-1]
    dx, dy = np.diff(x), np.diff(y)
    seg2 = np.maximum(dx * dx + dy * dy, 1e-18)
    out = np.empty(len(px))
    # Chunked so memory stays bounded on long runs (points × segments).
    for start in range(0, len(px), 2048):
        qx = px[start : start + 2048, None]
        qy = py[start : start + 2048, None]
        s = np.clip(((qx - ax) * dx + (qy - ay) * dy) / seg2, 0.0, 1.0)
        d = np.hypot(qx - (ax + s * dx), qy - (ay + s * dy))
        out[start : start + 2048] = d.min(axis=1)
    return out


def compute_online_metrics(log: dict[str, Any], replans: Any, field: TraversabilityField, full_plan: Any, config: Any) -> OnlineMetrics:
    """Online figures of a run (`replans`: the navigator's `Replan` list; `full_plan`: the plan on the true map)."""
    from .online import latency_summary

    summary = latency_summary(replans)
    t = log["t"]
    walking = t >= float(log["walk_start"])
    pos = log["base_pos"][walking]
    executed_cost, _ = path_cost(field, pos[:, 0], pos[:, 1])
    full_cost, _ = path_cost(field, full_plan.x, full_plan.y)
    deviation = distance_to_polyline(pos[::10, 0], pos[::10, 1], np.asarray(log["plan_x"]), np.asarray(log["plan_y"]))
    published = sorted(r.t_publish for r in replans if r.kind != "start")
    update_span = published[-1] - published[0] + float(config.update_period) if published else 0.0
    pushes = 0
    if "push_force" in log:
        active = np.any(log["push_force"] != 0.0, axis=1)
        pushes = int(np.count_nonzero(active[1:] & ~active[:-1]) + int(active[0])) if len(active) else 0
    known = log.get("known_final")
    height_error = log.get("map_height_error")
    map_cells, within = 0, None
    if height_error is not None and len(height_error):
        map_cells = len(height_error)
        within = float(np.mean(np.abs(height_error) <= 2.0 * np.asarray(log["map_height_sigma"])))
    return OnlineMetrics(
        map_updates=int(summary["map_updates"]),
        replans_in_use=int(summary["replans_in_use"]),
        rejected=[f"{r.kind} update seq {r.map_seq}: {r.outcome}" for r in replans if r.rejected],
        latency_p50=summary.get("latency_p50"),
        latency_p99=summary.get("latency_p99"),
        latency_max=summary.get("latency_max"),
        latency_budget=float(config.apply_delay),
        update_rate=len(published) / update_span if update_span > 0 else 0.0,
        executed_cost=executed_cost,
        full_knowledge_cost=full_cost,
        max_deviation=float(np.max(deviation)) if len(deviation) else 0.0,
        known_fraction=float(np.mean(known)) if known is not None else 1.0,
        pushes=pushes,
        map_cells=map_cells,
        map_within_2sigma=within,
    )
