"""Forks: DART snapshots, and runs continued from a saved post-stand-up state equal full runs.

The loop tests use a Python stand-in for the FMU with internal state (an integrator and a step
counter) and the estimator's sensor inputs, so a fork that lost any of it would show; the same with
the real FMU is in test_hs_fork_fmu.py.
"""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pfnav_harness import fmu_runner as fr
from pfnav_harness import paths
from pfnav_harness.body_sensors import BodySensorConfig
from pfnav_harness.cosim import PREFIX_FRICTION, CoSimConfig, CoSimulation, ForkPoint, RunResult, prefix_config
from pfnav_harness.errors import SimulationError
from pfnav_harness.planner_client import Plan
from pfnav_harness.pushes import PushSchedule, horizontal_push
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario
from pfnav_harness.world import Payload, QuadrupedWorld

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
CROUCH = ROBOT.crouch


class StatefulStandIn:
    """Joint PD with an integral term towards a stance that sinks once walking starts, gyro feedback.

    Its state (the integral, the steps taken) is what `save_state` serializes, like an FMU's.
    """

    def __init__(self, contract: fr.FmuContract) -> None:
        self.contract = contract
        self.inputs = fr.NamedVector(contract.real_inputs)
        self.outputs = fr.NamedVector(fr.REAL_OUTPUTS)
        self.can_save_state = True
        self.estimation: fr.EstimationIo | None = None
        self._integral = np.zeros(12)
        self._steps = 0
        self._mode = 0
        self._contacts = np.ones(4, dtype=np.int32)
        self.initialized = False

    def enable_estimation(self, mode: str) -> fr.EstimationIo:
        self.estimation = fr.EstimationIo.detached()
        return self.estimation

    def set_parameters(self, values: dict[str, float]) -> None:
        self.parameters = {**getattr(self, "parameters", {}), **values}

    def initialize(self, start_time: float = 0.0) -> None:
        self.initialized = True

    def exchange_inputs(self, mode: int, height_map: bool = True) -> None:
        self._mode = int(mode)

    def do_step(self, time: float, step: float) -> None:
        q = self.inputs.view(fr.JOINT_Q)
        dq = self.inputs.view(fr.JOINT_DQ)
        walking = self._mode == self.contract.mode.Locomotion
        target = CROUCH + (0.1 * np.sin(0.02 * self._steps) if walking else 0.0)
        error = target - q
        self._integral += error * step
        tau = 100.0 * error - 3.0 * dq + 40.0 * self._integral
        est = self.estimation
        if est is not None:
            tau[0::3] -= 0.5 * est.gyro[0]
            est.est_pos[:] = est.fix_pos if est.fix_valid[0] else est.est_pos
            est.est_rpy[:] = est.acc
        self.outputs.view(fr.TORQUE_OUTPUTS)[:] = tau
        self._steps += 1

    def read_outputs(self) -> None:
        pass

    def save_state(self) -> bytes:
        return np.concatenate([self._integral, [self._steps]]).tobytes()

    def restore_state(self, blob: bytes) -> None:
        values = np.frombuffer(blob, dtype=np.float64)
        self._integral = values[:12].copy()
        self._steps = int(values[12])

    def io_snapshot(self) -> fr.FmuIoSnapshot:
        est = self.estimation
        buffers = None if est is None else (est.gyro.copy(), est.acc.copy(), est.fix_pos.copy(), est.est_pos.copy(), est.est_rpy.copy())
        return fr.FmuIoSnapshot(self.inputs.values.copy(), self.outputs.values.copy(), self._mode, self._contacts.copy(), 0, buffers)

    def restore_io(self, io: fr.FmuIoSnapshot) -> None:
        self.inputs.values[:] = io.inputs
        self.outputs.values[:] = io.outputs
        self._mode = io.mode
        est = self.estimation
        if est is not None and io.estimation is not None:
            for live, saved in zip((est.gyro, est.acc, est.fix_pos, est.est_pos, est.est_rpy), io.estimation, strict=True):
                live[:] = saved

    @property
    def torques(self) -> np.ndarray:
        return self.outputs.view(fr.TORQUE_OUTPUTS)

    @property
    def contacts_array(self) -> np.ndarray:
        return self._contacts

    @property
    def fsm_state(self) -> int:
        return int(self.contract.fsm.Stand)

    def close(self) -> None:
        pass


