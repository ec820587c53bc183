"""Bad input at the command line: one clear line on stderr and a non-zero exit, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from pfnav_harness import paths

FAKE_PF_PLAN = textwrap.dedent(
    """\
    import sys
    from pathlib import Path
    import numpy as np
    from pfnav_harness.scenario import GoalRegion, Terrain, write_map
    args = sys.argv[1:]
    name, out = args[2], Path(args[args.index("--out") + 1])
    if name != "ramp":
        print(f"error: unknown scenario '{name}' (known: ramp)", file=sys.stderr)
        sys.exit(2)
    traversability = {"height_weight": 1.0, "slope_weight": 0.0, "p_floor": 0.05}
    write_map(Terrain((0.0, 0.0), 0.1, np.zeros((10, 20))), out, "ramp", traversability,
              start=(0.5, 0.5), goal=GoalRegion((1.5, 0.5), 0.2), seed=1)
    """
)


@pytest.fixture
def fake_tools(tmp_path: Path) -> dict[str, str]:
    pf_plan = tmp_path / "pf-plan"
    pf_plan.write_text(f"#!{sys.executable}\n" + FAKE_PF_PLAN)
    pf_plan.chmod(0o755)
    silent_service = tmp_path / "silent-service"
    silent_service.write_text("#!/bin/sh\necho 'silent service starting' >&2\nexec sleep 30\n")
    silent_service.chmod(0o755)
    fmu = tmp_path / "Fake.fmu"
    fmu.write_bytes(b"not really an FMU")
    return {
        **os.environ,
        "PFNAV_PF_PLAN": str(pf_plan),
        "PFNAV_PLANNER_SERVICE": str(silent_service),
        "PFNAV_FMU": str(fmu),
    }


def run_cli(env: dict[str, str], *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pfnav_harness", *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=120, check=False)


def assert_clean_failure(proc: subprocess.CompletedProcess[str], code: int, message: str) -> None:
    assert proc.returncode == code, proc.stderr
    assert "Traceback" not in proc.stderr
    assert message in proc.stderr
    assert any(line.startswith("pfnav-demo: error:") for line in proc.stderr.splitlines())


def test_missing_fmu(fake_tools: dict[str, str], tmp_path: Path) -> None:
    env = {**fake_tools, "PFNAV_FMU": str(tmp_path / "nowhere" / "QuadController.fmu")}
    proc = run_cli(env, "run", "--scenario", "ramp", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 3, "controller FMU not found")


def test_bad_robot_configs_fail_before_any_work(fake_tools: dict[str, str], tmp_path: Path) -> None:
    """--robot (and PFNAV_ROBOT) name a robot config; a bad one is one clear line, a robot not ours needs bundle-fmu."""
    proc = run_cli(fake_tools, "run", "--scenario", "ramp", "--robot", str(tmp_path / "nowhere.toml"), "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 7, "nowhere.toml: cannot read it")
    ours = paths.default_robot_config_path()
    bad = tmp_path / "bad" / "robot.toml"
    bad.parent.mkdir()
    (bad.parent / "quadruped.urdf").write_bytes((ours.parent / "quadruped.urdf").read_bytes())
    bad.write_text(ours.read_text().replace("stand_height = 0.28", "stand_heigth = 0.28"))
    proc = run_cli(fake_tools, "demo", "--robot", str(bad), "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 7, "unknown field `stand_heigth`")
    proc = run_cli({**fake_tools, "PFNAV_ROBOT": str(bad)}, "run", "--scenario", "ramp", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 7, "unknown field `stand_heigth`")
    bad.write_text(ours.read_text().replace("stand_height = 0.28", "stand_height = 0.3"))
    env = {**fake_tools, "PFNAV_BUNDLE_FMU": str(tmp_path / "no-bundle-fmu")}
    proc = run_cli(env, "run", "--scenario", "ramp", "--robot", str(bad), "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 3, "is not ours, so its FMU has to be bundled: bundle-fmu binary")
    assert "silent service starting" not in proc.stderr  # no service was started


def test_unknown_scenario(fake_tools: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(fake_tools, "demo", "--scenario", "atlantis", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 2, "unknown scenario 'atlantis'")


def test_planner_that_does_not_answer(fake_tools: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(
        fake_tools,
        "run",
        "--scenario",
        "ramp",
        "--lcm-url",
        "memq://",
        "--service-timeout",
        "1",
        # The stand-in FMU is no FMU: on ground truth nothing reads it before the planner answers.
        "--estimator",
        "groundTruth",
        "--out",
        str(tmp_path / "out"),
        cwd=tmp_path,
    )
    assert_clean_failure(proc, 4, "published no status")
    assert "silent service starting" in proc.stderr  # the service log tail is shown


def test_the_default_estimator_checks_the_fmu_before_planning(fake_tools: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(fake_tools, "run", "--scenario", "ramp", "--lcm-url", "memq://", "--service-timeout", "1", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 5, "cannot read the model description")
    assert "silent service starting" not in proc.stderr  # no service was started


def test_bad_arguments(fake_tools: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(fake_tools, "demo", "--methods", "pf,rrt", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 1, "unknown method(s) rrt")
    proc = run_cli(fake_tools, "run", "--scenario", "ramp", "--duration", "-1", cwd=tmp_path)
    assert_clean_failure(proc, 1, "--duration must be positive")
    proc = run_cli(fake_tools, "demo", "--jobs", "0", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_clean_failure(proc, 1, "--jobs must be >= 1, got 0")
    proc = run_cli(fake_tools, "run", "--scenario", "ramp", "--footprint-radius=-0.1", cwd=tmp_path)
    assert_clean_failure(proc, 1, "--footprint-radius must be finite and >= 0")


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (("--max-slope-deg", "95"), 1, "--max-slope-deg must lie in (0, 90)"),
        (("--traversability", "slope_weight"), 1, "--traversability takes FIELD=VALUE"),
        (("--traversability", "slope_weight=steep"), 1, "--traversability takes FIELD=VALUE"),
        (("--traversability", "max_slope_deg=20"), 1, "use --max-slope-deg"),
        (("--traversability", "slope_wieght=1"), 1, "no field slope_wieght in the planner's model"),
        (("--online", "--bad-map-updates", "nan,garbage"), 1, "unknown bad map update kind(s) garbage"),
        (("--online", "--sensor-range", "0"), 1, "sensor range must be a positive number"),
        (("--online", "--unknown-traversability", "1.5"), 1, "traversability of unknown cells must lie in (0, 1]"),
        (("--online", "--replan-budget", "0.7"), 1, "latency budget must lie in [0, update period"),
        (("--follow", "feedback", "--method", "astar"), 1, "feedback mode follows the P-F feedback field"),
        (("--push", "60@north:1+0.2"), 2, "push '60@north:1+0.2'"),
        (("--random-pushes", "2", "--push-window", "3"), 1, "--push-window must be two numbers"),
    ],
)
def test_bad_online_and_push_arguments(fake_tools: dict[str, str], tmp_path: Path, args: tuple[str, ...], code: int, message: str) -> None:
    proc = run_cli(fake_tools, "run", "--scenario", "ramp", "--out", str(tmp_path / "out"), *args, cwd=tmp_path)
    assert_clean_failure(proc, code, message)


def test_traversability_fields_reach_the_started_service(fake_tools: dict[str, str], tmp_path: Path) -> None:
    """The service is started with the cost model the metrics use (its argv, from a stand-in that records it)."""
    recorded = tmp_path / "service_argv"
    service = tmp_path / "recording-service"
    service.write_text(f'#!/bin/sh\nprintf "%s\\n" "$@" > {recorded}\nexec sleep 30\n')
    service.chmod(0o755)
    env = {**fake_tools, "PFNAV_PLANNER_SERVICE": str(service)}
    proc = run_cli(
        env, "run", "--scenario", "ramp", "--lcm-url", "memq://", "--service-timeout", "1",
        "--traversability", "height_weight=2", "--estimator", "groundTruth", "--out", str(tmp_path / "out"), cwd=tmp_path,
    )
    assert_clean_failure(proc, 4, "published no status")
    argv = recorded.read_text().splitlines()
    assert '--traversability={"height_weight": 2.0}' in argv, argv


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (("run", "--scenario", "ramp", "--online"), {"slope_fit_radius_m": 0.25}),
        (("run", "--scenario", "ramp", "--online", "--traversability", "slope_fit_radius_m=0"), {"slope_fit_radius_m": 0.0}),
        (("run", "--scenario", "ramp"), {}),
    ],
)
def test_online_runs_fit_the_slope_unless_told_otherwise(args: tuple[str, ...], expected: dict[str, float]) -> None:
    from pfnav_harness import cli

    assert cli._service_traversability(cli.build_parser().parse_args(args)) == expected


@pytest.mark.parametrize(("args", "engine"), [((), "dart"), (("--engine", "mujoco"), "mujoco"), (("--engine", "dart"), "dart")])
def test_the_engine_reaches_the_co_simulation_config(args: tuple[str, ...], engine: str) -> None:
    from pfnav_harness import cli

    parsed = cli.build_parser().parse_args(("run", "--scenario", "ramp", "--estimator", "groundTruth", *args))
    assert cli._config(parsed).engine == engine


def test_an_unknown_engine_is_a_usage_error(fake_tools: dict[str, str], tmp_path: Path) -> None:
    proc = run_cli(fake_tools, "run", "--scenario", "ramp", "--engine", "bullet", cwd=tmp_path)
    assert proc.returncode == 2
    assert "invalid choice: 'bullet'" in proc.stderr
