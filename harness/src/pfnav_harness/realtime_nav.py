"""The navigator as its own process on the bus: the planner's feedback field followed on the robot's own estimate.

It asks the planner service (over LCM) for a P-F plan of the scenario, then every 20 ms takes the
newest `robot_estimate_t` from pfnav-robot, turns it into a world pose, asks the field follower
(`follower.FieldFollower`, the co-simulation's feedback mode) for a velocity and heading, and
sends `nav_cmd_t`: Stand for `--stand-time` seconds after the robot first reports torque control,
Locomotion after, Stand again at the goal.

Frames: the controller estimates in the frame pfnav-robot gives it: the world frame when the
node was started with `--initial-position` (the demo passes the body's pose; a robot would take
it from a localisation fix), else a frame starting where the robot stood (x, y = 0 there, yaw
from the IMU, the world's axes). `--origin X Y Z` is that frame's origin in the world: the
estimate is moved into the world by it for the field, and the terrain plane under the robot
back into the controller's frame for `ref.z` and the slopes.
"""

from __future__ import annotations

import argparse
import math
import os
import struct
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import HarnessError
from .follower import FieldFollower, FollowerLimits
from .lcm_channels import DEFAULT_CHANNEL_PREFIX, DEFAULT_LCM_URL, ROBOT
from .process_signals import stop_requested_on_signals
from .reference import TERRAIN_PLANE_RADIUS
from .reference_source import PlaneCache
from .scenario import Scenario


@dataclass
class NavigatorState:
    commands_sent: int = 0
    estimates_received: int = 0
    walking_since: float | None = None
    reached: bool = False
    status: str = "waiting for the robot"


class Navigator:
    """Estimate in, nav_cmd_t out; the planning happens before `run`."""

    def __init__(
        self,
        scenario: Scenario,
        field: Any,
        origin: tuple[float, float, float],
        lcm: Any,
        prefix: str,
        stand_time: float,
        period: float = 0.02,
    ) -> None:
        """`origin`: where the controller's frame origin lies in the world (0, 0, 0 when pfnav-robot estimates in the world frame)."""
        from .planner_client import _import_types

        self.types = _import_types()
        self.scenario = scenario
        self.follower = FieldFollower(field, FollowerLimits())
        self.planes = PlaneCache(scenario.terrain, TERRAIN_PLANE_RADIUS)
        self.origin = origin
        self.lcm = lcm
        self.channel = prefix + ROBOT.nav_cmd
        self.stand_time = stand_time
        self.period = period
        self.estimate: Any = None
        self.torque_since: float | None = None
        self.state = NavigatorState()
        self.seq = 0
        self._subscription = lcm.subscribe(prefix + ROBOT.robot_estimate, self._on_estimate)

    def _on_estimate(self, _channel: str, data: bytes) -> None:
        try:
            estimate = self.types.robot_estimate_t.decode(data)
        except (ValueError, struct.error, IndexError, UnicodeDecodeError, OverflowError):
            return
        values = [*estimate.position, *estimate.velocity, *estimate.rpy]
        if not all(math.isfinite(v) for v in values):
            return
        self.estimate = estimate
        self.state.estimates_received += 1

    def command(self, now: float) -> Any:
        """The nav_cmd_t for now (Stand until the robot has stood `stand_time` in torque control)."""
        m = self.types.nav_cmd_t()
        m.header = self.types.header_t()
        m.header.utime = time.time_ns() // 1000
        m.header.seq = self.seq
        m.header.frame_id = "controller"
        self.seq += 1
        m.mode = m.MODE_STAND
        m.x = m.y = m.z = m.yaw = m.vx = m.vy = m.yaw_rate = 0.0
        m.body_height = m.terrain_dzdx = m.terrain_dzdy = 0.0
        e = self.estimate
        if e is None:
            return m
        if e.safety != self.types.robot_status_t.SAFETY_OK:
            # A damped robot is not walking; after it recovers it stands again first.
            self.torque_since = None
            self.state.status = "robot damped"
        elif self.torque_since is None:
            self.torque_since = now
        ox, oy, oz = self.origin
        x, y, yaw = e.position[0], e.position[1], e.rpy[2]
        world_x, world_y = x + ox, y + oy
        plane = self.planes.at(world_x, world_y)
        m.x, m.y, m.z = x, y, plane.height - oz
        m.terrain_dzdx, m.terrain_dzdy = plane.dzdx, plane.dzdy
        m.yaw = yaw
        walking = self.torque_since is not None and now - self.torque_since >= self.stand_time
        if not walking:
            return m
        if self.state.walking_since is None:
            self.state.walking_since = now
        cmd = self.follower.command(world_x, world_y, yaw, self.period)
        self.state.reached = cmd.reached
        self.state.status = cmd.status
        m.mode = m.MODE_LOCOMOTION
        m.yaw, m.vx, m.vy, m.yaw_rate = cmd.yaw, cmd.vx, cmd.vy, cmd.yaw_rate
        return m

    def run(self, duration: float | None, stop: Any) -> None:
        clock = time.monotonic
        start = clock()
        next_tick = start
        while not stop() and (duration is None or clock() - start < duration):
            next_tick += self.period
            while not stop():
                left = next_tick - clock()
                if left <= 0:
                    break
                try:
                    self.lcm.handle_timeout(max(1, int(left * 1000)))
                except OSError:
                    # A signal interrupted the wait (SIGTERM: `stop()` says so next).
                    continue
            now = clock()
            if now - next_tick > self.period:
                # Late by more than a tick: continue from now rather than catching up in a burst.
                next_tick = now
            self.lcm.publish(self.channel, self.command(now).encode())
            self.state.commands_sent += 1

    def close(self) -> None:
        self.lcm.unsubscribe(self._subscription)


