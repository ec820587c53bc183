"""Online navigation: the robot senses the terrain while it walks and the planner replans.

Every `update_period` simulated seconds the height sensor reveals the cells around the base, the
belief map goes out on `<prefix>MAP` like a perception system's elevation map, and a plan request
from the robot's current pose follows on it. The answer (feedback field and trajectory) is put in
use `apply_delay` simulated seconds after the map went out: the simulation waits there for it if
it is late, so a run is the same whatever the machine's load; the wall-clock latency of every
replan is measured and reported against that budget. An answer that fails (the service's status
and reason, a field on another grid, nothing within `answer_timeout`) is logged and the robot keeps
the plan it has.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from .elevation_map import PoseBelief
from .errors import PlannerError, SimulationError
from .feedback_field import FeedbackField
from .perception import PerceptionConfig, SensedMap
from .planner_client import PlanAnswer, PlannerClient, RequestOptions, StartPose, start_density_belief, terrain_map_message
from .scenario import Scenario
from .sensing import BeliefMap, SensorConfig

# Kinds of deliberately bad map updates (robustness checks): non-finite heights, a map of another
# shape, and a sequence number older than the last accepted map.
BAD_UPDATE_KINDS = ("nan", "shape", "stale")
OUTCOME_IN_USE = "in use"
OUTCOME_PENDING = "pending"
OUTCOME_RUN_ENDED = "run ended before its apply time"
# How many sequence numbers before the navigator's first map the "stale" update is stamped.
STALE_SEQ_AGE = 1000


@dataclass(frozen=True)
class OnlineConfig:
    # The ideal disc sensor (reveals true cells around the believed position)...
    sensor: SensorConfig = field(default_factory=SensorConfig)
    # ... unless a real terrain sensor and its elevation map are given.
    perception: PerceptionConfig | None = None
    # Simulated seconds between map updates (2 Hz).
    update_period: float = 0.5
    # Simulated seconds from a map update to the new plan being in use: the latency budget.
    apply_delay: float = 0.2
    # Wall seconds to wait for an answer at its apply time before keeping the last plan.
    answer_timeout: float = 10.0
    method: str = "pf"
    options: RequestOptions = field(default_factory=RequestOptions)
    # Bad updates sent instead of the regular ones, in this order, from the second update on.
    bad_updates: tuple[str, ...] = ()
    # Plan on the belief: send the estimator's position σ and the map's height variances, so the
    # planner keeps a margin for both. False plans as if both were exact (for comparison).
    belief_planning: bool = True

    def validate(self) -> None:
        self.sensor.validate()
        if self.perception is not None:
            self.perception.validate()
        if not (math.isfinite(self.update_period) and self.update_period > 0.0):
            raise SimulationError(f"the map update period must be positive, got {self.update_period}")
        if not (math.isfinite(self.apply_delay) and 0.0 <= self.apply_delay < self.update_period):
            raise SimulationError(f"the replan latency budget must lie in [0, update period = {self.update_period}), got {self.apply_delay}")
        unknown = [k for k in self.bad_updates if k not in BAD_UPDATE_KINDS]
        if unknown:
            raise SimulationError(f"unknown bad map update kind(s) {', '.join(unknown)}; choose from {', '.join(BAD_UPDATE_KINDS)}")


@dataclass(frozen=True)
class MapSnapshot:
    """The belief map at one update: heights and height variances (m, m²; NaN where unknown), float32
    to keep a run's log small (a recording draws them, nothing plans on them)."""

    heights: NDArray[np.float32]
    variances: NDArray[np.float32]

    @classmethod
    def of(cls, belief: BeliefMap | SensedMap) -> MapSnapshot:
        if isinstance(belief, SensedMap):
            known = belief.map.known
            heights, variances = belief.map.heights, belief.map.variances
        else:
            # The ideal sensor reveals exact heights: variance 0 where known.
            known = belief.known
            heights, variances = belief.heights, np.zeros(known.shape)
        return cls(np.where(known, heights, np.nan).astype(np.float32), np.where(known, variances, np.nan).astype(np.float32))


