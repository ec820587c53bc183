"""The LCM client's messages and protocol, against a fake service on an in-process memq:// bus."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from pfnav_harness.errors import PlannerError
from pfnav_harness.lcm_channels import PLANNER
from pfnav_harness.planner_client import METHODS, PlannerClient, _import_types, method_code, method_name, plan_from_reply, terrain_map_message
from pfnav_harness.scenario import Scenario, Terrain

pfnav = _import_types()


def test_terrain_map_message_round_trip() -> None:
    heights = np.arange(12, dtype=np.float64).reshape(3, 4) * 0.1
    obstacles = np.zeros((3, 4), dtype=bool)
    obstacles[1, 2] = True
    terrain = Terrain((-1.0, 2.0), 0.25, heights, obstacles)
    msg = pfnav.terrain_map_t.decode(terrain_map_message(terrain, seq=5, utime=42).encode())
    assert (msg.header.seq, msg.header.utime, msg.header.frame_id) == (5, 42, "world")
    assert (msg.origin_x, msg.origin_y, msg.resolution, msg.width, msg.height) == (-1.0, 2.0, 0.25, 4, 3)
    # Row-major iy·width + ix, exactly numpy's ravel of heights[iy, ix].
    assert msg.heights[1 * 4 + 2] == pytest.approx(heights[1, 2])
    np.testing.assert_array_equal(np.array(msg.heights).reshape(3, 4), heights)
    mask = list(msg.obstacle_mask)  # lcm-gen's Python decodes boolean arrays as a lazy `map`
    assert msg.num_obstacle_cells == 12 and mask[1 * 4 + 2] and sum(mask) == 1
    no_obstacles = pfnav.terrain_map_t.decode(terrain_map_message(Terrain((0.0, 0.0), 1.0, heights), seq=1).encode())
    assert no_obstacles.num_obstacle_cells == 0


def make_reply(request: Any, n: int = 5, status: int = 0, error: str = "") -> Any:
    reply = pfnav.plan_reply_t()
    reply.request_id = request.request_id
    reply.status = status
    reply.error = error
    reply.method = request.method
    reply.map_seq = request.map_seq
    if status == 0:
        for i in range(n):
            s = pfnav.trajectory_sample_t()
            s.t = 0.5 * i
            s.x = request.start_x + 0.25 * i
            s.y = request.start_y
            s.vx = 0.5
            reply.samples.append(s)
        reply.num_samples = n
        reply.metrics.cost = 1.25
        reply.metrics.length = 0.25 * (n - 1)
        reply.metrics.reached_goal = True
    return reply


class FakeService:
    """Answers plan requests on the client's own memq bus; can drop the first requests or fail."""

    def __init__(self, client: PlannerClient, drop_first: int = 0, status: int = 0, error: str = "") -> None:
        self.client = client
        self.drop_first = drop_first
        self.status = status
        self.error = error
        self.requests: list[Any] = []
        self.maps: list[Any] = []
        client.lc.subscribe(client.prefix + PLANNER.plan_request, self._on_request)
        client.lc.subscribe(client.prefix + PLANNER.map, self._on_map)

    def _on_map(self, _channel: str, data: bytes) -> None:
        self.maps.append(pfnav.terrain_map_t.decode(data))

    def _on_request(self, _channel: str, data: bytes) -> None:
        request = pfnav.plan_request_t.decode(data)
        self.requests.append(request)
        if len(self.requests) <= self.drop_first:
            return
        reply = make_reply(request, status=self.status, error=self.error)
        self.client.lc.publish(self.client.prefix + PLANNER.plan_reply, reply.encode())


def test_request_is_answered_and_converted(ramp_scenario: Scenario) -> None:
    with PlannerClient("memq://", "TEST_") as client:
        service = FakeService(client)
        seq = client.publish_map(ramp_scenario.terrain)
        plan = client.request_plan(ramp_scenario, "astar", seq, speed=0.4, timeout=2.0)
    assert len(service.maps) >= 1 and service.maps[0].header.seq == seq
    req = service.requests[0]
    assert (req.method, req.map_seq, req.num_inline_maps) == (pfnav.plan_request_t.METHOD_ASTAR, seq, 0)
    assert (req.start_x, req.start_y, req.goal_x, req.goal_radius) == (0.5, 1.0, 2.5, 0.3)
    assert req.options.speed == 0.4
    assert plan.method == "astar" and len(plan) == 5
    np.testing.assert_allclose(plan.x, [0.5, 0.75, 1.0, 1.25, 1.5])
    assert plan.metrics["cost"] == 1.25 and plan.duration == 2.0


def test_every_method_name_maps_to_its_own_schema_constant() -> None:
    constants = {name: value for name, value in vars(pfnav.plan_request_t).items() if name.startswith("METHOD_")}
    codes = [method_code(m) for m in METHODS]
    # One name per constant and back: a method added to the schema but not here (or the reverse) fails.
    assert sorted(codes) == sorted(constants.values())
    assert [method_name(c) for c in codes] == list(METHODS)
    assert method_code("astar-admissible") == pfnav.plan_request_t.METHOD_ASTAR_ADMISSIBLE
    assert method_name(99) == "method99"
    with pytest.raises(PlannerError, match="unknown planning method"):
        method_code("bfs")


def test_silence_is_retried_with_a_new_request_id(ramp_scenario: Scenario) -> None:
    with PlannerClient("memq://", "TEST_") as client:
        service = FakeService(client, drop_first=1)
        seq = client.publish_map(ramp_scenario.terrain)
        plan = client.request_plan(ramp_scenario, "pf", seq, timeout=0.3, retries=1)
    assert len(service.requests) == 2
    assert service.requests[0].request_id != service.requests[1].request_id
    assert len(service.maps) == 2  # the map is re-published before the retry
    assert plan.method == "pf"


def test_no_answer_and_error_status_raise_planner_errors(ramp_scenario: Scenario) -> None:
    with PlannerClient("memq://", "TEST_") as client:
        FakeService(client, drop_first=10)
        seq = client.publish_map(ramp_scenario.terrain)
        with pytest.raises(PlannerError, match=r"after 2 attempt\(s\): no reply"):
            client.request_plan(ramp_scenario, "pf", seq, timeout=0.2, retries=1)
    with PlannerClient("memq://", "TEST_") as client:
        FakeService(client, status=pfnav.plan_reply_t.STATUS_GOAL_UNREACHABLE, error="goal is walled in")
        seq = client.publish_map(ramp_scenario.terrain)
        with pytest.raises(PlannerError, match="goal is walled in"):
            client.request_plan(ramp_scenario, "pf", seq, timeout=1.0, retries=3)
    with PlannerClient("memq://", "TEST_") as client, pytest.raises(PlannerError, match="unknown planning method"):
        client.request_plan(ramp_scenario, "rrt", 1)


def test_connect_to_a_silent_bus_times_out() -> None:
    with PlannerClient("memq://", "TEST_") as client, pytest.raises(PlannerError, match="no planner service answers"):
        client.wait_for_service(timeout=0.3)


def test_reply_with_bad_trajectory_is_rejected() -> None:
    request = pfnav.plan_request_t()
    request.request_id = 3
    reply = make_reply(request, n=3)
    reply.samples[2].t = reply.samples[1].t
    with pytest.raises(PlannerError, match="increasing"):
        plan_from_reply(pfnav.plan_reply_t.decode(reply.encode()))
