"""Online navigation without a bus: the navigator against a scripted planner client."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from pfnav_harness.errors import SimulationError
from pfnav_harness.feedback_field import FeedbackField
from pfnav_harness.online import OnlineConfig, OnlineNavigator, latency_summary, map_snapshot_log, replan_field_log
from pfnav_harness.planner_client import Plan, PlanAnswer, RequestOptions, StartPose
from pfnav_harness.scenario import GoalRegion, Scenario, Terrain
from pfnav_harness.sensing import SensorConfig

SHAPE = (32, 32)
RES = 0.25


def _field(resolution: float = RES, shape: tuple[int, int] = SHAPE) -> FeedbackField:
    ones = np.ones(shape)
    return FeedbackField(
        origin=(0.0, 0.0),
        resolution=resolution,
        dir_x=ones.copy(),
        dir_y=np.zeros(shape),
        speed=0.5 * ones,
        cost_to_go=ones.copy(),
        goal=(7.0, 4.0, 0.5),
    )


def _plan(x0: float, y0: float) -> Plan:
    t = np.linspace(0.0, 2.0, 5)
    x = x0 + 0.5 * t
    zeros = np.zeros_like(t)
    return Plan("pf", t, x, np.full_like(t, y0), zeros, zeros, np.full_like(t, 0.5), zeros, zeros, {"cost": 1.0})


@dataclass
class ScriptedClient:
    """Answers every request at once; `statuses` scripts failures by request number."""

    statuses: dict[int, tuple[int, str]] = field(default_factory=dict)
    grids: dict[int, FeedbackField] = field(default_factory=dict)
    maps: list[Any] = field(default_factory=list)
    raw: list[Any] = field(default_factory=list)
    requests: list[tuple[int, StartPose, int]] = field(default_factory=list)
    # The height variances sent with each map of `maps` (None: exact heights).
    variances: list[Any] = field(default_factory=list)
    # The options of each request of `requests`.
    options: list[Any] = field(default_factory=list)
    seq: int = 100

    def publish_map(self, terrain: Terrain, known: Any = None, unknown_traversability: float = 0.0, variances: Any = None) -> int:
        self.seq += 1
        self.maps.append((self.seq, terrain, known, unknown_traversability))
        self.variances.append(variances)
        return self.seq

    def reserve_map_seq(self) -> int:
        self.seq += 1
        return self.seq

    def publish_raw_map(self, message: Any) -> None:
        self.raw.append(message)

    def send_request(self, pose: StartPose, goal: GoalRegion, method: str, map_seq: int, options: RequestOptions | None = None) -> int:
        request_id = len(self.requests) + 1
        self.requests.append((request_id, pose, map_seq))
        self.options.append(options)
        return request_id

    def await_answer(self, request_id: int, timeout: float) -> PlanAnswer | None:
        _, pose, _ = self.requests[request_id - 1]
        now = time.time()
        if request_id in self.statuses:
            status, error = self.statuses[request_id]
            return PlanAnswer(request_id, status, error, None, None, int(now * 1e6), now)
        grid = self.grids.get(request_id, _field())
        return PlanAnswer(request_id, 0, "", _plan(pose.x, pose.y), grid, int(now * 1e6), now)

    def request_answer(self, pose: StartPose, goal: GoalRegion, method: str, map_seq: int, options: Any = None, **_: Any) -> PlanAnswer:
        request_id = self.send_request(pose, goal, method, map_seq, options)
        answer = self.await_answer(request_id, 1.0)
        assert answer is not None
        return answer


def _scenario() -> Scenario:
    heights = np.zeros(SHAPE)
    obstacles = np.zeros(SHAPE, dtype=bool)
    obstacles[10:20, 20] = True
    terrain = Terrain((0.0, 0.0), RES, heights, obstacles)
    return Scenario("toy", terrain, (1.0, 4.0), 0.0, GoalRegion((7.0, 4.0), 0.5))


def _walk(navigator: OnlineNavigator, seconds: float, dt: float = 0.01) -> list[tuple[float, PlanAnswer]]:
    """Walks along +x at 0.5 m/s, the position's σ growing by 2 cm per second along y (1 cm along x)."""
    used = []
    for k in range(round(seconds / dt)):
        t = k * dt
        answer = navigator.tick(t, 1.0 + 0.5 * t, 4.0, 0.0, np.array([(0.01 * t) ** 2, (0.02 * t) ** 2, 1.0]))
        if answer is not None:
            used.append((t, answer))
    return used


def test_updates_go_out_at_the_period_and_answers_are_used_after_the_budget() -> None:
    client = ScriptedClient()
    navigator = OnlineNavigator(client, _scenario(), OnlineConfig(sensor=SensorConfig(range_m=1.0)))  # type: ignore[arg-type]
    first = navigator.start(1.0, 4.0, 0.0, timeout=1.0, retries=0)
    assert first.ok
    # The first map already carries what the sensor saw at the start: a partial map with a mask.
    _, _, known, prior_p = client.maps[0]
    assert known is not None and 0 < known.sum() < known.size and prior_p == 0.0  # the planner's default
    assert client.variances[0] is None  # the ideal sensor's heights are exact
    used = _walk(navigator, 3.0)
    publish_times = [r.t_publish for r in navigator.replans[1:]]
    # The start plan covers t = 0; updates follow every period.
    np.testing.assert_allclose(publish_times, [0.5, 1.0, 1.5, 2.0, 2.5], atol=1e-9)
    np.testing.assert_allclose([t for t, _ in used], [0.7, 1.2, 1.7, 2.2, 2.7], atol=1e-9)
    # Every replan starts from the pose at its update.
    assert [round(pose.x, 6) for _, pose, _ in client.requests[1:]] == [round(1.0 + 0.5 * t, 6) for t in publish_times]
    # ... with the position's uncertainty at that moment, for the planner's margin.
    assert client.requests[0][1].sigma == 0.0
    assert [round(pose.sigma, 6) for _, pose, _ in client.requests[1:]] == [round(0.02 * t, 6) for t in publish_times]
    summary = latency_summary(navigator.replans)
    assert summary["map_updates"] == 5 and summary["replans_in_use"] == 5