@dataclass
class Replan:
    """One map update and what became of its plan request."""

    t_publish: float
    map_seq: int
    request_id: int
    changed_cells: int
    kind: str = "update"
    t_apply: float | None = None
    # "in use", or why the answer was not used.
    outcome: str = OUTCOME_PENDING
    # Wall seconds from the map going out to the reply being sent by the service, and to the
    # answer being decoded here (the latter includes waiting for the simulation to ask).
    service_latency: float | None = None
    path_x: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    path_y: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    planner_cost: float | None = None
    # The feedback field put in use (P-F answers in use only).
    field: FeedbackField | None = None
    # The map as it was sent with this update (regular updates only; not the deliberately bad ones).
    map_snapshot: MapSnapshot | None = None
    _published_wall: float = 0.0

    @property
    def in_use(self) -> bool:
        return self.outcome == OUTCOME_IN_USE

    @property
    def rejected(self) -> bool:
        """An answer that came (or failed to come) and was not put in use."""
        return self.outcome not in (OUTCOME_IN_USE, OUTCOME_PENDING, OUTCOME_RUN_ENDED)


def horizontal_sigma(position_variance: NDArray[np.float64] | None) -> float:
    """The position's standard deviation along its worse horizontal axis, m (what the planner
    widens the footprint by, times κ); 0 without a variance."""
    if position_variance is None:
        return 0.0
    return math.sqrt(max(float(position_variance[0]), float(position_variance[1]), 0.0))


