"""Incline benchmark: stand up on an inclined plane and walk a straight line up, down or across it.

The terrain is one plane rising along +x at `angle` degrees (heights ≥ 0, 8 m × 8 m at the paper
maps' 0.125 m resolution, so the robot starts ≥ 2.5 m from every edge). The reference is a
straight walk of `distance` metres (horizontal) through the map centre, built directly as a
`Plan` timed at the planner's nominal speed: no planner is needed for a straight line.

What a run is judged by (`InclineOutcome`, from the co-simulation log and a probe on the physics
world that records foot positions and non-foot contacts):
- stood up: at the walk start the controller is in its stand state, the base is at least
  `STOOD_HEIGHT_FRACTION` of the nominal stand height above the ground and it has not fallen;
- walked: horizontal displacement of the base along the walking direction, walk start → end (or
  → the fall);
- fell: the harness's fall rule (`metrics.judge_fall`: height, tilt, controller damping),
  extended to the stand-up (tilt and damping only: the base starts crouched);
- slip: largest tangential displacement of the foot's material contact point during one stance
  (the point of the foot sphere that touched down, followed in the foot's frame, so rolling of
  the sphere is not counted);
- attitude error: body pitch and roll minus those of a body levelled with the plane;
- torque: peak |commanded torque| / effort limit, per joint (> 1: the physics clamps it).

The robot is set down lying on the plane (`lying_pose`: the robot config's crouch bent further),
body parallel to it, as one would put a robot down on a steep slope: in the crouch a robot
stands almost at full height, and on a 30° plane its centre of mass then lies outside its feet
across the slope before the controller has done anything (docs/slopes.md, 3b).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import fmu_runner as fr
from .cosim import CoSimConfig, CoSimulation, RunResult
from .engine import DEFAULT_ENGINE, PhysicsEngine
from .errors import ScenarioError, SimulationError
from .metrics import FallThresholds, judge_fall, rms_tracking_error, roll_pitch_yaw, terrain_pitch_roll
from .planner_client import Plan
from .robot import RobotDescription
from .scenario import GoalRegion, Scenario, Terrain
from .world import DEFAULT_FRICTION

FloatArray = NDArray[np.float64]

# Walking direction → heading relative to the uphill direction (+x): "across" walks along the
# contour with the slope rising to the robot's right.
DIRECTIONS: dict[str, float] = {"up": 0.0, "down": math.pi, "across": math.pi / 2.0}
# The planner's default nominal speed (planner/core/src/trajectory.rs, TrajectoryOptions), which
# the demo's plans are timed at.
NOMINAL_SPEED = 0.5
# The planner's default trajectory sample period, s.
SAMPLE_PERIOD = 0.1
MAP_SIZE = 8.0
# The paper maps' resolution (16 m / 128 cells).
MAP_RESOLUTION = 0.125
WALK_DISTANCE = 3.0
# Distance along the direction a run must walk to pass the benchmark (of `WALK_DISTANCE`), m.
MIN_WALKED = 2.5
MAX_ANGLE_DEG = 60.0
# At the walk start the base must be this fraction of the nominal stand height above the ground.
STOOD_HEIGHT_FRACTION = 0.75
# A foot that loses contact for longer than this (s) has ended its stance.
CONTACT_GAP = 0.01
# The probe reads the collision result every this many physics steps (it is the probe's dearest part).
CONTACT_PROBE_EVERY = 5


def incline_terrain(angle_deg: float, size: float = MAP_SIZE, resolution: float = MAP_RESOLUTION) -> Terrain:
    """A square plane rising along +x at `angle_deg`, lowest edge at height 0."""
    if not (math.isfinite(angle_deg) and 0.0 <= angle_deg <= MAX_ANGLE_DEG):
        raise ScenarioError(f"incline angle must be within [0, {MAX_ANGLE_DEG:.0f}] degrees, got {angle_deg}")
    if not (math.isfinite(size) and math.isfinite(resolution) and resolution > 0.0 and size >= 4.0 * resolution):
        raise ScenarioError(f"incline map needs a positive resolution and a size of at least 4 cells, got size {size} m, resolution {resolution} m")
    cells = round(size / resolution)
    xs = (np.arange(cells) + 0.5) * resolution
    heights = np.tile(math.tan(math.radians(angle_deg)) * xs, (cells, 1))
    return Terrain((0.0, 0.0), resolution, heights)


def incline_scenario(
    angle_deg: float,
    direction: str,
    distance: float = WALK_DISTANCE,
    size: float = MAP_SIZE,
    resolution: float = MAP_RESOLUTION,
) -> Scenario:
    """The incline and a straight walk of `distance` (horizontal) centred on the map, in `direction`."""
    if direction not in DIRECTIONS:
        raise ScenarioError(f"unknown incline direction '{direction}' (choose from {', '.join(DIRECTIONS)})")
    if not (math.isfinite(distance) and 0.0 < distance <= size - 2.0):
        raise ScenarioError(f"walk distance must be in (0, {size - 2.0:g}] m on a {size:g} m map (1 m margin at both ends), got {distance}")
    terrain = incline_terrain(angle_deg, size, resolution)
    heading = DIRECTIONS[direction]
    centre = size / 2.0
    half = distance / 2.0
    start = (centre - half * math.cos(heading), centre - half * math.sin(heading))
    goal = (centre + half * math.cos(heading), centre + half * math.sin(heading))
    return Scenario(
        name=f"incline_{angle_deg:g}deg_{direction}",
        terrain=terrain,
        start=start,
        start_yaw=heading,
        goal=GoalRegion(center=goal, radius=0.25),
    )


def straight_plan(scenario: Scenario, speed: float = NOMINAL_SPEED, sample_period: float = SAMPLE_PERIOD) -> Plan:
    """Start → goal centre at constant `speed`, sampled every `sample_period` like the planner's plans."""
    if not (math.isfinite(speed) and speed > 0.0):
        raise ScenarioError(f"walking speed must be positive, got {speed}")
    if not (math.isfinite(sample_period) and sample_period > 0.0):
        raise ScenarioError(f"sample period must be positive, got {sample_period}")
    sx, sy = scenario.start
    gx, gy = scenario.goal.center
    length = math.hypot(gx - sx, gy - sy)
    heading = math.atan2(gy - sy, gx - sx) if length > 0.0 else scenario.start_yaw
    duration = length / speed
    samples = max(2, math.ceil(duration / sample_period) + 1)
    t = np.linspace(0.0, duration, samples) if duration > 0.0 else np.arange(samples) * sample_period
    s = np.minimum(speed * t, length)
    x = sx + s * math.cos(heading)
    y = sy + s * math.sin(heading)
    moving = np.ones(samples) * (speed if length > 0.0 else 0.0)
    plan = Plan(
        "straight",
        t,
        x,
        y,
        scenario.terrain.height(x, y),
        np.full(samples, heading),
        moving * math.cos(heading),
        moving * math.sin(heading),
        np.zeros(samples),
        {"length": length, "duration": duration, "speed": speed},
    )
    plan.validate()
    return plan


