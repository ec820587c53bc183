"""Real elevation data end to end: a crop of matplotlib's USGS sample DEM → `pf-plan import` → `pfnav-demo run --map`.

The crop is chosen by scripts/real_terrain.py's own rule (slope p95 and max closest to 25° / 35°),
imported at robot scale with a keep-out rim along its edge, and walked for `--short` simulated
seconds with the P-F plan from a started planner service (LCM inside the private namespace).
The full trial, several crops and slope limits, is `scripts/real_terrain.py` (docs/real-terrain.md).
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from pfnav_harness.scenario import load_scenario

CELLS = 48
CELL_SIZE = 0.125


@pytest.fixture(scope="module")
def real_terrain(repo_root: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "real_terrain", repo_root / "scripts" / "real_terrain.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["real_terrain"] = module
    spec.loader.exec_module(module)
    return module


def test_real_dem_crop_plans_and_walks(
    real_terrain: ModuleType, pf_plan_bin: Path, lcm_url: str, tmp_path: Path
) -> None:
    dem = real_terrain.load_metric_dem()
    assert dem.heights.shape == (344, 403)
    # 3 arc-seconds at 36.6° N: about 74.6 m east-west and 92.5 m north-south.
    assert dem.dx == pytest.approx(74.6, abs=0.2)
    assert dem.dy == pytest.approx(92.5, abs=0.2)
    (crop,) = real_terrain.find_crops(dem, 24, 1, 25.0, 35.0)
    assert 20.0 <= crop.source_p95 <= 30.0
    side = CELLS * CELL_SIZE
    scale = side / (crop.columns * dem.dx)
    asc = real_terrain.write_esri_ascii(dem, tmp_path / "crop.asc", crop, rim=1)
    placeholder = ((side / 4, side / 4), (3 * side / 4, 3 * side / 4))
    real_terrain.run_import(
        pf_plan_bin,
        asc,
        tmp_path / "maps",
        "dem_crop",
        None,
        scale,
        CELL_SIZE,
        *placeholder,
    )
    heights = np.load(tmp_path / "maps" / "dem_crop.heights.npy")
    slopes = real_terrain.cell_slopes_deg(heights, CELL_SIZE, CELL_SIZE)
    start, _ = real_terrain.flattest_near(slopes, CELL_SIZE, (False, False))
    goal, _ = real_terrain.flattest_near(slopes, CELL_SIZE, (True, True))
    sidecar, summary = real_terrain.run_import(
        pf_plan_bin,
        asc,
        tmp_path / "maps",
        "dem_crop",
        None,
        scale,
        CELL_SIZE,
        start,
        goal,
    )
    _, p95, peak = real_terrain.summary_slopes(summary)
    assert p95 >= 15.0 and peak >= 25.0, summary  # real, steep ground at robot scale

    out = tmp_path / "out"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pfnav_harness",
            "run",
            "--map",
            str(sidecar),
            "--short",
            "--no-progress",
            "--lcm-url",
            lcm_url,
            # Channels of its own: the session's planner service (other tests) must not see this
            # run's map publications, which would push its cached maps out.
            "--channel-prefix",
            "PFNAV_REALTERRAIN_",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    (run,) = json.loads((out / "metrics.json").read_text())["runs"]
    assert run["scenario"] == "dem_crop"
    assert not run["fell"], run["fall_reason"]
    log = np.load(out / "logs" / "dem_crop_pf.npz")
    scenario = load_scenario(sidecar)
    # The plan stays on the map and off the keep-out rim.
    (x0, y0), (x1, y1) = scenario.terrain.bounds()
    assert np.all(
        (log["plan_x"] >= x0)
        & (log["plan_x"] <= x1)
        & (log["plan_y"] >= y0)
        & (log["plan_y"] <= y1)
    )
    assert not any(
        scenario.terrain.is_obstacle(x, y)
        for x, y in zip(log["plan_x"], log["plan_y"], strict=True)
    )
    # Progress toward the goal in the short run.
    base = log["base_pos"]
    distance = np.hypot(base[:, 0] - goal[0], base[:, 1] - goal[1])
    assert distance[-1] < distance[0] - 1.0, (distance[0], distance[-1])
    assert run["rms_error"] < 0.15
