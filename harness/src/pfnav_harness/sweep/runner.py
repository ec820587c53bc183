"""One sweep run on a worker: a row of factor values in, a result row out.

Workers only co-simulate: the scenario and its plan arrive ready-made from the driver (planned once
per terrain seed). Each run builds its own physics world (the spec's engine) and FMU instance and closes them at its end;
with one thread per worker process no two runs ever share an FMU (FMUs are not thread-safe). Any
exception in a run becomes a row with outcome "error" and the reason; the sweep goes on.

Forks: runs whose prefix (settle and stand-up) is the same form a group (`fork_group`); the
group's prefix runs once per sweep (`make_fork`, a task of its own) and its runs continue from the
saved state (`run_one` with the fork), each in a fresh world and FMU instance.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..body_sensors import BodySensorConfig
from ..cosim import CoSimConfig, CoSimulation, ForkPoint, prefix_config, prefix_signature, walk_start_step
from ..engine import DEFAULT_ENGINE
from ..fmu_runner import DEFAULT_ESTIMATOR
from ..metrics import RunMetrics, TraversabilityField, compute_metrics
from ..planner_client import Plan
from ..pushes import HEADING_DIRECTIONS, PushSchedule, horizontal_push
from ..robot import RobotDescription
from ..scenario import Scenario
from ..world import Payload

OUTCOMES = ("goal", "fell", "timeout", "error")


@dataclass(frozen=True)
class Artifacts:
    """Where a worker finds the FMU, the robot and pf-plan (resolved by the driver; workers need the same paths)."""

    fmu: Path
    robot: RobotDescription
    pf_plan: Path | None


@dataclass(frozen=True)
class Course:
    """What every run on one terrain shares: the exported scenario and the driver's plan on it."""

    terrain_seed: int
    scenario: Scenario
    plan: Plan


@dataclass(frozen=True)
class RunTask:
    run_id: int
    factors: dict[str, float | str]
    duration: float
    stand_time: float
    spec_hash: str
    estimator: str = DEFAULT_ESTIMATOR
    # Start from the group's fork when the run is long enough to have one (`forkable`).
    fork: bool = False
    engine: str = DEFAULT_ENGINE
    # Push magnitudes are multiplied by this (`push_scale_for`); the robot's mass, kg (NaN: not recorded).
    push_scale: float = 1.0
    robot_mass: float = math.nan


def push_scale_for(push_scaling: str, robot: RobotDescription) -> float:
    """What the spec's push magnitudes are multiplied by for `robot`: 1 ("force"), or its mass over
    our robot's ("mass": the same velocity change for every robot)."""
    if push_scaling == "force":
        return 1.0
    if push_scaling == "mass":
        from .. import paths

        return robot.mass / RobotDescription.load(paths.default_robot_config_path()).mass
    raise ValueError(f"unknown push scaling {push_scaling!r}")


@dataclass(frozen=True)
class PrefixFailure:
    """A fork prefix that could not be made: its runs become error rows with this reason."""

    reason: str


def push_schedule(factors: dict[str, float | str], scale: float = 1.0) -> PushSchedule | None:
    """The run's push (None without one), its magnitude times `scale`: a magnitude of 0 N means no push."""
    magnitude = float(factors["push_magnitude"]) * scale
    if magnitude <= 0.0:
        return None
    direction = factors["push_direction"]
    if isinstance(direction, str):
        push = horizontal_push(magnitude, HEADING_DIRECTIONS[direction], float(factors["push_time"]), float(factors["push_duration"]), heading_relative=True)
    else:
        push = horizontal_push(magnitude, float(direction), float(factors["push_time"]), float(factors["push_duration"]))
    return PushSchedule([push])


def run_config(task: RunTask) -> CoSimConfig:
    f = task.factors
    payload = Payload(float(f["payload_mass"]), (float(f["payload_offset_x"]), float(f["payload_offset_y"]), float(f["payload_offset_z"])))
    return CoSimConfig(
        comm_step=float(f["comm_step"]),
        stand_time=task.stand_time,
        max_duration=task.duration,
        friction=float(f["friction"]),
        pushes=push_schedule(f, task.push_scale),
        payload=None if payload == Payload() else payload,
        estimator=task.estimator,
        body_sensors=BodySensorConfig(seed=int(f["sensor_noise_seed"])),
        engine=task.engine,
    )


def forkable(task: RunTask) -> bool:
    """Whether the run starts from its group's fork: asked for, and the run lasts beyond the stand-up."""
    if not task.fork:
        return False
    config = run_config(task)
    return round(task.duration / config.physics_dt) > walk_start_step(config)


def fork_group(task: RunTask) -> str:
    """Runs with the same group share a prefix: the terrain and the prefix's configuration."""
    signature = prefix_signature(prefix_config(run_config(task)))
    return f"{int(task.factors['terrain_seed'])}-{hashlib.sha256(signature.encode()).hexdigest()[:12]}"


def start_run(course: Course, artifacts: Artifacts, config: CoSimConfig, cache_dir: Path) -> CoSimulation:
    """The run's starting point: a fresh world and FMU instance with the robot placed at the plan's start.

    A forked run is continued from its fork in it (`CoSimulation.run_from`), with the run's own
    payload and friction in the world.
    """
    return CoSimulation(course.scenario, course.plan, artifacts.fmu, artifacts.robot, cache_dir, config)


