"""`pfnav-sim`: the simulated robot body as its own process on the LCM bus, as a robot's motor and IMU boards are.

Every tick (1 kHz) it takes the newest `low_cmd_t`, turns it into joint torques through a motor
model (each motor driver's own loop, the law of low_cmd_t:
tau = tau_ff + kp (q* − q) + kd (dq* − dq), clamped to the effort limits; motors in
`MODE_IDLE` or without any command give no torque), steps the physics engine (DART by default,
`engine.make_engine`) one millisecond, and publishes `low_state_t` from the body sensors
(`body_sensors.BodySensors`: IMU with noise and bias, 14-bit encoders). It is what pfnav-robot
drives instead of a robot.

Two timings:

* **real time** (default): ticks on absolute `CLOCK_MONOTONIC` deadlines, the body's own clock.
  A tick sends the state measured at the end of the previous tick (stamped with the tick's
  time in ms, the body's clock), waits up to half a period (`--command-wait`) for the command
  answering it (a motor driver applies a command when it arrives), then steps with the newest
  command: the states leave on the clock, and a prompt answer acts on the step after its own
  state, a late one a tick later (`--command-wait 0`: every answer a tick later, as a motor
  board applying the newest command at its tick; the ticks are shorter). A tick that overruns
  its period is counted, and the clock continues on its grid after the present rather than
  running the missed ticks back to back.
* **lockstep** (`--lockstep`, for tests): the body waits for the command answering its last
  state (`low_cmd_t.state_seq`) before the next step, so a slow machine slows the run down
  instead of changing it.

Sensors the controller does not read are off unless asked for: `--foot-force-sensor` reports
`foot_force` as the magnitude of the engine's contact force on each foot in the last step, N (0
in the air; an ideal sensor, about 13 µs a tick with DART; else 0), and `--contact-sensor` the
engine's contacts as an ideal binary `foot_contact` (else −1, "unknown"). Not modelled: motor
dynamics beyond the torque law, and the transport's own delay.
"""

from __future__ import annotations

import argparse
import bisect
import gc
import json
import math
import os
import select
import struct
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .body_sensors import BodySensorConfig, BodySensors
from .engine import DEFAULT_ENGINE, ENGINE_NAMES, PhysicsEngine, make_engine
from .errors import HarnessError
from .lcm_channels import DEFAULT_CHANNEL_PREFIX, DEFAULT_LCM_URL, RECEIVE_THREAD_PRIORITY, ROBOT, SIM_ROBOT_STATE_NAME
from .process_signals import stop_requested_on_signals

FloatArray = NDArray[np.float64]
JOINTS = 12


def _types() -> Any:
    from .planner_client import _import_types

    return _import_types()


# low_cmd_t's motor modes, as lcm_types/low_cmd_t.lcm declares them.
MODE_IDLE = int(_types().low_cmd_t.MODE_IDLE)
MODE_SERVO = int(_types().low_cmd_t.MODE_SERVO)


@dataclass
class MotorCommand:
    """One low_cmd_t as the motor drivers hold it until the next one."""

    mode: NDArray[np.int8] = field(default_factory=lambda: np.full(JOINTS, MODE_IDLE, dtype=np.int8))
    q: FloatArray = field(default_factory=lambda: np.zeros(JOINTS))
    dq: FloatArray = field(default_factory=lambda: np.zeros(JOINTS))
    tau: FloatArray = field(default_factory=lambda: np.zeros(JOINTS))
    kp: FloatArray = field(default_factory=lambda: np.zeros(JOINTS))
    kd: FloatArray = field(default_factory=lambda: np.zeros(JOINTS))

    @classmethod
    def from_message(cls, message: Any) -> MotorCommand | None:
        """The command of a decoded low_cmd_t; None when a value is not finite (a driver rejects it)."""
        command = cls(
            np.array(message.mode, dtype=np.int8),
            np.array(message.q, dtype=np.float64),
            np.array(message.dq, dtype=np.float64),
            np.array(message.tau, dtype=np.float64),
            np.array(message.kp, dtype=np.float64),
            np.array(message.kd, dtype=np.float64),
        )
        values = np.concatenate((command.q, command.dq, command.tau, command.kp, command.kd))
        return command if bool(np.isfinite(values).all()) else None