class WorldProbe:
    """Records, per physics step, the feet's world transforms and which non-foot links touch anything.

    It wraps the `step` of one physics world (the co-simulation calls it once per physics step).
    """

    def __init__(self, world: PhysicsEngine, n_steps: int) -> None:
        self.world = world
        legs = len(world.description.legs)
        self.foot_rotation = np.zeros((n_steps, legs, 3, 3))
        self.foot_position = np.zeros((n_steps, legs, 3))
        self.link_contacts: dict[str, list[float]] = {}
        self.count = 0
        self._step = world.step
        world.step = self.step  # type: ignore[method-assign]

    def step(self) -> None:
        self._step()
        k = self.count
        if k < len(self.foot_position):
            self.foot_rotation[k], self.foot_position[k] = self.world.foot_poses()
            if k % CONTACT_PROBE_EVERY == 0:
                for name in self.world.touching_links():
                    self.link_contacts.setdefault(name, []).append(k * self.world.time_step)
        self.count += 1


def support_margin(world: PhysicsEngine) -> float:
    """Horizontal distance of the whole robot's centre of mass inside the polygon of its feet (m,
    negative: outside, the pose cannot stand still whatever the joints do)."""
    com = world.center_of_mass()[:2]
    feet = world.foot_positions()[:, :2]
    centre = feet.mean(axis=0)
    order = np.argsort(np.arctan2(feet[:, 1] - centre[1], feet[:, 0] - centre[0]))
    polygon = feet[order]
    margin = math.inf
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        edge = b - a
        inward = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
        # Counter-clockwise vertices: the inward normal is the edge turned left.
        margin = min(margin, float((com - a) @ inward))
    return margin


