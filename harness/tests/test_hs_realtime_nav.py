"""The real-time navigator's commands: Stand until the robot has stood in torque control, then the field followed on the estimate moved into the world."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pfnav_harness.feedback_field import FeedbackField
from pfnav_harness.planner_client import _import_types
from pfnav_harness.realtime_nav import Navigator
from pfnav_harness.scenario import Scenario

MODE_STAND = _import_types().nav_cmd_t.MODE_STAND
MODE_LOCOMOTION = _import_types().nav_cmd_t.MODE_LOCOMOTION


class FakeBus:
    def __init__(self) -> None:
        self.handlers: dict[str, Callable[[str, bytes], None]] = {}
        self.published: list[tuple[str, bytes]] = []

    def subscribe(self, channel: str, handler: Callable[[str, bytes], None]) -> str:
        self.handlers[channel] = handler
        return channel

    def unsubscribe(self, subscription: str) -> None:
        del self.handlers[subscription]

    def publish(self, channel: str, data: bytes) -> None:
        self.published.append((channel, data))


def east_field(scenario: Scenario) -> FeedbackField:
    """+x everywhere at 0.5 m/s on the scenario's grid, goal at its east edge."""
    ny, nx = scenario.terrain.heights.shape
    ones = np.ones((ny, nx))
    x0, y0 = scenario.terrain.origin
    goal = (x0 + (nx - 1) * scenario.resolution, y0 + ny * scenario.resolution / 2, 0.2)
    return FeedbackField(scenario.terrain.origin, scenario.resolution, ones, 0 * ones, 0.5 * ones, 10.0 * ones, goal)


def estimate(position: tuple[float, float, float], yaw: float, safety: int = 0) -> bytes:
    types = _import_types()
    m = types.robot_estimate_t()
    m.header = types.header_t()
    m.position = list(position)
    m.velocity = [0.0] * 3
    m.rpy = [0.0, 0.0, yaw]
    m.position_variance = [0.0] * 3
    m.fsm_state, m.safety = 2, safety
    return bytes(m.encode())


def test_stand_first_then_the_field_on_the_estimate_moved_to_the_world(ramp_scenario: Scenario) -> None:
    bus = FakeBus()
    start = ramp_scenario.start
    origin = (start[0], start[1], ramp_scenario.terrain.height_at(*start))
    nav = Navigator(ramp_scenario, east_field(ramp_scenario), origin, bus, "T_", stand_time=1.0)
    handler: Any = bus.handlers["T_ROBOT_ESTIMATE"]
    assert nav.command(0.0).mode == MODE_STAND, "no estimate yet"

    handler("T_ROBOT_ESTIMATE", estimate((0.2, 0.1, 0.3), 0.0))
    first = nav.command(10.0)
    assert first.mode == MODE_STAND, "torque control just began"
    assert (first.x, first.y) == (0.2, 0.1), "the reference is the estimate, in the controller's frame"
    # The ramp rises 0.2 m per metre along x: ref.z is the terrain under the robot (0.2 m east
    # of the start) relative to the ground under the start, and the plane's slope.
    assert abs(first.z - 0.2 * 0.2) < 0.02 and abs(first.terrain_dzdx - 0.2) < 0.02

    later = nav.command(11.5)
    assert later.mode == MODE_LOCOMOTION
    assert later.vx > 0.0 and abs(later.vy) < 1e-9, "heading east as the field says"

    # A damped robot stands again, and walks only after standing the stand time once more.
    handler("T_ROBOT_ESTIMATE", estimate((0.3, 0.1, 0.3), 0.0, safety=1))
    assert nav.command(12.0).mode == MODE_STAND
    handler("T_ROBOT_ESTIMATE", estimate((0.3, 0.1, 0.3), 0.0))
    assert nav.command(12.5).mode == MODE_STAND
    assert nav.command(13.6).mode == MODE_LOCOMOTION

    # Garbage and non-finite estimates are ignored.
    handler("T_ROBOT_ESTIMATE", b"junk")
    handler("T_ROBOT_ESTIMATE", estimate((float("nan"), 0.0, 0.0), 0.0))
    assert nav.estimate.position[0] == 0.3
    nav.close()
    assert not bus.handlers
