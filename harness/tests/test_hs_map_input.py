"""`pfnav-demo run --map FILE [--start X,Y] [--goal X,Y]`: flags, overrides and bad placements, without simulation."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness.cli import build_parser
from pfnav_harness.errors import HarnessError, ScenarioError
from pfnav_harness.map_input import load_map_scenario, parse_point
from pfnav_harness.scenario import GoalRegion, Terrain, write_map

# 20 × 10 cells of 0.1 m: x 0..2 m, y 0..1 m; cells (ix 10..11, iy 4..5) are an obstacle.
WIDTH, HEIGHT, RESOLUTION = 20, 10, 0.1


def write_sidecar(folder: Path, name: str = "hill", start: tuple[float, float] = (0.25, 0.25), goal: tuple[float, float] = (1.75, 0.75)) -> Path:
    xs = (np.arange(WIDTH) + 0.5) * RESOLUTION
    heights = np.tile(0.2 * xs, (HEIGHT, 1))
    obstacles = np.zeros((HEIGHT, WIDTH), dtype=bool)
    obstacles[4:6, 10:12] = True
    terrain = Terrain((0.0, 0.0), RESOLUTION, heights, obstacles)
    return write_map(terrain, folder, name, {"height_weight": 1.0}, start=start, start_yaw=0.3, goal=GoalRegion(goal, 0.2))


def test_map_cli_flags_parse() -> None:
    args = build_parser().parse_args(["run", "--map", "maps/hill.json", "--start", "0.5,0.5", "--goal", "1.5,0.5"])
    assert args.map == Path("maps/hill.json")
    assert args.scenario is None
    assert (args.start, args.goal) == ("0.5,0.5", "1.5,0.5")
    args = build_parser().parse_args(["run", "--scenario", "pits"])
    assert (args.scenario, args.map, args.start, args.goal) == ("pits", None, None, None)


@pytest.mark.parametrize("argv", [["run", "--scenario", "pits", "--map", "hill.json"], ["run"], ["run", "--start", "1,1"]])
def test_map_cli_needs_exactly_one_of_scenario_and_map(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--scenario" in err
    assert "--map" in err


def test_map_sidecar_start_and_goal_are_used(tmp_path: Path) -> None:
    scenario = load_map_scenario(write_sidecar(tmp_path))
    assert scenario.name == "hill"
    assert scenario.start == (0.25, 0.25)
    assert scenario.start_yaw == 0.3
    assert scenario.goal.center == (1.75, 0.75)
    assert scenario.goal.radius == 0.2
    assert scenario.terrain.shape == (HEIGHT, WIDTH)
    assert scenario.terrain.is_obstacle(1.05, 0.45)


def test_map_flags_override_start_and_goal(tmp_path: Path) -> None:
    scenario = load_map_scenario(write_sidecar(tmp_path), start=(0.55, 0.85), goal=(1.95, 0.05))
    assert scenario.start == (0.55, 0.85)
    assert scenario.goal.center == (1.95, 0.05)
    # The radius and heading stay the sidecar's.
    assert scenario.goal.radius == 0.2
    assert scenario.start_yaw == 0.3
    only_goal = load_map_scenario(write_sidecar(tmp_path), goal=(0.25, 0.95))
    assert only_goal.start == (0.25, 0.25)
    assert only_goal.goal.center == (0.25, 0.95)


@pytest.mark.parametrize(
    ("start", "goal", "message"),
    [
        ((2.0, 0.5), None, "start (2, 0.5) is off the map 'hill': it spans x 0..2, y 0..1 m"),
        ((-0.01, 0.5), None, "start (-0.01, 0.5) is off the map"),
        (None, (1.0, 1.5), "goal (1, 1.5) is off the map"),
        ((1.05, 0.45), None, "start (1.05, 0.45) lies on an obstacle of the map 'hill'"),
        (None, (1.15, 0.55), "goal (1.15, 0.55) lies on an obstacle"),
        ((1.7, 0.7), None, "already lies inside the goal region"),
    ],
)
def test_map_bad_placements_are_refused(tmp_path: Path, start: tuple[float, float] | None, goal: tuple[float, float] | None, message: str) -> None:
    with pytest.raises(ScenarioError) as exc:
        load_map_scenario(write_sidecar(tmp_path), start=start, goal=goal)
    assert message in str(exc.value)


def test_map_bad_sidecar_placement_is_refused(tmp_path: Path) -> None:
    sidecar = write_sidecar(tmp_path, start=(1.05, 0.55))
    with pytest.raises(ScenarioError, match=r"start .* lies on an obstacle"):
        load_map_scenario(sidecar)
    with pytest.raises(ScenarioError, match="is a directory"):
        load_map_scenario(tmp_path)
    with pytest.raises(ScenarioError, match="does not exist"):
        load_map_scenario(tmp_path / "missing.json")


@pytest.mark.parametrize("text", ["1", "1,2,3", "a,b", "nan,1", "1,inf", ""])
def test_map_point_flags_must_be_two_finite_numbers(text: str) -> None:
    with pytest.raises(HarnessError, match="--start must be"):
        parse_point(text, "--start")


def test_map_point_flag_parses() -> None:
    assert parse_point(" 1.5, -2 ", "--goal") == (1.5, -2.0)


@pytest.fixture
def fake_build(tmp_path: Path) -> dict[str, str]:
    """Build products that exist but never run: every case below must stop before planning."""
    never = tmp_path / "never-run"
    never.write_text("#!/bin/sh\necho 'must not run' >&2\nexit 99\n")
    never.chmod(0o755)
    fmu = tmp_path / "Fake.fmu"
    fmu.write_bytes(b"not really an FMU")
    return {**os.environ, "PFNAV_PF_PLAN": str(never), "PFNAV_PLANNER_SERVICE": str(never), "PFNAV_FMU": str(fmu)}


@pytest.mark.parametrize(
    ("extra", "code", "message"),
    [
        (("--start", "1"), 1, "--start must be two numbers X,Y"),
        (("--goal", "x,y"), 1, "--goal must be two numbers X,Y"),
        (("--start", "5,5"), 2, "start (5, 5) is off the map 'hill'"),
        (("--goal", "1.05,0.45"), 2, "goal (1.05, 0.45) lies on an obstacle"),
    ],
)
def test_map_cli_bad_placement_is_one_clear_line(fake_build: dict[str, str], tmp_path: Path, extra: tuple[str, ...], code: int, message: str) -> None:
    sidecar = write_sidecar(tmp_path / "maps")
    proc = subprocess.run(
        [sys.executable, "-m", "pfnav_harness", "run", "--map", str(sidecar), *extra, "--out", str(tmp_path / "out")],
        env=fake_build,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == code, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "must not run" not in proc.stderr
    assert f"pfnav-demo: error: {message}" in proc.stderr or message in proc.stderr.splitlines()[-1]


def test_map_cli_start_goal_only_with_map(fake_build: dict[str, str], tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "pfnav_harness", "run", "--scenario", "pits", "--goal", "1,1", "--out", str(tmp_path / "out")],
        env=fake_build,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 1, proc.stderr
    assert "pfnav-demo: error: --start and --goal place the robot on a --map file" in proc.stderr