class MotorModel:
    """The motor drivers: the torque of low_cmd_t's law, clamped to the effort limits."""

    def __init__(self, effort_limits: FloatArray) -> None:
        limits = np.asarray(effort_limits, dtype=np.float64)
        if limits.shape != (JOINTS,) or not bool((limits > 0).all()):
            raise HarnessError(f"the motor model needs {JOINTS} positive effort limits, got {limits}")
        self.effort_limits = limits
        self.torque = np.zeros(JOINTS)

    def torques(self, command: MotorCommand, q: FloatArray, dq: FloatArray) -> FloatArray:
        """tau_ff + kp (q* − q) + kd (dq* − dq) per servo motor, 0 for idle ones, clamped; into `self.torque`."""
        t = self.torque
        np.subtract(command.q, q, out=t)
        t *= command.kp
        t += command.tau
        t += command.kd * (command.dq - dq)
        t[command.mode != MODE_SERVO] = 0.0
        np.clip(t, -self.effort_limits, self.effort_limits, out=t)
        return t


# The bins of SimTiming's command ages, in states: each starts at its age and runs to the next
# bin's (the last has no end); their labels ("0", "3-9", "10+") are derived from these.
COMMAND_AGE_BIN_STARTS = (0, 1, 2, 3, 10)


def _age_bin_label(start: int, end: int | None) -> str:
    if end is None:
        return f"{start}+"
    return str(start) if end == start + 1 else f"{start}-{end - 1}"


COMMAND_AGE_BINS = tuple(
    _age_bin_label(start, end) for start, end in zip(COMMAND_AGE_BIN_STARTS, (*COMMAND_AGE_BIN_STARTS[1:], None), strict=True)
)


