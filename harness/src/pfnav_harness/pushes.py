"""Force impulses on the robot's trunk: single pushes from the command line and seeded random campaigns.

A push is a constant horizontal force on the trunk's centre of mass during [start, start + duration)
of simulated time. The co-simulation asks `PushSchedule.force_at(t, yaw)` before every physics step
at that step's start time t and hands the answer to `QuadrupedWorld.apply_trunk_force`, so the
force acts on exactly the steps whose start lies in the window. When start and duration are
multiples of the physics step (what `random_pushes` produces by default) the impulse delivered is
exactly force·duration; otherwise it is off by less than one step's force·dt.

Command-line text: `MAG@DIR:START+DURATION`, e.g. `60@90:5.0+0.2` = 60 N towards +y (DIR in degrees
counter-clockwise from +x, world frame) from t = 5.0 s for 0.2 s. DIR may also name a side of the
robot: `side` (= `left`), `right`, `front`, `back`. Those are resolved once, from the robot's
heading at the push's first step, and then held in the world frame for the rest of the push
(a shove does not turn with the robot it is shoving).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from .errors import HarnessError

Force = tuple[float, float, float]

# Directions relative to the robot's heading, degrees counter-clockwise from its forward axis.
HEADING_DIRECTIONS = {"side": 90.0, "left": 90.0, "right": -90.0, "front": 0.0, "back": 180.0}
PUSH_SYNTAX = "MAG@DIR:START+DURATION (N, degrees from +x or side/left/right/front/back, s, s), e.g. 60@90:5.0+0.2"
# Simulated times are sums of steps; this keeps a step that starts "at" the window's edge on the intended side.
_TIME_EPSILON = 1e-9

_NUMBER = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_PUSH_TEXT = re.compile(rf"^(?P<mag>{_NUMBER})@(?P<dir>{_NUMBER}|[a-z]+):(?P<start>{_NUMBER})\+(?P<duration>{_NUMBER})$")


class PushError(HarnessError, ValueError):
    """A push that cannot be applied (malformed text, non-positive duration, ...).

    Also a ValueError, so `argparse` can take `parse_push` as an argument type.
    """

    exit_code = 2


@dataclass(frozen=True)
class Push:
    """A constant force during [start, start + duration) of simulated time.

    `force` is in the world frame (N), or, with `heading_relative`, in the robot's heading frame
    (x forward, y left, z up) and turned into the world frame with the heading at the push's start.
    """

    start: float
    duration: float
    force: Force
    heading_relative: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and self.start >= 0.0):
            raise PushError(f"push start must be a time >= 0 s, got {self.start}")
        if not (math.isfinite(self.duration) and self.duration > 0.0):
            raise PushError(f"push duration must be > 0 s, got {self.duration}")
        if len(self.force) != 3 or not all(math.isfinite(f) for f in self.force):
            raise PushError(f"push force must be 3 finite components (N), got {self.force}")
        object.__setattr__(self, "force", tuple(float(f) for f in self.force))

    @property
    def end(self) -> float:
        return self.start + self.duration

    @property
    def magnitude(self) -> float:
        return math.sqrt(sum(f * f for f in self.force))

    @property
    def impulse(self) -> float:
        """|force|·duration, N·s."""
        return self.magnitude * self.duration

    def active(self, t: float) -> bool:
        return self.start - _TIME_EPSILON <= t < self.end - _TIME_EPSILON

    def world_force(self, yaw: float) -> Force:
        """The force in the world frame for a robot heading `yaw` (rad)."""
        if not self.heading_relative:
            return self.force
        c, s = math.cos(yaw), math.sin(yaw)
        fx, fy, fz = self.force
        return (c * fx - s * fy, s * fx + c * fy, fz)


def horizontal_push(magnitude: float, direction_deg: float, start: float, duration: float, heading_relative: bool = False) -> Push:
    """A horizontal push of `magnitude` N towards `direction_deg` (counter-clockwise from +x, or from the heading)."""
    angle = math.radians(direction_deg)
    return Push(start, duration, (magnitude * math.cos(angle), magnitude * math.sin(angle), 0.0), heading_relative)


def parse_push(text: str) -> Push:
    """A push from command-line text `MAG@DIR:START+DURATION` (see the module docstring)."""
    compact = "".join(text.split()).lower()
    match = _PUSH_TEXT.match(compact)
    if match is None:
        raise PushError(f"push '{text}': expected {PUSH_SYNTAX}")
    magnitude = float(match["mag"])
    start = float(match["start"])
    duration = float(match["duration"])
    direction = match["dir"]
    if direction in HEADING_DIRECTIONS:
        direction_deg, relative = HEADING_DIRECTIONS[direction], True
    elif direction[0].isalpha():
        raise PushError(f"push '{text}': unknown direction '{direction}' (degrees, or one of {', '.join(HEADING_DIRECTIONS)})")
    else:
        direction_deg, relative = float(direction), False
    if not (math.isfinite(magnitude) and magnitude > 0.0):
        raise PushError(f"push '{text}': magnitude must be > 0 N, got {match['mag']}")
    if not math.isfinite(direction_deg):
        raise PushError(f"push '{text}': direction must be a finite angle in degrees")
    if not (math.isfinite(start) and start >= 0.0):
        raise PushError(f"push '{text}': start must be a time >= 0 s, got {match['start']}")
    if not (math.isfinite(duration) and duration > 0.0):
        raise PushError(f"push '{text}': duration must be > 0 s, got {match['duration']}")
    return horizontal_push(magnitude, direction_deg, start, duration, relative)


class PushSchedule:
    """The pushes of one run. Overlapping pushes add up.

    Stateful only for heading-relative pushes: their world-frame force is fixed at their first
    active step (`reset` forgets it for a new run).
    """

    def __init__(self, pushes: Iterable[Push] = ()) -> None:
        self.pushes: tuple[Push, ...] = tuple(sorted(pushes, key=lambda p: (p.start, p.duration)))
        self._resolved: dict[int, Force] = {}
        self._last_end = max((p.end for p in self.pushes), default=0.0)

    @classmethod
    def parse(cls, texts: Iterable[str]) -> PushSchedule:
        return cls(parse_push(text) for text in texts)

    def __len__(self) -> int:
        return len(self.pushes)

    def __iter__(self) -> Iterator[Push]:
        return iter(self.pushes)

    def reset(self) -> None:
        self._resolved.clear()

    def force_at(self, t: float, yaw: float = 0.0) -> Force | None:
        """The summed world-frame force at simulated time `t` for a robot heading `yaw`; None when no push acts."""
        if t >= self._last_end:
            return None
        total: Force | None = None
        for index, push in enumerate(self.pushes):
            if push.start - _TIME_EPSILON > t:
                break  # sorted by start: no later push has begun either
            if not push.active(t):
                continue
            force = push.force
            if push.heading_relative:
                resolved = self._resolved.get(index)
                if resolved is None:
                    resolved = self._resolved[index] = push.world_force(yaw)
                force = resolved
            total = force if total is None else (total[0] + force[0], total[1] + force[1], total[2] + force[2])
        return total

    def resolved_forces(self) -> list[Force | None]:
        """Per push (in start order) the world-frame force it acted with; None for a heading-relative push that has not started."""
        return [self._resolved.get(i) if p.heading_relative else p.force for i, p in enumerate(self.pushes)]


def random_pushes(
    seed: int,
    count: int,
    magnitude: float,
    duration: float,
    window: tuple[float, float],
    time_step: float = 0.001,
) -> PushSchedule:
    """`count` horizontal pushes, directions uniform on the circle and starts uniform in `window` (s).

    Reproducible from `seed` (numpy's PCG64 Generator; draws: all starts, then all directions).
    Starts are rounded to multiples of `time_step` (the physics step; 0 keeps them as drawn) so each
    push delivers exactly magnitude·duration.
    """
    if count < 0:
        raise PushError(f"random pushes: count must be >= 0, got {count}")
    t0, t1 = float(window[0]), float(window[1])
    if not (math.isfinite(t0) and math.isfinite(t1) and 0.0 <= t0 <= t1):
        raise PushError(f"random pushes: window must satisfy 0 <= start <= end, got {window}")
    if not (math.isfinite(magnitude) and magnitude > 0.0):
        raise PushError(f"random pushes: magnitude must be > 0 N, got {magnitude}")
    if not (math.isfinite(time_step) and time_step >= 0.0):
        raise PushError(f"random pushes: time_step must be >= 0, got {time_step}")
    rng = np.random.default_rng(seed)
    starts = rng.uniform(t0, t1, size=count)
    directions = rng.uniform(0.0, 360.0, size=count)
    if time_step > 0.0:
        starts = np.round(starts / time_step) * time_step
    return PushSchedule(horizontal_push(magnitude, float(d), float(s), duration) for s, d in zip(starts, directions, strict=True))
