"""Velocity commands from the planner's feedback field at the robot's current position.

Instead of tracking a time-parameterised trajectory, the robot asks the optimal feedback law
u*(x) where it is now: a push or a slip leaves it somewhere else and the law there still leads to
the goal. The follower shapes u* into a command a legged controller can take:

* the commanded velocity (world frame) points where the field says, with speed ≤ the field's
  speed and ≤ `max_speed`, changed by at most `max_accel`·dt per call (so a new field or a fallback
  never makes it jump);
* the commanded heading follows the field direction (the robot walks forward) through a rate and
  acceleration limited tracker; while the heading error is large the translational speed drops so
  that the robot turns first instead of walking sideways;
* inside `slow_radius` of the goal's edge the speed shrinks in proportion to the distance (down
  to `min_approach_speed`, so the robot does arrive); inside the goal disc, where the field has no
  direction, the robot walks straight at the centre until it is `goal_stop_depth` deep, then stops;
* off the field's reachable support (pushed next to an obstacle, off the map) it steers by the
  steepest descent of the cost-to-go around the nearest reachable cell within two cells, and
  commands zero velocity when there is none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from .feedback_field import FeedbackField

STATUS_OK = "ok"
# Off the field's support: steering by the cost-to-go's steepest descent next to the robot.
STATUS_FALLBACK = "fallback"
STATUS_GOAL = "goal"
# Inside the goal disc, short of the stop depth: straight at the goal's centre.
STATUS_APPROACH = "approach"
STATUS_NO_FIELD = "no_field"

# A sampled velocity shorter than this (m/s) has no usable direction (opposite cells cancelling).
_MIN_FIELD_SPEED = 1e-6


@dataclass(frozen=True)
class FollowerLimits:
    """Limits and shaping of the follower's command (SI units, radians)."""

    # None: the field's own speed is the only bound.
    max_speed: float | None = None
    # Change of the commanded velocity vector, m/s² (what keeps swaps and fallbacks continuous).
    max_accel: float = 1.5
    max_yaw_rate: float = 1.0
    max_yaw_accel: float = 3.0
    # Distance from the goal's edge inside which the speed shrinks in proportion to it.
    slow_radius: float = 1.0
    # Floor of that slow-down: proportional alone would approach the edge without ever crossing it.
    min_approach_speed: float = 0.05
    # How deep into the goal disc (fraction of its radius) the robot walks before it stops: it
    # stops where it believes it is, and a robot on its own estimate is off by about 1 % of the
    # distance walked (0.1–0.2 m on the paper's scenarios), so stopping at the edge would often
    # stop outside.
    goal_stop_depth: float = 0.5
    # Once stopped at the goal the robot counts as there until it is this far outside the disc, so
    # a standing robot's sway across the edge does not restart the walk.
    goal_release_margin: float = 0.2
    # Proportional gain of the heading tracker (1/s) before the rate and acceleration limits.
    heading_gain: float = 3.0
    # Full speed below this heading error, `turning_speed_fraction` of it above the next one, linear between.
    full_speed_heading_error: float = math.radians(30.0)
    turn_first_heading_error: float = math.radians(60.0)
    turning_speed_fraction: float = 0.1
    # How far (cells) the fallback looks for a reachable cell around the robot.
    fallback_search_cells: int = 2

    def validate(self) -> None:
        positive = {
            "max_accel": self.max_accel,
            "max_yaw_rate": self.max_yaw_rate,
            "max_yaw_accel": self.max_yaw_accel,
            "heading_gain": self.heading_gain,
        }
        if self.max_speed is not None:
            positive["max_speed"] = self.max_speed
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"follower limit {name} must be a positive number, got {value}")
        if not (0.0 <= self.goal_stop_depth < 1.0 and self.goal_release_margin >= 0.0):
            raise ValueError("follower: goal_stop_depth must lie in [0, 1) and goal_release_margin be >= 0")
        if not (self.slow_radius >= 0.0 and self.min_approach_speed >= 0.0 and 0.0 <= self.turning_speed_fraction <= 1.0):
            raise ValueError("follower: slow_radius and min_approach_speed must be >= 0, turning_speed_fraction in [0, 1]")
        if not (0.0 <= self.full_speed_heading_error < self.turn_first_heading_error <= math.pi):
            raise ValueError("follower: need 0 <= full_speed_heading_error < turn_first_heading_error <= pi")
        if self.fallback_search_cells < 0:
            raise ValueError("follower: fallback_search_cells must be >= 0")