def test_failed_answers_keep_the_last_plan_with_the_reason() -> None:
    client = ScriptedClient(statuses={3: (3, "map seq 103 was rejected: non-finite height at cell (4, 4)")})
    client.grids[4] = _field(resolution=2 * RES, shape=(16, 16))
    navigator = OnlineNavigator(client, _scenario(), OnlineConfig())  # type: ignore[arg-type]
    navigator.start(1.0, 4.0, 0.0, timeout=1.0, retries=0)
    used = _walk(navigator, 2.5)
    outcomes = [r.outcome for r in navigator.replans]
    assert "non-finite height" in outcomes[2] and "kept the last plan" in outcomes[2]
    assert "grid changed" in outcomes[3]
    assert [a.request_id for _, a in used] == [2, 5]


def test_bad_updates_are_published_in_order_after_the_first_regular_one() -> None:
    client = ScriptedClient()
    config = OnlineConfig(bad_updates=("nan", "shape", "stale"))
    navigator = OnlineNavigator(client, _scenario(), config)  # type: ignore[arg-type]
    navigator.start(1.0, 4.0, 0.0, timeout=1.0, retries=0)
    _walk(navigator, 3.0)
    kinds = [r.kind for r in navigator.replans]
    assert kinds[:6] == ["start", "update", "nan", "shape", "stale", "update"]
    nan_map, shape_map, stale_map = client.raw
    assert any(np.isnan(h) for h in nan_map.heights)
    assert (shape_map.width, shape_map.height) == (SHAPE[1] // 2, SHAPE[0] // 2)
    assert stale_map.header.seq < navigator.replans[0].map_seq


def test_the_log_keeps_each_field_in_use_and_each_map_sent() -> None:
    client = ScriptedClient(statuses={3: (3, "rejected")})
    # The fourth answer's field points along +y: the log must keep each field as it was.
    client.grids[4] = dataclasses.replace(_field(), dir_x=np.zeros(SHAPE), dir_y=np.ones(SHAPE))
    config = OnlineConfig(sensor=SensorConfig(range_m=1.0), bad_updates=("nan",))
    navigator = OnlineNavigator(client, _scenario(), config)  # type: ignore[arg-type]
    navigator.start(1.0, 4.0, 0.0, timeout=1.0, retries=0)
    _walk(navigator, 2.3)
    replans = navigator.replans
    assert [r.kind for r in replans] == ["start", "update", "nan", "update", "update"]
    fields = replan_field_log(replans)
    # The start and the replans put in use, not the rejected answer to the bad update (row 2).
    assert fields["replan_field_rows"].tolist() == [i for i, r in enumerate(replans) if r.in_use] == [0, 1, 3, 4]
    assert fields["replan_field_dir_x"].shape == (4, *SHAPE) and fields["replan_field_dir_x"].dtype == np.float16
    np.testing.assert_array_equal(fields["replan_field_dir_y"][2], 1.0)
    np.testing.assert_array_equal(fields["replan_field_dir_y"][[0, 1, 3]], 0.0)
    np.testing.assert_allclose(fields["replan_field_origin"], [0.0, 0.0])
    assert float(fields["replan_field_resolution"]) == RES
    # The map as each regular update sent it: the ideal sensor's cells known so far (exact: σ² = 0), NaN elsewhere.
    maps = map_snapshot_log(replans)
    assert maps["map_snapshot_rows"].tolist() == [0, 1, 3, 4]
    known = np.isfinite(maps["map_snapshot_heights"])
    assert known.shape == (4, *SHAPE) and maps["map_snapshot_heights"].dtype == np.float32
    # Each snapshot knows what its map message marked known, and the map grows as the robot walks.
    for k, (_, _, mask, _) in zip(range(4), [client.maps[i] for i in (0, 1, 2, 3)], strict=True):
        np.testing.assert_array_equal(known[k], mask)
    assert known[0].sum() < known[-1].sum()
    np.testing.assert_array_equal(maps["map_snapshot_variances"][known], 0.0)
    assert np.isnan(maps["map_snapshot_variances"][~known]).all()


@pytest.mark.parametrize(
    ("config", "message"),
    [
        (OnlineConfig(update_period=0.0), "update period"),
        (OnlineConfig(apply_delay=0.6), "latency budget"),
        (OnlineConfig(bad_updates=("garbage",)), "unknown bad map update"),
    ],
)
def test_bad_online_settings_are_refused(config: OnlineConfig, message: str) -> None:
    with pytest.raises(SimulationError, match=message):
        OnlineNavigator(ScriptedClient(), _scenario(), config)  # type: ignore[arg-type]