def standing_plan(x: float, y: float) -> Plan:
    t = np.array([0.0, 1.0])
    one = np.ones(2)
    return Plan("pf", t, x * one, y * one, 0 * one, 0 * one, 0 * one, 0 * one, 0 * one)


# 3 ms communication steps and a 0.5 s stand: the fork (step 500) falls between two communication
# points, so the held torques and FMU values have to come with it.
def config(**changes: Any) -> CoSimConfig:
    base = CoSimConfig(
        comm_step=0.003,
        stand_time=0.5,
        max_duration=0.9,
        estimator="kalman",
        body_sensors=BodySensorConfig(seed=3, fix_rate=50.0),
    )
    return dataclasses.replace(base, **changes)


def simulation(scenario: Scenario, contract: fr.FmuContract, folder: Path, cfg: CoSimConfig) -> CoSimulation:
    return CoSimulation(scenario, standing_plan(1.5, 1.0), None, ROBOT, folder, cfg, controller=StatefulStandIn(contract))  # type: ignore[arg-type]


def assert_same_log(a: RunResult, b: RunResult) -> None:
    assert a.stop_reason == b.stop_reason
    assert set(a.log) == set(b.log)
    for key in a.log:
        np.testing.assert_array_equal(a.log[key], b.log[key], err_msg=key)
        assert a.log[key].dtype == b.log[key].dtype, key


def test_world_snapshot_restores_bit_exactly(ramp_scenario: Scenario, tmp_path: Path) -> None:
    """t → t + 0.5 s twice from one snapshot, in the same world and in a fresh one: the same states bit for bit."""

    def make() -> QuadrupedWorld:
        world = QuadrupedWorld(ramp_scenario.terrain, ROBOT, tmp_path)
        world.place(1.5, 1.0, 0.3)
        return world

    state = np.zeros(37)

    def drive(world: QuadrupedWorld, steps: int) -> tuple[np.ndarray, np.ndarray]:
        states, contacts = np.zeros((steps, 37)), np.zeros((steps, 4), dtype=bool)
        for k in range(steps):
            world.state_vector(state)
            world.apply_torques(120.0 * (CROUCH - state[13:25]) - 3.0 * state[25:37] + 5.0 * np.sin(0.01 * k + np.arange(12)))
            world.step()
            states[k], contacts[k] = state, world.foot_contacts()
        return states, contacts

    world = make()
    drive(world, 700)
    snapshot = world.snapshot()
    # Through pickle, as a fork travels to a worker.
    snapshot = pickle.loads(pickle.dumps(snapshot))
    assert snapshot.time == pytest.approx(0.7)
    first, first_contacts = drive(world, 500)
    world.restore(snapshot)
    assert world.time == pytest.approx(0.7)
    np.testing.assert_array_equal(world.foot_contacts(), snapshot.contacts)
    again, again_contacts = drive(world, 500)
    fresh = make()
    drive(fresh, 123)  # another history before the restore
    fresh.restore(snapshot)
    other, other_contacts = drive(fresh, 500)
    assert first_contacts.any()
    for states, contacts in ((again, again_contacts), (other, other_contacts)):
        np.testing.assert_array_equal(states, first)
        np.testing.assert_array_equal(contacts, first_contacts)
    with pytest.raises(SimulationError, match="the snapshot holds skeletons"):
        fresh.restore(type(snapshot)(0.0, {"robot": np.zeros(3)}, {"robot": np.zeros(3)}, snapshot.held_torques, snapshot.contacts))


