"""Sweep specs: parsing, refusals with a clear reason, and per-run factor draws that depend on (seed, run id) only."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pfnav_harness import paths
from pfnav_harness.fmu_runner import DEFAULT_ESTIMATOR
from pfnav_harness.sweep.driver import run_tasks
from pfnav_harness.sweep.runner import fork_group, forkable, run_config
from pfnav_harness.sweep.spec import FACTORS, SpecError, load_spec, parse_spec
from pfnav_harness.sweep.store import StoreError, SweepStore
from pfnav_harness.world import Payload

BASE: dict[str, Any] = {"scenario": "mountain_pass", "duration": 4.0, "seed": 3, "runs": 20}


def spec_with(**changes: Any) -> dict[str, Any]:
    return {**BASE, **changes}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (spec_with(factors={"gravity": 9.81}), "unknown factor 'gravity'"),
        (spec_with(factors={"friction": {"range": [0.9, 0.9]}}), "empty range [0.9, 0.9]"),
        (spec_with(factors={"friction": {"range": [1.0, 0.5]}}), "empty range"),
        (spec_with(factors={"friction": {"values": []}}), "non-empty list"),
        (spec_with(factors={"friction": {"range": [0.0, 1.0]}}), "values must be > 0"),
        (spec_with(factors={"push_direction": {"values": ["up"]}}), "unknown value 'up'"),
        (spec_with(factors={"push_magnitude": {"range": [0, 50], "values": [1]}}), "exactly one of"),
        (spec_with(factors={"terrain_seed": {"values": [1.5]}}), "must be integers"),
        (spec_with(estimator="groundTruth", factors={"sensor_noise_seed": {"values": [1, 2]}}), 'only acts with `estimator = "kalman"`'),
        (spec_with(estimator="particle"), "`estimator` must be one of groundTruth, kalman"),
        (spec_with(engine="bullet"), "`engine` (physics engine) must be one of dart, mujoco, got 'bullet'"),
        (spec_with(runs=-3), "`runs` must be an integer >= 1, got -3"),
        (spec_with(runs=0), "`runs` must be an integer >= 1"),
        (spec_with(duration=0), "`duration`"),
        (spec_with(sampling="sobol"), "`sampling` must be one of random, grid"),
        (spec_with(colour="red"), "unknown key(s) colour"),
        (spec_with(fork="yes"), "`fork` must be true or false"),
        ({"scenario": "pits", "duration": 2.0}, "missing `seed`"),
        (spec_with(sampling="grid", factors={"friction": {"range": [0.5, 1.0]}}), "grid sampling needs `steps`"),
        (spec_with(sampling="grid", runs=5, factors={"friction": {"values": [0.5, 1.0]}}), "grid sampling has 2 combinations"),
    ],
)
def test_bad_specs_are_refused_with_the_reason(data: dict[str, Any], message: str) -> None:
    with pytest.raises(SpecError) as err:
        parse_spec(data)
    assert message in str(err.value)


def test_bad_toml_and_missing_file(tmp_path: Path) -> None:
    broken = tmp_path / "broken.toml"
    broken.write_text("scenario = \n")
    with pytest.raises(SpecError, match="not valid TOML"):
        load_spec(broken)
    with pytest.raises(SpecError, match="cannot read the sweep spec"):
        load_spec(tmp_path / "absent.toml")


def test_random_draws_depend_on_seed_and_run_id_only() -> None:
    factors = {"push_magnitude": {"range": [0.0, 100.0]}, "push_direction": {"values": ["left", "right", 45.0]}, "terrain_seed": {"range": [1, 4]}}
    spec = parse_spec(spec_with(factors=factors))
    rows = [spec.run_factors(i) for i in range(spec.runs)]
    # Reproducible, in any order.
    assert [spec.run_factors(i) for i in reversed(range(spec.runs))] == rows[::-1]
    assert all(0.0 <= r["push_magnitude"] <= 100.0 for r in rows)
    assert {r["push_direction"] for r in rows} == {"left", "right", 45.0}
    assert {r["terrain_seed"] for r in rows} <= {1, 2, 3, 4} and all(isinstance(r["terrain_seed"], int) for r in rows)
    assert len({r["push_magnitude"] for r in rows}) == spec.runs
    # Factors left out keep their defaults.
    assert all(r["friction"] == FACTORS["friction"].default for r in rows)
    # Adding a factor does not change the draws of the others; another seed does.
    more = parse_spec(spec_with(factors={**factors, "friction": {"range": [0.5, 1.0]}}))
    assert [more.run_factors(i)["push_magnitude"] for i in range(spec.runs)] == [r["push_magnitude"] for r in rows]
    reseeded = parse_spec(spec_with(seed=4, factors=factors))
    assert reseeded.run_factors(0)["push_magnitude"] != rows[0]["push_magnitude"]
    assert spec.terrain_seeds() == list(dict.fromkeys(r["terrain_seed"] for r in rows))
    with pytest.raises(SpecError, match="outside"):
        spec.run_factors(spec.runs)


def test_grid_takes_every_combination_once() -> None:
    spec = parse_spec(
        spec_with(runs=None, sampling="grid", factors={"friction": {"range": [0.5, 1.0], "steps": 3}, "push_direction": {"values": ["left", "right"]}})
    )
    assert spec.runs == 6
    combos = [(r["push_direction"], r["friction"]) for r in (spec.run_factors(i) for i in range(6))]
    assert combos == [(d, f) for d in ("left", "right") for f in (0.5, 0.75, 1.0)]


def test_hash_covers_content_not_layout(tmp_path: Path) -> None:
    a = tmp_path / "a.toml"
    b = tmp_path / "b.toml"
    a.write_text('scenario = "pits"\nduration = 3\nseed = 1\nruns = 2\n[factors]\nfriction = 0.6\npush_magnitude = { range = [1, 2] }\n')
    b.write_text('# the same sweep\nruns = 2\nseed = 1\nscenario = "pits"\nduration = 3.0\n[factors]\npush_magnitude = {range=[1,2]}\nfriction = 0.6\n')
    assert load_spec(a).hash == load_spec(b).hash
    c = tmp_path / "c.toml"
    c.write_text(a.read_text().replace("runs = 2", "runs = 3"))
    assert load_spec(c).hash != load_spec(a).hash


def test_the_repository_specs_are_valid() -> None:
    specs = sorted((paths.repo_root() / "sweeps").glob("*.toml"))
    assert len(specs) >= 2
    loaded = {p.stem: load_spec(p) for p in specs}
    assert loaded["tiny"].runs == 4
    assert max(s.runs for s in loaded.values()) >= 300


def test_sensor_noise_seed_reaches_the_run_config_with_the_estimator() -> None:
    spec = parse_spec(spec_with(estimator="kalman", factors={"sensor_noise_seed": {"range": [0, 1000]}}))
    task = run_tasks(spec, set())[3]
    config = run_config(task)
    assert config.estimator == "kalman"
    seed = config.body_sensors.seed
    assert seed == task.factors["sensor_noise_seed"]
    assert isinstance(seed, int) and 0 <= seed <= 1000
    assert {run_config(t).body_sensors.seed for t in run_tasks(spec, set())[:4]} != {seed}, "each run draws its own seed"
    assert run_config(run_tasks(parse_spec(BASE), set())[0]).estimator == DEFAULT_ESTIMATOR


def test_run_config_carries_push_payload_and_friction() -> None:
    factors = {"push_magnitude": 50.0, "push_direction": "right", "push_time": 3.0, "payload_mass": 0.1, "payload_offset_x": 0.02, "friction": 0.6}
    config = run_config(run_tasks(parse_spec(spec_with(runs=1, factors=factors)), set())[0])
    assert config.friction == 0.6 and config.max_duration == 4.0
    assert config.payload == Payload(0.1, (0.02, 0.0, 0.0))
    assert config.pushes is not None
    (push,) = config.pushes
    assert push.heading_relative and push.start == 3.0 and push.duration == 0.2
    assert push.force == pytest.approx((0.0, -50.0, 0.0))
    # No push, no payload by default.
    plain = run_config(run_tasks(parse_spec(BASE), set())[0])
    assert plain.pushes is None and plain.payload is None


def test_forks_are_on_by_default_and_group_runs_by_their_prefix() -> None:
    data = spec_with(
        estimator="kalman",
        factors={
            "push_magnitude": {"range": [0, 100]},
            "payload_mass": {"range": [-0.2, 0.2]},
            "friction": {"range": [0.5, 1.0]},
            "comm_step": {"values": [0.001, 0.002]},
            "sensor_noise_seed": {"values": [1, 2]},
        },
    )
    spec = parse_spec(data)
    assert spec.fork and spec.as_json()["fork"] is True
    unforked = parse_spec({**data, "fork": False})
    assert unforked.hash != spec.hash
    # An unforked spec hashes as before forks existed: stores written then resume with `fork = false`.
    assert "fork" not in unforked.as_json()
    tasks = run_tasks(spec, set())
    assert all(forkable(t) for t in tasks) and not any(forkable(t) for t in run_tasks(unforked, set()))
    # Push, payload and friction act after the fork; the communication step and the sensor seed shape the prefix.
    groups: dict[str, set[tuple[object, object]]] = {}
    for task in tasks:
        groups.setdefault(fork_group(task), set()).add((task.factors["comm_step"], task.factors["sensor_noise_seed"]))
    distinct = {(t.factors["comm_step"], t.factors["sensor_noise_seed"]) for t in tasks}
    assert len(distinct) >= 3 and len(groups) == len(distinct) and all(len(keys) == 1 for keys in groups.values())
    # A run that ends before the walk starts has nothing to fork.
    assert not any(forkable(t) for t in run_tasks(parse_spec({**data, "duration": 1.5}), set()))


def test_a_store_of_unforked_runs_is_not_continued_with_forks(tmp_path: Path) -> None:
    spec = parse_spec(spec_with())
    SweepStore.create(tmp_path / "store", dataclasses.replace(spec, fork=False))
    with pytest.raises(StoreError, match="resume it with `fork = false`"):
        SweepStore.create(tmp_path / "store", spec)
    assert SweepStore.create(tmp_path / "store", dataclasses.replace(spec, fork=False)).done_ids() == set()


def test_the_estimator_can_be_chosen_at_load_time_and_is_checked_like_the_spec_s_own(tmp_path: Path) -> None:
    spec_file = tmp_path / "pushes.toml"
    spec_file.write_text('scenario = "mountain_pass"\nduration = 4.0\nseed = 3\nruns = 20\nestimator = "kalman"\n')
    own = load_spec(spec_file)
    truth = load_spec(spec_file, "groundTruth")
    assert (own.estimator, truth.estimator) == ("kalman", "groundTruth")
    assert dataclasses.replace(truth, estimator="kalman") == own
    assert truth.hash != own.hash
    spec_file.write_text(spec_file.read_text() + "[factors]\nsensor_noise_seed = { values = [1, 2] }\n")
    with pytest.raises(SpecError, match='only acts with `estimator = "kalman"`'):
        load_spec(spec_file, "groundTruth")
    with pytest.raises(SpecError, match="`estimator` must be one of"):
        load_spec(spec_file, "particle")


def test_the_engine_is_part_of_the_spec_and_a_dart_spec_keeps_its_hash(tmp_path: Path) -> None:
    """`engine` defaults to DART; naming DART changes nothing (stores written before the key existed resume),
    MuJoCo is another spec; `--engine` at load time replaces the spec's own."""
    plain = parse_spec(BASE)
    assert plain.engine == "dart" and "engine" not in plain.as_json()
    assert parse_spec(spec_with(engine="dart")).hash == plain.hash
    mujoco = parse_spec(spec_with(engine="mujoco"))
    assert mujoco.engine == "mujoco" and mujoco.as_json()["engine"] == "mujoco" and mujoco.hash != plain.hash
    assert {run_config(t).engine for t in run_tasks(mujoco, set())} == {"mujoco"}
    assert {run_config(t).engine for t in run_tasks(plain, set())} == {"dart"}
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text('scenario = "mountain_pass"\nduration = 4.0\nseed = 3\nruns = 20\nengine = "mujoco"\n')
    assert load_spec(spec_file).hash == mujoco.hash
    assert load_spec(spec_file, engine="dart").hash == plain.hash
    with pytest.raises(SpecError, match="`engine`"):
        load_spec(spec_file, engine="bullet")


