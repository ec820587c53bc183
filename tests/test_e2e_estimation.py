"""The controller on its own state estimate (kalman mode), end to end, for a few simulated seconds.

Planner service over LCM (udpm, private network namespace) → reference → controller FMU whose
estimator reads the harness's simulated IMU, encoders and position fixes → DART. Asserts that the
robot stands up and walks without falling and that the estimate stays finite and near the truth.
The full-length measurements against the issue's targets are the demo's job (docs/estimation-harness.md).
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pfnav_harness import fmu_runner as fr
from pfnav_harness.body_sensors import BodySensorConfig
from pfnav_harness.cosim import CoSimConfig
from pfnav_harness.errors import SimulationError
from pfnav_harness.estimation_metrics import estimation_errors
from pfnav_harness.pipeline import SimOutcome, simulate
from pfnav_harness.planner_client import Plan
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario

SHORT_SECONDS = 5.0
STAND_SECONDS = 1.5


@pytest.fixture
def short_kalman_walk(
    plan_for: Callable[[str, str], Plan],
    paper_scenarios: dict[str, Scenario],
    fmu_file: Path,
    robot: RobotDescription,
    tmp_path: Path,
) -> Callable[[BodySensorConfig], SimOutcome]:
    """A few seconds of mountain_pass's A* plan in kalman mode with the given body sensors."""

    def walk(sensors: BodySensorConfig) -> SimOutcome:
        config = CoSimConfig(
            stand_time=STAND_SECONDS,
            max_duration=SHORT_SECONDS,
            estimator="kalman",
            body_sensors=sensors,
        )
        return simulate(
            paper_scenarios["mountain_pass"],
            plan_for("mountain_pass", "astar"),
            fmu_file,
            robot,
            tmp_path,
            config,
            show_progress=False,
        )

    return walk


@pytest.mark.parametrize("fix_rate", [0.0, 2.0])
def test_short_kalman_run(
    fix_rate: float,
    short_kalman_walk: Callable[[BodySensorConfig], SimOutcome],
    fmu_file: Path,
) -> None:
    outcome = short_kalman_walk(
        BodySensorConfig(seed=1, fix_rate=fix_rate, fix_noise=0.02)
    )
    log = outcome.result.log
    m = outcome.metrics
    assert outcome.result.stop_reason == "completed", outcome.result.stop_reason
    assert not m.fell, m.fall_reason
    assert np.any(log["fsm"] == fr.read_contract(fmu_file).fsm.Locomotion)
    for key in ("est_pos", "est_vel", "est_rpy"):
        assert np.all(np.isfinite(log[key])), key
    errors = estimation_errors(log)
    walking = log["t"] >= STAND_SECONDS
    horizontal = np.hypot(errors["pos"][walking, 0], errors["pos"][walking, 1])
    assert horizontal.max() < 0.10
    assert np.max(np.abs(errors["yaw"][walking])) < math.radians(5.0)
    e = outcome.estimation
    assert e is not None
    assert e.velocity_rms < 0.15
    # The robot did walk: the estimate was judged over a real path.
    assert e.path_length > 0.5
    assert e.fixes == (
        0 if fix_rate == 0.0 else pytest.approx(SHORT_SECONDS * fix_rate, abs=1)
    )


def test_the_estimator_is_told_the_fix_noise(
    short_kalman_walk: Callable[[BodySensorConfig], SimOutcome],
) -> None:
    # GNSS-class fixes, 0.5 m per axis at 2 Hz: the estimate weighs them as such, so after a few
    # seconds its σ is still the leg odometry's (≈ 0.04 m), not that of fixes believed to 2 cm
    # (≈ 0.014 m), and it does not jump with each fix.
    outcome = short_kalman_walk(BodySensorConfig(seed=1, fix_rate=2.0, fix_noise=0.5))
    assert not outcome.metrics.fell, outcome.metrics.fall_reason
    e = outcome.estimation
    assert e is not None and e.fixes >= 6
    assert e.position_sigma_final > 0.03, e.position_sigma_final
    assert e.position_error_final <= 2.0 * e.position_sigma_final


def test_kalman_mode_is_refused_for_an_fmu_without_the_estimator(
    fmu_model_description: Any, fmu_file: Path
) -> None:
    contract = fr.FmuContract(fmu_model_description, "bundled FMU")
    assert contract.has_estimation, contract.estimation_problems
    assert set(contract.estimator_codes) >= set(fr.ESTIMATOR_MODES)
    md = copy.copy(fmu_model_description)
    md.modelVariables = [
        v
        for v in fmu_model_description.modelVariables
        if v.name not in ("imu.gyro[1]", "est.status")
    ]
    old = fr.FmuContract(md, "old FMU")
    assert not old.has_estimation
    with pytest.raises(
        SimulationError,
        match=re.escape(
            "old FMU has no state estimator (no variable imu.gyro[1]; no variable est.status)"
        ),
    ):
        old.require_estimation()
    with fr.ControllerFmu(fmu_file) as fmu:
        io = fmu.enable_estimation("kalman")
        assert io.gyro.shape == (3,) and io.est_status.shape == (1,)
        with pytest.raises(SimulationError, match="unknown estimator mode"):
            fmu.enable_estimation("ekf")
