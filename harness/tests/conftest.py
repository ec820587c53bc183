"""Fixtures of the harness unit tests: small synthetic scenarios written in the exported format."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness import fmu_runner, paths
from pfnav_harness.errors import MissingArtifactError
from pfnav_harness.scenario import GoalRegion, Scenario, Terrain, load_scenario, write_map


def write_scenario(
    folder: Path,
    name: str,
    heights: np.ndarray,
    resolution: float = 0.1,
    origin: tuple[float, float] = (0.0, 0.0),
    obstacles: np.ndarray | None = None,
    start: tuple[float, float] = (0.5, 0.5),
    goal: tuple[float, float] = (1.5, 0.5),
    goal_radius: float = 0.3,
) -> Path:
    """Writes NAME.heights.npy (+ obstacles) and the NAME.json sidecar like `pf-plan scenario export`."""
    terrain = Terrain(origin, resolution, heights, None if obstacles is None else obstacles.astype(bool))
    traversability = {"height_weight": 1.0, "p_floor": 0.05}
    return write_map(terrain, folder, name, traversability, start=start, goal=GoalRegion(goal, goal_radius), seed=7)


@pytest.fixture
def scenario_writer() -> Callable[..., Path]:
    """`write_scenario` for tests that need their own terrain."""
    return write_scenario


@pytest.fixture
def ramp_scenario(tmp_path: Path) -> Scenario:
    """A 3 m × 2 m ramp rising 0.2 m per metre along x, on a 0.1 m grid (heights ≥ 0)."""
    nx, ny, res = 30, 20, 0.1
    xs = (np.arange(nx) + 0.5) * res
    heights = np.tile(0.1 + 0.2 * xs, (ny, 1))
    return load_scenario(write_scenario(tmp_path, "ramp", heights, res, start=(0.5, 1.0), goal=(2.5, 1.0)))


@pytest.fixture(scope="session")
def fmu_contract() -> fmu_runner.FmuContract:
    """Names, value references and enumeration codes of the bundled FMU (target/fmu, or PFNAV_FMU)."""
    try:
        return fmu_runner.read_contract(paths.fmu_path())
    except MissingArtifactError as err:
        pytest.fail(str(err), pytrace=False)
