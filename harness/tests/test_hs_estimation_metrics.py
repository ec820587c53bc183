"""Estimation metrics on a synthetic log whose errors are known, the report's section, and the estimator in the co-simulation loop."""

from __future__ import annotations

import math
from enum import IntEnum
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from test_hs_cosim import PdStandIn, standing_plan

from pfnav_harness import fmu_runner as fr
from pfnav_harness import paths
from pfnav_harness.body_sensors import AS5047P, BodySensorConfig
from pfnav_harness.cli import _config, build_parser
from pfnav_harness.cosim import CoSimConfig, CoSimulation
from pfnav_harness.errors import HarnessError, SimulationError
from pfnav_harness.estimation_metrics import compute_estimation_metrics, estimation_section, has_estimate
from pfnav_harness.metrics import RunMetrics
from pfnav_harness.report import RunRecord
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())

WALK_START = 2.0


def _log() -> dict[str, np.ndarray]:
    """Truth walks along +x at 0.5 m/s after 2 s; the estimate drifts sideways at 1 cm/s and in yaw."""
    t = np.arange(0.0, 10.0 + 1e-9, 0.01)
    walked = np.clip(t - WALK_START, 0.0, None)
    n = len(t)
    pos = np.zeros((n, 3))
    pos[:, 0] = 1.0 + 0.5 * walked
    pos[:, 2] = 0.3
    vel = np.zeros((n, 3))
    vel[t >= WALK_START, 0] = 0.5
    yaw = np.full(n, 0.4)
    quat = np.stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)], axis=1)
    est_pos = pos.copy()
    est_pos[:, 0] += 0.1  # an offset already there when walking starts: not drift
    est_pos[:, 1] += 0.01 * walked
    est_pos[:, 2] += 0.02
    est_vel = vel.copy()
    est_vel[t >= WALK_START, 1] = 0.01
    est_rpy = np.zeros((n, 3))
    est_rpy[:, 2] = yaw + 0.0025 * walked
    ref = np.zeros((n, 9))
    ref[:, 0] = pos[:, 0]
    ref[:, 1] = pos[:, 1] + 0.03
    status = np.zeros(n, dtype=np.int32)
    status[t < 1.0] = 4  # before the walk: not counted
    status[500] = 1
    fix_valid = np.zeros(n, dtype=bool)
    fix_valid[::50] = True
    return {
        "t": t,
        "walk_start": np.array(WALK_START),
        "base_pos": pos,
        "base_vel": vel,
        "base_quat": quat,
        "ref": ref,
        "est_pos": est_pos,
        "est_vel": est_vel,
        "est_rpy": est_rpy,
        "est_status": status,
        "fix_valid": fix_valid,
        "fix_pos": pos.copy(),
        "estimator": np.array("kalman"),
        "fix_rate": np.array(2.0),
        "fix_noise": np.array(0.02),
        "sensor_seed": np.array(7),
    }


def test_metrics_of_a_log_with_known_errors() -> None:
    e = compute_estimation_metrics(_log())
    assert e.velocity_rms == pytest.approx(0.01)
    assert e.velocity_rms_horizontal == pytest.approx(0.01)
    assert e.velocity_rms_axes == pytest.approx((0.0, 0.01, 0.0))
    assert e.path_length == pytest.approx(4.0)
    # 8 cm sideways over 4 m walked; the 10 cm offset from before the walk is not drift.
    assert e.drift_percent == pytest.approx(2.0)
    assert e.position_error_final == pytest.approx(math.hypot(0.1, 0.08))
    assert e.position_error_max == pytest.approx(math.hypot(0.1, 0.08))
    assert e.height_error_rms == pytest.approx(0.02)
    assert e.yaw_error_final == pytest.approx(0.02)
    assert e.yaw_error_max == pytest.approx(0.02)
    assert e.tracking_rms == pytest.approx(0.03)
    assert e.status_bits == 1
    assert e.fixes == 21
    assert (e.estimator, e.fix_rate, e.fix_noise, e.sensor_seed) == ("kalman", 2.0, 0.02, 7)


def test_a_run_that_fell_is_measured_up_to_its_fall() -> None:
    log = _log()
    e = compute_estimation_metrics(log, until=6.0)
    assert e.measured_until == pytest.approx(6.0)
    assert e.yaw_error_final == pytest.approx(0.01)
    assert e.path_length == pytest.approx(2.0)
    assert e.drift_percent == pytest.approx(2.0)
    assert compute_estimation_metrics(log).measured_until == pytest.approx(10.0)


def test_yaw_error_wraps_around_pi() -> None:
    log = _log()
    log["base_quat"][:] = (math.cos(math.pi / 2 - 0.005), 0.0, 0.0, math.sin(math.pi / 2 - 0.005))  # yaw π − 0.01
    log["est_rpy"][:, 2] = -math.pi + 0.01
    e = compute_estimation_metrics(log)
    assert e.yaw_error_max == pytest.approx(0.02, abs=1e-9)


def test_a_log_without_an_estimate_is_refused() -> None:
    log = _log()
    del log["est_vel"]
    assert not has_estimate(log)
    with pytest.raises(KeyError, match="est_vel"):
        compute_estimation_metrics(log)


