"""Scenario files (written by `pf-plan scenario export`) and the terrain surface they define.

The paper's scenarios are defined once, in the planner (`planner/core/src/scenarios.rs`): the
harness asks `pf-plan scenario list` for their names and `pf-plan scenario export` for their maps.
Further built-in scenarios (`pf-plan scenario list --all`, e.g. `surprise`) are exported by name.

A scenario may carry a *prior*: the map the robot is given before it moves (`Scenario.prior`), while
`Scenario.terrain` is the true ground its sensors reveal. The prior has the true map's geometry; the
paper's scenarios have none (the robot then starts knowing nothing).

The planner's map stores one height per cell centre. The physics terrain is the triangle mesh
through those centres, each cell quad split along its (ix, iy)→(ix+1, iy+1) diagonal. `Terrain`
evaluates exactly that piecewise-linear surface, so the heights the reference, the metrics and the
FMU's terrain inputs use are the heights the robot's feet touch.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import paths
from .errors import ScenarioError
from .tools import run_tool

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GoalRegion:
    center: tuple[float, float]
    radius: float


def grid_triangles(rows: int, cols: int) -> NDArray[np.int64]:
    """Vertex indices of the two triangles of every cell of a `rows` × `cols` grid of vertices
    (vertex index row · cols + column), counter-clockwise seen from +z (ODE needs that)."""
    iy, ix = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (iy * cols + ix).ravel()
    lower = np.stack([a, a + 1, a + cols + 1], axis=1)
    upper = np.stack([a, a + cols + 1, a + cols], axis=1)
    return np.concatenate([lower, upper], axis=0).astype(np.int64)


@dataclass(frozen=True)
class TerrainPlane:
    """z = height + dzdx·(x − x0) + dzdy·(y − y0) around the query point (x0, y0)."""

    height: float
    dzdx: float
    dzdy: float


# Corner heights a, b, c, d, cell coordinates u, v and the lower-triangle flag of points.
_TrianglePoints = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]


class Terrain:
    """The piecewise-linear surface through the cell-centre heights of a grid map."""

    def __init__(
        self,
        origin: tuple[float, float],
        resolution: float,
        heights: FloatArray,
        obstacles: NDArray[np.bool_] | None = None,
    ) -> None:
        heights = np.asarray(heights, dtype=np.float64)
        if heights.ndim != 2 or heights.shape[0] < 2 or heights.shape[1] < 2:
            raise ScenarioError(f"terrain needs a 2-D height grid of at least 2x2 cells, got shape {heights.shape}")
        if not np.all(np.isfinite(heights)):
            raise ScenarioError("terrain heights contain NaN or infinite values")
        if not (math.isfinite(resolution) and resolution > 0.0):
            raise ScenarioError(f"terrain resolution must be a positive number, got {resolution}")
        if not all(math.isfinite(v) for v in origin):
            raise ScenarioError(f"terrain origin must be finite, got {origin}")
        if obstacles is not None and obstacles.shape != heights.shape:
            raise ScenarioError(f"obstacle mask shape {obstacles.shape} differs from heights shape {heights.shape}")
        self.origin = (float(origin[0]), float(origin[1]))
        self.resolution = float(resolution)
        self.heights = heights
        self.obstacles = None if obstacles is None else np.asarray(obstacles, dtype=bool)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows along y, columns along x)."""
        return (int(self.heights.shape[0]), int(self.heights.shape[1]))

    def bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Map rectangle (lower-left, upper-right) in world coordinates."""
        ny, nx = self.shape
        return self.origin, (self.origin[0] + nx * self.resolution, self.origin[1] + ny * self.resolution)

    def vertices(self) -> FloatArray:
        """Mesh vertices (one per cell centre), row-major like the map, shape (ny·nx, 3)."""
        ny, nx = self.shape
        xs = self.origin[0] + (np.arange(nx) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(ny) + 0.5) * self.resolution
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx.ravel(), gy.ravel(), self.heights.ravel()], axis=1)

    def triangles(self) -> NDArray[np.int64]:
        """Vertex indices of the triangles, counter-clockwise seen from +z (ODE needs that)."""
        return grid_triangles(*self.shape)

    def _locate(self, x: FloatArray, y: FloatArray) -> tuple[NDArray[np.int64], NDArray[np.int64], FloatArray, FloatArray]:
        ny, nx = self.shape
        fx = (np.asarray(x, dtype=np.float64) - self.origin[0]) / self.resolution - 0.5
        fy = (np.asarray(y, dtype=np.float64) - self.origin[1]) / self.resolution - 0.5
        # Beyond the outermost centres the mesh ends: clamp onto its border.
        fx = np.clip(fx, 0.0, nx - 1.0)
        fy = np.clip(fy, 0.0, ny - 1.0)
        ix = np.minimum(np.floor(fx).astype(np.int64), nx - 2)
        iy = np.minimum(np.floor(fy).astype(np.int64), ny - 2)
        return ix, iy, fx - ix, fy - iy

    def _triangle(self, x: FloatArray | float, y: FloatArray | float) -> _TrianglePoints:
        """The heights of the cell corners around each point (a, b, c, d counter-clockwise from
        the lower left), the point's place in the cell (u, v) and which triangle holds it."""
        ix, iy, u, v = self._locate(np.asarray(x), np.asarray(y))
        h = self.heights
        return h[iy, ix], h[iy, ix + 1], h[iy + 1, ix + 1], h[iy + 1, ix], u, v, u >= v

    def height_and_gradient(self, x: FloatArray | float, y: FloatArray | float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Surface height and its gradient (dz/dx, dz/dy) at points (vectorised)."""
        za, zb, zc, zd, u, v, lower = self._triangle(x, y)
        dzdu = np.where(lower, zb - za, zc - zd)
        dzdv = np.where(lower, zc - zb, zd - za)
        z = za + u * dzdu + v * dzdv
        return z, dzdu / self.resolution, dzdv / self.resolution

    def height(self, x: FloatArray | float, y: FloatArray | float) -> FloatArray:
        """Surface height at points (vectorised): `height_and_gradient`'s height, the same
        operations (bit for bit) without the gradient (ray casting asks for many points)."""
        za, zb, zc, zd, u, v, lower = self._triangle(x, y)
        return za + u * np.where(lower, zb - za, zc - zd) + v * np.where(lower, zc - zb, zd - za)

    def height_at(self, x: float, y: float) -> float:
        """`height(x, y)` at one point: the same operations on Python floats (bit for bit), without
        numpy's per-call overhead (the co-simulation asks every 10th step)."""
        ny, nx = self.heights.shape
        fx = (x - self.origin[0]) / self.resolution - 0.5
        fy = (y - self.origin[1]) / self.resolution - 0.5
        if not (math.isfinite(fx) and math.isfinite(fy)):
            return float(self.height(x, y))
        fx = min(max(fx, 0.0), nx - 1.0)
        fy = min(max(fy, 0.0), ny - 1.0)
        ix = min(math.floor(fx), nx - 2)
        iy = min(math.floor(fy), ny - 2)
        u = fx - ix
        v = fy - iy
        row, above = self.heights[iy], self.heights[iy + 1]
        za, zb = float(row[ix]), float(row[ix + 1])
        zc, zd = float(above[ix + 1]), float(above[ix])
        if u >= v:
            dzdu, dzdv = zb - za, zc - zb
        else:
            dzdu, dzdv = zc - zd, zd - za
        return za + u * dzdu + v * dzdv

    def local_grid(self, x: float, y: float, size: int) -> tuple[float, float, FloatArray] | None:
        """The `size`×`size` block of mesh vertices nearest to (x, y) (kept inside the map).

        Returns the world (x, y) of its first vertex and the heights (rows along y), or None when
        the map is smaller than the block. The mesh between these vertices is exactly the terrain.
        """
        corner = self.local_grid_corner(x, y, size)
        if corner is None:
            return None
        ix0, iy0 = corner
        res = self.resolution
        x0 = self.origin[0] + (ix0 + 0.5) * res
        y0 = self.origin[1] + (iy0 + 0.5) * res
        return x0, y0, self.heights[iy0 : iy0 + size, ix0 : ix0 + size]

    def local_grid_corner(self, x: float, y: float, size: int) -> tuple[int, int] | None:
        """The (column, row) of the first vertex of `local_grid(x, y, size)`; None where it gives None.

        The block only changes when this does, so a caller can skip rebuilding an unchanged one.
        """
        ny, nx = self.heights.shape
        if size < 2 or nx < size or ny < size:
            return None
        res = self.resolution
        ix0 = round((x - self.origin[0]) / res - 0.5) - size // 2
        iy0 = round((y - self.origin[1]) / res - 0.5) - size // 2
        return min(max(ix0, 0), nx - size), min(max(iy0, 0), ny - size)

    def plane(self, x: float, y: float, radius: float = 0.3, samples: int = 7) -> TerrainPlane:
        """Least-squares plane of the surface over a square window around (x, y).

        The controller treats the ground under the robot as one plane; fitting it over about the
        footprint smooths the cell-to-cell kinks of the mesh instead of taking one triangle's slope.
        """
        offsets = np.linspace(-radius, radius, samples)
        dx, dy = np.meshgrid(offsets, offsets)
        dx = dx.ravel()
        dy = dy.ravel()
        z = self.height(x + dx, y + dy)
        design = np.stack([np.ones_like(dx), dx, dy], axis=1)
        coef, *_ = np.linalg.lstsq(design, z, rcond=None)
        return TerrainPlane(height=float(coef[0]), dzdx=float(coef[1]), dzdy=float(coef[2]))

    def is_obstacle(self, x: float, y: float) -> bool:
        if self.obstacles is None:
            return False
        ny, nx = self.shape
        ix = math.floor((x - self.origin[0]) / self.resolution)
        iy = math.floor((y - self.origin[1]) / self.resolution)
        if not (0 <= ix < nx and 0 <= iy < ny):
            return False
        return bool(self.obstacles[iy, ix])

    def obstacles_at(self, x: FloatArray, y: FloatArray) -> NDArray[np.bool_]:
        """`is_obstacle` at many points (False off the map and without a mask)."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        if self.obstacles is None:
            return np.zeros(x.shape, dtype=bool)
        ny, nx = self.shape
        with np.errstate(invalid="ignore"):
            fx = np.floor((x - self.origin[0]) / self.resolution)
            fy = np.floor((y - self.origin[1]) / self.resolution)
        inside = np.isfinite(fx) & np.isfinite(fy) & (fx >= 0) & (fx < nx) & (fy >= 0) & (fy < ny)
        ix = np.where(inside, fx, 0).astype(np.int64)
        iy = np.where(inside, fy, 0).astype(np.int64)
        return inside & self.obstacles[iy, ix]


@dataclass
class Scenario:
    name: str
    terrain: Terrain
    start: tuple[float, float]
    start_yaw: float
    goal: GoalRegion
    seed: int | None = None
    traversability: dict[str, Any] = field(default_factory=dict)
    source: Path | None = None
    prior: Terrain | None = None
    """The map known before the robot moves (same geometry as `terrain`), or None."""

    @property
    def origin(self) -> tuple[float, float]:
        return self.terrain.origin

    @property
    def resolution(self) -> float:
        return self.terrain.resolution


def _require(meta: dict[str, Any], key: str, path: Path) -> Any:
    if key not in meta:
        raise ScenarioError(f"{path}: missing field '{key}'")
    return meta[key]


def _pair(value: Any, what: str, path: Path) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError) as err:
        raise ScenarioError(f"{path}: '{what}' must be a pair of numbers, got {value!r}") from err
    if not (math.isfinite(a) and math.isfinite(b)):
        raise ScenarioError(f"{path}: '{what}' must be finite, got {value!r}")
    return (a, b)


def _array_file(folder: Path, value: Any, what: str, json_path: Path) -> Path:
    """A sidecar's array file: a relative path inside the sidecar's folder (as pf-plan requires)."""
    name = str(value)
    relative = Path(name)
    if not name or relative.is_absolute() or any(part in ("..", "") for part in relative.parts):
        raise ScenarioError(f"{json_path}: {what} file {name!r} must be a relative path inside the sidecar's directory")
    return folder / relative


def _load_prior(meta: dict[str, Any], folder: Path, terrain: Terrain, json_path: Path) -> Terrain | None:
    """The sidecar's `prior` map (heights + optional obstacles on the true map's grid), or None."""
    prior_meta = meta.get("prior")
    if prior_meta is None:
        return None
    if not isinstance(prior_meta, dict):
        raise ScenarioError(f"{json_path}: 'prior' must be an object with 'heights' (and 'obstacles')")
    heights_file = _array_file(folder, _require(prior_meta, "heights", json_path), "prior heights", json_path)
    try:
        heights = np.load(heights_file, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise ScenarioError(f"cannot read prior heights {heights_file}: {err}") from err
    if heights.shape != terrain.shape:
        raise ScenarioError(f"{heights_file}: prior shape {heights.shape} differs from the map's {terrain.shape}")
    obstacles = None
    if prior_meta.get("obstacles"):
        obstacles_file = _array_file(folder, prior_meta["obstacles"], "prior obstacles", json_path)
        try:
            obstacles = np.load(obstacles_file, allow_pickle=False).astype(bool)
        except (OSError, ValueError) as err:
            raise ScenarioError(f"cannot read prior obstacles {obstacles_file}: {err}") from err
    return Terrain(terrain.origin, terrain.resolution, heights.astype(np.float64), obstacles)


def load_scenario(json_path: Path) -> Scenario:
    """Reads `NAME.json` and the `.npy` arrays it names (format: see COMMON conventions / pf-plan)."""
    json_path = Path(json_path)
    try:
        meta = json.loads(json_path.read_text())
    except FileNotFoundError as err:
        raise ScenarioError(f"scenario file {json_path} does not exist") from err
    except (OSError, json.JSONDecodeError) as err:
        raise ScenarioError(f"cannot read scenario file {json_path}: {err}") from err
    if not isinstance(meta, dict):
        raise ScenarioError(f"{json_path}: expected a JSON object")

    folder = json_path.parent
    heights_file = folder / str(_require(meta, "heights", json_path))
    try:
        heights = np.load(heights_file, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise ScenarioError(f"cannot read heights {heights_file}: {err}") from err
    width = int(_require(meta, "width", json_path))
    height = int(_require(meta, "height", json_path))
    if heights.shape != (height, width):
        raise ScenarioError(f"{heights_file}: shape {heights.shape} but the sidecar says (height, width) = ({height}, {width})")

    obstacles = None
    if meta.get("obstacles"):
        obstacles_file = folder / str(meta["obstacles"])
        try:
            obstacles = np.load(obstacles_file, allow_pickle=False).astype(bool)
        except (OSError, ValueError) as err:
            raise ScenarioError(f"cannot read obstacles {obstacles_file}: {err}") from err

    terrain = Terrain(
        _pair(_require(meta, "origin", json_path), "origin", json_path),
        float(_require(meta, "resolution", json_path)),
        heights.astype(np.float64),
        obstacles,
    )
    goal_meta = _require(meta, "goal", json_path)
    if not isinstance(goal_meta, dict):
        raise ScenarioError(f"{json_path}: 'goal' must be an object with 'center' and 'radius'")
    goal = GoalRegion(
        center=_pair(_require(goal_meta, "center", json_path), "goal.center", json_path),
        radius=float(_require(goal_meta, "radius", json_path)),
    )
    if not (math.isfinite(goal.radius) and goal.radius > 0.0):
        raise ScenarioError(f"{json_path}: goal radius must be positive, got {goal.radius}")
    seed = meta.get("seed")
    return Scenario(
        name=str(meta.get("name", json_path.stem)),
        terrain=terrain,
        start=_pair(_require(meta, "start", json_path), "start", json_path),
        start_yaw=float(meta.get("start_yaw", 0.0)),
        goal=goal,
        seed=None if seed is None else int(seed),
        traversability=dict(meta.get("traversability") or {}),
        source=json_path,
        prior=_load_prior(meta, folder, terrain, json_path),
    )


def write_map(
    terrain: Terrain,
    folder: Path,
    name: str,
    traversability: dict[str, Any] | None = None,
    *,
    start: tuple[float, float] | None = None,
    start_yaw: float = 0.0,
    goal: GoalRegion | None = None,
    seed: int | None = None,
) -> Path:
    """Writes `terrain` as FOLDER/NAME.json + .npy arrays in the `pf-plan scenario export` format
    (the harness's one writer of it; the planner's is `pf_planner::io::save_scenario`).

    Without `start`/`goal` (`pf-plan path-cost --map`, `pf-plan traversability --map` read only the
    map and the traversability model) both are the centre of cell (0, 0).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ny, nx = terrain.shape
    np.save(folder / f"{name}.heights.npy", np.ascontiguousarray(terrain.heights, dtype=np.float64))
    obstacles = None
    if terrain.obstacles is not None:
        obstacles = f"{name}.obstacles.npy"
        np.save(folder / obstacles, np.ascontiguousarray(terrain.obstacles, dtype=bool))
    corner = (terrain.origin[0] + 0.5 * terrain.resolution, terrain.origin[1] + 0.5 * terrain.resolution)
    goal = goal or GoalRegion(corner, 0.0)
    meta = {
        "name": name,
        "seed": seed,
        "origin": list(terrain.origin),
        "resolution": terrain.resolution,
        "width": nx,
        "height": ny,
        "heights": f"{name}.heights.npy",
        "obstacles": obstacles,
        "start": list(start or corner),
        "start_yaw": start_yaw,
        "goal": {"center": list(goal.center), "radius": goal.radius},
        "traversability": dict(traversability or {}),
    }
    path = folder / f"{name}.json"
    path.write_text(json.dumps(meta))
    return path


def planner_scenario_names(pf_plan: Path, timeout: float = 60.0, every: bool = False) -> tuple[str, ...]:
    """The planner's paper scenarios, from `pf-plan scenario list` (`every`: all built-in ones, `--all`)."""
    out = run_tool(
        pf_plan,
        ["scenario", "list", *(["--all"] if every else [])],
        what="`pf-plan scenario list` failed",
        failure=ScenarioError,
        timeout=timeout,
    )
    names = tuple(line.strip() for line in out.splitlines() if line.strip())
    if not names:
        raise ScenarioError("`pf-plan scenario list` listed no scenario")
    return names


@functools.cache
def paper_scenario_names() -> tuple[str, ...]:
    """The paper's scenarios: the planner's built-in list, declared once in the planner."""
    return planner_scenario_names(paths.pf_plan_path())