def test_forked_run_equals_the_full_run(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    cfg = config()
    with simulation(ramp_scenario, fmu_contract, tmp_path, cfg) as sim:
        full = sim.run()
    with simulation(ramp_scenario, fmu_contract, tmp_path, prefix_config(cfg)) as sim:
        assert sim.walk_start_step() == 500
        fork = sim.run_prefix()
    assert fork.step == 500 and fork.step % 3 != 0
    fork = pickle.loads(pickle.dumps(fork))
    with simulation(ramp_scenario, fmu_contract, tmp_path, cfg) as sim:
        forked = sim.run_from(fork)
    assert len(full.log["t"]) == 900
    assert_same_log(full, forked)
    assert forked.timing.simulated == full.timing.simulated


def test_a_fork_continues_identically_twice_and_loads_the_robot(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    cfg = config()
    with simulation(ramp_scenario, fmu_contract, tmp_path, prefix_config(cfg)) as sim:
        fork = sim.run_prefix()
    blob = pickle.dumps(fork)
    push = PushSchedule([horizontal_push(60.0, 90.0, 0.1, 0.1)])
    loaded = config(payload=Payload(0.2, (0.03, 0.0, 0.0)), friction=0.5, pushes=push)
    results = []
    for _ in range(2):
        with simulation(ramp_scenario, fmu_contract, tmp_path, loaded) as sim:
            assert sim.fork_key() == fork.key  # payload, friction and pushes are applied at the fork
            results.append(sim.run_from(pickle.loads(blob)))
    assert_same_log(results[0], results[1])
    with simulation(ramp_scenario, fmu_contract, tmp_path, cfg) as sim:
        unloaded = sim.run_from(fork)
    # The prefix rows are the fork's; afterwards the load and the push move the robot.
    np.testing.assert_array_equal(results[0].log["base_pos"][:500], unloaded.log["base_pos"][:500])
    assert np.abs(results[0].log["base_pos"][600:] - unloaded.log["base_pos"][600:]).max() > 1e-3
    assert np.abs(results[0].log["push_force"]).max() == pytest.approx(60.0)


def test_forks_refuse_what_they_cannot_continue(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    cfg = config()
    with simulation(ramp_scenario, fmu_contract, tmp_path, config(payload=Payload(0.1))) as sim, pytest.raises(SimulationError, match="without payload"):
        sim.run_prefix()
    with simulation(ramp_scenario, fmu_contract, tmp_path, prefix_config(cfg)) as sim:
        fork: ForkPoint = sim.run_prefix()
    assert fork.friction == PREFIX_FRICTION
    # Another communication step, sensor seed or stand time is another prefix.
    for other in (config(comm_step=0.002), config(body_sensors=BodySensorConfig(seed=4, fix_rate=50.0)), config(stand_time=0.6)):
        with simulation(ramp_scenario, fmu_contract, tmp_path, other) as sim, pytest.raises(SimulationError, match="another prefix"):
            sim.run_from(fork)
    with simulation(ramp_scenario, fmu_contract, tmp_path, config(max_duration=0.4)) as sim, pytest.raises(SimulationError, match="before its fork point"):
        sim.run_from(fork)


def test_the_fork_key_names_the_robot_by_its_config_and_urdf_content(ramp_scenario: Scenario, fmu_contract: fr.FmuContract, tmp_path: Path) -> None:
    """A copy of the robot elsewhere is the same robot; an edited URDF or config at the same path is another."""
    folder = tmp_path / "copy"
    folder.mkdir()
    config_text = ROBOT.config_text
    urdf_text = ROBOT.urdf_path.read_text()
    config_copy = folder / ROBOT.config_path.name
    urdf_copy = folder / ROBOT.urdf_path.name
    config_copy.write_text(config_text)
    urdf_copy.write_text(urdf_text)
    cfg = config()

    def key(robot: RobotDescription) -> str:
        sim = CoSimulation(ramp_scenario, standing_plan(1.5, 1.0), None, robot, tmp_path, cfg, controller=StatefulStandIn(fmu_contract))  # type: ignore[arg-type]
        with sim:
            return sim.fork_key()

    ours = key(ROBOT)
    assert key(RobotDescription.load(config_copy)) == ours
    heavier = urdf_text.replace('<mass value="5.0"/>', '<mass value="5.5"/>', 1)
    assert heavier != urdf_text
    urdf_copy.write_text(heavier)
    assert key(RobotDescription.load(config_copy)) != ours
    urdf_copy.write_text(urdf_text)
    higher = config_text.replace("stand_height = 0.28", "stand_height = 0.29")
    assert higher != config_text
    config_copy.write_text(higher)
    assert key(RobotDescription.load(config_copy)) != ours
