"""The planner's optimal feedback law u*(x) sampled on its grid, as the harness receives it.

The planner publishes, per cell of its map, the unit direction and the speed of the optimal action
and the cost-to-go ∫p ds to the goal (−1 where the goal cannot be reached, 0 inside the goal set),
either as `pfnav.feedback_field_t` over LCM or as the npz of `pf-plan --field-out`. A follower
samples it at the robot's position at every control step, so `sample` works on flat Python arrays
built once per field (no numpy call per sample).

Cell (ix, iy) covers [origin + (ix, iy)·resolution, origin + (ix + 1, iy + 1)·resolution); its
values belong to its centre, like the map's heights.
"""

from __future__ import annotations

import functools
import math
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .errors import PlannerError

FIELD_ARRAYS = ("dir_x", "dir_y", "speed", "cost_to_go")
# |direction| of a cell with an action; float32 transport and the planner's normalisation stay well inside.
UNIT_TOLERANCE = 0.01
UNREACHABLE = -1.0


class FieldSample(NamedTuple):
    """The field at a point: velocity (direction·speed, m/s, world frame) and cost-to-go."""

    vx: float
    vy: float
    cost_to_go: float

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)


class _FlatTables(NamedTuple):
    """Row-major copies (iy·width + ix) that index as Python floats in tens of nanoseconds."""

    vx: array[float]
    vy: array[float]
    cost: array[float]
    width: int
    height: int


