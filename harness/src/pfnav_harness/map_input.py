"""`pfnav-demo run --map FILE`: any map written by `pf-plan import` / `pf-plan scenario export`.

Start and goal come from the map's sidecar unless `--start X,Y` / `--goal X,Y` override them.
Either way they are checked here, before the planner service starts: both must lie on the map
and off its obstacles, so a typo gives one clear line instead of a planner error after start-up.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from .errors import HarnessError, ScenarioError
from .scenario import GoalRegion, Scenario, load_scenario


def parse_point(text: str, flag: str) -> tuple[float, float]:
    """`X,Y` (metres, map coordinates) from a command-line flag, finite."""
    parts = [part.strip() for part in text.split(",")]
    if len(parts) != 2:
        raise HarnessError(f"{flag} must be two numbers X,Y (map coordinates, m), got {text!r}")
    try:
        x, y = (float(part) for part in parts)
    except ValueError as err:
        raise HarnessError(f"{flag} must be two numbers X,Y (map coordinates, m), got {text!r}") from err
    if not (math.isfinite(x) and math.isfinite(y)):
        raise HarnessError(f"{flag} must be finite, got {text!r}")
    return (x, y)


def check_placement(scenario: Scenario, point: tuple[float, float], what: str) -> None:
    """Raises ScenarioError unless `point` lies on the map and off its obstacles."""
    (x0, y0), (x1, y1) = scenario.terrain.bounds()
    x, y = point
    where = f"{what} ({x:g}, {y:g})"
    if not (x0 <= x < x1 and y0 <= y < y1):
        raise ScenarioError(f"{where} is off the map {scenario.name!r}: it spans x {x0:g}..{x1:g}, y {y0:g}..{y1:g} m")
    if scenario.terrain.is_obstacle(x, y):
        raise ScenarioError(f"{where} lies on an obstacle of the map {scenario.name!r}")


def load_map_scenario(path: Path, start: tuple[float, float] | None = None, goal: tuple[float, float] | None = None) -> Scenario:
    """The map scenario at `path`, with start and/or goal centre replaced, both checked."""
    path = Path(path)
    if path.is_dir():
        raise ScenarioError(f"--map takes a map's JSON sidecar (NAME.json), {path} is a directory")
    scenario = load_scenario(path)
    if start is not None:
        scenario = dataclasses.replace(scenario, start=start)
    if goal is not None:
        scenario = dataclasses.replace(scenario, goal=GoalRegion(center=goal, radius=scenario.goal.radius))
    check_placement(scenario, scenario.start, "start")
    check_placement(scenario, scenario.goal.center, "goal")
    if math.dist(scenario.start, scenario.goal.center) <= scenario.goal.radius:
        raise ScenarioError(
            f"the start {scenario.start} already lies inside the goal region (centre {scenario.goal.center}, radius {scenario.goal.radius:g} m): "
            "give --start or --goal"
        )
    return scenario
