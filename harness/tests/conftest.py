"""Fixtures of the harness unit tests: small synthetic scenarios written in the exported format."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness import fmu_runner, paths
from pfnav_harness.errors import MissingArtifactError
from pfnav_harness.scenario import Scenario, load_scenario


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
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / f"{name}.heights.npy", heights.astype(np.float64))
    if obstacles is not None:
        np.save(folder / f"{name}.obstacles.npy", obstacles.astype(np.uint8))
    meta = {
        "name": name,
        "seed": 7,
        "origin": list(origin),
        "resolution": resolution,
        "width": int(heights.shape[1]),
        "height": int(heights.shape[0]),
        "heights": f"{name}.heights.npy",
        "obstacles": f"{name}.obstacles.npy" if obstacles is not None else None,
        "start": list(start),
        "start_yaw": 0.0,
        "goal": {"center": list(goal), "radius": goal_radius},
        "traversability": {"height_weight": 1.0, "p_floor": 0.05},
    }
    path = folder / f"{name}.json"
    path.write_text(json.dumps(meta))
    return path


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