def _record(log: dict[str, np.ndarray], with_estimate: bool) -> RunRecord:
    metrics = RunMetrics("synthetic", "pf", 10.0, WALK_START, 0.03, 0.03, 0.0, 0.0, 0.0, True, 5.0, False, None, "", 0.0, 0.0, 4.0, 0.0, 4.0, None)
    estimation = compute_estimation_metrics(log) if with_estimate else None
    return RunRecord(metrics, log, 1.0, {"total": 0.1}, "completed", estimation=estimation)


def test_report_section_has_the_table_and_the_plot(tmp_path: Path) -> None:
    log = _log()
    lines = estimation_section({"synthetic": [_record(log, True)]}, tmp_path)
    text = "\n".join(lines)
    assert "## State estimation" in text
    assert "| synthetic | pf | 10.0 | 2 / 0.02 | 0.010 / 0.010 |" in text
    assert "| 2.00 of 4.0 |" in text and "| 0x1 |" in text
    assert (tmp_path / "synthetic_pf_estimation.png").stat().st_size > 10_000
    assert "(synthetic_pf_estimation.png)" in text
    assert estimation_section({"synthetic": [_record(log, False)]}, tmp_path) == []


# --- The estimator in the co-simulation loop, with a Python stand-in for the FMU ----------------


class EstimatingStandIn(PdStandIn):
    """PD to the stance plus a toy estimator: position from the last fix, yaw from the integrated gyro."""

    def __init__(self, contract: Any) -> None:
        super().__init__(contract)
        self.estimator_mode: str | None = None
        self.received: list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]] = []

    def enable_estimation(self, mode: str) -> fr.EstimationIo:
        self.estimator_mode = mode
        self.estimation = fr.EstimationIo.detached()
        return self.estimation

    def set_parameters(self, values: dict[str, float]) -> None:
        self.parameters = {**getattr(self, "parameters", {}), **values}

    def do_step(self, time: float, step: float) -> None:
        super().do_step(time, step)
        io = self.estimation
        q = self.inputs.view(fr.JOINT_Q).copy()
        self.received.append((io.gyro.copy(), io.acc.copy(), q, bool(io.fix_valid[0])))
        if io.fix_valid[0]:
            io.est_pos[:] = io.fix_pos
            io.est_status[0] += 1
        io.est_rpy[2] += io.gyro[2] * step


def _fake_contract() -> Any:
    fsm = IntEnum("FsmState", {"Passive": 0, "Stand": 1, "Locomotion": 2, "Damping": 3})
    mode = IntEnum("ModeRequest", {"Passive": 0, "Stand": 1, "Locomotion": 2})
    # A 3×3 height map: the harness takes the size from the contract, whatever the FMU's is.
    heights = fr.height_map_heights(3)
    return SimpleNamespace(fsm=fsm, mode=mode, height_map_size=3, height_map_heights=heights, real_inputs=fr.FIXED_REAL_INPUTS + heights)


def test_kalman_mode_feeds_sensor_readings_and_logs_the_estimate(ramp_scenario: Scenario, tmp_path: Path) -> None:
    stand_in = EstimatingStandIn(_fake_contract())
    sensors = BodySensorConfig(seed=2, fix_rate=2.0, fix_noise=0.01)
    config = CoSimConfig(comm_step=0.002, stand_time=0.5, settle_time=1.0, estimator="kalman", body_sensors=sensors)
    with CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), None, ROBOT, tmp_path, config, controller=stand_in) as sim:
        result = sim.run()
    log = result.log
    assert stand_in.estimator_mode == "kalman"
    # The estimator is told the fix receiver's noise.
    assert stand_in.parameters == {fr.FIX_NOISE_PARAMETER: 0.01}
    assert len(stand_in.received) == len(log["t"]) // 2
    # Standing on a ramp of slope 0.2: the accelerometer reads about g, mostly along body z.
    acc = np.array([r[1] for r in stand_in.received[-200:]])
    assert np.linalg.norm(acc.mean(axis=0)) == pytest.approx(9.81, abs=0.3)
    assert acc.mean(axis=0)[2] > 9.0
    # Joint angles reach the FMU as the encoder reads them; the log keeps the truth.
    q_in = np.array([r[2] for r in stand_in.received])
    step = AS5047P.resolution
    np.testing.assert_allclose(q_in / step, np.round(q_in / step), atol=1e-6)
    assert np.any(np.abs(log["q"][::2] / step - np.round(log["q"][::2] / step)) > 0.01)
    # Fixes at 2 Hz, flagged once each, in the FMU's inputs and in the log.
    valid = [k for k, r in enumerate(stand_in.received) if r[3]]
    assert len(valid) == 5 and int(log["fix_valid"].sum()) == 5
    np.testing.assert_allclose(log["t"][log["fix_valid"]], [0.0, 0.5, 1.0, 1.5, 2.0])
    # The FMU's estimate is logged next to the truth (held between communication points).
    assert log["est_status"][-1] == 5
    np.testing.assert_allclose(log["est_pos"][-1], log["fix_pos"][-1])
    assert np.linalg.norm(log["est_pos"][-1] - log["base_pos"][-1]) < 0.1
    assert str(log["estimator"]) == "kalman" and float(log["fix_rate"]) == 2.0
    e = compute_estimation_metrics(log)
    # Walking from 0.5 s: the toy status counted fixes 2 … 5 then, 0b010 | 0b011 | 0b100 | 0b101.
    assert e.fixes == 5 and e.status_bits == 7
    assert e.velocity_rms < 0.2  # the stand-in says "at rest" and the robot stands
    # Without a contact sensor the FMU is told nothing (−1: its gait schedule).
    assert np.all(stand_in.estimation.contact == -1)