def plan_field(scenario: Scenario, lcm_url: str, planner_prefix: str, timeout: float) -> Any:
    """The P-F feedback field for the scenario from a running planner service (waited for up to `timeout` s)."""
    from .planner_client import plan_answers

    answer = plan_answers(scenario, ["pf"], lcm_url, planner_prefix, timeout=timeout, retries=2, service_wait=timeout)["pf"]
    if answer.field is None:
        raise HarnessError("the planner's P-F answer carried no feedback field")
    return answer.field


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pfnav-navigator", description="The feedback-field navigator as an LCM process: robot_estimate_t in, nav_cmd_t out (50 Hz)."
    )
    p.add_argument("--scenario", required=True, help="paper scenario (terrain, start, goal)")
    p.add_argument(
        "--origin",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="the controller frame's origin in the world: 0 0 0 when pfnav-robot was given --initial-position in the world frame "
        "(default: the scenario's start and the ground height there, the frame of a node started without it)",
    )
    p.add_argument("--lcm-url", default=os.environ.get("LCM_DEFAULT_URL", DEFAULT_LCM_URL))
    p.add_argument("--channel-prefix", default=DEFAULT_CHANNEL_PREFIX, help="prefix of the robot node's channels")
    p.add_argument("--planner-prefix", default=DEFAULT_CHANNEL_PREFIX, help="prefix of the planner service's channels")
    p.add_argument("--stand-time", type=float, default=1.5, help="seconds of Stand after the robot reports torque control, before walking")
    p.add_argument("--plan-timeout", type=float, default=120.0, help="seconds to wait for the service and its plan")
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument("--out", type=Path, default=Path("out/navigator"), help="folder of the exported scenario")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from . import paths
    from .pipeline import export_scenario
    from .planner_client import _import_lcm

    try:
        scenario = export_scenario(paths.pf_plan_path(), args.scenario, args.out / "scenarios")
        field = plan_field(scenario, args.lcm_url, args.planner_prefix, args.plan_timeout)
    except HarnessError as err:
        print(f"pfnav-navigator: {err}", file=sys.stderr)
        return err.exit_code
    if args.origin is not None:
        origin = (args.origin[0], args.origin[1], args.origin[2])
    else:
        origin = (scenario.start[0], scenario.start[1], scenario.terrain.height_at(*scenario.start))
    navigator = Navigator(scenario, field, origin, _import_lcm().LCM(args.lcm_url), args.channel_prefix, args.stand_time)
    stop_requested = stop_requested_on_signals()
    print(f"pfnav-navigator: planned {scenario.name}; sending {navigator.channel}", file=sys.stderr, flush=True)
    navigator.run(args.duration, stop_requested)
    s = navigator.state
    print(
        f"pfnav-navigator: stopped; {s.commands_sent} commands, {s.estimates_received} estimates, status {s.status}, reached {s.reached}",
        file=sys.stderr,
        flush=True,
    )
    navigator.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
