"""The physics engine chosen for a run reaches its world on every path a run is configured by:
a sweep spec (`engine`), online navigation (`pfnav-demo run --online --engine`) and the incline
benchmark (`run_incline(engine=...)`, `scripts/bench_slopes.py --engine`).

Each test builds or briefly runs the real co-simulation and checks the world that was made, not
only the configuration: a path that dropped the engine on the way would walk in DART.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_hs_fast_loop import walking_plan
from test_hs_online import ScriptedClient

from pfnav_harness import cli, cosim, paths
from pfnav_harness.cosim import CoSimConfig
from pfnav_harness.engine import PhysicsEngine, make_engine
from pfnav_harness.errors import SimulationError
from pfnav_harness.incline import run_incline
from pfnav_harness.pipeline import simulate_online
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario
from pfnav_harness.sweep.driver import run_tasks
from pfnav_harness.sweep.runner import Artifacts, Course, fork_group, result_row, run_config, start_run
from pfnav_harness.sweep.spec import parse_spec

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
# Simulated seconds of the runs below: enough to build, place and step the world, not to walk.
BRIEF = 0.05


def engines_made(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The names of the worlds the co-simulation builds from now on (in order)."""
    made: list[str] = []

    def recording_make_engine(name: str, *args: object, **kwargs: object) -> PhysicsEngine:
        world = make_engine(name, *args, **kwargs)  # type: ignore[arg-type]
        made.append(world.name)
        return world

    monkeypatch.setattr(cosim, "make_engine", recording_make_engine)
    return made


def test_a_sweep_spec_s_engine_reaches_each_run_s_world_and_row(ramp_scenario: Scenario, tmp_path: Path) -> None:
    """`engine = "mujoco"` in a spec: every run's world is MuJoCo's, with the run's payload and friction, the row says so,
    and its runs fork from prefixes of their own (a DART prefix cannot continue in MuJoCo)."""
    data = {"scenario": "ramp", "duration": 4.0, "seed": 3, "runs": 2, "factors": {"payload_mass": 0.1, "friction": 0.6}}
    spec = parse_spec({**data, "engine": "mujoco"})
    task = run_tasks(spec, set())[0]
    course = Course(0, ramp_scenario, walking_plan())
    with start_run(course, Artifacts(paths.fmu_path(), ROBOT, None), run_config(task), tmp_path) as sim:
        world = sim.world
        assert world.name == "mujoco"
        plain = make_engine("mujoco", ramp_scenario.terrain, ROBOT, tmp_path)
        assert world.mass == pytest.approx(plain.mass + 0.1 * plain.trunk_mass)  # type: ignore[attr-defined]
        np.testing.assert_array_equal(world.model.geom_friction[:, 0], 0.6)  # type: ignore[attr-defined]
    assert result_row(task, course)["engine"] == "mujoco"
    dart_task = run_tasks(parse_spec(data), set())[0]
    assert result_row(dart_task, course)["engine"] == "dart"
    assert fork_group(dart_task) != fork_group(task)


def test_online_navigation_walks_in_the_engine_of_the_command_line(ramp_scenario: Scenario, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`pfnav-demo run --online --engine mujoco`: the online run's world is MuJoCo's (the planner is a scripted client)."""
    args = cli.build_parser().parse_args(
        ("run", "--scenario", "ramp", "--online", "--engine", "mujoco", "--estimator", "groundTruth", "--terrain-sensor", "ideal", "--duration", str(BRIEF))
    )
    made = engines_made(monkeypatch)
    outcome = simulate_online(
        ScriptedClient(), ramp_scenario, paths.fmu_path(), ROBOT, tmp_path, cli._config(args), cli._online_config(args), 1.0, 0, show_progress=False
    )
    assert made == ["mujoco"]
    assert str(outcome.result.log["engine"]) == "mujoco"
    assert outcome.result.timing.simulated == pytest.approx(BRIEF)


@pytest.mark.parametrize("engine", ["mujoco", "dart"])
def test_the_incline_benchmark_walks_in_the_engine_asked_for(engine: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`run_incline(engine=...)` (bench_slopes.py --engine) builds that engine's world, whatever engine its config names."""
    made = engines_made(monkeypatch)
    config = CoSimConfig(settle_time=1.0, estimator="groundTruth", max_duration=BRIEF, engine="dart" if engine == "mujoco" else "mujoco")
    run = run_incline(10.0, "up", paths.fmu_path(), ROBOT, tmp_path, config=config, engine=engine)
    assert made == [engine]
    assert run.outcome.engine == engine
    assert str(run.result.log["engine"]) == engine


def test_the_incline_benchmark_s_contact_time_constant_reaches_mujoco_s_world_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`run_incline(contact_time_constant=...)` (bench_slopes.py --contact-time-constant) sets every contact of the
    MuJoCo world it walks in to that time constant; DART has no such setting and refuses it."""
    from pfnav_harness.mujoco_world import MujocoWorld

    worlds: list[PhysicsEngine] = []

    def recording(*args: object, **kwargs: object) -> PhysicsEngine:
        world = make_engine(*args, **kwargs)  # type: ignore[arg-type]
        worlds.append(world)
        return world

    monkeypatch.setattr(cosim, "make_engine", recording)
    config = CoSimConfig(settle_time=1.0, estimator="groundTruth", max_duration=BRIEF)
    run_incline(10.0, "up", paths.fmu_path(), ROBOT, tmp_path, config=config, engine="mujoco", contact_time_constant=0.005)
    assert isinstance(worlds[0], MujocoWorld)
    np.testing.assert_array_equal(worlds[0].model.geom_solref[:, 0], 0.005)
    with pytest.raises(SimulationError, match="contact time constant"):
        run_incline(10.0, "up", paths.fmu_path(), ROBOT, tmp_path, config=config, engine="dart", contact_time_constant=0.005)
