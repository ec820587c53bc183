"""Co-simulation master: physics (DART, or MuJoCo: `CoSimConfig.engine`) at 1 kHz, the controller FMU at its communication step.

Per communication point: physics state → FMU inputs (state, reference at plan time, terrain plane,
mode request) → fmi2DoStep(h) → joint torques, held (zero-order) for the physics steps of h.
The robot first stands (mode request "stand") for `stand_time`, then the plan clock starts and
the mode request becomes "locomotion". Every physics step is logged.

Forks: everything before the walk's first step (settle and stand-up) is the same for runs that
differ only in what acts after it. `run_prefix()` runs that prefix once and returns a `ForkPoint`
(DART state, the FMU's serialized state, the loop's own state and the prefix's log rows), and
`run_from(fork)` continues it in a fresh world and FMU instance to the end, giving the same
result and log as `run()`. The run's payload and friction are in its world from the fork on: the
robot stands up unloaded at `PREFIX_FRICTION` and is loaded, and the ground changed, after it
stood up. Pushes act on the walk clock only, so they never touch the prefix.
"""

from __future__ import annotations

import dataclasses
import gc
import hashlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from . import fmu_runner as fr
from .body_sensors import BodyReadings, BodySensorConfig, BodySensors, BodySensorsState
from .elevation_map import PoseBelief
from .engine import DEFAULT_ENGINE, PhysicsEngine, make_engine, validate_engine_name
from .errors import SimulationError
from .feedback_field import FeedbackField
from .metrics import FallThresholds
from .online import OnlineNavigator, map_snapshot_log, replan_field_log
from .perception import SensedMap
from .planner_client import Plan
from .pushes import PushSchedule
from .reference import N_COLUMNS, T_DZDX, T_DZDY, T_HEIGHT, TERRAIN_PLANE_RADIUS, VX, VY, YAW, YAW_RATE, X, Y
from .reference_source import FOLLOW_MODES, FieldSource, TrajectorySource, yaw_of
from .robot import RobotDescription
from .scenario import Scenario
from .world import DEFAULT_FRICTION, Payload, quaternion_to_rpy, terrain_digest

Progress = Callable[[float], None]
# FMU reference input ← column of a reference row. ref.z is the height of the local terrain plane
# whose slopes are terrain.dzdx/dzdy (the mesh under the plan, not the plan's own z).
REFERENCE_COLUMNS = {
    "ref.x": X,
    "ref.y": Y,
    "ref.z": T_HEIGHT,
    "ref.yaw": YAW,
    "ref.vx": VX,
    "ref.vy": VY,
    "ref.yawRate": YAW_RATE,
    "terrain.dzdx": T_DZDX,
    "terrain.dzdy": T_DZDY,
}
# Physics steps whose trajectory reference is sampled at once (a replan resamples from its step on).
REFERENCE_BLOCK = 500
# How far (m, per axis) the belief offset may move before the height map is registered at it
# again. A perception stack's map moves with the robot's estimate at its own update rate, not at
# 1 kHz; re-sending it on every sub-millimetre move of the estimate cost 4–13 % of an estimator
# run's wall time (the FMU takes in a changed map, the master rebuilds it), for height and
# position changes below what the controller's footholds resolve.
MAP_REGISTRATION_TOLERANCE = 0.001
# Logged state blocks: log key ← FMU state inputs.
STATE_LOG = {
    "base_pos": fr.BASE_POS,
    "base_quat": fr.BASE_QUAT,
    "base_vel": fr.BASE_VEL,
    "base_omega": fr.BASE_OMEGA,
    "q": fr.JOINT_Q,
    "dq": fr.JOINT_DQ,
}


