from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness.errors import ScenarioError
from pfnav_harness.scenario import Scenario, Terrain, load_scenario


def test_load_round_trip(ramp_scenario: Scenario) -> None:
    s = ramp_scenario
    assert s.name == "ramp"
    assert s.terrain.shape == (20, 30)
    assert s.start == (0.5, 1.0)
    assert s.goal.center == (2.5, 1.0) and s.goal.radius == 0.3
    assert s.seed == 7
    assert s.traversability["p_floor"] == 0.05
    assert s.terrain.bounds() == ((0.0, 0.0), pytest.approx((3.0, 2.0)))


def test_linear_terrain_is_reproduced_exactly_everywhere() -> None:
    # A plane through the cell centres is reproduced exactly by any triangulation.
    nx, ny, res = 12, 9, 0.25
    ox, oy = -1.0, 2.0
    xs = ox + (np.arange(nx) + 0.5) * res
    ys = oy + (np.arange(ny) + 0.5) * res
    gx, gy = np.meshgrid(xs, ys)
    terrain = Terrain((ox, oy), res, 0.3 + 0.1 * gx - 0.25 * gy)
    rng = np.random.default_rng(3)
    px = rng.uniform(xs[0], xs[-1], 500)
    py = rng.uniform(ys[0], ys[-1], 500)
    z, dzdx, dzdy = terrain.height_and_gradient(px, py)
    np.testing.assert_allclose(z, 0.3 + 0.1 * px - 0.25 * py, atol=1e-12)
    np.testing.assert_allclose(dzdx, 0.1, atol=1e-12)
    np.testing.assert_allclose(dzdy, -0.25, atol=1e-12)
    plane = terrain.plane(0.5, 3.1)  # window well inside the centre grid
    assert plane.dzdx == pytest.approx(0.1, abs=1e-9)
    assert plane.dzdy == pytest.approx(-0.25, abs=1e-9)


def test_surface_passes_through_cell_centres_and_follows_the_diagonal_split() -> None:
    heights = np.array([[0.0, 1.0], [2.0, 4.0]])  # rows y, columns x
    terrain = Terrain((0.0, 0.0), 1.0, heights)
    for iy in range(2):
        for ix in range(2):
            assert terrain.height_at(ix + 0.5, iy + 0.5) == pytest.approx(heights[iy, ix])
    # Lower-right triangle (u ≥ v) through (0,0)=0, (1,0)=1, (1,1)=4: at u=0.75, v=0.25 → 0.75 + 0.25·3.
    assert terrain.height_at(1.25, 0.75) == pytest.approx(0.75 + 0.25 * 3.0)
    # Upper-left triangle (v > u) through (0,0)=0, (1,1)=4, (0,1)=2: at u=0.25, v=0.75 → 0.75·2 + 0.25·2.
    assert terrain.height_at(0.75, 1.25) == pytest.approx(0.75 * 2.0 + 0.25 * 2.0)
    # Outside the centre grid the surface is clamped to its border.
    assert terrain.height_at(-5.0, 0.5) == pytest.approx(0.0)


def test_triangles_are_counter_clockwise_seen_from_above() -> None:
    rng = np.random.default_rng(1)
    terrain = Terrain((0.0, 0.0), 0.2, rng.uniform(0, 1, (5, 7)))
    v = terrain.vertices()
    tri = terrain.triangles()
    assert tri.shape == (2 * 4 * 6, 3)
    a, b, c = v[tri[:, 0], :2], v[tri[:, 1], :2], v[tri[:, 2], :2]
    cross_z = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert np.all(cross_z > 0)
    # The triangles tile the centre rectangle exactly once.
    assert np.sum(cross_z) / 2 == pytest.approx((6 * 0.2) * (4 * 0.2))


def test_bad_files_give_scenario_errors(tmp_path: Path, scenario_writer: Callable[..., Path]) -> None:
    write_scenario = scenario_writer
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(tmp_path / "nope.json")
    path = write_scenario(tmp_path, "bad", np.zeros((4, 5)))
    meta = json.loads(path.read_text())
    meta["width"] = 6
    path.write_text(json.dumps(meta))
    with pytest.raises(ScenarioError, match="shape"):
        load_scenario(path)
    # A file another program wrote with NaN heights (the harness's writer refuses to write one).
    path = write_scenario(tmp_path, "nan", np.zeros((4, 5)))
    np.save(tmp_path / "nan.heights.npy", np.full((4, 5), np.nan))
    with pytest.raises(ScenarioError, match="NaN"):
        load_scenario(path)
    path = write_scenario(tmp_path, "goal", np.zeros((4, 5)), goal_radius=0.0)
    with pytest.raises(ScenarioError, match="radius"):
        load_scenario(path)
    (tmp_path / "junk.json").write_text("{not json")
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "junk.json")


def test_obstacles_are_loaded_and_queried(tmp_path: Path, scenario_writer: Callable[..., Path]) -> None:
    write_scenario = scenario_writer
    obstacles = np.zeros((4, 5), dtype=bool)
    obstacles[2, 3] = True
    s = load_scenario(write_scenario(tmp_path, "obs", np.zeros((4, 5)), 1.0, obstacles=obstacles))
    assert s.terrain.is_obstacle(3.5, 2.5)
    assert not s.terrain.is_obstacle(2.5, 2.5)
    assert not s.terrain.is_obstacle(-1.0, 2.5)


def test_local_grid_is_the_block_of_mesh_vertices_around_a_point() -> None:
    rng = np.random.default_rng(3)
    heights = rng.uniform(0.0, 0.5, size=(20, 30))
    terrain = Terrain((1.0, -2.0), 0.125, heights)
    grid = terrain.local_grid(2.3, -1.0, 11)
    assert grid is not None
    x0, y0, block = grid
    assert block.shape == (11, 11)
    # The block's vertices are mesh vertices: the surface passes through them.
    for iy in (0, 4, 10):
        for ix in (0, 7, 10):
            assert terrain.height_at(x0 + ix * 0.125, y0 + iy * 0.125) == pytest.approx(block[iy, ix])
    # Centred on the nearest vertex, clamped inside the map near its border.
    assert abs(x0 + 5 * 0.125 - 2.3) <= 0.0625 + 1e-12
    x0_edge, y0_edge, _ = terrain.local_grid(1.0, -2.0, 11) or (0.0, 0.0, None)
    assert (x0_edge, y0_edge) == pytest.approx((1.0625, -1.9375))
    assert terrain.local_grid(2.3, -1.0, 31) is None


def test_height_at_is_height_bit_for_bit() -> None:
    """`height_at` (plain floats, the co-simulation's fall check) equals `height` everywhere: inside,
    on vertices and cell edges, on both triangles of a cell, beyond the border, at −0.0."""
    rng = np.random.default_rng(8)
    heights = rng.normal(size=(13, 17))
    heights[0, 0] = -0.0
    terrain = Terrain((-1.0, 2.0), 0.25, heights)
    xs = np.concatenate([rng.uniform(-2.0, 4.0, 4000), -1.0 + (np.arange(17) + 0.5) * 0.25, [-0.875, -0.0, 0.0, 1e9, -1e9]])
    ys = np.concatenate([rng.uniform(1.0, 6.0, 4000), 2.0 + (np.arange(17) % 13 + 0.5) * 0.25, [2.125, -0.0, 0.0, 1e9, -1e9]])
    for x, y in zip(xs.tolist(), ys.tolist(), strict=True):
        assert np.float64(terrain.height_at(x, y)).tobytes() == np.float64(terrain.height(x, y)).tobytes(), (x, y)
