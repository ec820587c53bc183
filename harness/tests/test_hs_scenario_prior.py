"""A scenario's prior map (what the robot is told before it moves) is loaded beside the true map."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness.errors import ScenarioError
from pfnav_harness.scenario import load_scenario


def _with_prior(
    path: Path,
    heights: np.ndarray,
    obstacles: np.ndarray | None = None,
    heights_name: str | None = None,
) -> Path:
    """Adds a `prior` to an exported sidecar the way `pf-plan scenario export` writes it."""
    meta = json.loads(path.read_text())
    stem = meta["name"]
    np.save(path.parent / f"{stem}.prior.heights.npy", heights.astype(np.float64))
    prior: dict[str, str | None] = {
        "heights": f"{stem}.prior.heights.npy" if heights_name is None else heights_name,
        "obstacles": None,
    }
    if obstacles is not None:
        np.save(path.parent / f"{stem}.prior.obstacles.npy", obstacles.astype(bool))
        prior["obstacles"] = f"{stem}.prior.obstacles.npy"
    meta["prior"] = prior
    path.write_text(json.dumps(meta))
    return path


def test_a_sidecar_without_prior_loads_with_none(tmp_path: Path, scenario_writer: Callable[..., Path]) -> None:
    s = load_scenario(scenario_writer(tmp_path, "plain", np.zeros((4, 5))))
    assert s.prior is None


def test_the_prior_is_a_terrain_on_the_true_maps_grid(tmp_path: Path, scenario_writer: Callable[..., Path]) -> None:
    truth = np.full((4, 5), 0.3)
    truth[1:3, 2] = 0.02
    trench = np.zeros((4, 5), dtype=bool)
    trench[1:3, 2] = True
    path = scenario_writer(tmp_path, "surprising", truth, 0.5, origin=(1.0, -2.0), obstacles=trench)
    prior_obstacles = np.zeros((4, 5), dtype=bool)
    prior_obstacles[0, 0] = True
    s = load_scenario(_with_prior(path, np.full((4, 5), 0.3), prior_obstacles))
    assert s.prior is not None
    assert s.prior.shape == s.terrain.shape
    assert s.prior.origin == s.terrain.origin == (1.0, -2.0)
    assert s.prior.resolution == s.terrain.resolution == 0.5
    np.testing.assert_array_equal(s.prior.heights, np.full((4, 5), 0.3))
    # The trench is in the true map only; the prior has its own obstacles.
    assert s.terrain.is_obstacle(2.25, -1.25) and not s.prior.is_obstacle(2.25, -1.25)
    assert s.prior.is_obstacle(1.25, -1.75) and not s.terrain.is_obstacle(1.25, -1.75)
    assert s.prior.height_at(2.25, -1.25) == pytest.approx(0.3)


def test_a_bad_prior_is_a_scenario_error(tmp_path: Path, scenario_writer: Callable[..., Path]) -> None:
    path = scenario_writer(tmp_path / "maps", "bad", np.zeros((4, 5)))
    with pytest.raises(ScenarioError, match=r"prior shape \(3, 5\) differs from the map's \(4, 5\)"):
        load_scenario(_with_prior(path, np.zeros((3, 5))))
    with pytest.raises(ScenarioError, match="NaN"):
        load_scenario(_with_prior(path, np.full((4, 5), np.nan)))
    np.save(tmp_path / "elsewhere.npy", np.zeros((4, 5)))
    for outside in ("../elsewhere.npy", str(tmp_path / "elsewhere.npy"), ""):
        with pytest.raises(ScenarioError, match="must be a relative path inside"):
            load_scenario(_with_prior(path, np.zeros((4, 5)), heights_name=outside))
    meta = json.loads(path.read_text())
    meta["prior"] = "bad.prior.heights.npy"
    path.write_text(json.dumps(meta))
    with pytest.raises(ScenarioError, match="'prior' must be an object"):
        load_scenario(path)