@dataclass
class CoSimConfig:
    physics_dt: float = 0.001
    # FMU communication step; an integer multiple of physics_dt.
    comm_step: float = 0.001
    # Time the robot is asked to stand before the plan clock starts (stand-up + settle).
    stand_time: float = 1.5
    # Extra time after the plan's last sample to converge onto the goal.
    settle_time: float = 3.0
    # Stop early this long after a fall is detected (nothing useful happens afterwards).
    after_fall: float = 1.0
    friction: float = DEFAULT_FRICTION
    # Desired base height above the terrain; ≤ 0 lets the controller use its own nominal height.
    body_height: float = 0.0
    plane_radius: float = TERRAIN_PLANE_RADIUS
    # Moving-average window (s) over the plan's heading and velocity feed-forward (positions untouched).
    heading_smoothing: float = 1.0
    # Feed the controller the local elevation map (mesh vertices around the base).
    height_map: bool = True
    fall: FallThresholds = field(default_factory=FallThresholds)
    # Hard cap on simulated time (None: stand + plan + settle).
    max_duration: float | None = None
    # "trajectory": track the plan's time-indexed reference; "feedback": velocity and heading from
    # the planner's feedback field at the robot's current position.
    follow: str = "trajectory"
    # Feedback mode has no plan clock: the walk may take this many times the plan's duration
    # (plus 10 s) before the run ends without reaching the goal (online, the first plan is made
    # knowing little and detours can triple the walk).
    feedback_time_factor: float = 3.0
    # Force impulses on the trunk (walk-clock times).
    pushes: PushSchedule | None = None
    # Mass added to the trunk (the controller is not told).
    payload: Payload | None = None
    # What the controller runs on: "groundTruth" (the DART state) or "kalman" (its own estimate
    # from the body sensors below; needs an FMU with the estimator).
    estimator: str = fr.DEFAULT_ESTIMATOR
    body_sensors: BodySensorConfig = field(default_factory=BodySensorConfig)
    # The physics engine the robot walks in (engine.ENGINE_NAMES).
    engine: str = DEFAULT_ENGINE

    def validate(self) -> None:
        if not (self.physics_dt > 0 and math.isfinite(self.physics_dt)):
            raise SimulationError(f"physics_dt must be positive, got {self.physics_dt}")
        ratio = self.comm_step / self.physics_dt
        if not (self.comm_step > 0 and abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1):
            raise SimulationError(f"the FMU communication step ({self.comm_step}) must be a positive multiple of the physics step ({self.physics_dt})")
        if self.stand_time < 0 or self.settle_time < 0:
            raise SimulationError("stand_time and settle_time must be >= 0")
        if self.follow not in FOLLOW_MODES:
            raise SimulationError(f"unknown follow mode '{self.follow}' (choose from {', '.join(FOLLOW_MODES)})")
        if self.estimator not in fr.ESTIMATOR_MODES:
            raise SimulationError(f"unknown estimator mode '{self.estimator}' (choose from {', '.join(fr.ESTIMATOR_MODES)})")
        self.body_sensors.validate()
        validate_engine_name(self.engine)


# Ground and foot friction of every fork prefix (CoSimConfig's default): a run's own friction
# acts from the fork on.
PREFIX_FRICTION = DEFAULT_FRICTION
# Config fields a prefix does not depend on: applied at the fork point, or acting on the walk clock only.
APPLIED_AT_FORK = ("pushes", "payload", "friction")
# Config fields that only decide when a run ends (never before the walk starts).
RUN_END_FIELDS = ("max_duration", "settle_time", "after_fall", "fall", "feedback_time_factor")


def prefix_signature(config: CoSimConfig) -> str:
    """The config fields a fork prefix depends on, as text: all but `APPLIED_AT_FORK` and `RUN_END_FIELDS`.

    A field added to CoSimConfig later is part of it unless listed there (more prefixes, never a wrong fork).
    """
    skipped = APPLIED_AT_FORK + RUN_END_FIELDS
    return ";".join(f"{f.name}={getattr(config, f.name)!r}" for f in dataclasses.fields(config) if f.name not in skipped)


def walk_start_step(config: CoSimConfig) -> int:
    """The first physics step of the walk (the first k with k·dt ≥ stand_time): where runs fork."""
    k = max(0, math.ceil(config.stand_time / config.physics_dt) - 1)
    while k * config.physics_dt < config.stand_time:
        k += 1
    return k


def prefix_config(config: CoSimConfig) -> CoSimConfig:
    """The configuration the fork prefix of runs with `config` is simulated in: no push, no payload, `PREFIX_FRICTION`."""
    return dataclasses.replace(config, pushes=None, payload=None, friction=PREFIX_FRICTION)


@dataclass
class Timing:
    physics: float = 0.0
    fmu: float = 0.0
    total: float = 0.0
    simulated: float = 0.0

    @property
    def overhead(self) -> float:
        return max(self.total - self.physics - self.fmu, 0.0)

    def per_sim_second(self) -> dict[str, float]:
        s = self.simulated if self.simulated > 0 else float("nan")
        return {
            "physics": self.physics / s,
            "fmu": self.fmu / s,
            "overhead": self.overhead / s,
            "total": self.total / s,
        }


@dataclass
class RunResult:
    scenario: str
    method: str
    log: dict[str, NDArray[np.float64]]
    timing: Timing
    stop_reason: str
    # Physics step (log row) at which the fall rule fired; None when the robot did not fall.
    fall_step: int | None = None


@dataclass(frozen=True)
class EstimatorLogState:
    """The estimator's log rows before a fork and its body sensors' state there."""

    rows: NDArray[np.float64]
    status: NDArray[np.int32]
    fix_valid: NDArray[np.bool_]
    new_fix: bool
    sensors: BodySensorsState


@dataclass(frozen=True)
class ForkPoint:
    """A run stopped just before its walk's first step, to be continued by `CoSimulation.run_from` (picklable).

    `key` names the prefix (`CoSimulation.fork_key`); `step` is the first step still to run; the
    `log_*` arrays are the prefix's rows of the loop's logs; `fmu_io` holds the values the master
    last exchanged with the FMU (held between communication points), `mode` the mode request last
    sent; `timing` is the prefix's share of the run's timing.
    """

    key: str
    step: int
    # The physics engine's snapshot (`PhysicsEngine.snapshot`).
    world: object
    fmu_state: bytes
    fmu_io: fr.FmuIoSnapshot
    mode: int
    friction: float
    log_state: NDArray[np.float64]
    log_outputs: NDArray[np.float64]
    log_ref: NDArray[np.float64]
    log_flags: NDArray[np.int8]
    estimator: EstimatorLogState | None
    belief_offset: NDArray[np.float64]
    map_offset: NDArray[np.float64]
    timing: Timing


