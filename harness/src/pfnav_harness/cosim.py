"""Co-simulation master: DART physics at 1 kHz, the controller FMU at its communication step.

Per communication point: DART state → FMU inputs (state, reference at plan time, terrain plane,
mode request) → fmi2DoStep(h) → joint torques, held (zero-order) for the physics steps of h.
The robot first stands (mode request "stand") for `stand_time`, then the plan clock starts and
the mode request becomes "locomotion". Every physics step is logged.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from . import fmu_runner as fr
from .body_sensors import BodySensorConfig, BodySensors
from .errors import SimulationError
from .feedback_field import FeedbackField
from .metrics import FallThresholds
from .online import OnlineNavigator
from .planner_client import Plan
from .pushes import PushSchedule
from .reference import N_COLUMNS, T_DZDX, T_DZDY, T_HEIGHT, VX, VY, YAW, YAW_RATE, X, Y
from .reference_source import FOLLOW_MODES, FieldSource, TrajectorySource, yaw_of
from .scenario import Scenario
from .world import NUM_JOINTS, Payload, QuadrupedWorld, quaternion_to_rpy

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
    friction: float = 0.8
    # Desired base height above the terrain; ≤ 0 lets the controller use its own nominal height.
    body_height: float = 0.0
    plane_radius: float = 0.3
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
    estimator: str = "groundTruth"
    body_sensors: BodySensorConfig = field(default_factory=BodySensorConfig)

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


class CoSimulation:
    """One run: one scenario, one plan (or an online navigator that replans), one FMU instance, one DART world."""

    def __init__(
        self,
        scenario: Scenario,
        plan: Plan,
        fmu_path: Path | None,
        urdf: Path,
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
        c = self.config
        self.source: TrajectorySource | FieldSource
        if c.follow == "feedback":
            if field is None:
                raise SimulationError("feedback mode needs the plan's feedback field (P-F plans carry one)")
            start_yaw = float(plan.yaw[0]) if len(plan.yaw) else scenario.start_yaw
            self.source = FieldSource(field, scenario.terrain, c.plane_radius, c.physics_dt, start_yaw)
        else:
            self.source = TrajectorySource(plan, scenario.terrain, c.plane_radius, c.heading_smoothing)
        self.world = QuadrupedWorld(scenario.terrain, urdf, cache_dir, self.config.physics_dt, self.config.friction, payload=self.config.payload)
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

    def run(self, progress: Progress | None = None) -> RunResult:
        c = self.config
        dt = c.physics_dt
        ratio = round(c.comm_step / dt)
        n_steps = max(1, round(self.duration() / dt))
        walk_start = c.stand_time

        # One row per physics step; wide per-step vectors are copied with one assignment each.
        log_t = np.arange(n_steps) * dt
        fmu = self.fmu
        world = self.world
        fsm, modes = fmu.contract.fsm, fmu.contract.mode
        inputs, outputs = fmu.inputs, fmu.outputs
        state_names = fr.NamedVector(fr.STATE_INPUTS)
        log_state = np.zeros((n_steps, len(state_names.names)))
        log_outputs = np.zeros((n_steps, len(outputs.names)))
        log_ref = np.zeros((n_steps, N_COLUMNS))
        # contacts scheduled (4), contacts actual (4), FSM state, mode request
        log_flags = np.zeros((n_steps, 10), dtype=np.int8)
        state = inputs.view(fr.STATE_INPUTS)
        ref_in = inputs.indices(list(REFERENCE_COLUMNS))
        ref_columns = np.array(list(REFERENCE_COLUMNS.values()), dtype=np.intp)
        body_height_in = inputs.index("ref.bodyHeight")
        map_origin = inputs.view(fr.HEIGHT_MAP_ORIGIN)
        map_spacing = inputs.index(fr.HEIGHT_MAP_SPACING)
        map_heights = inputs.view(fr.HEIGHT_MAP_HEIGHTS)
        input_values = inputs.values
        terrain = self.scenario.terrain
        use_map = c.height_map
        ref_row = np.zeros(N_COLUMNS)
        torques = np.zeros(NUM_JOINTS)
        source = self.source
        online = self.online
        pushes = c.pushes
        push_force = np.zeros(3)
        log_push = np.zeros((n_steps, 3)) if pushes is not None else None
        goal_since: float | None = None
        timing = Timing()
        contacts_view = fmu.contacts_array
        perf = time.perf_counter

        estimator = EstimatorInTheLoop(fmu, world, c, n_steps) if c.estimator == "kalman" else None
        fmu.initialize(0.0)
        stop_reason = "completed"
        fall_step: int | None = None
        min_height = c.fall.min_base_height
        progress_every = max(1, n_steps // 200)
        t_begin = perf()
        k = 0
        for k in range(n_steps):
            t = k * dt
            world.state_vector(state)
            if not math.isfinite(float(state.sum())):
                stop_reason = f"physics state became non-finite at t={t:.3f} s"
                break
            walking = t >= walk_start
            tau = t - walk_start
            if online is not None and walking and k % ratio == 0:
                answer = online.tick(tau, float(state[0]), float(state[1]), yaw_of(state[3:7]))
                if answer is not None:
                    if isinstance(source, FieldSource):
                        assert answer.field is not None  # the navigator only passes on P-F answers with a field
                        source.replace(answer.field)
                    else:
                        assert answer.plan is not None
                        source.replace(answer.plan, online.replans[-1].t_publish)
            source.sample(tau, state, walking, ref_row)
            if pushes is not None and walking:
                force = pushes.force_at(tau, yaw_of(state[3:7]))
                if force is not None:
                    push_force[:] = force
                    world.apply_trunk_force(force)
                    assert log_push is not None
                    log_push[k] = push_force
            # The truth is logged before the body sensors overwrite joint angles with their readings.
            log_state[k] = state
            if k % ratio == 0:
                input_values[ref_in] = ref_row[ref_columns]
                input_values[body_height_in] = c.body_height
                # The elevation map a perception stack would give: the mesh vertices around the base.
                grid = terrain.local_grid(float(state[0]), float(state[1]), fr.HEIGHT_MAP_SIZE) if use_map else None
                if grid is None:
                    input_values[map_spacing] = 0.0
                else:
                    map_origin[0], map_origin[1] = grid[0], grid[1]
                    input_values[map_spacing] = terrain.resolution
                    map_heights[:] = grid[2].ravel()
                if estimator is not None:
                    estimator.write_inputs(t, state)
                mode = modes.Locomotion if walking else modes.Stand
                t0 = perf()
                fmu.exchange_inputs(mode)
                fmu.do_step(t, c.comm_step)
                fmu.read_outputs()
                timing.fmu += perf() - t0
                torques[:] = fmu.torques
                if not math.isfinite(float(torques.sum())):
                    raise SimulationError(f"the FMU returned non-finite torques at t={t:.3f} s")
                world.apply_torques(torques)
            t0 = perf()
            world.step()
            timing.physics += perf() - t0

            log_outputs[k] = outputs.values
            log_ref[k] = ref_row
            flags = log_flags[k]
            flags[0:4] = contacts_view
            flags[4:8] = world.foot_contacts()
            flags[8] = fmu.fsm_state
            flags[9] = mode
            if estimator is not None:
                estimator.log_step(k)

            # The controller's damping state is its own verdict that the robot is down.
            if walking and fall_step is None and k % 10 == 0 and (flags[8] == fsm.Damping or self._fallen(state, min_height)):
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
        else:
            k = n_steps
        if online is not None:
            online.finish()
        if fall_step is not None and stop_reason.startswith("completed"):
            stop_reason = f"fell at t={fall_step * dt:.2f} s"
        n = min(k + 1, n_steps) if stop_reason != "completed" else n_steps
        timing.total = perf() - t_begin
        timing.simulated = n * dt
        if progress is not None:
            progress(n * dt)

        log = {
            "t": log_t[:n],
            **{key: log_state[:n, state_names.span(names)] for key, names in STATE_LOG.items()},
            "tau": log_outputs[:n, outputs.span(fr.TORQUE_OUTPUTS)],
            "ref": log_ref[:n],
            "forces": log_outputs[:n, outputs.span(fr.FORCE_OUTPUTS)],
            "contact_scheduled": log_flags[:n, 0:4],
            "contact_actual": log_flags[:n, 4:8],
            "fsm": log_flags[:n, 8],
            # The FMU's code of its damping state, so the log's FSM codes can be read without it.
            "fsm_damping": np.array(int(fsm.Damping)),
            "mpc_solve_time": log_outputs[:n, outputs.index(fr.SOLVE_TIME_OUTPUT)],
            "mode": log_flags[:n, 9],
            "walk_start": np.array(walk_start),
            "comm_step": np.array(c.comm_step),
            "physics_dt": np.array(dt),
            "follow": np.array(c.follow),
            **self.plan.to_npz_dict(),
        }
        if log_push is not None:
            log["push_force"] = log_push[:n]
        log["estimator"] = np.array(c.estimator)
        if estimator is not None:
            log.update(estimator.log(n))
        if online is not None:
            log.update(replan_log(online))
        return RunResult(self.scenario.name, self.plan.method, log, timing, stop_reason)

    def _fallen(self, state: NDArray[np.float64], min_height: float) -> bool:
        """Cheap per-step fall check (absolute tilt and height); metrics apply the full rule later."""
        ground = self.scenario.terrain.height_at(float(state[0]), float(state[1]))
        if state[2] - ground < min_height:
            return True
        roll, pitch, _ = quaternion_to_rpy(state[3:7])
        # Absolute tilt with margin for the slope the robot stands on (≤ ~15° on walkable routes).
        return abs(roll) > self.config.fall.max_roll + 0.3 or abs(pitch) > self.config.fall.max_pitch + 0.3


class EstimatorInTheLoop:
    """Kalman mode: body sensor readings into the FMU's estimator inputs, its estimate into the log.

    Joint angles reach the FMU as the encoders read them; the log keeps the DART truth.
    """

    def __init__(self, fmu: fr.ControllerFmu, world: QuadrupedWorld, config: CoSimConfig, n_steps: int) -> None:
        self.config = config
        self.world = world
        self.io = fmu.enable_estimation(config.estimator)
        self.sensors = BodySensors(config.body_sensors, config.comm_step)
        self.joint_q = fmu.inputs.view(fr.JOINT_Q)
        # est.pos, est.vel, est.rpy | imu.gyro, imu.acc | fix.pos
        self._log = np.zeros((n_steps, 18))
        self._status = np.zeros(n_steps, dtype=np.int32)
        self._fix_valid = np.zeros(n_steps, dtype=bool)
        self._new_fix = False

    def write_inputs(self, t: float, state: NDArray[np.float64]) -> None:
        readings = self.sensors.sample(t, state)
        io = self.io
        io.gyro[:] = readings.gyro
        io.acc[:] = readings.acc
        io.fix_pos[:] = readings.fix_pos
        io.fix_valid[0] = int(readings.fix_valid)
        self._new_fix = readings.fix_valid
        self.joint_q[:] = readings.joint_q
        if self.config.body_sensors.contact_sensor:
            # The last physics step's collision check: the contacts of the state just read.
            io.contact[:] = self.world.foot_contacts()

    def log_step(self, k: int) -> None:
        io = self.io
        row = self._log[k]
        row[0:3] = io.est_pos
        row[3:6] = io.est_vel
        row[6:9] = io.est_rpy
        row[9:12] = io.gyro
        row[12:15] = io.acc
        row[15:18] = io.fix_pos
        self._status[k] = io.est_status[0]
        self._fix_valid[k] = self._new_fix
        self._new_fix = False

    def log(self, n: int) -> dict[str, NDArray[np.float64]]:
        sensors = self.config.body_sensors
        return {
            "est_pos": self._log[:n, 0:3],
            "est_vel": self._log[:n, 3:6],
            "est_rpy": self._log[:n, 6:9],
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
    }


def save_log(result: RunResult, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **result.log)
