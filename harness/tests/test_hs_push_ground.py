"""The ground along each run's push: the distance search on a map, and the report's section from a
store's own courses."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from test_hs_sweep_stats import fake_rows

from pfnav_harness.planner_client import Plan
from pfnav_harness.scenario import GoalRegion, Terrain, write_map
from pfnav_harness.sweep.push_ground import GROUND_CHANGE, ground_by_impulse_lines, ground_change_distance, push_ground_distances
from pfnav_harness.sweep.report import write_report
from pfnav_harness.sweep.spec import parse_spec
from pfnav_harness.sweep.store import SweepStore

RESOLUTION = 0.1


def walled_terrain() -> Terrain:
    """4 m × 4 m from (−2, −2), flat, with a wall 0.3 m high wherever y ≥ 0.6 (cell centres)."""
    ys = -2.0 + (np.arange(40) + 0.5) * RESOLUTION
    heights = np.where(ys[:, None] >= 0.6, 0.3, 0.0) * np.ones((40, 40))
    return Terrain((-2.0, -2.0), RESOLUTION, heights)


def test_distance_to_the_wall_along_a_direction() -> None:
    terrain = walled_terrain()
    # Towards +y from the origin: the surface is 0.15 m high halfway between the cell centres at
    # 0.55 and 0.65, and higher from there; the first 0.05 m step beyond is at 0.65.
    assert ground_change_distance(terrain, 0.0, 0.0, math.pi / 2) == pytest.approx(0.65)
    # At 45°, the same wall lies √2 times as far along the push.
    assert ground_change_distance(terrain, 0.0, 0.0, math.pi / 4) == pytest.approx(0.6 * math.sqrt(2), abs=0.05)
    # Away from it, along it, and off the map: none.
    assert ground_change_distance(terrain, 0.0, 0.0, -math.pi / 2) == math.inf
    assert ground_change_distance(terrain, 0.0, 0.0, 0.0) == math.inf
    assert ground_change_distance(terrain, 1.9, 0.0, 0.0) == math.inf
    # Standing on the wall, the drop counts the same.
    assert ground_change_distance(terrain, 0.0, 1.0, -math.pi / 2) == pytest.approx(0.45)
    assert GROUND_CHANGE < 0.3


def store_with_course(tmp_path: Path, outcomes: list[str], **factors: list[object]) -> SweepStore:
    """A store of `fake_rows` whose course (terrain seed 5) is the walled map, walked along +x on
    y = 0 towards −x at 1 m/s from x = 1.5 (heading π: its left is −y, the wall on its right)."""
    spec = parse_spec({"scenario": "flat", "duration": 1.0, "seed": 1, "runs": len(outcomes)})
    store = SweepStore.create(tmp_path / "store", spec)
    write_map(walled_terrain(), store.scenarios_dir / "scenario_default", "flat", goal=GoalRegion((1.5, 0.0), 0.3), seed=5)
    t = np.linspace(0.0, 3.0, 31)
    zero = 0.0 * t
    store.save_plan("flat", 5, Plan("pf", t, 1.5 - t, zero, zero, zero + math.pi, zero - 1.0, zero, zero))
    store.append(fake_rows(spec.hash, outcomes, **factors))
    return store


def test_distances_of_a_stores_pushes(tmp_path: Path) -> None:
    directions = ["right", "left", "front", "right"]
    magnitudes = [100.0, 100.0, 100.0, 0.0]
    store = store_with_course(tmp_path, ["fell", "goal", "goal", "goal"], push_direction=directions, push_magnitude=magnitudes, push_time=[1.0] * 4)
    distances = push_ground_distances(store.table(), store)
    # Right of a robot heading −x is +y: the wall 0.65 m away; left and ahead nothing; no push: none.
    assert distances[0] == pytest.approx(0.65)
    assert distances[1] == math.inf and distances[2] == math.inf
    assert math.isnan(distances[3])
    lines = ground_by_impulse_lines(distances, store.table())
    # 100 N for 0.2 s: 20 N·s, the (18, 24] bin.
    assert lines[2].startswith("| (0, 0.5] m |") and lines[2].endswith(" 0/0 |")
    assert lines[3].startswith("| (0.5, 1] m |") and lines[3].endswith(" 1/1 |")
    assert lines[-1].startswith("| none within 2 m |") and lines[-1].endswith(" 0/2 |")


def test_report_section_needs_the_stores_courses(tmp_path: Path) -> None:
    store = store_with_course(tmp_path, ["fell", "goal"], push_direction=["right", "left"], push_magnitude=[100.0, 100.0], push_time=[1.0, 1.0])
    text = write_report(store).read_text()
    assert "### ground along the push (m)" in text
    assert "| (0.5, 1] m | 1 | 1 | 100.0 %" in text
    assert (store.folder / "fall_rate_push_ground.png").stat().st_size > 5000
    # Without the stored scenario the section is left out, the report still written.
    for path in store.scenarios_dir.rglob("*.json"):
        path.unlink()
    assert "ground along the push" not in write_report(store).read_text()
    assert np.isnan(push_ground_distances(pa.Table.from_pylist(fake_rows("h", ["goal"])), store)).all()
