"""Where the controller's reference comes from at each control step: a trajectory or the feedback field.

- `TrajectorySource` samples a time-indexed plan (the paper's way): a robot knocked off the path
  is pulled back to where the plan says it should be by now.
- `FieldSource` asks the planner's feedback law at the robot's current position: the reference
  position is the robot's own, the velocity and heading come from the field, so a pushed robot
  heads for the goal from where it landed.

Both are sampled at the pose the robot believes it has (`pose`: x, y, yaw — its estimate in kalman
mode, the truth otherwise) and describe the terrain the way a body-relative perception would: the
ground actually under the robot, moved into the robot's estimated frame by `offset` (estimate −
truth: dx, dy, dz).

Both can swap in a new plan mid-walk (online replanning) without a jump in the reference.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .feedback_field import FeedbackField
from .follower import FieldFollower, FollowerLimits
from .planner_client import Plan
from .reference import T_DZDX, T_DZDY, T_HEIGHT, VX, VY, YAW, YAW_RATE, ReferenceTrajectory, X, Y, Z
from .scenario import Terrain, TerrainPlane

FOLLOW_MODES = ("trajectory", "feedback")


def yaw_of(quaternion: NDArray[np.float64]) -> float:
    """Heading of a (w, x, y, z) quaternion."""
    w, x, y, z = quaternion.tolist()
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class TrajectorySource:
    """A plan's reference trajectory, indexed by the walk clock."""

    def __init__(self, plan: Plan, terrain: Terrain, plane_radius: float, heading_smoothing: float) -> None:
        self.terrain = terrain
        self.plane_radius = plane_radius
        self.heading_smoothing = heading_smoothing
        self.reference = ReferenceTrajectory(plan, terrain, plane_radius, heading_smoothing)
        # Walk-clock time of the plan's first sample.
        self._start = 0.0

    @property
    def duration(self) -> float:
        return self.reference.duration

    @property
    def finished(self) -> bool:
        return False

    def sample(self, tau: float, pose: NDArray[np.float64], offset: NDArray[np.float64], walking: bool, out: NDArray[np.float64]) -> None:
        # Indexed by the walk clock alone: the plan (its positions and their terrain) is the map's.
        self.reference.sample(tau - self._start if walking else 0.0, out)

    def sample_block(self, tau: NDArray[np.float64], walking: NDArray[np.bool_], out: NDArray[np.float64]) -> None:
        """`sample` at each walk-clock time of `tau` into the rows of `out` (the pose does not matter here)."""
        self.reference.sample_block(np.where(walking, tau - self._start, 0.0), out)

    def replace(self, plan: Plan, planned_at: float) -> None:
        """Continues on `plan`, which starts where the robot was at walk-clock time `planned_at`."""
        self.reference = ReferenceTrajectory(plan, self.terrain, self.plane_radius, self.heading_smoothing)
        self._start = planned_at


class PlaneCache:
    """The terrain plane under the robot, fitted once per quarter cell (the fit costs ~60 µs)."""

    def __init__(self, terrain: Terrain, radius: float) -> None:
        self.terrain = terrain
        self.radius = radius
        self.quantum = terrain.resolution / 2.0
        self._planes: dict[tuple[int, int], TerrainPlane] = {}

    def at(self, x: float, y: float) -> TerrainPlane:
        key = (round(x / self.quantum), round(y / self.quantum))
        plane = self._planes.get(key)
        if plane is None:
            plane = self.terrain.plane(key[0] * self.quantum, key[1] * self.quantum, radius=self.radius)
            self._planes[key] = plane
        return plane


class FieldSource:
    """Velocity and heading from the planner's feedback field at the robot's current position."""

    def __init__(
        self, field: FeedbackField, terrain: Terrain, plane_radius: float, control_dt: float, start_yaw: float, limits: FollowerLimits | None = None
    ) -> None:
        self.follower = FieldFollower(field, limits or FollowerLimits())
        self.planes = PlaneCache(terrain, plane_radius)
        self.control_dt = control_dt
        self.start_yaw = start_yaw
        self.status = "ok"
        self._at_goal = False

    @property
    def duration(self) -> float:
        return math.inf

    @property
    def finished(self) -> bool:
        return self._at_goal

    def sample(self, tau: float, pose: NDArray[np.float64], offset: NDArray[np.float64], walking: bool, out: NDArray[np.float64]) -> None:
        x, y, yaw = float(pose[0]), float(pose[1]), float(pose[2])
        plane = self.planes.at(x - float(offset[0]), y - float(offset[1]))
        height = plane.height + float(offset[2])
        out[X] = x
        out[Y] = y
        out[Z] = height
        out[T_HEIGHT] = height
        out[T_DZDX] = plane.dzdx
        out[T_DZDY] = plane.dzdy
        if not walking:
            out[YAW] = self.start_yaw
            out[VX] = out[VY] = out[YAW_RATE] = 0.0
            return
        command = self.follower.command(x, y, yaw, self.control_dt)
        out[YAW] = command.yaw
        out[VX] = command.vx
        out[VY] = command.vy
        out[YAW_RATE] = command.yaw_rate
        self.status = command.status
        self._at_goal = command.reached

    def replace(self, field: FeedbackField) -> None:
        self.follower.swap_field(field)