@dataclass
class SlipEvent:
    foot: str
    time: float
    slip: float


@dataclass
class InclineOutcome:
    """What one incline run measured (see the module docstring)."""

    angle_deg: float
    direction: str
    friction: float
    stop_reason: str
    stood_up: bool
    stand_height: float
    """Base height above the ground at the walk start, m."""
    placed_margin: float
    """`support_margin` of the pose the robot is placed in (body aligned with the plane), m."""
    stand_slide: float
    """Horizontal base displacement during stand-up (t = 0 → walk start), m."""
    walked: float
    """Base displacement along the walking direction, walk start → end or fall, m (horizontal)."""
    fell: bool
    fall_time: float | None
    fall_reason: str
    fell_before_walk: bool
    """The robot went down during stand-up: the walk figures below are then empty (zero)."""
    max_stance_slip: float
    """Largest stance-foot slip after the walk start, m."""
    stand_slip: float
    """Largest foot slip before the walk start (stand-up and stand), m."""
    worst_slip: SlipEvent | None
    max_pitch_error_deg: float
    max_roll_error_deg: float
    peak_torque_ratio: float
    peak_torque_joint: str
    torque_saturation: float
    """Fraction of the walk's control steps with some joint at ≥ 99 % of its effort limit."""
    rms_tracking_error: float
    non_foot_contacts: dict[str, float] = field(default_factory=dict)
    """Link name → first time it touched the ground (a knee, the trunk…)."""
    walk_contacts: dict[str, float] = field(default_factory=dict)
    """The same from the walk start on (up to a fall): a link other than a foot on the ground while
    walking, which the stand-up from lying does not excuse."""
    wall_time: float = 0.0
    engine: str = DEFAULT_ENGINE
    """The physics engine the run walked in (the world's own name)."""

    @property
    def passed(self) -> bool:
        """The benchmark's criterion: stood up, no fall, at least `MIN_WALKED` along the direction, and
        only the feet on the ground while walking (a thigh or calf dragging is no pass)."""
        return self.stood_up and not self.fell and self.walked >= MIN_WALKED and not self.walk_contacts

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def stance_slips(
    contact_scheduled: NDArray[np.int8],
    contact_actual: NDArray[np.int8],
    foot_position: FloatArray,
    foot_rotation: FloatArray,
    foot_radius: float,
    normal: FloatArray,
    dt: float,
    foot_names: tuple[str, ...],
) -> list[SlipEvent]:
    """Per stance, the largest tangential slip of the touched-down point while the foot touches.

    A stance is a run of scheduled contact; its slip is measured from the first step with physical
    contact until the contact is lost for longer than `CONTACT_GAP` (a foot lifted off the ground
    is not slipping). The reference is the foot sphere's lowest point (along −`normal`) at
    touch-down, followed in the foot's own frame; its displacement is projected onto the plane
    with unit `normal`.
    """
    _, n_feet = contact_scheduled.shape
    normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    tangential = np.eye(3) - np.outer(normal, normal)
    max_gap = max(1, round(CONTACT_GAP / dt))
    events: list[SlipEvent] = []
    for i in range(n_feet):
        stance = contact_scheduled[:, i] > 0
        edges = np.diff(np.concatenate([[0], stance.astype(np.int8), [0]]))
        for begin, end in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True):
            touching = np.nonzero(contact_actual[begin:end, i] > 0)[0] + begin
            if len(touching) == 0:
                continue
            breaks = np.nonzero(np.diff(touching) > max_gap)[0]
            last = touching[breaks[0]] if len(breaks) else touching[-1]
            k0 = int(touching[0])
            contact_world = foot_position[k0, i] - foot_radius * normal
            local = foot_rotation[k0, i].T @ (contact_world - foot_position[k0, i])
            span = slice(k0, int(last) + 1)
            point = foot_position[span, i] + np.einsum("kab,b->ka", foot_rotation[span, i], local)
            distance = np.linalg.norm((point - contact_world) @ tangential, axis=1)
            j = int(np.argmax(distance))
            events.append(SlipEvent(foot_names[i], float((k0 + j) * dt), float(distance[j])))
    return events