def make_fork(task: RunTask, course: Course, artifacts: Artifacts) -> ForkPoint | PrefixFailure:
    """The prefix of `task`'s group, simulated once (without payload, at the prefix friction); never raises."""
    try:
        with start_run(course, artifacts, prefix_config(run_config(task)), _worker_cache_dir()) as sim:
            return sim.run_prefix()
    except Exception as err:  # every run of the group reports it instead
        return PrefixFailure(f"fork prefix failed: {_reason(err)}")


# Per worker process: the terrain mesh cache and pf-plan's traversability field of each terrain
# (made on the first run of that terrain, reused by the following ones).
_cache_dir: Path | None = None
_fields: dict[tuple[str, int], TraversabilityField] = {}


def _worker_cache_dir() -> Path:
    global _cache_dir
    if _cache_dir is None:
        # Per process: two workers writing the same mesh file at once could read each other's half-written file.
        _cache_dir = Path(tempfile.mkdtemp(prefix=f"pfnav_sweep_{os.getpid()}_"))
    return _cache_dir


def _field(course: Course, artifacts: Artifacts) -> TraversabilityField:
    key = (course.scenario.name, course.terrain_seed)
    field = _fields.get(key)
    if field is None:
        field = _fields[key] = TraversabilityField(course.scenario.terrain, course.scenario.traversability, artifacts.pf_plan)
    return field


def outcome_of(metrics: RunMetrics) -> str:
    if metrics.fell:
        return "fell"
    return "goal" if metrics.goal_reached else "timeout"


def result_row(task: RunTask, course: Course, **results: Any) -> dict[str, Any]:
    """A result row: run id, every factor value (push direction split into degrees and frame), results."""
    f = task.factors
    direction = f["push_direction"]
    relative = isinstance(direction, str)
    row: dict[str, Any] = {
        "run_id": task.run_id,
        "spec_hash": task.spec_hash,
        "terrain_seed": course.terrain_seed,
        "push_magnitude": float(f["push_magnitude"]),
        "push_force": float(f["push_magnitude"]) * task.push_scale,
        "push_direction_deg": HEADING_DIRECTIONS[direction] if isinstance(direction, str) else float(direction),
        "push_heading_relative": relative,
        "push_time": float(f["push_time"]),
        "push_duration": float(f["push_duration"]),
        "payload_mass": float(f["payload_mass"]),
        "payload_offset_x": float(f["payload_offset_x"]),
        "payload_offset_y": float(f["payload_offset_y"]),
        "payload_offset_z": float(f["payload_offset_z"]),
        "friction": float(f["friction"]),
        "comm_step": float(f["comm_step"]),
        "sensor_noise_seed": int(f["sensor_noise_seed"]),
        "engine": task.engine,
        "robot_mass": task.robot_mass,
        "forked": forkable(task),
        "outcome": "error",
        "fall_time": math.nan,
        "rms_tracking_error": math.nan,
        "max_tracking_error": math.nan,
        "path_cost": math.nan,
        "path_length": math.nan,
        "simulated_time": 0.0,
        "stop_reason": "",
        "failure_reason": "",
        "wall_time": 0.0,
        "cpu_time": 0.0,
    }
    row.update(results)
    return row


def _reason(err: BaseException) -> str:
    where = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
    location = f" ({Path(where.filename).name}:{where.lineno})" if where else ""
    return f"{type(err).__name__}: {err}{location}"


def run_one(task: RunTask, course: Course, artifacts: Artifacts, fork: ForkPoint | PrefixFailure | None = None) -> dict[str, Any]:
    """Co-simulates one run (from `fork` when given) and returns its result row; never raises for a failed run."""
    start = time.perf_counter()
    cpu_start = time.process_time()
    if isinstance(fork, PrefixFailure):
        return result_row(task, course, forked=True, failure_reason=fork.reason)
    try:
        config = run_config(task)
        with start_run(course, artifacts, config, _worker_cache_dir()) as sim:
            result = sim.run() if fork is None else sim.run_from(fork)
        metrics = compute_metrics(
            result.log, course.scenario.terrain, course.scenario.goal, _field(course, artifacts), course.scenario.name, course.plan.method, config.fall
        )
        walk_start = float(result.log["walk_start"])
        return result_row(
            task,
            course,
            outcome=outcome_of(metrics),
            # On the walk clock, like the push times.
            fall_time=metrics.fall_time - walk_start if metrics.fall_time is not None else math.nan,
            rms_tracking_error=metrics.rms_error,
            max_tracking_error=metrics.max_error,
            path_cost=metrics.executed_cost,
            path_length=metrics.executed_length,
            simulated_time=float(np.round(result.timing.simulated, 6)),
            stop_reason=result.stop_reason,
            forked=fork is not None,
            wall_time=time.perf_counter() - start,
            cpu_time=time.process_time() - cpu_start,
        )
    except Exception as err:  # a failed run is a row, never the end of the sweep
        return result_row(
            task, course, forked=fork is not None, failure_reason=_reason(err), wall_time=time.perf_counter() - start, cpu_time=time.process_time() - cpu_start
        )
