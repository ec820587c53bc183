"""The master loop with a Python stand-in for the FMU (same interface): stepping, logging, stopping."""

from __future__ import annotations

from pathlib import Path

import lcm
import numpy as np
import pytest

from pfnav_harness import fmu_runner as fr
from pfnav_harness import paths
from pfnav_harness.cosim import CoSimConfig, CoSimulation, save_log
from pfnav_harness.errors import SimulationError
from pfnav_harness.metrics import TraversabilityField, compute_metrics, judge_fall
from pfnav_harness.planner_client import Plan
from pfnav_harness.report import RunRecord, write_report
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario
from pfnav_harness.state_log import CHANNEL, robot_state_type, write_state_log

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
CROUCH = ROBOT.crouch


class PdStandIn:
    """Joint PD to the crouched stance: what a controller FMU looks like to the master."""

    def __init__(self, contract: fr.FmuContract, kp: float = 120.0, kd: float = 3.0) -> None:
        self.contract = contract
        self.inputs = fr.NamedVector(contract.real_inputs)
        self.outputs = fr.NamedVector(fr.REAL_OUTPUTS)
        self.kp, self.kd = kp, kd
        self.steps: list[tuple[float, float]] = []
        self.modes: list[int] = []
        self.closed = False

    def initialize(self, start_time: float = 0.0) -> None:
        self.steps.clear()

    def exchange_inputs(self, mode: int, height_map: bool = True) -> None:
        self.modes.append(mode)

    def do_step(self, time: float, step: float) -> None:
        self.steps.append((time, step))
        q = self.inputs.view(fr.JOINT_Q)
        dq = self.inputs.view(fr.JOINT_DQ)
        self.torques[:] = self.kp * (CROUCH - q) - self.kd * dq

    def read_outputs(self) -> None:
        pass

    @property
    def torques(self) -> np.ndarray:
        return self.outputs.view(fr.TORQUE_OUTPUTS)

    @property
    def forces(self) -> np.ndarray:
        return self.outputs.view(fr.FORCE_OUTPUTS)

    @property
    def solve_time(self) -> float:
        return 0.0

    @property
    def contacts(self) -> list[int]:
        return [1, 1, 1, 1]

    @property
    def contacts_array(self) -> np.ndarray:
        return np.ones(4, dtype=np.int32)

    @property
    def fsm_state(self) -> int:
        return int(self.contract.fsm.Stand)

    def close(self) -> None:
        self.closed = True


def standing_plan(x: float, y: float) -> Plan:
    t = np.array([0.0, 1.0])
    one = np.ones(2)
    return Plan("pf", t, x * one, y * one, 0 * one, 0 * one, 0 * one, 0 * one, 0 * one)


def test_master_steps_logs_and_closes(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    stand_in = PdStandIn(fmu_contract)
    config = CoSimConfig(comm_step=0.004, stand_time=0.2, settle_time=0.3, estimator="groundTruth")
    with CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), None, ROBOT, tmp_path, config, controller=stand_in) as sim:
        assert sim.duration() == pytest.approx(1.5)
        result = sim.run()
    assert stand_in.closed
    log = result.log
    assert len(log["t"]) == 1500
    # One doStep of 4 ms per 4 physics steps, at the right communication points.
    assert len(stand_in.steps) == 375
    assert stand_in.steps[1] == (pytest.approx(0.004), 0.004)
    # Mode: stand for 0.2 s, then locomotion.
    modes = fmu_contract.mode
    assert stand_in.modes[0] == modes.Stand and stand_in.modes[-1] == modes.Locomotion
    assert stand_in.modes.count(modes.Stand) == 50
    assert np.all(log["fsm"] == fmu_contract.fsm.Stand) and log["fsm_damping"] == fmu_contract.fsm.Damping
    # The FSM's names and codes as the FMU's modelDescription declares them, for a replay to name the states by.
    assert dict(zip(log["fsm_state_names"].tolist(), log["fsm_state_codes"].tolist(), strict=True)) == {s.name: int(s) for s in fmu_contract.fsm}
    # Torques are held between communication points (zero-order hold).
    np.testing.assert_array_equal(log["tau"][4], log["tau"][7])
    assert result.stop_reason == "completed"
    assert result.timing.simulated == pytest.approx(1.5)
    assert result.timing.total >= result.timing.physics + result.timing.fmu
    # The PD stand-in holds the robot up: a standing run is not a fall and tracks the fixed point.
    field = TraversabilityField(ramp_scenario.terrain, ramp_scenario.traversability)
    m = compute_metrics(log, ramp_scenario.terrain, ramp_scenario.goal, field, "ramp", "pf")
    assert not m.fell
    assert m.rms_error < 0.1
    save_log(result, tmp_path / "logs" / "run.npz")
    with np.load(tmp_path / "logs" / "run.npz") as saved:
        np.testing.assert_array_equal(saved["base_pos"], log["base_pos"])
    # The optional LCM log replays the same states.
    count = write_state_log(log, tmp_path / "run.lcmlog", period=0.01)
    assert count == 150
    robot_state_t = robot_state_type()
    events = list(lcm.EventLog(str(tmp_path / "run.lcmlog"), "r"))
    assert len(events) == 150 and all(e.channel == CHANNEL for e in events)
    last = robot_state_t.decode(events[-1].data)
    assert last.utime == round(log["t"][1490] * 1e6)
    np.testing.assert_array_equal(last.position, log["base_pos"][1490])
    np.testing.assert_array_equal(last.joint_torques, log["tau"][1490])
    report = write_report(
        tmp_path / "out",
        {"ramp": ramp_scenario},
        {"ramp": [RunRecord(m, log, 1.0, result.timing.per_sim_second(), result.stop_reason)]},
    )
    text = report.read_text()
    assert "| ramp | P-F | no | no |" in text
    for png in ("ramp_paths.png", "ramp_tracking.png", "ramp_pf_torques.png", "ramp_pf_contacts.png"):
        assert (tmp_path / "out" / png).stat().st_size > 5000
        assert f"({png})" in text


def test_a_collapsing_robot_is_stopped_early_as_a_fall(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    limp = PdStandIn(fmu_contract, kp=0.0, kd=0.0)
    config = CoSimConfig(stand_time=0.0, settle_time=5.0, after_fall=0.2, estimator="groundTruth")
    with CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), None, ROBOT, tmp_path, config, controller=limp) as sim:
        result = sim.run()
    assert result.stop_reason.startswith("fell at")
    assert result.timing.simulated < 2.0
    # The metrics judge the log by the rule the run stopped on: the same fall time.
    verdict = judge_fall(result.log, ramp_scenario.terrain, config.fall)
    assert verdict.fell and result.stop_reason == f"fell at t={verdict.fall_time:.2f} s"
    assert result.fall_step is not None and result.log["t"][result.fall_step] == verdict.fall_time


def test_bad_configs_are_rejected(ramp_scenario: Scenario, tmp_path: Path) -> None:
    with pytest.raises(SimulationError, match="multiple"):
        CoSimConfig(comm_step=0.0015).validate()
    with pytest.raises(SimulationError, match="positive"):
        CoSimConfig(physics_dt=0.0).validate()
    with pytest.raises(SimulationError, match="FMU path or a controller"):
        CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), None, ROBOT, tmp_path)