# eq=False: field-wise == would compare numpy arrays (ambiguous truth value); use `same_grid` and the arrays.
@dataclass(frozen=True, eq=False)
class FeedbackField:
    """The optimal feedback law on the planner's grid (arrays indexed [iy, ix])."""

    origin: tuple[float, float]
    resolution: float
    dir_x: NDArray[np.float64]
    dir_y: NDArray[np.float64]
    speed: NDArray[np.float64]
    cost_to_go: NDArray[np.float64]
    goal: tuple[float, float, float]
    map_seq: int = -1
    request_id: int = 0

    def __post_init__(self) -> None:
        # Frozen: coerce through object.__setattr__ so every consumer sees float64 arrays and floats.
        for name in FIELD_ARRAYS:
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        object.__setattr__(self, "resolution", float(self.resolution))
        object.__setattr__(self, "goal", tuple(float(v) for v in self.goal))

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def from_npz(cls, path: Path | str) -> FeedbackField:
        """Reads the npz of `pf-plan --field-out` (dir_x, dir_y, speed, cost_to_go, origin, resolution, goal)."""
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = [key for key in (*FIELD_ARRAYS, "origin", "resolution", "goal") if key not in data.files]
                if missing:
                    raise PlannerError(f"feedback field {path}: missing arrays {', '.join(missing)}")
                origin = np.asarray(data["origin"], dtype=np.float64).ravel()
                goal = np.asarray(data["goal"], dtype=np.float64).ravel()
                if origin.shape != (2,) or goal.shape != (3,):
                    raise PlannerError(f"feedback field {path}: origin needs 2 values and goal 3 (x, y, radius), got {origin.shape[0]} and {goal.shape[0]}")
                field = cls(
                    origin=(float(origin[0]), float(origin[1])),
                    resolution=float(np.asarray(data["resolution"]).ravel()[0]),
                    dir_x=data["dir_x"],
                    dir_y=data["dir_y"],
                    speed=data["speed"],
                    cost_to_go=data["cost_to_go"],
                    goal=(float(goal[0]), float(goal[1]), float(goal[2])),
                    map_seq=int(data["map_seq"]) if "map_seq" in data.files else -1,
                    request_id=int(data["request_id"]) if "request_id" in data.files else 0,
                )
        except (OSError, ValueError) as err:
            raise PlannerError(f"cannot read feedback field {path}: {err}") from err
        field.validate()
        return field

    @classmethod
    def from_message(cls, msg: Any) -> FeedbackField:
        """Builds the field from a decoded `pfnav.feedback_field_t` (flat arrays row-major iy·width + ix)."""
        width, height, num_cells = int(msg.width), int(msg.height), int(msg.num_cells)
        if width <= 0 or height <= 0 or num_cells != width * height:
            raise PlannerError(f"feedback field message: {width}x{height} cells but num_cells = {num_cells}")
        grids = {}
        for name in FIELD_ARRAYS:
            values = np.asarray(getattr(msg, name), dtype=np.float64)
            if values.shape != (num_cells,):
                raise PlannerError(f"feedback field message: {name} has {values.size} values, expected {num_cells}")
            grids[name] = values.reshape(height, width)
        field = cls(
            origin=(float(msg.origin_x), float(msg.origin_y)),
            resolution=float(msg.resolution),
            goal=(float(msg.goal_x), float(msg.goal_y), float(msg.goal_radius)),
            map_seq=int(msg.map_seq),
            request_id=int(msg.request_id),
            **grids,
        )
        field.validate()
        return field

    # --- checks -------------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """(height, width): rows along y, columns along x."""
        return (int(self.dir_x.shape[0]), int(self.dir_x.shape[1])) if self.dir_x.ndim == 2 else (0, 0)

    def validate(self) -> None:
        """Raises PlannerError naming the first thing that makes the field unusable."""
        shape = self.dir_x.shape
        if len(shape) != 2 or shape[0] < 1 or shape[1] < 1:
            raise PlannerError(f"feedback field: dir_x must be a non-empty (height, width) grid, got shape {shape}")
        for name in FIELD_ARRAYS:
            values = getattr(self, name)
            if values.shape != shape:
                raise PlannerError(f"feedback field: {name} has shape {values.shape}, dir_x {shape}")
            if not np.all(np.isfinite(values)):
                raise PlannerError(f"feedback field: {name} contains NaN or infinite values")
        if not (math.isfinite(self.resolution) and self.resolution > 0.0):
            raise PlannerError(f"feedback field: resolution must be a positive number, got {self.resolution}")
        if not all(math.isfinite(v) for v in (*self.origin, *self.goal)):
            raise PlannerError(f"feedback field: origin {self.origin} and goal {self.goal} must be finite")
        if self.goal[2] < 0.0:
            raise PlannerError(f"feedback field: goal radius must be >= 0, got {self.goal[2]}")
        if np.any(self.speed < 0.0):
            raise PlannerError(f"feedback field: negative speed ({self.speed.min():.3g} m/s)")
        bad_cost = (self.cost_to_go < 0.0) & (self.cost_to_go != UNREACHABLE)
        if np.any(bad_cost):
            iy, ix = np.argwhere(bad_cost)[0]
            raise PlannerError(f"feedback field: cost_to_go {self.cost_to_go[iy, ix]:.3g} at cell (ix={ix}, iy={iy}) (only -1 marks unreachable)")
        norm = np.hypot(self.dir_x, self.dir_y)
        not_unit = (norm != 0.0) & (np.abs(norm - 1.0) > UNIT_TOLERANCE)
        if np.any(not_unit):
            iy, ix = np.argwhere(not_unit)[0]
            raise PlannerError(f"feedback field: direction at cell (ix={ix}, iy={iy}) has length {norm[iy, ix]:.4g}, neither 0 nor 1")

    def same_grid(self, other: FeedbackField) -> bool:
        """Same cells (origin, resolution, shape): values of the two fields belong to the same points."""
        tolerance = 1e-9 * self.resolution
        return (
            self.shape == other.shape
            and abs(self.resolution - other.resolution) <= tolerance
            and abs(self.origin[0] - other.origin[0]) <= tolerance
            and abs(self.origin[1] - other.origin[1]) <= tolerance
        )

    # --- queries ------------------------------------------------------------------------------
    @functools.cached_property
    def _tables(self) -> _FlatTables:
        # cached_property writes the instance __dict__ directly, which a frozen dataclass allows.
        height, width = self.shape
        return _FlatTables(
            vx=array("d", (self.dir_x * self.speed).ravel().tobytes()),
            vy=array("d", (self.dir_y * self.speed).ravel().tobytes()),
            cost=array("d", np.ascontiguousarray(self.cost_to_go).ravel().tobytes()),
            width=width,
            height=height,
        )

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """(ix, iy) of the cell containing the point, None off the grid."""
        tables = self._tables
        ix = math.floor((x - self.origin[0]) / self.resolution)
        iy = math.floor((y - self.origin[1]) / self.resolution)
        if 0 <= ix < tables.width and 0 <= iy < tables.height:
            return ix, iy
        return None

    def cell_center(self, ix: int, iy: int) -> tuple[float, float]:
        return self.origin[0] + (ix + 0.5) * self.resolution, self.origin[1] + (iy + 0.5) * self.resolution

    def sample(self, x: float, y: float) -> FieldSample | None:
        """Bilinear interpolation between the 4 surrounding cell centres, over reachable cells only.

        Unreachable cells (cost_to_go < 0) and cells beyond the grid's edge (within the outer half
        cell) are left out and the remaining weights renormalised, so an obstacle's "no action"
        never drags the velocity towards zero next to it. None off the grid or when none of the 4
        cells is reachable.
        """
        tables = self._tables
        width, height = tables.width, tables.height
        gx = (x - self.origin[0]) / self.resolution
        gy = (y - self.origin[1]) / self.resolution
        # The comparison is false for NaN too: a NaN position is off the grid.
        if not (0.0 <= gx <= width and 0.0 <= gy <= height):
            return None
        gx -= 0.5
        gy -= 0.5
        ix0 = math.floor(gx)
        iy0 = math.floor(gy)
        fx = gx - ix0
        fy = gy - iy0
        cost = tables.cost
        vx_table = tables.vx
        vy_table = tables.vy
        total = vx = vy = c = 0.0
        reachable = 0
        # The four corners unrolled (this runs once per control step): lower row iy0, upper row iy0 + 1.
        x_in_lo = ix0 >= 0
        x_in_hi = ix0 + 1 < width
        for iy, wy in ((iy0, 1.0 - fy), (iy0 + 1, fy)):
            if iy < 0 or iy >= height:
                continue
            k = iy * width + ix0
            if x_in_lo and cost[k] >= 0.0:
                w = (1.0 - fx) * wy
                reachable += 1
                total += w
                vx += w * vx_table[k]
                vy += w * vy_table[k]
                c += w * cost[k]
            k += 1
            if x_in_hi and cost[k] >= 0.0:
                w = fx * wy
                reachable += 1
                total += w
                vx += w * vx_table[k]
                vy += w * vy_table[k]
                c += w * cost[k]
        if reachable == 0:
            return None
        if total <= 1e-12:
            # Exactly on the line through cell centres whose only reachable cells carry zero weight:
            # their plain mean (a measure-zero case) instead of refusing a point next to the support.
            return self._mean_of_reachable(ix0, iy0)
        return FieldSample(vx / total, vy / total, c / total)

    def _mean_of_reachable(self, ix0: int, iy0: int) -> FieldSample | None:
        tables = self._tables
        picked = [
            iy * tables.width + ix
            for iy in (iy0, iy0 + 1)
            for ix in (ix0, ix0 + 1)
            if 0 <= ix < tables.width and 0 <= iy < tables.height and tables.cost[iy * tables.width + ix] >= 0.0
        ]
        if not picked:
            return None
        n = float(len(picked))
        return FieldSample(
            sum(tables.vx[k] for k in picked) / n,
            sum(tables.vy[k] for k in picked) / n,
            sum(tables.cost[k] for k in picked) / n,
        )

    def cell_values(self, ix: int, iy: int) -> FieldSample:
        """Velocity and cost-to-go of one cell (no interpolation)."""
        tables = self._tables
        k = iy * tables.width + ix
        return FieldSample(tables.vx[k], tables.vy[k], tables.cost[k])

    def cell_cost(self, ix: int, iy: int) -> float:
        """Cost-to-go of one cell (−1: unreachable)."""
        tables = self._tables
        return tables.cost[iy * tables.width + ix]

    def max_speed(self) -> float:
        reachable = self.cost_to_go >= 0.0
        return float(self.speed[reachable].max()) if np.any(reachable) else 0.0
