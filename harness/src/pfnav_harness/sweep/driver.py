"""The driver side of a sweep: terrains and plans once per terrain seed, then the runs on Dask.

Planning needs the planner service over LCM (`plan_scenario` starts one, as the demo does), so it
stays in the driver; the plans are stored with the rows and shipped to the workers, which only
co-simulate. A resumed sweep reuses the stored plans and needs no planner at all.
"""

from __future__ import annotations

import math
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from ..pipeline import export_scenario
from ..planner_client import METHODS, Plan
from ..robot import RobotDescription
from ..scenario import Scenario
from .runner import Artifacts, Course, RunTask, fork_group, forkable, make_fork, push_scale_for, result_row, run_one
from .spec import SpecError, SweepSpec
from .store import SweepStore

# Plans one scenario (the LCM planner service in the CLI).
Planner = Callable[[Scenario, str], Plan]
# Rows go to Parquet in batches of this many, or at least this often (seconds).
BATCH_ROWS = 8
BATCH_SECONDS = 30.0


@dataclass
class SweepSummary:
    total: int
    skipped: int
    ran: int
    errors: int
    wall_seconds: float

    @property
    def runs_per_minute(self) -> float:
        return 60.0 * self.ran / self.wall_seconds if self.wall_seconds > 0 else 0.0


def prepare_courses(spec: SweepSpec, store: SweepStore, pf_plan: Path, planner: Planner | None, work_dir: Path) -> dict[int, Course]:
    """Exports each terrain seed's scenario and plans it once (or loads the stored plan).

    Keys: the terrain seed as the runs name it (-1: the scenario's own seed).
    """
    if spec.method not in METHODS:
        raise SpecError(f"unknown planner method '{spec.method}' (known: {', '.join(METHODS)})")
    courses: dict[int, Course] = {}
    for seed in spec.terrain_seeds():
        folder = work_dir / f"scenario_{'default' if seed is None else seed}"
        scenario = export_scenario(pf_plan, spec.scenario, folder, seed=seed)
        resolved = seed if seed is not None else scenario.seed
        if resolved is None:
            raise SpecError(f"scenario '{spec.scenario}' was exported without its seed; give terrain_seed explicitly")
        plan = store.load_plan(spec.scenario, resolved, spec.method)
        if plan is None:
            if planner is None:
                raise SpecError(f"no stored plan for '{spec.scenario}' terrain seed {resolved} and no planner to make one")
            plan = planner(scenario, spec.method)
            store.save_plan(spec.scenario, resolved, plan)
        courses[-1 if seed is None else seed] = Course(int(resolved), scenario, plan)
    return courses


def run_tasks(spec: SweepSpec, done: set[int], robot: RobotDescription | None = None) -> list[RunTask]:
    """The runs of `spec` not in `done`, for `robot` (its mass scales the pushes when the spec says so)."""
    push_scale = push_scale_for(spec.push_scaling, robot) if robot is not None else 1.0
    mass = robot.mass if robot is not None else math.nan
    return [
        RunTask(run_id, spec.run_factors(run_id), spec.duration, spec.stand_time, spec.hash, spec.estimator, spec.fork, spec.engine, push_scale, mass)
        for run_id in range(spec.runs)
        if run_id not in done
    ]


def run_sweep(
    spec: SweepSpec,
    store: SweepStore,
    courses: dict[int, Course],
    artifacts: Artifacts,
    client: Any,
    show_progress: bool = True,
    batch_rows: int = BATCH_ROWS,
) -> SweepSummary:
    """Runs every run of `spec` not yet in `store` on the Dask `client`, appending rows as runs finish."""
    from distributed import as_completed

    begin = time.perf_counter()
    tasks = run_tasks(spec, store.done_ids(), artifacts.robot)
    skipped = spec.runs - len(tasks)
    if not tasks:
        return SweepSummary(spec.runs, skipped, 0, 0, 0.0)
    # Every worker gets each course once, instead of once per task.
    shipped = {seed: client.scatter(course, broadcast=True, hash=False) for seed, course in courses.items()}
    futures = {}
    # Keys unique per call: a resumed sweep on the same client must run again, not find an old result.
    token = uuid.uuid4().hex[:8]
    # One prefix per group and sweep, a task of its own: its runs wait for it, Dask ships the fork
    # (a few MB) to each worker that runs one of them, once.
    forks: dict[str, Any] = {}
    for task in tasks:
        seed = int(task.factors["terrain_seed"])
        fork = None
        if forkable(task):
            group = fork_group(task)
            if group not in forks:
                forks[group] = client.submit(make_fork, task, shipped[seed], artifacts, key=f"pfnav-fork-{spec.hash}-{group}-{token}", pure=False)
            fork = forks[group]
        future = client.submit(run_one, task, shipped[seed], artifacts, fork, key=f"pfnav-run-{spec.hash}-{task.run_id}-{token}", pure=False)
        futures[future] = task
    pending: list[dict[str, Any]] = []
    last_flush = time.perf_counter()
    errors = ran = fell = 0
    bar = tqdm(total=len(tasks), desc=f"sweep {spec.scenario}", unit="run", disable=not show_progress, initial=0)
    try:
        for future in as_completed(futures):
            task = futures.pop(future)
            try:
                row = future.result()
            except Exception as err:  # the worker died (e.g. the FMU crashed the process): the run is a row all the same
                row = result_row(task, courses[int(task.factors["terrain_seed"])], failure_reason=f"worker lost: {type(err).__name__}: {err}")
            errors += row["outcome"] == "error"
            fell += row["outcome"] == "fell"
            ran += 1
            pending.append(row)
            bar.update(1)
            bar.set_postfix(fell=fell, errors=errors, refresh=False)
            if len(pending) >= batch_rows or time.perf_counter() - last_flush >= BATCH_SECONDS:
                store.append(pending)
                pending = []
                last_flush = time.perf_counter()
    finally:
        # Also on Ctrl-C: what finished is kept, a re-run continues from there.
        store.append(pending)
        bar.close()
        for future in [*futures, *forks.values()]:
            future.cancel()
    return SweepSummary(spec.runs, skipped, ran, errors, time.perf_counter() - begin)