def evaluate(
    scenario: Scenario,
    result: RunResult,
    probe: WorldProbe,
    world: PhysicsEngine,
    nominal_height: float,
    stand_code: int,
    friction: float,
    angle_deg: float,
    direction: str,
    placed_margin: float = math.nan,
    fall: FallThresholds | None = None,
) -> InclineOutcome:
    """Turns one run's log and probe records into an `InclineOutcome`."""
    log = result.log
    t = log["t"]
    n = len(t)
    dt = float(log["physics_dt"])
    walk_start = float(log["walk_start"])
    k_walk = min(round(walk_start / dt), n - 1)
    pos = log["base_pos"]
    terrain = scenario.terrain
    ground = terrain.height(pos[:, 0], pos[:, 1])
    heading = DIRECTIONS[direction]

    # The harness's fall rule (the run's, which it stopped on), with tilt and damping judged from
    # t = 0: a robot that tips over while standing up has fallen too.
    verdict = judge_fall(log, terrain, fall or FallThresholds(), tilt_from=0.0)
    fell, fall_time, fall_reason = verdict.fell, verdict.fall_time, verdict.reason
    fell_before_walk = bool(fall_time is not None and fall_time < t[k_walk])
    if fell_before_walk:
        fall_reason = "before the walk: " + fall_reason
    height = pos[:, 2] - ground
    roll, pitch, yaw = roll_pitch_yaw(log["base_quat"])
    # The last step before the walk: the mode request switches to locomotion at the walk start.
    # (The base starts crouched, so its height is judged there only.)
    k_stood = max(k_walk - 1, 0)
    stand_height = float(height[k_stood])
    stood_up = bool(int(log["fsm"][k_stood]) == stand_code and stand_height >= STOOD_HEIGHT_FRACTION * nominal_height and not fell_before_walk)
    stand_slide = float(np.hypot(*(pos[k_walk, :2] - pos[0, :2])))

    k_end = n - 1 if fall_time is None else min(round(fall_time / dt), n - 1)
    k_end = max(k_end, k_walk)
    along = np.array([math.cos(heading), math.sin(heading)])
    walked = float((pos[k_end, :2] - pos[k_walk, :2]) @ along)

    plane = terrain.plane(float(pos[0, 0]), float(pos[0, 1]))
    normal = np.array([-plane.dzdx, -plane.dzdy, 1.0])
    steps = min(probe.count, n)
    slips = stance_slips(
        log["contact_scheduled"][:steps],
        log["contact_actual"][:steps],
        probe.foot_position[:steps],
        probe.foot_rotation[:steps],
        world.foot_radius,
        normal,
        dt,
        world.description.foot_links,
    )
    walk_slips = [e for e in slips if e.time >= walk_start and (fall_time is None or e.time <= fall_time)]
    stand_slips = [e for e in slips if e.time < walk_start]
    worst = max(walk_slips, key=lambda e: e.slip, default=None)

    # Attitude error against a body levelled with the plane, over the walk up to a fall.
    span = slice(k_walk, k_end + 1)
    level_pitch, level_roll = terrain_pitch_roll(terrain, pos[span, 0], pos[span, 1], yaw[span])
    pitch_error = np.degrees(np.abs(pitch[span] - level_pitch))
    roll_error = np.degrees(np.abs(roll[span] - level_roll))

    tau = np.abs(log["tau"][span])
    ratio = tau / world.effort_limits
    peak = np.unravel_index(int(np.argmax(ratio)), ratio.shape) if ratio.size else (0, 0)
    saturated = float(np.mean(np.any(ratio >= 0.99, axis=1))) if ratio.size else 0.0

    return InclineOutcome(
        angle_deg=angle_deg,
        direction=direction,
        friction=friction,
        stop_reason=result.stop_reason,
        stood_up=stood_up,
        stand_height=stand_height,
        placed_margin=placed_margin,
        stand_slide=stand_slide,
        walked=walked,
        fell=fell,
        fall_time=fall_time,
        fall_reason=fall_reason,
        fell_before_walk=fell_before_walk,
        max_stance_slip=max((e.slip for e in walk_slips), default=0.0),
        stand_slip=max((e.slip for e in stand_slips), default=0.0),
        worst_slip=worst,
        max_pitch_error_deg=float(pitch_error.max()) if pitch_error.size else 0.0,
        max_roll_error_deg=float(roll_error.max()) if roll_error.size else 0.0,
        peak_torque_ratio=float(ratio[peak]) if ratio.size else 0.0,
        peak_torque_joint=world.description.joint_names[int(peak[1])],
        torque_saturation=saturated,
        rms_tracking_error=rms_tracking_error(log),
        non_foot_contacts=dict(sorted(((name, times[0]) for name, times in probe.link_contacts.items()), key=lambda item: item[1])),
        walk_contacts=contacts_between(probe.link_contacts, walk_start, fall_time),
    )