def test_the_contact_sensor_reports_the_feet_dart_finds_on_the_ground(ramp_scenario: Scenario, tmp_path: Path) -> None:
    stand_in = EstimatingStandIn(_fake_contract())
    config = CoSimConfig(stand_time=0.2, settle_time=0.2, max_duration=0.6, estimator="kalman", body_sensors=BodySensorConfig(contact_sensor=True))
    with CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), None, ROBOT, tmp_path, config, controller=stand_in) as sim:
        log = sim.run().log
    # The PD stand-in keeps all four feet down; the input agrees with the contacts DART logged.
    np.testing.assert_array_equal(stand_in.estimation.contact, [1, 1, 1, 1])
    np.testing.assert_array_equal(log["contact_actual"][-2], [1, 1, 1, 1])
    assert bool(log["contact_sensor"])


def test_ground_truth_mode_touches_no_estimator_variables(ramp_scenario: Scenario, tmp_path: Path) -> None:
    stand_in = PdStandIn(_fake_contract())  # has no enable_estimation: must not be asked
    config = CoSimConfig(stand_time=0.1, settle_time=0.1, max_duration=0.3, estimator="groundTruth")
    with CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), None, ROBOT, tmp_path, config, controller=stand_in) as sim:
        log = sim.run().log
    assert str(log["estimator"]) == "groundTruth" and not has_estimate(log)


def test_an_unknown_estimator_mode_is_refused() -> None:
    with pytest.raises(SimulationError, match="unknown estimator mode 'ekf'"):
        CoSimConfig(estimator="ekf").validate()
    with pytest.raises(SimulationError, match="fix rate"):
        CoSimConfig(estimator="kalman", body_sensors=BodySensorConfig(fix_rate=-2.0)).validate()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--estimator", "kalman", "--fix-rate", "-1"], "fix rate"),
        (["--estimator", "kalman", "--fix-noise", "nan"], "fix noise"),
        (["--estimator", "kalman", "--sensor-seed", "-3"], "seed"),
        (["--estimator", "groundTruth", "--fix-rate", "2"], "which --estimator groundTruth turns off"),
        (["--estimator", "groundTruth", "--contact-sensor"], "which --estimator groundTruth turns off"),
        (["--estimator", "groundTruth", "--fix-noise", "0.05"], "which --estimator groundTruth turns off"),
    ],
)
def test_bad_estimation_flags_give_a_clear_error(args: list[str], message: str) -> None:
    parsed = build_parser().parse_args(["run", "--scenario", "pits", *args])
    with pytest.raises(HarnessError, match=message):
        _config(parsed)


def test_estimation_flags_reach_the_config() -> None:
    parsed = build_parser().parse_args(
        ["run", "--scenario", "pits", "--estimator", "kalman", "--fix-rate", "2", "--fix-noise", "0.05", "--sensor-seed", "9", "--contact-sensor"]
    )
    config = _config(parsed)
    assert config.estimator == "kalman"
    b = config.body_sensors
    assert (b.fix_rate, b.fix_noise, b.seed, b.contact_sensor) == (2.0, 0.05, 9, True)
    # Without the flag the controller runs on its estimate, like a real robot; the flags then need no --estimator.
    default = _config(build_parser().parse_args(["run", "--scenario", "pits", "--fix-rate", "2"]))
    assert (default.estimator, default.body_sensors.fix_rate) == ("kalman", 2.0)
    assert _config(build_parser().parse_args(["run", "--scenario", "pits", "--estimator", "groundTruth"])).estimator == "groundTruth"


def test_the_final_error_is_judged_against_the_estimators_own_sigma(tmp_path: Path) -> None:
    log = _log()
    final_error = compute_estimation_metrics(log).position_error_final  # √(0.1² + 0.08²)
    assert final_error == pytest.approx(math.hypot(0.1, 0.08))
    for sigma, verdict in ((0.07, "within"), (0.06, "outside")):
        log["est_pos_var"] = np.full((len(log["t"]), 3), sigma**2 / 2)
        e = compute_estimation_metrics(log)
        assert e.position_sigma_final == pytest.approx(sigma)
        assert e.final_error_within_2sigma is (verdict == "within")
        text = "\n".join(estimation_section({"synthetic": [_record(log, True)]}, tmp_path))
        assert f"| {sigma:.3f} ({verdict} 2σ) |" in text
    del log["est_pos_var"]
    assert compute_estimation_metrics(log).final_error_within_2sigma is None