def test_rows_stored_before_the_engine_column_read_back_without_an_engine(tmp_path: Path) -> None:
    """A store written before rows recorded their engine still reads: those rows (DART runs) have none."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pfnav_harness.sweep.runner import Course, result_row
    from pfnav_harness.sweep.store import ROW_SCHEMA

    spec = parse_spec(spec_with(runs=2))
    store = SweepStore.create(tmp_path / "store", spec)
    course = Course(0, None, None)  # type: ignore[arg-type]
    old, new = (result_row(task, course) for task in run_tasks(spec, set()))
    old_schema = pa.schema([f for f in ROW_SCHEMA if f.name != "engine"])
    del old["engine"]
    pq.write_table(pa.Table.from_pylist([old], schema=old_schema), store.rows_dir / "part-00000000-0001-old.parquet")
    store.append([new])
    assert store.table()["engine"].to_pylist() == [None, "dart"]


def test_the_robot_and_the_push_scaling_are_part_of_the_spec(tmp_path: Path) -> None:
    """Without `robot` and `push_scaling` a spec keeps its hash; with them it is another spec, and
    `--robot` at load time replaces the spec's robot."""
    plain = parse_spec(BASE)
    assert plain.robot is None and plain.push_scaling == "force" and plain.hash == parse_spec(spec_with(push_scaling="force")).hash
    go1 = parse_spec(spec_with(robot="robot/third_party/go1.toml", push_scaling="mass"))
    assert go1.as_json()["robot"] == "robot/third_party/go1.toml" and go1.as_json()["push_scaling"] == "mass"
    assert len({plain.hash, go1.hash, parse_spec(spec_with(robot="robot/third_party/go1.toml")).hash}) == 3
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text('scenario = "mountain_pass"\nduration = 4.0\nseed = 3\nruns = 20\npush_scaling = "mass"\n')
    assert load_spec(spec_file, robot="robot/third_party/go1.toml").hash == go1.hash
    with pytest.raises(SpecError, match="`push_scaling` must be one of force, mass"):
        parse_spec(spec_with(push_scaling="weight"))
    with pytest.raises(SpecError, match="`robot` must be the path of a robot config"):
        parse_spec(spec_with(robot=3))


