"""pfnav-sim's body: the motor model's law and clamp, and the body on a memq bus in lockstep with a stand-in controller."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pfnav_harness.body_sensors import BodySensorConfig, BodySensors
from pfnav_harness.body_sim import MODE_IDLE, MODE_SERVO, BodyNode, BodySimulation, Channels, MotorCommand, MotorModel
from pfnav_harness.engine import make_engine
from pfnav_harness.errors import HarnessError
from pfnav_harness.planner_client import _import_lcm, _import_types
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario


def test_the_motor_law_is_feed_forward_plus_pd_clamped_to_the_effort_limits() -> None:
    limits = np.full(12, 20.0)
    model = MotorModel(limits)
    command = MotorCommand()
    command.mode[:] = MODE_SERVO
    command.q[:] = 0.5
    command.dq[:] = 1.0
    command.tau[:] = 2.0
    command.kp[:] = 10.0
    command.kd[:] = 0.5
    q, dq = np.full(12, 0.3), np.full(12, -1.0)
    # 2 + 10 (0.5 − 0.3) + 0.5 (1 − (−1)) = 5 N m.
    np.testing.assert_allclose(model.torques(command, q, dq), 5.0)
    command.kp[0] = 1000.0
    command.kp[1] = -1000.0
    command.mode[2] = MODE_IDLE
    torque = model.torques(command, q, dq)
    assert torque[0] == 20.0 and torque[1] == -20.0, "clamped to the effort limit"
    assert torque[2] == 0.0, "an idle motor gives no torque"
    # Damping as pfnav-robot sends it: tau = −kd dq.
    damping = MotorCommand()
    damping.mode[:] = MODE_SERVO
    damping.kd[:] = 2.0
    np.testing.assert_allclose(model.torques(damping, q, dq), 2.0)


def test_commands_with_non_finite_values_are_rejected() -> None:
    types = _import_types()
    message = types.low_cmd_t()
    message.header = types.header_t()
    message.mode = [MODE_SERVO] * 12
    message.q, message.dq, message.tau, message.kp, message.kd = ([0.0] * 12 for _ in range(5))
    assert MotorCommand.from_message(message) is not None
    message.kd = [0.0] * 11 + [float("nan")]
    assert MotorCommand.from_message(message) is None
    with pytest.raises(HarnessError, match="positive effort limits"):
        MotorModel(np.zeros(12))


@pytest.fixture
def body(ramp_scenario: Scenario, tmp_path: Path) -> BodySimulation:
    from pfnav_harness import paths

    robot = RobotDescription.load(paths.default_robot_config_path())
    world = make_engine("dart", ramp_scenario.terrain, robot, tmp_path / "cache")
    world.place(ramp_scenario.start[0], ramp_scenario.start[1], 0.0)
    sensors = BodySensors(BodySensorConfig(seed=3, imu_noise_scale=0.0), world.time_step)
    return BodySimulation(world, sensors, foot_force_sensor=True)


KP, KD = 200.0, 4.0


def test_in_lockstep_the_body_steps_once_per_answer_and_follows_a_pd_command(body: BodySimulation) -> None:
    """A stand-in controller answers each state with a stiff PD to the crouch pose: the body
    steps once per answer, its states count up, the joints settle at the targets, the
    estimated torque is the motor model's and the IMU reads gravity on a robot at rest."""
    lcm_module, types = _import_lcm(), _import_types()
    lcm = lcm_module.LCM("memq://")
    channels = Channels.with_prefix("SIMTEST_")
    node = BodyNode(body, lcm, channels)
    target = body.state[13:25].copy()
    states: list[Any] = []

    def answer(_channel: str, data: bytes) -> None:
        state = types.low_state_t.decode(data)
        states.append(state)
        command = types.low_cmd_t()
        command.header = types.header_t()
        command.state_seq = state.header.seq
        command.mode = [MODE_SERVO] * 12
        command.q = target.tolist()
        command.dq = [0.0] * 12
        command.tau = [0.0] * 12
        command.kp = [KP] * 12
        command.kd = [KD] * 12
        lcm.publish(channels.low_cmd, command.encode())

    subscription = lcm.subscribe(channels.low_state, answer)
    deadline = time.monotonic() + 120.0
    node.run_lockstep(600, stop=lambda: time.monotonic() > deadline)
    lcm.unsubscribe(subscription)
    node.close()

    assert body.steps == 600, "one step per answered state"
    # The state after the last step went out; nobody handled it any more.
    assert node.seq == 601
    assert [s.header.seq for s in states] == list(range(1, 601))
    assert node.commands_received == 600 and node.commands_rejected == 0
    last = states[-1]
    q, dq, tau = np.array(last.q), np.array(last.dq), np.array(last.tau_est)
    np.testing.assert_allclose(q, target, atol=0.05)
    # The reported torque is the motor law's on the reported joints (up to the 14-bit encoder's
    # rounding of q, 0.38 mrad × KP).
    np.testing.assert_allclose(tau, KP * (target - q) - KD * dq, atol=KP * 4e-4 + 1e-3)
    assert list(last.foot_contact) == [-1] * 4 and last.tick == 599
    # Standing: the four force sensors carry the body's weight.
    assert min(last.foot_force) > 0.0
    assert sum(last.foot_force) == pytest.approx(body.world.mass * 9.81, rel=0.15)
    # At rest on the ground the accelerometer's specific force is +g along the trunk's up axis.
    assert np.linalg.norm(np.array(last.imu_accelerometer)) == pytest.approx(9.81, abs=0.5)