class FollowerCommand(NamedTuple):
    """World-frame velocity, heading (wrapped to [−π, π]) and yaw rate to send to the controller."""

    vx: float
    vy: float
    yaw: float
    yaw_rate: float
    reached: bool
    status: str
    # The field's cost-to-go ∫p ds at the robot (fallback: at the nearest reachable cell; NaN without a field).
    cost_to_go: float


class FieldFollower:
    """Turns a FeedbackField into rate-limited velocity and heading commands, one call per control step.

    State: the commanded velocity, heading and yaw rate of the previous call (the first call starts
    from the measured heading at rest). `swap_field` keeps that state, so a replanned field
    continues the command within the limits instead of jumping to it.

    Cost (CPython 3.11 on the 2-core VM, 128² field, best of 7 × 20 000 calls): 5–6 µs a call on
    the field (4 µs of it `FeedbackField.sample`), ~20 µs in the fallback (rare: off the support);
    with both cores busy `test_command_cost` sees up to ~20 and ~50 µs. No numpy call per call,
    only the returned tuple is allocated.
    """

    def __init__(self, field: FeedbackField, limits: FollowerLimits | None = None) -> None:
        self.limits = limits or FollowerLimits()
        self.limits.validate()
        self._started = False
        self._at_goal = False
        self._vx = 0.0
        self._vy = 0.0
        self._yaw = 0.0  # unwrapped, so the heading tracker never sees a 2π jump
        self._yaw_rate = 0.0
        self.swap_field(field)

    @property
    def field(self) -> FeedbackField:
        return self._field

    def swap_field(self, new_field: FeedbackField) -> None:
        """Follows `new_field` from the next call on; the commanded state carries over unchanged."""
        new_field.validate()
        self._field = new_field
        self._field_max_speed = new_field.max_speed()
        self._goal_x, self._goal_y, self._goal_radius = new_field.goal

    def reset(self) -> None:
        """Forgets the commanded state: the next call starts from the measured heading at rest."""
        self._started = False
        self._at_goal = False

    def command(self, x: float, y: float, yaw: float, dt: float) -> FollowerCommand:
        """The command for the robot at (x, y) heading `yaw`, `dt` seconds after the previous call."""
        if not dt > 0.0:
            raise ValueError(f"follower: dt must be positive, got {dt}")
        lim = self.limits
        if not self._started:
            self._started = True
            self._vx = self._vy = self._yaw_rate = 0.0
            self._yaw = yaw

        # Reached once the robot is `goal_stop_depth` into the disc; it stays reached until it is
        # `goal_release_margin` outside (a latch, so sway at the stop point does not restart the walk).
        centre_distance = math.hypot(x - self._goal_x, y - self._goal_y)
        stop_radius = (1.0 - lim.goal_stop_depth) * self._goal_radius
        if self._at_goal and centre_distance > self._goal_radius + lim.goal_release_margin:
            self._at_goal = False
        elif centre_distance <= stop_radius:
            self._at_goal = True
        reached = self._at_goal
        distance_to_goal = centre_distance - stop_radius
        speed = 0.0
        ux = uy = 0.0
        cost_to_go = math.nan
        if reached:
            status = STATUS_GOAL
            cost_to_go = 0.0
        else:
            if centre_distance <= self._goal_radius:
                # The goal set is absorbing (cost 0, no velocity), and samples near its rim blend
                # that zero with the approach cells' directions into a short vector that can point
                # anywhere: a robot there crept on it and turned in place for the rest of its run.
                status = STATUS_APPROACH
                ux = (self._goal_x - x) / centre_distance
                uy = (self._goal_y - y) / centre_distance
                speed = self._field_max_speed
                cost_to_go = 0.0
            else:
                status, ux, uy, speed, cost_to_go = self._field_direction(x, y)
            if lim.max_speed is not None and speed > lim.max_speed:
                speed = lim.max_speed
            if distance_to_goal < lim.slow_radius:
                speed = min(speed, max(speed * distance_to_goal / lim.slow_radius, lim.min_approach_speed))

        # Heading: track the field direction while moving, hold it (and stop turning) otherwise.
        yaw_cmd = self._yaw
        if speed > 0.0:
            desired = math.atan2(uy, ux)
            error_cmd = math.remainder(desired - yaw_cmd, math.tau)
            error_measured = math.remainder(desired - yaw, math.tau)
            wanted_rate = lim.heading_gain * error_cmd
            # Time-optimal braking: never turn faster than the yaw-acceleration limit can stop at the target.
            brake = math.sqrt(2.0 * lim.max_yaw_accel * abs(error_cmd))
            bound = min(lim.max_yaw_rate, brake)
            wanted_rate = max(-bound, min(bound, wanted_rate))
            # Walking fast needs both the commanded and the actual heading along the field.
            heading_error = max(abs(error_cmd), abs(error_measured))
            if heading_error > lim.full_speed_heading_error:
                if heading_error >= lim.turn_first_heading_error:
                    speed *= lim.turning_speed_fraction
                else:
                    blend = (heading_error - lim.full_speed_heading_error) / (lim.turn_first_heading_error - lim.full_speed_heading_error)
                    speed *= 1.0 - blend * (1.0 - lim.turning_speed_fraction)
        else:
            wanted_rate = 0.0
        max_rate_step = lim.max_yaw_accel * dt
        rate = self._yaw_rate + max(-max_rate_step, min(max_rate_step, wanted_rate - self._yaw_rate))
        self._yaw_rate = rate
        self._yaw = yaw_cmd + rate * dt

        # Velocity: towards speed·u, the vector's change bounded by max_accel·dt.
        dvx = speed * ux - self._vx
        dvy = speed * uy - self._vy
        change = math.hypot(dvx, dvy)
        max_change = lim.max_accel * dt
        if change > max_change:
            scale = max_change / change
            dvx *= scale
            dvy *= scale
        self._vx += dvx
        self._vy += dvy
        return FollowerCommand(self._vx, self._vy, math.remainder(self._yaw, math.tau), rate, reached, status, cost_to_go)

    def _field_direction(self, x: float, y: float) -> tuple[str, float, float, float, float]:
        """(status, direction x, direction y, speed, cost-to-go) of the field at the robot, by the
        steepest descent next to it where the field has no direction, zero speed where neither has one."""
        sample = self._field.sample(x, y)
        if sample is not None:
            speed = math.hypot(sample.vx, sample.vy)
            if speed > _MIN_FIELD_SPEED:
                return STATUS_OK, sample.vx / speed, sample.vy / speed, speed, sample.cost_to_go
        descent = self._steepest_descent(x, y)
        if descent is None:
            return STATUS_NO_FIELD, 0.0, 0.0, 0.0, sample.cost_to_go if sample is not None else math.nan
        return (STATUS_FALLBACK, *descent)

    def _steepest_descent(self, x: float, y: float) -> tuple[float, float, float, float] | None:
        """(direction x, direction y, speed, that cell's cost-to-go) from the nearest reachable cell within the search radius.

        The direction is the steepest descent of the cost-to-go among that cell's 8 neighbours; in
        the goal set (cost 0, nothing lower around) it is straight at the goal's centre.
        """
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        field = self._field
        height, width = field.shape
        cell_x = math.floor((x - field.origin[0]) / field.resolution)
        cell_y = math.floor((y - field.origin[1]) / field.resolution)
        reach = self.limits.fallback_search_cells
        nearest: tuple[int, int] | None = None
        nearest_distance = math.inf
        for iy in range(max(cell_y - reach, 0), min(cell_y + reach, height - 1) + 1):
            for ix in range(max(cell_x - reach, 0), min(cell_x + reach, width - 1) + 1):
                if field.cell_cost(ix, iy) < 0.0:
                    continue
                distance = (field.origin[0] + (ix + 0.5) * field.resolution - x) ** 2 + (field.origin[1] + (iy + 0.5) * field.resolution - y) ** 2
                if distance < nearest_distance:
                    nearest, nearest_distance = (ix, iy), distance
        if nearest is None:
            return None
        ix0, iy0 = nearest
        here = field.cell_values(ix0, iy0)
        best_slope = 0.0
        direction: tuple[float, float] | None = None
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                ix, iy = ix0 + dx, iy0 + dy
                if (dx == 0 and dy == 0) or not (0 <= ix < width and 0 <= iy < height):
                    continue
                cost = field.cell_cost(ix, iy)
                if cost < 0.0:
                    continue
                step = math.hypot(dx, dy)
                slope = (here.cost_to_go - cost) / step
                if slope > best_slope:
                    best_slope, direction = slope, (dx / step, dy / step)
        if direction is None:
            if here.cost_to_go > 0.0:
                return None
            to_goal = math.hypot(self._goal_x - x, self._goal_y - y)
            if to_goal <= 0.0:
                return None
            direction = ((self._goal_x - x) / to_goal, (self._goal_y - y) / to_goal)
        speed = math.hypot(here.vx, here.vy)
        if speed <= _MIN_FIELD_SPEED:
            speed = self._field_max_speed
        if speed <= 0.0:
            return None
        return direction[0], direction[1], speed, here.cost_to_go