def test_mass_scaling_pushes_every_robot_to_the_same_velocity_change() -> None:
    """With `push_scaling = "mass"` the force applied is the magnitude times the robot's mass over
    ours (the same impulse per kg); with "force" it is the magnitude; rows record both and the mass."""
    from pfnav_harness import paths
    from pfnav_harness.robot import RobotDescription
    from pfnav_harness.sweep.runner import Course, result_row

    ours = RobotDescription.load(paths.default_robot_config_path())
    go1 = RobotDescription.load(paths.repo_root() / "robot" / "third_party" / "go1.toml")
    factors = {"push_magnitude": {"values": [100.0]}, "push_direction": "left", "push_time": 3.0}
    scaled = parse_spec(spec_with(runs=1, factors=factors, push_scaling="mass"))
    forces = {}
    for robot in (ours, go1):
        (task,) = run_tasks(scaled, set(), robot)
        (push,) = run_config(task).pushes.pushes  # type: ignore[union-attr]
        forces[robot.mass] = float(np.hypot(*push.force[:2]))
        row = result_row(task, Course(0, None, None))  # type: ignore[arg-type]
        assert row["push_magnitude"] == 100.0 and row["push_force"] == pytest.approx(forces[robot.mass]) and row["robot_mass"] == robot.mass
    assert forces[ours.mass] == pytest.approx(100.0)
    assert forces[go1.mass] / go1.mass == pytest.approx(100.0 / ours.mass) and go1.mass != ours.mass
    (unscaled,) = run_tasks(parse_spec(spec_with(runs=1, factors=factors)), set(), go1)
    assert float(np.hypot(*run_config(unscaled).pushes.pushes[0].force[:2])) == pytest.approx(100.0)  # type: ignore[union-attr]


def test_the_first_runs_of_a_spec_are_a_spec_of_fewer_runs(tmp_path: Path) -> None:
    """`--runs N` keeps the draws: run k of the N-run spec is run k of the full one."""
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text('scenario = "mountain_pass"\nduration = 4.0\nseed = 3\nruns = 20\n[factors]\nfriction = { range = [0.5, 1.0] }\n')
    full, first = load_spec(spec_file), load_spec(spec_file, runs=5)
    assert first.runs == 5 and first.hash != full.hash
    assert [first.run_factors(k) for k in range(5)] == [full.run_factors(k) for k in range(5)]
    with pytest.raises(SpecError, match="`runs` must be an integer >= 1"):
        load_spec(spec_file, runs=0)