def test_in_lockstep_the_body_stops_when_no_answer_comes(body: BodySimulation) -> None:
    lcm = _import_lcm().LCM("memq://")
    node = BodyNode(body, lcm, Channels.with_prefix("SILENT_"))
    started = time.monotonic()
    node.run_lockstep(100, stop=lambda: False, answer_timeout=0.3)
    assert body.steps == 0
    assert time.monotonic() - started < 30.0
    node.close()


def test_without_the_foot_force_sensor_the_forces_read_zero(body: BodySimulation) -> None:
    body.foot_force_sensor = False
    for _ in range(300):
        body.step()
    assert list(body.low_state(1).foot_force) == [0.0] * 4
    body.foot_force_sensor = True
    assert sum(body.low_state(2).foot_force) > 0.0, "standing, the sensor would read the weight"


def test_the_tick_statistics_count_the_ticks_by_the_age_of_their_command() -> None:
    from pfnav_harness.body_sim import SimTiming

    timing = SimTiming()
    assert timing.to_json()["command_age"] == {"0": 0, "1": 0, "2": 0, "3-9": 0, "10+": 0, "max": 0}
    for age in [0, 0, 1, 2, 3, 9, 10, 557]:
        timing.count_command_age(age)
    assert timing.to_json()["command_age"] == {"0": 2, "1": 1, "2": 1, "3-9": 2, "10+": 2, "max": 557}
    assert timing.answered_in_time == 2 and timing.to_json()["answered_in_time"] == 2


def test_in_real_time_without_a_controller_the_body_ticks_on_and_reports_its_slowest_tick(body: BodySimulation) -> None:
    """No command ever answers: the body still ticks on its clock (about one tick a millisecond,
    fewer when ticks overrun), every tick steps with a command older than its state, and the
    slowest tick's phases add up to its work."""
    lcm = _import_lcm().LCM("memq://")
    node = BodyNode(body, lcm, Channels.with_prefix("UNANSWERED_"))
    node.run_realtime(0.3, stop=lambda: False, command_wait=0.0)
    node.close()
    timing = node.timing
    assert 0 < timing.ticks <= 310 and timing.ticks + timing.overruns >= 100
    assert body.steps == timing.ticks
    assert timing.answered_in_time == 0 and sum(timing.command_age_ticks) == timing.ticks
    slowest = timing.slowest_tick
    assert slowest["work"] == pytest.approx(max(timing.work))
    phases = slowest["publish"] + slowest["wait"] + slowest["step"] + slowest["state"]
    assert phases == pytest.approx(slowest["work"], rel=1e-6, abs=1e-9)
    assert 0.0 <= slowest["at"] < 0.3
    assert 0.2 < timing.wall_time < 1.0
    assert "slowest tick" in timing.summary()
