"""The end-to-end steps shared by the CLI and the tests: scenario → plans → co-simulation → metrics."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .cosim import CoSimConfig, CoSimulation, RunResult, save_log
from .errors import ScenarioError
from .estimation_metrics import EstimationMetrics, compute_estimation_metrics, has_estimate
from .feedback_field import FeedbackField
from .metrics import OnlineMetrics, RunMetrics, TraversabilityField, compute_metrics, compute_online_metrics
from .online import OnlineConfig, OnlineNavigator, check_first_answer
from .planner_client import Plan, PlannerClient, StartPose
from .report import RunRecord
from .robot import RobotDescription
from .scenario import Scenario, load_scenario
from .state_log import write_state_log
from .tools import run_tool


def export_scenario(pf_plan: Path, name: str, out_dir: Path, timeout: float = 120.0, seed: int | None = None) -> Scenario:
    """Runs `pf-plan scenario export NAME --out DIR [--seed SEED]` and loads the result (seed None: the scenario's own)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    seed_args = [] if seed is None else ["--seed", str(seed)]
    run_tool(
        pf_plan,
        ["scenario", "export", name, "--out", str(out_dir), *seed_args],
        what=f"scenario '{name}' could not be exported by pf-plan",
        failure=ScenarioError,
        timeout=timeout,
    )
    json_path = out_dir / f"{name}.json"
    if not json_path.is_file():
        raise ScenarioError(f"pf-plan exported scenario '{name}' but {json_path} is missing")
    return load_scenario(json_path)


@dataclass
class SimOutcome:
    result: RunResult
    metrics: RunMetrics
    wall_seconds: float
    online: OnlineMetrics | None = None
    estimation: EstimationMetrics | None = None

    def record(self, log_file: str | None = None) -> RunRecord:
        return RunRecord(
            metrics=self.metrics,
            log=self.result.log,
            wall_seconds=self.wall_seconds,
            timing_per_sim_second=self.result.timing.per_sim_second(),
            stop_reason=self.result.stop_reason,
            log_file=log_file,
            online=self.online,
            estimation=self.estimation,
        )


def run_label(method: str, config: CoSimConfig, online: bool) -> str:
    """How a run is named in logs and the report: the method, plus the way its plan was followed."""
    if online:
        return f"{method}-online"
    return f"{method}-feedback" if config.follow == "feedback" else method


def simulate(
    scenario: Scenario,
    plan: Plan,
    fmu: Path,
    robot: RobotDescription,
    cache_dir: Path,
    config: CoSimConfig,
    log_path: Path | None = None,
    show_progress: bool = True,
    field: TraversabilityField | None = None,
    lcm_log_path: Path | None = None,
    feedback_field: FeedbackField | None = None,
    online: OnlineNavigator | None = None,
) -> SimOutcome:
    """Co-simulates one plan and computes its metrics (optionally saving the npz log)."""
    start = time.perf_counter()
    label = run_label(plan.method, config, online is not None)
    with CoSimulation(scenario, plan, fmu, robot, cache_dir, config, field=feedback_field, online=online) as sim:
        total = sim.duration()
        desc = f"{scenario.name}/{label}"
        with tqdm(
            total=round(total, 1),
            desc=desc,
            unit="sim s",
            disable=not show_progress,
            leave=True,
            bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} sim s [{elapsed}<{remaining}]",
        ) as bar:
            last = [0.0]

            def progress(t: float) -> None:
                bar.update(round(t - last[0], 3))
                last[0] = t

            result = sim.run(progress)
    wall = time.perf_counter() - start
    field = field or TraversabilityField(scenario.terrain, scenario.traversability)
    metrics = compute_metrics(
        result.log,
        scenario.terrain,
        scenario.goal,
        field,
        scenario.name,
        label,
        config.fall,
        planner_cost=plan.metrics.get("cost"),
        planner_solve_time=plan.metrics.get("solve_time"),
    )
    estimation = compute_estimation_metrics(result.log, until=metrics.fall_time) if has_estimate(result.log) else None
    # The planner's cost model for this run (the scenario's, with the demo's overrides), so that a
    # replay can plan the same map again (`replay.density`).
    result.log["traversability"] = np.array(json.dumps(scenario.traversability, sort_keys=True))
    if log_path is not None:
        save_log(result, log_path)
    if lcm_log_path is not None:
        write_state_log(result.log, lcm_log_path)
    return SimOutcome(result, metrics, wall, estimation=estimation)


def simulate_online(
    client: PlannerClient,
    scenario: Scenario,
    fmu: Path,
    robot: RobotDescription,
    cache_dir: Path,
    config: CoSimConfig,
    online_config: OnlineConfig,
    plan_timeout: float,
    retries: int,
    log_path: Path | None = None,
    show_progress: bool = True,
    field: TraversabilityField | None = None,
) -> SimOutcome:
    """Online navigation of one scenario: sense, replan, follow; compared with the full-knowledge plan."""
    method = online_config.method
    field = field or TraversabilityField(scenario.terrain, scenario.traversability)
    # The full-knowledge optimum, for ∫p ds of the walked path against it.
    seq = client.publish_map(scenario.terrain)
    start = StartPose(scenario.start[0], scenario.start[1], scenario.start_yaw)
    full = client.request_answer(
        start, scenario.goal, method, seq, online_config.options, timeout=plan_timeout, retries=retries, context=f"'{scenario.name}' (full knowledge)"
    )
    full_plan = full.plan_or_raise(method)
    navigator = OnlineNavigator(client, scenario, online_config)
    trunk_height = config.body_height if config.body_height > 0.0 else robot.stand_height
    first = navigator.start(start.x, start.y, start.yaw, timeout=plan_timeout, retries=retries, trunk_height=trunk_height)
    check_first_answer(first, method)
    assert first.plan is not None
    outcome = simulate(scenario, first.plan, fmu, robot, cache_dir, config, log_path, show_progress, field, feedback_field=first.field, online=navigator)
    outcome.online = compute_online_metrics(outcome.result.log, navigator.replans, field, full_plan, online_config)
    return outcome