def contacts_between(link_contacts: dict[str, list[float]], start: float, end: float | None) -> dict[str, float]:
    """Link → first contact time in [start, end] (`end` None: to the end of the run), by time."""
    inside = ((name, [t for t in times if t >= start and (end is None or t <= end)]) for name, times in link_contacts.items())
    return dict(sorted(((name, min(times)) for name, times in inside if times), key=lambda item: item[1]))


@dataclass
class InclineRun:
    outcome: InclineOutcome
    result: RunResult
    scenario: Scenario
    plan: Plan


# How much further than its crouch the robot's hips and knees are bent when it is set down.
LYING_BEND = 1.5
# Distance kept from the joint limits when bending, rad.
LYING_LIMIT_MARGIN = 0.05


def lying_pose(world: PhysicsEngine) -> NDArray[np.float64]:
    """The robot config's crouch with hip and knee angles × `LYING_BEND`, inside the joint limits."""
    pose = np.array(world.description.crouch, dtype=np.float64)
    pose[1::3] *= LYING_BEND
    pose[2::3] *= LYING_BEND
    lower, upper = world.joint_position_limits()
    lower = lower + LYING_LIMIT_MARGIN
    upper = upper - LYING_LIMIT_MARGIN
    return np.clip(pose, np.minimum(lower, upper), np.maximum(lower, upper))


def run_incline(
    angle_deg: float,
    direction: str,
    fmu_path: Path,
    robot: RobotDescription,
    cache_dir: Path,
    friction: float = DEFAULT_FRICTION,
    distance: float = WALK_DISTANCE,
    speed: float = NOMINAL_SPEED,
    parameters: dict[str, float] | None = None,
    config: CoSimConfig | None = None,
    progress: Callable[[float], None] | None = None,
    engine: str = DEFAULT_ENGINE,
    contact_time_constant: float | None = None,
) -> InclineRun:
    """One incline run with the controller FMU (optionally with FMU `parameters` changed from their defaults)
    in the physics engine `engine` (it and `friction` replace those of `config`); `contact_time_constant`:
    MuJoCo's contacts with that time constant (`MujocoWorld.set_contact_time_constant`) instead of its own."""
    if not (math.isfinite(friction) and friction > 0.0):
        raise SimulationError(f"friction coefficient must be positive, got {friction}")
    scenario = incline_scenario(angle_deg, direction, distance)
    plan = straight_plan(scenario, speed)
    config = dataclasses.replace(config or CoSimConfig(settle_time=1.0, estimator="groundTruth"), friction=friction, engine=engine)
    config.validate()
    controller = fr.ControllerFmu(fmu_path)
    try:
        if parameters:
            controller.set_parameters(parameters)
        contract = controller.contract
        nominal_height = float((parameters or {}).get(fr.STAND_HEIGHT_PARAMETER, contract.stand_height))
        stand_code = int(contract.fsm.Stand)
        sim = CoSimulation(scenario, plan, None, robot, cache_dir, config, controller=controller)
        if contact_time_constant is not None:
            from .mujoco_world import MujocoWorld

            if not isinstance(sim.world, MujocoWorld):
                raise SimulationError(f"a contact time constant is MuJoCo's soft-contact setting, not {engine}'s")
            sim.world.set_contact_time_constant(contact_time_constant)
    except BaseException:
        controller.close()
        raise

    with sim:
        sim.world.place(float(plan.x[0]), float(plan.y[0]), float(plan.yaw[0]), joint_positions=lying_pose(sim.world))
        placed_margin = support_margin(sim.world)
        probe = WorldProbe(sim.world, max(1, round(sim.duration() / config.physics_dt)) + 1)
        begin = time.perf_counter()
        result = sim.run(progress)
        wall = time.perf_counter() - begin
        outcome = evaluate(scenario, result, probe, sim.world, nominal_height, stand_code, friction, angle_deg, direction, placed_margin, config.fall)
    outcome.wall_time = wall
    outcome.engine = sim.world.name
    return InclineRun(outcome, result, scenario, plan)