class OnlineNavigator:
    """Sensing, map updates and replanning for one run; the co-simulation asks it every control step."""

    def __init__(self, client: PlannerClient, scenario: Scenario, config: OnlineConfig) -> None:
        config.validate()
        self.client = client
        self.scenario = scenario
        self.config = config
        # Planning on the belief starts the P-F density from it too (unless a density is asked for).
        self.options = config.options
        if config.belief_planning and config.options.start_density == 0:
            self.options = replace(config.options, start_density=start_density_belief())
        self.belief: BeliefMap | SensedMap
        if config.perception is None:
            self.belief = BeliefMap(scenario.terrain, scenario.prior, config.sensor)
        else:
            self.belief = SensedMap(scenario.terrain, scenario.prior, config.perception)
        self.replans: list[Replan] = []
        self._pending: Replan | None = None
        self._next_update = 0.0
        self._current_field: FeedbackField | None = None
        self._last_good_seq = -1
        self._first_seq = -1
        self._bad_updates = list(config.bad_updates)

    @property
    def senses_terrain(self) -> bool:
        """Whether the co-simulation must call `sense` with the trunk's true and estimated pose."""
        return isinstance(self.belief, SensedMap)

    def scan_due(self, t: float) -> bool:
        """Whether `sense` at walk time `t` would scan (the co-simulation builds the poses only then)."""
        return isinstance(self.belief, SensedMap) and self.belief.scan_due(t)

    def sense(self, t: float, true_position: NDArray[np.float64], true_quaternion: NDArray[np.float64], belief: PoseBelief) -> None:
        """The terrain sensor's scans due by walk time `t`, fused at the estimated pose `belief`."""
        if isinstance(self.belief, SensedMap):
            self.belief.sense(t, true_position, true_quaternion, belief)

    def start(self, x: float, y: float, yaw: float, timeout: float, retries: int, trunk_height: float | None = None) -> PlanAnswer:
        """Senses at the start pose and plans on that knowledge (blocking): the first plan.

        With a real terrain sensor the robot scans once standing at the start, its trunk
        `trunk_height` above the ground (its estimate is the truth there).
        """
        changed = self._observe(x, y)
        if isinstance(self.belief, SensedMap):
            if trunk_height is None:
                raise SimulationError("a terrain sensor scans from the trunk: give the start's trunk height")
            position = np.array([x, y, float(self.scenario.terrain.height_at(x, y)) + trunk_height])
            quaternion = np.array([math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)])
            self.belief.sense(0.0, position, quaternion, PoseBelief(position, quaternion))
            changed = self.belief.take_changed()
        seq = self._publish_belief()
        snapshot = MapSnapshot.of(self.belief)
        self._first_seq = seq
        published = time.time()
        answer = self.client.request_answer(
            StartPose(x, y, yaw),
            self.scenario.goal,
            self.config.method,
            seq,
            self.options,
            timeout=timeout,
            retries=retries,
            context=f"'{self.scenario.name}' (start)",
        )
        replan = Replan(0.0, seq, answer.request_id, changed, kind="start", map_snapshot=snapshot, _published_wall=published)
        self._accept(replan, answer, 0.0)
        self.replans.append(replan)
        self._next_update = self.config.update_period
        return answer

    def tick(self, t: float, x: float, y: float, yaw: float, position_variance: NDArray[np.float64] | None = None) -> PlanAnswer | None:
        """Called with the walk clock `t` and the believed pose (`position_variance`: the
        estimator's x, y, z variances, m², read only when an update goes out; None: exact);
        returns an answer to put in use now, else None."""
        answer_now: PlanAnswer | None = None
        pending = self._pending
        if pending is not None and t >= pending.t_publish + self.config.apply_delay - 1e-9:
            self._pending = None
            answer = self._collect(pending)
            if answer is not None and self._accept(pending, answer, t):
                answer_now = answer
        if t >= self._next_update - 1e-9 and self._pending is None:
            self._next_update += self.config.update_period
            goal = self.scenario.goal
            # Inside the goal region there is nothing left to plan.
            if math.hypot(x - goal.center[0], y - goal.center[1]) > goal.radius:
                sigma = horizontal_sigma(position_variance) if self.config.belief_planning else 0.0
                self._send_update(t, x, y, yaw, sigma)
        return answer_now

    def _collect(self, pending: Replan) -> PlanAnswer | None:
        """The answer to `pending`, or None with the reason in its outcome."""
        try:
            answer = self.client.await_answer(pending.request_id, self.config.answer_timeout)
        except PlannerError as err:
            # A malformed answer (e.g. a one-sample plan from a start inside the goal) is one
            # failed replan, not the end of the walk.
            pending.outcome = f"unusable answer: {err}; kept the last plan"
            return None
        if answer is None:
            pending.outcome = f"no answer within {self.config.answer_timeout:.0f} s; kept the last plan"
        return answer

    def _observe(self, x: float, y: float) -> int:
        """The ideal sensor reveals the cells around (x, y); a real one has been fusing scans all along."""
        if isinstance(self.belief, BeliefMap):
            return self.belief.observe(x, y)
        return self.belief.take_changed()

    def _publish_belief(self) -> int:
        b = self.belief
        variances = b.height_variances() if self.config.belief_planning else None
        return self.client.publish_map(b.terrain(), known=b.known_mask(), unknown_traversability=b.unknown_traversability, variances=variances)

    def _send_update(self, t: float, x: float, y: float, yaw: float, sigma: float) -> None:
        changed = self._observe(x, y)
        kind = "update"
        snapshot = None
        if self._bad_updates and len(self.replans) >= 2:
            kind = self._bad_updates.pop(0)
            seq = self._publish_bad(kind)
        else:
            seq = self._publish_belief()
            snapshot = MapSnapshot.of(self.belief)
        published = time.time()
        request_id = self.client.send_request(StartPose(x, y, yaw, sigma), self.scenario.goal, self.config.method, seq, self.options)
        replan = Replan(t, seq, request_id, changed, kind=kind, map_snapshot=snapshot, _published_wall=published)
        self.replans.append(replan)
        self._pending = replan

    def _publish_bad(self, kind: str) -> int:
        """Publishes a deliberately broken update of the belief map; returns the seq it names."""
        b = self.belief
        terrain = b.terrain()
        known = b.known_mask()
        if kind == "stale":
            # A map stamped before anything this robot has sent: a delayed, superseded update.
            seq = self._first_seq - STALE_SEQ_AGE
            message = terrain_map_message(terrain, seq, known=known, unknown_traversability=b.unknown_traversability)
            message.heights = [h + 0.01 for h in message.heights]
            self.client.publish_raw_map(message)
            return seq
        seq = self.client.reserve_map_seq()
        message = terrain_map_message(terrain, seq, known=known, unknown_traversability=b.unknown_traversability)
        if kind == "nan":
            heights = list(message.heights)
            heights[len(heights) // 2] = math.nan
            message.heights = heights
        else:  # shape: the same area at half the resolution
            from .scenario import Terrain

            coarse = Terrain(terrain.origin, terrain.resolution * 2.0, terrain.heights[::2, ::2].copy(), None)
            message = terrain_map_message(coarse, seq, unknown_traversability=b.unknown_traversability)
        self.client.publish_raw_map(message)
        return seq

    def _accept(self, replan: Replan, answer: PlanAnswer, t: float) -> bool:
        replan.service_latency = answer.reply_utime * 1e-6 - replan._published_wall
        if not answer.ok or answer.plan is None:
            replan.outcome = f"status {answer.status}: {answer.error}; kept the last plan"
            return False
        if replan.map_seq < self._last_good_seq:
            replan.outcome = f"planned on map seq {replan.map_seq}, older than the plan in use (seq {self._last_good_seq}); kept the last plan"
            return False
        if self.config.method == "pf":
            if answer.field is None:
                replan.outcome = "the feedback field was lost on the bus; kept the last plan"
                return False
            current = self._current_field
            if current is not None and not current.same_grid(answer.field):
                replan.outcome = (
                    f"the feedback field's grid changed ({current.dir_x.shape[1]}x{current.dir_x.shape[0]} cells of "
                    f"{current.resolution:g} m -> {answer.field.dir_x.shape[1]}x{answer.field.dir_x.shape[0]} of "
                    f"{answer.field.resolution:g} m); kept the last plan"
                )
                return False
            self._current_field = answer.field
            replan.field = answer.field
        plan = answer.plan
        replan.t_apply = t
        replan.outcome = OUTCOME_IN_USE
        replan.path_x = plan.x.copy()
        replan.path_y = plan.y.copy()
        replan.planner_cost = plan.metrics.get("cost")
        self._last_good_seq = replan.map_seq
        return True

    def finish(self) -> None:
        """Collects the answer of a request still in flight at the end of the run (for the latency figures)."""
        pending = self._pending
        if pending is None:
            return
        self._pending = None
        answer = self._collect(pending)
        if answer is not None:
            pending.service_latency = answer.reply_utime * 1e-6 - pending._published_wall
            pending.outcome = OUTCOME_RUN_ENDED


def replan_field_log(replans: Sequence[Replan]) -> dict[str, NDArray[np.generic]]:
    """The feedback fields put in use, stacked (npz-friendly): `replan_field_rows` names each one's
    replan (row of the `replan_*` arrays). The navigator refuses a field on another grid than the
    one in use, so all share one grid. Directions and speeds as float16, cost-to-go as float32:
    a drawing's precision at a third of the bytes."""
    rows = [i for i, r in enumerate(replans) if r.field is not None]
    if not rows:
        return {}
    fields = [replans[i].field for i in rows]
    first = fields[0]
    assert first is not None and all(f is not None and f.same_grid(first) for f in fields), "fields in use share one grid"
    return {
        "replan_field_rows": np.array(rows, dtype=np.int64),
        "replan_field_origin": np.array(first.origin),
        "replan_field_resolution": np.array(first.resolution),
        "replan_field_goal": np.array(first.goal),
        "replan_field_dir_x": np.stack([f.dir_x for f in fields if f is not None]).astype(np.float16),
        "replan_field_dir_y": np.stack([f.dir_y for f in fields if f is not None]).astype(np.float16),
        "replan_field_speed": np.stack([f.speed for f in fields if f is not None]).astype(np.float16),
        "replan_field_cost_to_go": np.stack([f.cost_to_go for f in fields if f is not None]).astype(np.float32),
    }


def map_snapshot_log(replans: Sequence[Replan]) -> dict[str, NDArray[np.generic]]:
    """The belief map sent with each regular update, stacked: `map_snapshot_rows` names each one's
    replan (row of the `replan_*` arrays; its `replan_t_publish` is the snapshot's time)."""
    rows = [i for i, r in enumerate(replans) if r.map_snapshot is not None]
    if not rows:
        return {}
    snapshots = [replans[i].map_snapshot for i in rows]
    return {
        "map_snapshot_rows": np.array(rows, dtype=np.int64),
        "map_snapshot_heights": np.stack([s.heights for s in snapshots if s is not None]),
        "map_snapshot_variances": np.stack([s.variances for s in snapshots if s is not None]),
    }


def latency_summary(replans: Sequence[Replan]) -> dict[str, float | int]:
    """Replan count and latency percentiles (map published → reply sent), seconds."""
    regular = [r for r in replans if r.kind in ("update", "start")]
    latencies = np.array([r.service_latency for r in regular if r.service_latency is not None and r.kind == "update"])
    used = [r for r in replans if r.in_use and r.kind == "update"]
    rejected = [r for r in replans if r.rejected]
    summary: dict[str, float | int] = {
        "map_updates": len([r for r in replans if r.kind != "start"]),
        "replans_in_use": len(used),
        "rejected": len(rejected),
    }
    if len(latencies):
        summary["latency_p50"] = float(np.percentile(latencies, 50))
        summary["latency_p99"] = float(np.percentile(latencies, 99))
        summary["latency_max"] = float(latencies.max())
    return summary


def check_first_answer(answer: PlanAnswer, method: str) -> None:
    if answer.plan is None:
        raise PlannerError(f"no first {method} plan: status {answer.status}: {answer.error}")
    if method == "pf" and answer.field is None:
        raise PlannerError("the first P-F answer came without its feedback field")