@dataclass
class _Loop:
    """The master loop's state between calls of `CoSimulation._advance` (one run)."""

    n_steps: int
    state_names: fr.NamedVector
    log_state: NDArray[np.float64]
    log_outputs: NDArray[np.float64]
    log_ref: NDArray[np.float64]
    log_flags: NDArray[np.int8]
    log_push: NDArray[np.float64] | None
    estimator: EstimatorInTheLoop | None
    timing: Timing
    # Estimate − truth at the last communication point (dx, dy, dz, dyaw); zeros without an estimator.
    belief_offset: NDArray[np.float64] = field(default_factory=lambda: np.zeros(4))
    # The offset (dx, dy, dz) the height map inputs were last registered at (`MAP_REGISTRATION_TOLERANCE`).
    map_offset: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    # The next step to simulate; after a stop, the number of logged rows.
    k: int = 0
    mode: int = 0
    fall_step: int | None = None
    goal_since: float | None = None
    stop_reason: str | None = None


class CoSimulation:
    """One run: one scenario, one plan (or an online navigator that replans), one FMU instance, one physics world (`config.engine`)."""

    def __init__(
        self,
        scenario: Scenario,
        plan: Plan,
        fmu_path: Path | None,
        robot: RobotDescription,
        cache_dir: Path,
        config: CoSimConfig | None = None,
        controller: fr.ControllerFmu | None = None,
        field: FeedbackField | None = None,
        online: OnlineNavigator | None = None,
    ) -> None:
        """`controller` replaces the FMU at `fmu_path` (tests use a Python stand-in with the same interface).

        Feedback mode needs the plan's `field`; with `online` the navigator's replans replace the
        plan (or field) while the robot walks.
        """
        self.config = config or CoSimConfig()
        self.config.validate()
        self.scenario = scenario
        self.plan = plan
        self.online = online
        self.robot = robot
        c = self.config
        self.source: TrajectorySource | FieldSource
        if c.follow == "feedback":
            if field is None:
                raise SimulationError("feedback mode needs the plan's feedback field (P-F plans carry one)")
            start_yaw = float(plan.yaw[0]) if len(plan.yaw) else scenario.start_yaw
            self.source = FieldSource(field, scenario.terrain, c.plane_radius, c.physics_dt, start_yaw)
        else:
            self.source = TrajectorySource(plan, scenario.terrain, c.plane_radius, c.heading_smoothing)
        self.world: PhysicsEngine = make_engine(c.engine, scenario.terrain, robot, cache_dir, c.physics_dt, c.friction, payload=c.payload)
        start_yaw = float(plan.yaw[0]) if len(plan.yaw) else scenario.start_yaw
        self.world.place(float(plan.x[0]), float(plan.y[0]), start_yaw)
        if controller is not None:
            self.fmu = controller
        elif fmu_path is not None:
            self.fmu = fr.ControllerFmu(fmu_path)
        else:
            raise SimulationError("either an FMU path or a controller is needed")

    def close(self) -> None:
        self.fmu.close()

    def __enter__(self) -> CoSimulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def duration(self) -> float:
        c = self.config
        walk = self.plan.duration
        if c.follow == "feedback" or self.online is not None:
            walk = c.feedback_time_factor * walk + 10.0
        total = c.stand_time + walk + c.settle_time
        return min(total, c.max_duration) if c.max_duration is not None else total

    def walk_start_step(self) -> int:
        return walk_start_step(self.config)

    def fork_key(self) -> str:
        """What the prefix up to `walk_start_step` depends on, as a digest: runs with equal keys share a fork.

        Covers the FMU, the robot (its config, URDF and meshes by content), the scenario's terrain and start, the
        plan and the config's `prefix_signature`.
        """
        h = hashlib.sha256()
        guid = getattr(getattr(self.fmu, "info", None), "guid", type(self.fmu).__name__)
        # The robot by content: an edited config or URDF at the same path is another robot.
        h.update(f"fmu={guid};robot={self.robot.digest};scenario={self.scenario.name};start_yaw={self.scenario.start_yaw!r};".encode())
        h.update(terrain_digest(self.scenario.terrain).encode())
        for name, values in self.plan.to_npz_dict().items():
            h.update(name.encode())
            h.update(np.ascontiguousarray(values, dtype=np.float64).tobytes())
        h.update(prefix_signature(self.config).encode())
        return h.hexdigest()[:16]

    def run(self, progress: Progress | None = None) -> RunResult:
        """The whole run from the robot's placement: stand-up, walk, settle."""
        loop = self._start_loop()
        self._advance(loop, loop.n_steps, progress)
        return self._result(loop, progress)

    def run_prefix(self) -> ForkPoint:
        """Runs the common prefix (settle and stand-up, every step before `walk_start_step`) and returns its fork point.

        The simulation must be set up like the prefix (`prefix_config`: no payload, the prefix
        friction); its world and FMU are left at the fork point.
        """
        c = self.config
        if c.payload is not None or c.friction != PREFIX_FRICTION:
            raise SimulationError(
                f"a fork prefix runs without payload and at friction {PREFIX_FRICTION} (the run's own are applied at the fork): "
                f"build it with prefix_config(config), got payload {c.payload} and friction {c.friction}"
            )
        if self.online is not None:
            raise SimulationError("runs with an online navigator cannot fork (its planner service is not part of the saved state)")
        loop = self._start_loop()
        end = self.walk_start_step()
        if end >= loop.n_steps:
            raise SimulationError(f"the run ends ({loop.n_steps} steps) before the walk starts (step {end}): there is nothing to fork")
        self._advance(loop, end, None)
        if loop.stop_reason is not None:
            raise SimulationError(f"the prefix stopped before the walk: {loop.stop_reason}")
        est = loop.estimator
        return ForkPoint(
            key=self.fork_key(),
            step=end,
            world=self.world.snapshot(),
            fmu_state=self.fmu.save_state(),
            fmu_io=self.fmu.io_snapshot(),
            mode=loop.mode,
            friction=c.friction,
            log_state=loop.log_state[:end].copy(),
            log_outputs=loop.log_outputs[:end].copy(),
            log_ref=loop.log_ref[:end].copy(),
            log_flags=loop.log_flags[:end].copy(),
            estimator=None if est is None else est.save(end),
            belief_offset=loop.belief_offset.copy(),
            map_offset=loop.map_offset.copy(),
            timing=dataclasses.replace(loop.timing),
        )

    def run_from(self, fork: ForkPoint, progress: Progress | None = None) -> RunResult:
        """Continues `fork` to the end of this run; the result and log are laid out as `run()`'s (prefix rows included).

        This simulation's payload and friction act from the fork on (the robot is loaded after it
        stood up); its pushes, duration and end rules are its own. Its prefix must be the fork's
        (equal `fork_key`). The result's timing includes the prefix's (as measured when it ran).
        """
        key = self.fork_key()
        if fork.key != key:
            raise SimulationError(
                f"fork {fork.key} was taken from another prefix than this run's ({key}): terrain, plan, FMU, communication step, "
                "estimator, sensor seed or stand time differ"
            )
        if self.online is not None:
            raise SimulationError("runs with an online navigator cannot fork (its planner service is not part of the saved state)")
        loop = self._start_loop()
        if fork.step >= loop.n_steps:
            raise SimulationError(f"the run ends ({loop.n_steps} steps) before its fork point (step {fork.step}): run it from the start")
        self.world.restore(fork.world)
        self.fmu.restore_state(fork.fmu_state)
        self.fmu.restore_io(fork.fmu_io)
        k = fork.step
        loop.log_state[:k] = fork.log_state
        loop.log_outputs[:k] = fork.log_outputs
        loop.log_ref[:k] = fork.log_ref
        loop.log_flags[:k] = fork.log_flags
        if (loop.estimator is None) != (fork.estimator is None):
            raise SimulationError("the fork and this run differ in whether the estimator runs")
        if loop.estimator is not None and fork.estimator is not None:
            loop.estimator.restore(fork.estimator)
        loop.belief_offset[:] = fork.belief_offset
        loop.map_offset[:] = fork.map_offset
        loop.k = k
        loop.mode = fork.mode
        loop.timing = dataclasses.replace(fork.timing)
        self._advance(loop, loop.n_steps, progress)
        return self._result(loop, progress)

    def _start_loop(self) -> _Loop:
        """The loop's logs (one row per physics step, preallocated) and the initialised FMU, at step 0."""
        c = self.config
        n_steps = max(1, round(self.duration() / c.physics_dt))
        state_names = fr.NamedVector(fr.STATE_INPUTS)
        loop = _Loop(
            n_steps=n_steps,
            state_names=state_names,
            log_state=np.zeros((n_steps, len(state_names.names))),
            log_outputs=np.zeros((n_steps, len(self.fmu.outputs.names))),
            log_ref=np.zeros((n_steps, N_COLUMNS)),
            # contacts scheduled (4), contacts actual (4), FSM state, mode request
            log_flags=np.zeros((n_steps, 10), dtype=np.int8),
            log_push=np.zeros((n_steps, 3)) if c.pushes is not None else None,
            estimator=EstimatorInTheLoop(self.fmu, self.world, c, n_steps) if c.estimator == "kalman" else None,
            timing=Timing(),
        )
        self.fmu.initialize(0.0)
        return loop

    def _advance(self, loop: _Loop, end: int, progress: Progress | None) -> None:
        """Physics steps loop.k … end − 1, or until the run stops (sets loop.stop_reason).

        The hot loop (its Python part was about 40 % of a run's wall time at 1 kHz): everything
        it touches is looked up once per call, nothing is allocated per step, and what only
        changes at a communication point (or when the robot crosses a map cell) is only redone
        then. The cyclic garbage collector is off meanwhile: the loop makes no reference cycles,
        and its passes over the whole heap showed as ~4 % of a run.
        """
        gc_was_enabled = gc.isenabled()
        gc.disable()
        try:
            self._advance_steps(loop, end, progress)
        finally:
            if gc_was_enabled:
                gc.enable()

    def _advance_steps(self, loop: _Loop, end: int, progress: Progress | None) -> None:
        c = self.config
        dt = c.physics_dt
        ratio = round(c.comm_step / dt)
        n_steps = loop.n_steps
        walk_start = c.stand_time

        fmu = self.fmu
        world = self.world
        fsm, modes = fmu.contract.fsm, fmu.contract.mode
        inputs, outputs = fmu.inputs, fmu.outputs
        log_state, log_outputs, log_ref, log_flags, log_push = loop.log_state, loop.log_outputs, loop.log_ref, loop.log_flags, loop.log_push
        state = inputs.view(fr.STATE_INPUTS)
        read_state = world.state_reader(state)
        ref_in = inputs.indices(list(REFERENCE_COLUMNS))
        ref_columns = np.array(list(REFERENCE_COLUMNS.values()), dtype=np.intp)
        # A constant of the run: written once, kept by the FMU's input buffer.
        inputs.values[inputs.index("ref.bodyHeight")] = c.body_height
        map_origin = inputs.view(fr.HEIGHT_MAP_ORIGIN)
        map_spacing = inputs.index(fr.HEIGHT_MAP_SPACING)
        map_heights = inputs.view(fmu.contract.height_map_heights)
        map_size = fmu.contract.height_map_size
        input_values = inputs.values
        terrain = self.scenario.terrain
        use_map = c.height_map
        # The block corner of the height map last written to the inputs (None: not written by
        # this call yet, so the first communication point writes it) and the belief offset it was
        # registered at (kept across calls and forks, so a continued run writes the same map).
        map_corner: object = None
        map_written = False
        map_offset = loop.map_offset
        ref_row = np.zeros(N_COLUMNS)
        # The torques of the last doStep, a live view of the output buffer.
        torques = outputs.values[outputs.span(fr.TORQUE_OUTPUTS)]
        output_values = outputs.values
        source = self.source
        # A trajectory's reference depends on the clock alone: it is sampled for a block of steps
        # at once, straight into the log (rows loop.k … ref_end − 1 are sampled), and again from
        # the current step when a replan swaps the plan.
        block_source = source if isinstance(source, TrajectorySource) else None
        ref_end = loop.k
        # The feedback law is sampled at the believed pose every step.
        pose_every_step = block_source is None
        online = self.online
        # A real terrain sensor scans from the true trunk; its map places the returns at the belief.
        senses_terrain = online is not None and online.senses_terrain
        pushes = c.pushes
        push_force = np.zeros(3)
        goal_since = loop.goal_since
        fall_step = loop.fall_step
        mode = loop.mode
        timing = loop.timing
        # The loop's own clocks, added to `timing` when it returns (an attribute update per step costs more).
        fmu_seconds = physics_seconds = 0.0
        contacts_view = fmu.contacts_array
        perf = time.perf_counter
        estimator = loop.estimator
        offset = loop.belief_offset
        # The pose the robot's navigation works with: x, y, yaw (truth + offset).
        pose = np.zeros(3)
        true_yaw = 0.0
        # A log row's flags: scheduled contacts, actual contacts, FSM state, mode request. All but
        # the actual contacts only change at communication points.
        flags = np.zeros(10, dtype=np.int8)
        flags[0:4] = contacts_view
        flags[8] = fmu.fsm_state
        flags[9] = mode
        # The engine writes the actual contacts through a boolean view of their bytes (0 or 1, no casting).
        actual_contacts = flags[4:8].view(np.bool_)
        write_contacts = world.write_foot_contacts
        world_step = world.step
        damping = int(fsm.Damping)
        locomotion, stand = int(modes.Locomotion), int(modes.Stand)
        # Finiteness checks by sums: a vector is finite when its sum is (short of an overflow
        # past 1e308). A dot product with ones is that sum in about half the time of
        # np.add.reduce (ndarray.sum costs more still: a Python-level wrapper).
        state_sum, torque_sum = state.dot, torques.dot
        state_ones, torque_ones = np.ones(len(state)), np.ones(len(torques))
        # Without an estimator the belief offset stays zero: only the block corner moves the map.
        offset_moves = estimator is not None
        stop_reason: str | None = None
        fall_every = c.fall.every_steps
        progress_every = max(1, n_steps // 200)
        isfinite = math.isfinite
        t_begin = perf()
        k = loop.k
        for k in range(loop.k, end):
            t = k * dt
            read_state()
            # (np.float64 is a float: math.isfinite takes it as it is)
            if not isfinite(state_sum(state_ones)):
                stop_reason = f"physics state became non-finite at t={t:.3f} s"
                break
            walking = t >= walk_start
            tau = t - walk_start
            comm = k % ratio == 0
            if pose_every_step or (pushes is not None and walking) or (comm and (online is not None or estimator is not None)):
                true_yaw = yaw_of(state[3:7])
                pose[0] = state[0] + offset[0]
                pose[1] = state[1] + offset[1]
                pose[2] = true_yaw + offset[3]
            if senses_terrain and walking and comm:
                assert online is not None
                # The poses are built only when a scan is due (5–10 Hz), not every control step.
                if online.scan_due(tau):
                    io = None if estimator is None else estimator.io
                    online.sense(tau, state[0:3].copy(), state[3:7].copy(), believed_trunk_pose(state, offset, io))
            if online is not None and walking and comm:
                variance = None if estimator is None else estimator.io.est_pos_var
                answer = online.tick(tau, float(pose[0]), float(pose[1]), float(pose[2]), variance)
                if answer is not None:
                    if isinstance(source, FieldSource):
                        assert answer.field is not None  # the navigator only passes on P-F answers with a field
                        source.replace(answer.field)
                    else:
                        assert answer.plan is not None
                        source.replace(answer.plan, online.replans[-1].t_publish)
                        ref_end = k
            if block_source is not None:
                if k >= ref_end:
                    ref_end = min(end, k + REFERENCE_BLOCK)
                    t_block = np.arange(k, ref_end) * dt
                    block_source.sample_block(t_block - walk_start, t_block >= walk_start, log_ref[k:ref_end])
                ref_row = log_ref[k]
            else:
                source.sample(tau, pose, offset, walking, ref_row)
                log_ref[k] = ref_row
            if pushes is not None and walking:
                force = pushes.force_at(tau, true_yaw)
                if force is not None:
                    push_force[:] = force
                    world.apply_trunk_force(force)
                    assert log_push is not None
                    log_push[k] = push_force
            # The truth is logged before the body sensors overwrite joint angles with their readings.
            log_state[k] = state
            if comm:
                input_values[ref_in] = ref_row[ref_columns]
                # The elevation map a perception stack would give: the mesh vertices around the base,
                # in the robot's estimated frame (perception measures the ground relative to the body).
                map_changed = False
                if use_map:
                    corner = terrain.local_grid_corner(float(state[0]), float(state[1]), map_size)
                    if offset_moves and (
                        abs(offset[0] - map_offset[0]) > MAP_REGISTRATION_TOLERANCE
                        or abs(offset[1] - map_offset[1]) > MAP_REGISTRATION_TOLERANCE
                        or abs(offset[2] - map_offset[2]) > MAP_REGISTRATION_TOLERANCE
                    ):
                        map_offset[:] = offset[0:3]
                        map_written = False
                    if not map_written or corner != map_corner:
                        map_corner, map_written, map_changed = corner, True, True
                        grid = terrain.local_grid(float(state[0]), float(state[1]), map_size)
                        if grid is None:
                            input_values[map_spacing] = 0.0
                        else:
                            map_origin[0], map_origin[1] = grid[0] + map_offset[0], grid[1] + map_offset[1]
                            input_values[map_spacing] = terrain.resolution
                            map_heights[:] = grid[2].ravel() + map_offset[2]
                elif not map_written:
                    map_written, map_changed = True, True
                    input_values[map_spacing] = 0.0
                if estimator is not None:
                    estimator.write_inputs(t, state)
                mode = locomotion if walking else stand
                t0 = perf()
                fmu.exchange_inputs(mode, height_map=map_changed)
                fmu.do_step(t, c.comm_step)
                fmu.read_outputs()
                fmu_seconds += perf() - t0
                if not isfinite(torque_sum(torque_ones)):
                    raise SimulationError(f"the FMU returned non-finite torques at t={t:.3f} s")
                if estimator is not None:
                    estimator.belief_offset(state, true_yaw, offset)
                world.apply_torques(torques)
                flags[0:4] = contacts_view
                flags[8] = fmu.fsm_state
                flags[9] = mode
            t0 = perf()
            world_step()
            physics_seconds += perf() - t0

            log_outputs[k] = output_values
            write_contacts(actual_contacts)
            log_flags[k] = flags
            if estimator is not None:
                estimator.log_step(k)

            # The controller's damping state is its own verdict that the robot is down.
            if walking and fall_step is None and k % fall_every == 0 and (flags[8] == damping or self._fallen(state)):
                fall_step = k
            if fall_step is not None and (k - fall_step) * dt >= c.after_fall:
                stop_reason = f"fell at t={fall_step * dt:.2f} s"
                break
            if source.finished:
                goal_since = t if goal_since is None else goal_since
                if t - goal_since >= c.settle_time:
                    stop_reason = "completed: stood at the goal"
                    break
            else:
                goal_since = None
            if progress is not None and k % progress_every == 0:
                progress(t)
        timing.total += perf() - t_begin
        timing.fmu += fmu_seconds
        timing.physics += physics_seconds
        # Rows 0 … loop.k − 1 are the log: a stopped run keeps the step it stopped in.
        loop.k = k + 1 if stop_reason is not None else max(end, loop.k)
        loop.stop_reason = stop_reason
        loop.mode = int(mode)
        loop.fall_step = fall_step
        loop.goal_since = goal_since

    def _result(self, loop: _Loop, progress: Progress | None) -> RunResult:
        c = self.config
        dt = c.physics_dt
        fmu = self.fmu
        online = self.online
        if online is not None:
            online.finish()
        stop_reason = loop.stop_reason or "completed"
        if loop.fall_step is not None and stop_reason.startswith("completed"):
            stop_reason = f"fell at t={loop.fall_step * dt:.2f} s"
        n = min(loop.k, loop.n_steps)
        loop.timing.simulated = n * dt
        if progress is not None:
            progress(n * dt)

        outputs, state_names = fmu.outputs, loop.state_names
        log_outputs, log_flags = loop.log_outputs, loop.log_flags
        log = {
            "t": np.arange(loop.n_steps)[:n] * dt,
            **{key: loop.log_state[:n, state_names.span(names)] for key, names in STATE_LOG.items()},
            "tau": log_outputs[:n, outputs.span(fr.TORQUE_OUTPUTS)],
            "ref": loop.log_ref[:n],
            "forces": log_outputs[:n, outputs.span(fr.FORCE_OUTPUTS)],
            "contact_scheduled": log_flags[:n, 0:4],
            "contact_actual": log_flags[:n, 4:8],
            "fsm": log_flags[:n, 8],
            # The FMU's code of its damping state, so the log's FSM codes can be read without it.
            "fsm_damping": np.array(int(fmu.contract.fsm.Damping)),
            # The FSM's state names and their codes, as the FMU's modelDescription declares them.
            "fsm_state_names": np.array([state.name for state in fmu.contract.fsm]),
            "fsm_state_codes": np.array([int(state) for state in fmu.contract.fsm], dtype=np.int64),
            "mpc_solve_time": log_outputs[:n, outputs.index(fr.SOLVE_TIME_OUTPUT)],
            "mode": log_flags[:n, 9],
            "walk_start": np.array(c.stand_time),
            "comm_step": np.array(c.comm_step),
            "physics_dt": np.array(dt),
            "follow": np.array(c.follow),
            **self.plan.to_npz_dict(),
        }
        if loop.log_push is not None:
            log["push_force"] = loop.log_push[:n]
        log["estimator"] = np.array(c.estimator)
        log["engine"] = np.array(c.engine)
        if loop.estimator is not None:
            log.update(loop.estimator.log(n))
        if online is not None:
            log.update(replan_log(online))
            if isinstance(online.belief, SensedMap) and n > 0:
                errors, sigmas = online.belief.height_errors(loop.log_state[n - 1, 0:3], loop.belief_offset)
                log["map_height_error"] = errors
                log["map_height_sigma"] = sigmas
                # The sensed map at the end, in the estimator's frame (NaN/inf where unknown).
                log["map_heights_final"] = online.belief.map.heights.copy()
                log["map_variances_final"] = online.belief.map.variances.copy()
                log["map_measurement_variances_final"] = online.belief.map.measurement_variances()
        return RunResult(self.scenario.name, self.plan.method, log, loop.timing, stop_reason, loop.fall_step)

    def _fallen(self, state: NDArray[np.float64]) -> bool:
        """The height and tilt part of the fall rule (`FallThresholds`) at the state just read."""
        ground = self.scenario.terrain.height_at(float(state[0]), float(state[1]))
        roll, pitch, _ = quaternion_to_rpy(state[3:7])
        return self.config.fall.fallen(float(state[2]) - ground, roll, pitch)


class EstimatorInTheLoop:
    """Kalman mode: body sensor readings into the FMU's estimator inputs, its estimate into the log.

    Joint angles reach the FMU as the encoders read them; the log keeps the DART truth.
    """

    def __init__(self, fmu: fr.ControllerFmu, world: PhysicsEngine, config: CoSimConfig, n_steps: int) -> None:
        self.config = config
        self.world = world
        self.io = io = fmu.enable_estimation(config.estimator)
        if config.body_sensors.fix_rate > 0.0:
            # The estimator is told the fix receiver's noise, as a user sets it from its datasheet
            # (left at its default it would trust 0.5 m fixes to 2 cm and jump with each of them).
            fmu.set_parameters({fr.FIX_NOISE_PARAMETER: max(config.body_sensors.fix_noise, 1e-4)})
        # The sensors write their IMU and fix readings straight into the FMU's input buffers.
        readings = BodyReadings(gyro=io.gyro, acc=io.acc, fix_pos=io.fix_pos)
        self.sensors = BodySensors(config.body_sensors, config.comm_step, readings)
        self.joint_q = fmu.inputs.view(fr.JOINT_Q)
        # est.pos, est.vel, est.rpy | imu.gyro, imu.acc | fix.pos | est.posVar
        self._log = np.zeros((n_steps, 21))
        self._status = np.zeros(n_steps, dtype=np.int32)
        self._fix_valid = np.zeros(n_steps, dtype=bool)
        self._new_fix = False

    def write_inputs(self, t: float, state: NDArray[np.float64]) -> None:
        readings = self.sensors.sample(t, state)
        io = self.io
        io.fix_valid[0] = int(readings.fix_valid)
        self._new_fix = readings.fix_valid
        self.joint_q[:] = readings.joint_q
        if self.config.body_sensors.contact_sensor:
            # The last physics step's collision check: the contacts of the state just read.
            io.contact[:] = self.world.foot_contacts()

    def belief_offset(self, state: NDArray[np.float64], true_yaw: float, out: NDArray[np.float64]) -> None:
        """Estimate − truth after a communication step: dx, dy, dz, dyaw (wrapped to ±π) into `out`.

        `state` is the truth the step started from; at one control tick per step the estimate is of
        that same instant.
        """
        io = self.io
        ex, ey, ez = io.est_pos.tolist()
        x, y, z = state[0:3].tolist()
        new = (ex - x, ey - y, ez - z, math.remainder(float(io.est_rpy[2]) - true_yaw, math.tau))
        # A lost estimate (the FMU says so in est.status) keeps the last good offset.
        if math.isfinite(sum(new)):
            out[:] = new

    def log_step(self, k: int) -> None:
        io = self.io
        row = self._log[k]
        row[0:9] = io.estimate_block
        row[9:18] = io.sensor_block
        row[18:21] = io.est_pos_var
        self._status[k] = io.est_status[0]
        self._fix_valid[k] = self._new_fix
        self._new_fix = False

    def save(self, n: int) -> EstimatorLogState:
        """The first `n` log rows and the sensors' state (a fork at step `n`)."""
        return EstimatorLogState(self._log[:n].copy(), self._status[:n].copy(), self._fix_valid[:n].copy(), self._new_fix, self.sensors.save_state())

    def restore(self, saved: EstimatorLogState) -> None:
        n = len(saved.rows)
        self._log[:n] = saved.rows
        self._status[:n] = saved.status
        self._fix_valid[:n] = saved.fix_valid
        self._new_fix = saved.new_fix
        self.sensors.restore_state(saved.sensors)

    def log(self, n: int) -> dict[str, NDArray[np.float64]]:
        sensors = self.config.body_sensors
        return {
            "est_pos": self._log[:n, 0:3],
            "est_vel": self._log[:n, 3:6],
            "est_rpy": self._log[:n, 6:9],
            "est_pos_var": self._log[:n, 18:21],
            "est_status": self._status[:n],
            "imu_gyro": self._log[:n, 9:12],
            "imu_acc": self._log[:n, 12:15],
            "fix_pos": self._log[:n, 15:18],
            "fix_valid": self._fix_valid[:n],
            "fix_rate": np.array(sensors.fix_rate),
            "fix_noise": np.array(sensors.fix_noise),
            "sensor_seed": np.array(sensors.seed),
            "imu_model": np.array(sensors.imu.name),
            "encoder_model": np.array(sensors.encoder.name),
            "contact_sensor": np.array(sensors.contact_sensor),
        }


def believed_trunk_pose(state: NDArray[np.float64], offset: NDArray[np.float64], io: fr.EstimationIo | None = None) -> PoseBelief:
    """The trunk pose the robot believes: the truth moved by the estimate's offset (dx, dy, dz, dyaw),
    with the estimator's position and attitude variances (`io`; none: ground truth, exact).
    """
    half = 0.5 * float(offset[3])
    cz, sz = math.cos(half), math.sin(half)
    w, x, y, z = state[3:7].tolist()
    # q_yaw ⊗ q_true: the yaw error turns the trunk about the world's vertical.
    quaternion = np.array([cz * w - sz * z, cz * x - sz * y, cz * y + sz * x, cz * z + sz * w])
    if io is None:
        return PoseBelief(state[0:3] + offset[0:3], quaternion, np.zeros((3, 3)), np.zeros(3))
    return PoseBelief(state[0:3] + offset[0:3], quaternion, np.diag(io.est_pos_var), io.est_att_var.copy())


def replan_log(online: OnlineNavigator) -> dict[str, NDArray[np.float64]]:
    """The replans as flat arrays (npz-friendly): one row per map update, paths concatenated."""
    replans = online.replans
    lengths = np.array([len(r.path_x) for r in replans], dtype=np.int64)
    nan = float("nan")
    return {
        "replan_t_publish": np.array([r.t_publish for r in replans]),
        "replan_t_apply": np.array([nan if r.t_apply is None else r.t_apply for r in replans]),
        "replan_latency": np.array([nan if r.service_latency is None else r.service_latency for r in replans]),
        "replan_in_use": np.array([r.in_use for r in replans]),
        "replan_kind": np.array([r.kind for r in replans]),
        "replan_outcome": np.array([r.outcome for r in replans]),
        "replan_changed_cells": np.array([r.changed_cells for r in replans], dtype=np.int64),
        "replan_path_lengths": lengths,
        "replan_path_x": np.concatenate([r.path_x for r in replans]) if replans else np.zeros(0),
        "replan_path_y": np.concatenate([r.path_y for r in replans]) if replans else np.zeros(0),
        "known_final": online.belief.known.copy(),
        **replan_field_log(replans),
        **map_snapshot_log(replans),
    }


def save_log(result: RunResult, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **result.log)