@dataclass
class SimTiming:
    """Tick statistics of a real-time run (seconds)."""

    ticks: int = 0
    overruns: int = 0
    # Ticks by how many states older than the tick's own the command they stepped with answers,
    # in the bins of COMMAND_AGE_BINS (0: its own state's answer), and the largest age.
    command_age_ticks: list[int] = field(default_factory=lambda: [0] * len(COMMAND_AGE_BINS))
    command_age_max: int = 0
    work: list[float] = field(default_factory=list)
    period: list[float] = field(default_factory=list)
    # Wall seconds from the first tick's deadline to the end of the run (real time only).
    wall_time: float = 0.0
    # The longest tick's work and where it went (seconds: when, publishing the state, waiting
    # for the answer, the physics step, the next state), to tell a stall's cause.
    slowest_tick: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        def stats(values: list[float]) -> dict[str, float]:
            if not values:
                return {"count": 0, "p50": 0.0, "p99": 0.0, "max": 0.0}
            a = np.array(values)
            return {"count": len(values), "p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)), "max": float(a.max())}

        return {
            "ticks": self.ticks,
            "overruns": self.overruns,
            "answered_in_time": self.answered_in_time,
            "command_age": {**dict(zip(COMMAND_AGE_BINS, self.command_age_ticks, strict=True)), "max": self.command_age_max},
            "work": stats(self.work),
            "period": stats(self.period),
            "wall_time": self.wall_time,
            "slowest_tick": self.slowest_tick,
        }

    @property
    def answered_in_time(self) -> int:
        """Ticks whose step ran with the command answering that tick's own state."""
        return self.command_age_ticks[0]

    def count_command_age(self, age: int) -> None:
        """One tick stepped with a command `age` states older than its own state (≥ 0)."""
        self.command_age_ticks[bisect.bisect_right(COMMAND_AGE_BIN_STARTS, age) - 1] += 1
        self.command_age_max = max(self.command_age_max, age)

    def summary(self) -> str:
        if not self.work:
            return "no ticks"
        work = np.array(self.work) * 1e3
        text = f"{self.ticks} ticks, work p50/p99/max {np.percentile(work, 50):.3f}/{np.percentile(work, 99):.3f}/{work.max():.3f} ms"
        if self.period:
            period = np.array(self.period) * 1e3
            text += f", period p50/p99/max {np.percentile(period, 50):.3f}/{np.percentile(period, 99):.3f}/{period.max():.3f} ms"
        text += f", {self.overruns} overruns, {self.answered_in_time} ticks stepped with their own state's answer"
        slowest = self.slowest_tick
        if slowest:
            text += (
                f"; slowest tick {slowest['work'] * 1e3:.3f} ms at {slowest['at']:.3f} s (publish {slowest['publish'] * 1e3:.3f}, "
                f"wait {slowest['wait'] * 1e3:.3f}, step {slowest['step'] * 1e3:.3f}, state {slowest['state'] * 1e3:.3f} ms)"
            )
        return text


class BodySimulation:
    """The robot in a physics world, driven by low_cmd_t and reporting low_state_t (no transport: see `BodyNode`)."""

    def __init__(self, world: PhysicsEngine, sensors: BodySensors, contact_sensor: bool = False, foot_force_sensor: bool = False) -> None:
        self.world = world
        self.sensors = sensors
        self.contact_sensor = contact_sensor
        self.foot_force_sensor = foot_force_sensor
        self.motors = MotorModel(world.effort_limits)
        self.command = MotorCommand()
        self.state = np.zeros(37)
        self._read_state = world.state_reader(self.state)
        self._contacts = np.zeros(4, dtype=np.int8)
        self._foot_forces = np.zeros(4)
        self.steps = 0
        self._types = _types()
        self._read_state()

    @property
    def time(self) -> float:
        return self.steps * self.world.time_step

    def step(self) -> None:
        """One physics step under the motors' torques for the held command."""
        s = self.state
        torque = self.motors.torques(self.command, s[13:25], s[25:37])
        self.world.apply_torques(torque)
        self.world.step()
        self.steps += 1
        self._read_state()

    def truth(self) -> Any:
        """The simulated robot's true state as a robot_state_t (for logs and evaluation; a robot has no such message)."""
        s = self.state
        message = self._types.robot_state_t()
        message.utime = round(self.time * 1e6)
        message.position = s[0:3].tolist()
        message.orientation = s[3:7].tolist()
        message.linear_velocity = s[7:10].tolist()
        message.angular_velocity = s[10:13].tolist()
        message.joint_positions = s[13:25].tolist()
        message.joint_velocities = s[25:37].tolist()
        message.joint_torques = self.motors.torque.tolist()
        self.world.write_foot_contacts(self._contacts)
        message.foot_contact = [bool(c) for c in self._contacts]
        message.fsm_state = -1
        message.reference = [0.0] * 7
        return message

    def low_state(self, seq: int, tick_ms: int | None = None) -> Any:
        """The body sensors now, as a low_state_t with header.seq = `seq` and tick `tick_ms` (None: the simulated time, ms)."""
        s = self.state
        readings = self.sensors.sample(self.time, s)
        message = self._types.low_state_t()
        header = self._types.header_t()
        header.utime = time.time_ns() // 1000
        header.seq = seq
        header.frame_id = "body"
        message.header = header
        message.tick = round(self.time * 1e3) if tick_ms is None else tick_ms
        message.imu_quaternion = s[3:7].tolist()
        message.imu_gyroscope = readings.gyro.tolist()
        message.imu_accelerometer = readings.acc.tolist()
        message.q = readings.joint_q.tolist()
        message.dq = readings.joint_dq.tolist()
        message.tau_est = self.motors.torque.tolist()
        if self.foot_force_sensor:
            self.world.write_foot_forces(self._foot_forces)
        message.foot_force = self._foot_forces.tolist()
        if self.contact_sensor:
            self.world.write_foot_contacts(self._contacts)
            message.foot_contact = [int(c) for c in self._contacts]
        else:
            message.foot_contact = [-1] * 4
        return message


@dataclass
class Channels:
    low_state: str
    low_cmd: str
    truth: str

    @classmethod
    def with_prefix(cls, prefix: str) -> Channels:
        return cls(prefix + ROBOT.low_state, prefix + ROBOT.low_cmd, prefix + SIM_ROBOT_STATE_NAME)


class BodyNode:
    """A `BodySimulation` on an LCM bus: commands in, states out, in real time or in lockstep."""

    def __init__(self, sim: BodySimulation, lcm: Any, channels: Channels, truth_every: int = 0) -> None:
        """`truth_every` > 0: also publish the true state (robot_state_t on the simulation channel) every that many ticks."""
        self.sim = sim
        self.truth_every = truth_every
        self.lcm = lcm
        self.channels = channels
        self.seq = 0
        self.commands_received = 0
        self.commands_rejected = 0
        self.last_answered_seq = -1
        self.timing = SimTiming()
        self._types = _types()
        self._subscription = lcm.subscribe(channels.low_cmd, self._on_command)

    def close(self) -> None:
        self.lcm.unsubscribe(self._subscription)

    def _on_command(self, _channel: str, data: bytes) -> None:
        try:
            message = self._types.low_cmd_t.decode(data)
        except (ValueError, struct.error, KeyError, IndexError, UnicodeDecodeError, OverflowError):
            # Not a low_cmd_t (wrong fingerprint, truncated): a motor driver ignores it.
            self.commands_rejected += 1
            return
        command = MotorCommand.from_message(message)
        if command is None:
            self.commands_rejected += 1
            return
        self.commands_received += 1
        self.sim.command = command
        self.last_answered_seq = int(message.state_seq)

    def _drain(self, timeout: float = 0.0) -> None:
        """Handles every command already received; waits up to `timeout` s for the first one."""
        fd = self.lcm.fileno()
        wait = timeout
        while select.select([fd], [], [], wait)[0]:
            self.lcm.handle()
            wait = 0.0

    def next_state(self, tick_ms: int | None = None) -> bytes:
        """The encoded low_state_t of the body now, with the next seq (and `tick_ms` as its tick; None: the simulated time)."""
        self.seq += 1
        return bytes(self.sim.low_state(self.seq, tick_ms).encode())

    def _drain_until_answer(self, seq: int, until_ns: int) -> None:
        """Handles commands until one answers state `seq` or CLOCK_MONOTONIC reaches `until_ns`."""
        fd = self.lcm.fileno()
        while self.last_answered_seq < seq:
            left = until_ns - time.monotonic_ns()
            if left <= 0:
                break
            if select.select([fd], [], [], left * 1e-9)[0]:
                self.lcm.handle()
        self._drain()

    def publish_state(self) -> None:
        self.lcm.publish(self.channels.low_state, self.next_state())

    def run_realtime(self, duration: float | None, stop: Callable[[], bool], rate: float = 1000.0, command_wait: float = 0.5) -> None:
        """Ticks at `rate` Hz on absolute deadlines until `stop()` or `duration` seconds of wall time.

        `command_wait`: fraction of the period a tick waits for the command answering its state
        before it steps with the newest command it has (0: it steps at once, as a robot's motor
        board applies the newest command at its tick).
        """
        if not 0.0 <= command_wait < 1.0:
            raise HarnessError(f"the command wait must be a fraction of the period in [0, 1), got {command_wait}")
        period_ns = round(1e9 / rate)
        if abs(period_ns * 1e-9 - self.sim.world.time_step) > 1e-12:
            raise HarnessError(f"the tick ({period_ns * 1e-6} ms) must equal the physics step ({self.sim.world.time_step * 1e3} ms)")
        clock = time.monotonic_ns
        start = clock()
        end = None if duration is None else start + round(duration * 1e9)
        deadline = start
        # Each tick sends the state measured at the end of the previous one first, so the states
        # leave on the tick's clock and the physics step's varying cost does not jitter them;
        # then it waits a while for the answer, as a motor driver applies a command when it
        # arrives: in time, the step runs with the torque computed from this very state (the
        # delay is the node's latency, not a tick); late, with the previous command.
        wait_ns = round(command_wait * period_ns)
        state = self.next_state(0)
        # The cyclic garbage collector off while ticking (the loop makes no reference cycles; a
        # pass over the heap with the physics world in it stalls a tick by milliseconds), and
        # what exists now moved out of its sight for good.
        gc_was_enabled = gc.isenabled()
        gc.disable()
        gc.freeze()
        try:
            self._tick_realtime(state, period_ns, wait_ns, deadline, end, stop)
        finally:
            if gc_was_enabled:
                gc.enable()

    def _tick_realtime(self, state: bytes, period_ns: int, wait_ns: int, deadline: int, end: int | None, stop: Callable[[], bool]) -> None:
        clock = time.monotonic_ns
        start = deadline
        previous: int | None = None
        timing = self.timing
        while not stop():
            deadline += period_ns
            now = clock()
            if deadline > now:
                time.sleep((deadline - now) * 1e-9)
            tick_start = clock()
            if end is not None and tick_start >= end:
                break
            if previous is not None:
                timing.period.append((tick_start - previous) * 1e-9)
            previous = tick_start
            self.lcm.publish(self.channels.low_state, state)
            published = clock()
            self._drain_until_answer(self.seq, tick_start + wait_ns)
            answered = clock()
            timing.count_command_age(max(0, self.seq - self.last_answered_seq))
            self.sim.step()
            stepped = clock()
            # Stamped with the body's clock, the tick grid in ms, as a robot's board stamps its
            # states.
            state = self.next_state((deadline + period_ns - start) // 1_000_000)
            if self.truth_every and self.sim.steps % self.truth_every == 0:
                self.lcm.publish(self.channels.truth, self.sim.truth().encode())
            done = clock()
            work = (done - tick_start) * 1e-9
            if work > timing.slowest_tick.get("work", 0.0):
                timing.slowest_tick = {
                    "work": work,
                    "at": (tick_start - start) * 1e-9,
                    "publish": (published - tick_start) * 1e-9,
                    "wait": (answered - published) * 1e-9,
                    "step": (stepped - answered) * 1e-9,
                    "state": (done - stepped) * 1e-9,
                }
            timing.work.append(work)
            timing.ticks += 1
            if done - deadline > period_ns:
                # Overran by more than a period: continue on the grid after now instead of
                # running the lost ticks back to back (the body's time falls behind the wall
                # clock by them, as a stalled robot's would).
                timing.overruns += 1
                deadline += (done - deadline) // period_ns * period_ns
        timing.wall_time = (clock() - start) * 1e-9

    def run_lockstep(self, steps: int | None, stop: Callable[[], bool], answer_timeout: float = 5.0) -> None:
        """One step per command answering the last state; stops after `steps` steps, at `stop()`, or when no answer comes for `answer_timeout` s."""
        self.publish_state()
        while not stop() and (steps is None or self.sim.steps < steps):
            waited_until = time.monotonic() + answer_timeout
            while self.last_answered_seq < self.seq:
                left = waited_until - time.monotonic()
                if left <= 0 or stop():
                    return
                self._drain(min(left, 0.1))
            start = time.perf_counter()
            self.sim.step()
            self.publish_state()
            if self.truth_every and self.sim.steps % self.truth_every == 0:
                self.lcm.publish(self.channels.truth, self.sim.truth().encode())
            self.timing.work.append(time.perf_counter() - start)
            self.timing.ticks += 1


@dataclass(frozen=True)
class RealtimeSettings:
    fifo_priority: bool
    memory_locked: bool


def set_fifo(priority: int, consequence: str) -> bool:
    """SCHED_FIFO at `priority` for the calling thread (and the threads it starts); a refusal is said on stderr with `consequence`."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as err:
        print(f"pfnav-sim: SCHED_FIFO {priority} refused ({err}): {consequence}", file=sys.stderr)
        return False
    return True


def apply_realtime(priority: int) -> RealtimeSettings:
    """SCHED_FIFO at `priority` for this process and mlockall, as pfnav-robot does; either may be refused (then said on stderr)."""
    import ctypes

    fifo = set_fifo(priority, "ordinary scheduling, more jitter")
    libc = ctypes.CDLL(None, use_errno=True)
    mcl_current, mcl_future = 1, 2
    locked = libc.mlockall(mcl_current | mcl_future) == 0
    if not locked:
        print(f"pfnav-sim: mlockall refused ({os.strerror(ctypes.get_errno())}): page faults may delay ticks", file=sys.stderr)
    return RealtimeSettings(fifo, locked)


def build_body(
    scenario_name: str | None,
    robot_config: Path | None,
    out: Path,
    engine: str = DEFAULT_ENGINE,
    seed: int = 0,
    imu_noise_scale: float = 1.0,
    contact_sensor: bool = False,
    start: tuple[float, float, float] | None = None,
    foot_force_sensor: bool = False,
) -> BodySimulation:
    """The robot of `robot_config` (None: the default) placed at the scenario's start (or `start` = x, y, yaw) in engine `engine`."""
    from . import paths
    from .pipeline import export_scenario
    from .robot import RobotDescription
    from .scenario import paper_scenario_names

    robot = RobotDescription.load(robot_config if robot_config is not None else paths.robot_config_path())
    name = scenario_name or paper_scenario_names()[0]
    scenario = export_scenario(paths.pf_plan_path(), name, out / "scenarios")
    world = make_engine(engine, scenario.terrain, robot, out / "cache")
    x, y, yaw = start if start is not None else (scenario.start[0], scenario.start[1], scenario.start_yaw)
    world.place(x, y, yaw)
    sensors = BodySensors(BodySensorConfig(seed=seed, imu_noise_scale=imu_noise_scale, contact_sensor=contact_sensor), world.time_step)
    return BodySimulation(world, sensors, contact_sensor, foot_force_sensor)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pfnav-sim",
        description="The simulated robot body as an LCM process: low_cmd_t in (PD + feed-forward motor model), physics 1 kHz, low_state_t out.",
    )
    p.add_argument("--scenario", help="paper scenario whose terrain and start the body stands on (default: the first one)")
    p.add_argument("--start", type=float, nargs=3, metavar=("X", "Y", "YAW"), help="place the robot here instead of the scenario's start")
    p.add_argument("--robot", type=Path, help="robot config (default: $PFNAV_ROBOT, else robot/quadruped.toml)")
    p.add_argument("--engine", choices=ENGINE_NAMES, default=DEFAULT_ENGINE, help="physics engine")
    p.add_argument("--lcm-url", default=os.environ.get("LCM_DEFAULT_URL", DEFAULT_LCM_URL), help="LCM URL (default: $LCM_DEFAULT_URL, else the stack's bus)")
    p.add_argument("--channel-prefix", default=DEFAULT_CHANNEL_PREFIX, help="prefix of the low_state/low_cmd channels")
    p.add_argument("--lockstep", action="store_true", help="step only when the command answering the last state has arrived (tests)")
    p.add_argument("--duration", type=float, help="stop after this many wall seconds (real time) or simulated seconds (lockstep)")
    p.add_argument("--seed", type=int, default=0, help="seed of the IMU noise")
    p.add_argument("--imu-noise-scale", type=float, default=1.0, help="multiplies the IMU's noise and bias (0: ideal)")
    p.add_argument("--contact-sensor", action="store_true", help="report the engine's foot contacts (else foot_contact = -1)")
    p.add_argument(
        "--foot-force-sensor", action="store_true", help="report each foot's contact force magnitude, N (else foot_force = 0; ~13 µs a tick)"
    )
    p.add_argument("--out", type=Path, default=Path("out/sim"), help="folder of the exported scenario and the mesh cache")
    p.add_argument(
        "--truth-rate",
        type=float,
        default=0.0,
        help="also publish the true state (robot_state_t, channel of [simulation] robot_state) at this rate, Hz (0: never)",
    )
    p.add_argument(
        "--command-wait",
        type=float,
        default=0.5,
        help=(
            "real time: fraction of a period a tick waits for the command answering its state before it steps "
            "(0: it steps at once with the newest command, one tick of actuation delay)"
        ),
    )
    p.add_argument("--priority", type=int, default=0, help="SCHED_FIFO priority (1..99) and mlockall for the real-time loop; 0: neither")
    p.add_argument("--report-json", type=Path, help="at exit, write the tick statistics and counters to this JSON file")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        print("pfnav-sim: --duration must be a positive number of seconds", file=sys.stderr)
        return 2
    from .cli import check_lcm_url
    from .planner_client import _import_lcm

    try:
        check_lcm_url(args.lcm_url, allow_host_network=False)
        sim = build_body(
            args.scenario, args.robot, args.out, args.engine, args.seed, args.imu_noise_scale, args.contact_sensor, args.start, args.foot_force_sensor
        )
    except HarnessError as err:
        print(f"pfnav-sim: {err}", file=sys.stderr)
        return 2
    lcm = _import_lcm().LCM(args.lcm_url)
    if not (math.isfinite(args.truth_rate) and 0.0 <= args.truth_rate <= 1000.0):
        print("pfnav-sim: --truth-rate must be in 0 ..= 1000 Hz", file=sys.stderr)
        return 2
    truth_every = round(1000.0 / args.truth_rate) if args.truth_rate > 0 else 0
    if not 0 <= args.priority <= 99:
        print("pfnav-sim: --priority must be 0 (ordinary scheduling) or 1..99", file=sys.stderr)
        return 2
    realtime_loop = args.priority > 0 and not args.lockstep
    if realtime_loop:
        # liblcm starts its receive thread at the subscription, with this thread's scheduling:
        # under ordinary scheduling busy ordinary processes held the commands back (a tick once
        # waited 24 ms for one), at the loop's priority it preempted the loops for every packet
        # on the bus. The lowest SCHED_FIFO priority is above the one and below the other.
        set_fifo(RECEIVE_THREAD_PRIORITY, "liblcm's receive thread runs under ordinary scheduling")
    node = BodyNode(sim, lcm, Channels.with_prefix(args.channel_prefix), truth_every)
    realtime = apply_realtime(args.priority) if realtime_loop else RealtimeSettings(False, False)
    stop_requested = stop_requested_on_signals()
    mode = "lockstep" if args.lockstep else "real time"
    print(f"pfnav-sim: {mode}, {args.engine}, channels {node.channels.low_state} / {node.channels.low_cmd} on {args.lcm_url}", file=sys.stderr, flush=True)
    if args.lockstep:
        steps = None if args.duration is None else round(args.duration / sim.world.time_step)
        node.run_lockstep(steps, stop_requested)
    else:
        node.run_realtime(args.duration, stop_requested, command_wait=args.command_wait)
    print(
        f"pfnav-sim: stopped at t={sim.time:.3f} s simulated; {node.timing.summary()}; {node.commands_received} commands, {node.commands_rejected} rejected",
        file=sys.stderr,
        flush=True,
    )
    if args.report_json is not None:
        report = {
            "mode": "lockstep" if args.lockstep else "realtime",
            "simulated_time": sim.time,
            # Simulated over wall time: below 1 when overrun ticks held the body's time back.
            "real_time_factor": sim.time / node.timing.wall_time if node.timing.wall_time > 0.0 else None,
            "states_sent": node.seq,
            "commands_received": node.commands_received,
            "commands_rejected": node.commands_rejected,
            "realtime_priority": realtime.fifo_priority,
            "memory_locked": realtime.memory_locked,
            **node.timing.to_json(),
        }
        args.report_json.write_text(json.dumps(report, indent=2) + "\n")
    node.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
