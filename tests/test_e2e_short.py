"""CI version of the demo: a few simulated seconds of each scenario with the P-F plan.

Planner service over LCM (udpm, private network namespace) → reference → controller FMU (fmpy) →
DART. Asserts that the robot stands up, starts walking along the plan, does not fall, and tracks
with bounded error; also with 5 ms communication steps, where the controller's joint feedback
acts on a state held for 5 physics steps. The full-length runs are the demo's job (scripts/demo.sh).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from pfnav_harness.cosim import CoSimConfig
from pfnav_harness.fmu_runner import read_contract
from pfnav_harness.pipeline import simulate
from pfnav_harness.planner_client import Plan
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario, paper_scenario_names

SHORT_SECONDS = 6.0
STAND_SECONDS = 1.5


@pytest.mark.parametrize(("name", "comm_step"), [*((n, 0.001) for n in paper_scenario_names()), ("mountain_pass", 0.005)])
def test_short_pf_run(
    name: str,
    comm_step: float,
    plan_for: Callable[[str, str], Plan],
    paper_scenarios: dict[str, Scenario],
    fmu_file: Path,
    robot: RobotDescription,
    tmp_path: Path,
) -> None:
    scenario = paper_scenarios[name]
    plan = plan_for(name, "pf")
    config = CoSimConfig(comm_step=comm_step, stand_time=STAND_SECONDS, max_duration=SHORT_SECONDS, estimator="groundTruth")
    outcome = simulate(
        scenario,
        plan,
        fmu_file,
        robot,
        tmp_path,
        config,
        tmp_path / "run.npz",
        show_progress=False,
    )
    m = outcome.metrics
    log = outcome.result.log
    assert outcome.result.stop_reason == "completed", outcome.result.stop_reason
    assert not m.fell, m.fall_reason
    assert m.duration == pytest.approx(SHORT_SECONDS, abs=0.01)
    # The controller reached locomotion and the robot walked along the plan.
    assert np.any(log["fsm"] == read_contract(fmu_file).fsm.Locomotion)
    walked = np.hypot(*(log["base_pos"][-1, :2] - log["base_pos"][0, :2]))
    expected = float(np.hypot(*(log["ref"][-1, :2] - log["ref"][0, :2])))
    assert walked > 0.5 * expected
    assert m.rms_error <= 0.15
    assert m.max_error <= 0.30
    assert (tmp_path / "run.npz").stat().st_size > 10_000
