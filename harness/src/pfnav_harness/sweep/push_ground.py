"""The ground each run's push drives the robot towards: the distance along the push, from where the
plan had the robot when it began, to the first place the terrain is `GROUND_CHANGE` higher or
lower (a valley side, a wall, a pit). A trunk pushed sideways at 1.3-2.6 m/s travels 0.35-1.4 m
while the controller brakes it at 2.5 m/s², so how near that ground lies separates the falls more
than any drawn factor (docs/push-recovery.md). It is a property of the draw (course, push time and direction),
the same for every controller and estimator that walks it.
"""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from ..planner_client import Plan
from ..pushes import horizontal_push
from ..scenario import Scenario, Terrain, load_scenario
from .stats import IMPULSE_EDGES, FallRate, bin_bounds, binned_fall_rates, float_column, push_impulses, row_outcomes
from .store import SweepStore

# Height change that counts as other ground, m: about half a leg's length, no step of a trot's stride.
GROUND_CHANGE = 0.15
# How far along the push the ground is searched, and the step, m (the maps' cells are 0.125 m).
SEARCH_RANGE = 2.0
SEARCH_STEP = 0.05
# Upper edges of the distance bins, m; the last bin is "none within SEARCH_RANGE".
DISTANCE_EDGES = (0.5, 1.0, SEARCH_RANGE)


def ground_change_distance(terrain: Terrain, x: float, y: float, angle: float) -> float:
    """Distance from (x, y) along the direction `angle` (rad, counter-clockwise from +x) to the
    first point whose height differs from (x, y)'s by more than `GROUND_CHANGE`; inf when none
    does within `SEARCH_RANGE` (or the map ends first)."""
    base = terrain.height_at(x, y)
    (x0, y0), (x1, y1) = terrain.bounds()
    steps = round(SEARCH_RANGE / SEARCH_STEP)
    for k in range(1, steps + 1):
        d = k * SEARCH_STEP
        px, py = x + d * math.cos(angle), y + d * math.sin(angle)
        if not (x0 <= px <= x1 and y0 <= py <= y1):
            return math.inf
        if abs(terrain.height_at(px, py) - base) > GROUND_CHANGE:
            return d
    return math.inf


def _courses(store: SweepStore, scenario: str, method: str) -> dict[int, tuple[Scenario, Plan, np.ndarray]]:
    """The stored courses of a store by terrain seed: its exported scenarios, their plans and the
    plans' headings unwrapped (to interpolate across ±π)."""
    courses: dict[int, tuple[Scenario, Plan, np.ndarray]] = {}
    for path in sorted(store.scenarios_dir.glob(f"*/{scenario}.json")):
        course = load_scenario(path)
        if course.seed is None:
            continue
        plan = store.load_plan(scenario, course.seed, method)
        if plan is not None:
            courses[int(course.seed)] = (course, plan, np.unwrap(plan.yaw))
    return courses


def push_ground_distances(table: pa.Table, store: SweepStore) -> np.ndarray:
    """Per row, `ground_change_distance` along its push from the plan's pose at the push's start
    (heading-relative directions turned by the plan's heading there); NaN for runs without a push
    or whose course is not stored."""
    distances = np.full(table.num_rows, np.nan)
    spec = (store.stored_spec() or {}).get("spec", {})
    if not {"push_time", "push_direction_deg", "terrain_seed"} <= set(table.column_names) or "scenario" not in spec:
        return distances
    courses = _courses(store, spec["scenario"], spec.get("method", "pf"))
    impulses = push_impulses(table)
    relative = table["push_heading_relative"].to_pylist() if "push_heading_relative" in table.column_names else [True] * table.num_rows
    rows = zip(table["terrain_seed"].to_pylist(), float_column(table, "push_time"), float_column(table, "push_direction_deg"), relative, strict=True)
    for i, (seed, start, direction, heading_relative) in enumerate(rows):
        course = courses.get(int(seed)) if seed is not None else None
        if course is None or not impulses[i] > 0.0 or not math.isfinite(start):
            continue
        scenario, plan, headings = course
        x, y, yaw = (float(np.interp(start, plan.t, values)) for values in (plan.x, plan.y, headings))
        # The push as the run applied it, turned into the world frame at the plan's heading.
        fx, fy, _ = horizontal_push(1.0, direction, start, 1.0, bool(heading_relative)).world_force(yaw)
        distances[i] = ground_change_distance(scenario.terrain, x, y, math.atan2(fy, fx))
    return distances


def distance_rates(distances: np.ndarray, table: pa.Table) -> list[FallRate]:
    """Fall rate per bin of `distances` (`DISTANCE_EDGES`; "> SEARCH_RANGE" is no change within it)."""
    return binned_fall_rates(distances, row_outcomes(table), (0.0, *DISTANCE_EDGES), "m")


def ground_by_impulse_lines(distances: np.ndarray, table: pa.Table) -> list[str]:
    """Markdown: falls/trials per distance bin (rows) and push-impulse bin (columns)."""
    outcomes = row_outcomes(table)
    trial = ~np.isnan(distances) & (outcomes != "error")
    impulses = push_impulses(table)
    # The last impulse bin is open: pushes scaled by a robot's mass reach beyond its edge.
    impulse_bins = bin_bounds(IMPULSE_EDGES[:-1])
    distance_bins = bin_bounds((0.0, *DISTANCE_EDGES))
    columns = [f"({lo:g}, {hi:g}] N·s" if math.isfinite(hi) else f"> {lo:g} N·s" for lo, hi in impulse_bins]
    lines = [
        f"| ground more than {GROUND_CHANGE:g} m higher or lower at | " + " | ".join(columns) + " | all |",
        "| --- |" + " ---: |" * (len(impulse_bins) + 1),
    ]
    for low, high in distance_bins:
        in_bin = trial & (distances > low) & (distances <= high)
        cells = [in_bin & (impulses > lo) & (impulses <= hi) for lo, hi in impulse_bins] + [in_bin]
        label = f"none within {SEARCH_RANGE:g} m" if math.isinf(high) else f"({low:g}, {high:g}] m"
        lines.append(f"| {label} | " + " | ".join(f"{int((outcomes[c] == 'fell').sum())}/{int(c.sum())}" for c in cells) + " |")
    return lines
