"""FMU state save and restore through `ControllerFmu`, and forked co-simulation runs with the real controller FMU.

`mpc.solveTime` is left out of the bit-for-bit comparisons: it is the wall-clock time the MPC's
solver took (`Instant::elapsed` in controller/src/mpc/solver.rs), not a result of the state.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness import fmu_runner as fr
from pfnav_harness import paths
from pfnav_harness.body_sensors import BodySensorConfig
from pfnav_harness.cosim import CoSimConfig, CoSimulation, RunResult, prefix_config
from pfnav_harness.errors import SimulationError
from pfnav_harness.planner_client import Plan
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
CROUCH = ROBOT.crouch

DT = 0.001


def open_fmu() -> fr.ControllerFmu:
    return fr.ControllerFmu(paths.fmu_path())


def set_standing_inputs(fmu: fr.ControllerFmu) -> None:
    """A level robot at rest in its crouched stance, asked to walk forward at 0.3 m/s (inputs held constant)."""
    values = fmu.inputs
    values.values[:] = 0.0
    values.view(fr.BASE_POS)[:] = (0.0, 0.0, 0.3)
    values.view(fr.BASE_QUAT)[:] = (1.0, 0.0, 0.0, 0.0)
    values.view(fr.JOINT_Q)[:] = CROUCH
    values.values[values.index("ref.vx")] = 0.3


def drive(fmu: fr.ControllerFmu, start: float, seconds: float) -> np.ndarray:
    """doSteps of 1 ms from `start`: stand for the first 1.5 s, then walk; one row of outputs per step."""
    solve_time = fmu.outputs.index(fr.SOLVE_TIME_OUTPUT)
    steps = round(seconds / DT)
    rows = np.zeros((steps, len(fmu.outputs.names) + 5))
    modes = fmu.contract.mode
    for i in range(steps):
        t = start + i * DT
        fmu.exchange_inputs(modes.Locomotion if t >= 1.5 else modes.Stand)
        fmu.do_step(t, DT)
        fmu.read_outputs()
        rows[i, : len(fmu.outputs.names)] = fmu.outputs.values
        rows[i, solve_time] = 0.0
        rows[i, -5:-1] = fmu.contacts_array
        rows[i, -1] = fmu.fsm_state
    return rows


def test_fmu_state_save_and_restore_is_bit_exact() -> None:
    """Get the state at t = 2 s, run 1 s, set it back, run the same 1 s: identical outputs; also in a second instance."""
    with open_fmu() as fmu:
        assert fmu.can_save_state
        set_standing_inputs(fmu)
        fmu.initialize(0.0)
        drive(fmu, 0.0, 2.0)
        blob = fmu.save_state()
        first = drive(fmu, 2.0, 1.0)
        # The run really moves on: torques change from step to step and the gait switches contacts.
        assert np.ptp(first[:, 0]) > 0.1 and np.ptp(first[:, -5:-1]) == 1
        fmu.restore_state(blob)
        again = drive(fmu, 2.0, 1.0)
        np.testing.assert_array_equal(again, first)
    with open_fmu() as other:
        set_standing_inputs(other)
        other.initialize(0.0)
        other.restore_state(blob)
        np.testing.assert_array_equal(drive(other, 2.0, 1.0), first)


def test_bad_fmu_states_are_refused() -> None:
    with open_fmu() as fmu:
        with pytest.raises(SimulationError, match="between initialisation and close"):
            fmu.save_state()
        set_standing_inputs(fmu)
        fmu.initialize(0.0)
        drive(fmu, 0.0, 0.05)
        blob = fmu.save_state()
        for bad in (blob[: len(blob) // 2], b"not a state of this FMU" * 4):
            with pytest.raises(SimulationError, match="refused the serialized state"):
                fmu.restore_state(bad)
        with pytest.raises(SimulationError, match="cannot be empty"):
            fmu.restore_state(b"")
        # The instance still works after the refusals.
        drive(fmu, 0.05, 0.01)
        fmu.can_save_state = False  # as an FMU whose modelDescription says it cannot
        with pytest.raises(SimulationError, match="canGetAndSetFMUstate"):
            fmu.save_state()


def standing_plan(x: float, y: float) -> Plan:
    t = np.array([0.0, 1.0])
    one = np.ones(2)
    return Plan("pf", t, x * one, y * one, 0 * one, 0 * one, 0 * one, 0 * one, 0 * one)


def assert_same_log(a: RunResult, b: RunResult) -> None:
    assert a.stop_reason == b.stop_reason
    assert set(a.log) == set(b.log)
    for key in a.log:
        if key != "mpc_solve_time":
            np.testing.assert_array_equal(a.log[key], b.log[key], err_msg=key)


@pytest.mark.parametrize("estimator", ["groundTruth", "kalman"])
def test_forked_runs_equal_the_full_run_with_the_fmu(estimator: str, ramp_scenario: Scenario, tmp_path: Path) -> None:
    """(i) with no payload and the prefix's friction a forked run's log is the full run's, bit for bit; (ii) twice the same.

    A 1.501 s stand with 2 ms communication steps puts the fork between two communication points.
    """
    config = CoSimConfig(
        comm_step=0.002,
        stand_time=1.501,
        max_duration=2.0,
        estimator=estimator,
        body_sensors=BodySensorConfig(seed=5, fix_rate=10.0, contact_sensor=True),
    )

    def simulation(cfg: CoSimConfig) -> CoSimulation:
        return CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), paths.fmu_path(), ROBOT, tmp_path, cfg)

    with simulation(config) as sim:
        full = sim.run()
    with simulation(prefix_config(config)) as sim:
        fork = sim.run_prefix()
    assert fork.step == 1501
    blob = pickle.dumps(fork)
    forked = []
    for _ in range(2):
        with simulation(config) as sim:
            forked.append(sim.run_from(pickle.loads(blob)))
    assert len(full.log["t"]) == 2000
    # The robot stood in the prefix and trots after it, without falling.
    contract = fr.read_contract(paths.fmu_path())
    assert full.stop_reason == "completed"
    assert full.log["fsm"][1400] == contract.fsm.Stand and full.log["fsm"][-1] == contract.fsm.Locomotion
    assert full.log["contact_actual"][1000:1500].mean() > 0.95 and full.log["contact_actual"][1600:].mean() < 0.9
    assert_same_log(full, forked[0])
    assert_same_log(forked[0], forked[1])
