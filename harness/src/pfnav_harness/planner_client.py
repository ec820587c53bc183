"""LCM client of `pf-planner-service`: publishes the terrain like a perception system, asks for plans.

UDP multicast is lossy, so every request carries an id, the reply echoes it, and the client
re-publishes the map and retries after a timeout. The service may be started here (a child
process that is terminated on `close`) or be one that is already running on the bus.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import HarnessError, PlannerError
from .feedback_field import FeedbackField
from .lcm_channels import DEFAULT_CHANNEL_PREFIX, DEFAULT_LCM_URL, PLANNER
from .paths import repo_root
from .process_signals import stop_processes
from .scenario import GoalRegion, Scenario, Terrain

# Planning methods by name; the wire code of each is the schema's constant
# plan_request_t.METHOD_<NAME> (upper case, '-' as '_'), looked up by `method_code`.
METHODS = ("pf", "astar", "astar-admissible", "dijkstra")
# P-F basis and RBF generator kinds by name; the wire code of each is the schema's constant
# plan_options_t.BASIS_<NAME> / GENERATORS_<NAME>, looked up by `option_code`.
BASES = ("indicator", "rbf")
GENERATORS = ("transfer", "ansdmd")
# Footprint radius the harness starts the service with (m). The robot's feet stand 0.13 m beside
# its centre line and its controller keeps them 5 cm off edges; a path closer than ~0.25 m to the
# foot of a steep flank makes it pull the uphill feet in under the body, and the narrowed trot
# support tips over (mountain_pass). 0.25 m is two cells of the scenario maps.
ROBOT_FOOTPRINT_RADIUS = 0.25


def _schema_method_code(method: str) -> int | None:
    """`plan_request_t.METHOD_<NAME>` of a method name, None if the generated types lack it."""
    code = getattr(_import_types().plan_request_t, "METHOD_" + method.upper().replace("-", "_"), None)
    return None if code is None else int(code)


def method_code(method: str) -> int:
    """`plan_request_t.METHOD_*` of a method name of `METHODS`."""
    if method not in METHODS:
        raise PlannerError(f"unknown planning method '{method}' (choose from {', '.join(METHODS)})")
    code = _schema_method_code(method)
    if code is None:
        raise HarnessError(f"the generated LCM Python types have no code for '{method}': run `bash lcm_types/gen_python.sh`")
    return code


def option_code(kind: str, name: str) -> int:
    """`plan_options_t.<KIND>_<NAME>` (kind BASIS or GENERATORS) of a name of `BASES` / `GENERATORS`."""
    names = {"BASIS": BASES, "GENERATORS": GENERATORS}[kind]
    if name not in names:
        raise PlannerError(f"unknown {kind.lower()} '{name}' (choose from {', '.join(names)})")
    code = getattr(_import_types().plan_options_t, f"{kind}_{name.upper()}", None)
    if code is None:
        raise HarnessError(f"the generated LCM Python types have no {kind}_{name.upper()}: run `bash lcm_types/gen_python.sh`")
    return int(code)


def method_name(code: int) -> str:
    """The name of a `plan_request_t.METHOD_*` code (`method<code>` for one this client does not know)."""
    for name in METHODS:
        if _schema_method_code(name) == code:
            return name
    return f"method{code}"


def start_density_belief() -> int:
    """`plan_options_t.START_DENSITY_BELIEF`: the P-F start density is the robot's position belief."""
    return int(_import_types().plan_options_t.START_DENSITY_BELIEF)


def _import_types() -> Any:
    """The lcm-gen generated package `pfnav` (build/lcm_python, put on sys.path by setup.sh's .pth)."""
    try:
        import pfnav
    except ImportError:
        generated = repo_root() / "build" / "lcm_python"
        if not (generated / "pfnav").is_dir():
            raise HarnessError("the generated LCM Python types are missing: run `bash lcm_types/gen_python.sh` (or scripts/setup.sh)") from None
        sys.path.insert(0, str(generated))
        import pfnav
    return pfnav


def _import_lcm() -> Any:
    try:
        import lcm
    except ImportError as err:
        raise HarnessError("the Python package `lcm` is missing: run scripts/setup.sh") from err
    return lcm


@dataclass
class Plan:
    """A reference trajectory from the planner, with the planner's own figures."""

    method: str
    t: NDArray[np.float64]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    z: NDArray[np.float64]
    yaw: NDArray[np.float64]
    vx: NDArray[np.float64]
    vy: NDArray[np.float64]
    yaw_rate: NDArray[np.float64]
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    def __len__(self) -> int:
        return len(self.t)

    def validate(self) -> None:
        if len(self.t) < 2:
            raise PlannerError(f"{self.method} plan has {len(self.t)} samples; at least 2 are needed")
        columns = (self.t, self.x, self.y, self.z, self.yaw, self.vx, self.vy, self.yaw_rate)
        if any(len(c) != len(self.t) for c in columns):
            raise PlannerError(f"{self.method} plan columns have different lengths")
        if not all(np.all(np.isfinite(c)) for c in columns):
            raise PlannerError(f"{self.method} plan contains NaN or infinite values")
        if np.any(np.diff(self.t) <= 0.0):
            raise PlannerError(f"{self.method} plan times are not strictly increasing")

    def to_npz_dict(self, prefix: str = "plan_") -> dict[str, NDArray[np.float64]]:
        return {f"{prefix}{name}": getattr(self, name) for name in ("t", "x", "y", "z", "yaw", "vx", "vy", "yaw_rate")}


@dataclass(frozen=True)
class StartPose:
    x: float
    y: float
    yaw: float
    # Standard deviation of the position, m (the estimator's, worst horizontal axis; 0: exact):
    # the service widens the footprint by confidence_sigmas times it.
    sigma: float = 0.0


@dataclass(frozen=True)
class RequestOptions:
    """Planner settings of a request (0 = the service's default for each)."""

    speed: float = 0.0
    directions: int = 0
    sample_period: float = 0.0
    max_solve_time: float = 0.0
    # κ of the margin for the start's uncertainty (0: the service's default, 2).
    confidence_sigmas: float = 0.0
    # P-F start density: one of plan_options_t.START_DENSITY_* (0: the service's default).
    start_density: int = 0
    # P-F basis: one of plan_options_t.BASIS_* (0: the service's default, indicator).
    basis: int = 0
    # RBF generators: one of plan_options_t.GENERATORS_* (0: the service's default, transfer).
    generators: int = 0


@dataclass
class PlanAnswer:
    """The service's answer to one request: a plan (and its feedback field) or a status with the reason."""

    request_id: int
    status: int
    error: str
    plan: Plan | None
    field: FeedbackField | None
    # When the service sent the reply (its header utime, µs) and when it was read here (s, epoch).
    reply_utime: int
    received: float

    @property
    def ok(self) -> bool:
        return self.plan is not None

    def plan_or_raise(self, method: str) -> Plan:
        if self.plan is None:
            raise PlannerError(f"no {method} plan: status {self.status}: {self.error}")
        return self.plan


def terrain_map_message(
    terrain: Terrain,
    seq: int,
    utime: int | None = None,
    known: NDArray[np.bool_] | None = None,
    unknown_traversability: float = 0.0,
    variances: NDArray[np.float64] | None = None,
) -> Any:
    """The terrain as `pfnav.terrain_map_t` (heights row-major iy·width + ix, like the map).

    `known` marks the observed cells of a partially known map (None: every cell is known); the
    planner gives the others `unknown_traversability` (0: its default). `variances` (m², None:
    exact heights) lets the planner price each known cell from its confidence bounds.
    """
    pfnav = _import_types()
    msg = pfnav.terrain_map_t()
    msg.header.utime = int(time.time() * 1e6) if utime is None else utime
    msg.header.seq = seq
    msg.header.frame_id = "world"
    msg.origin_x, msg.origin_y = terrain.origin
    msg.resolution = terrain.resolution
    ny, nx = terrain.shape
    msg.width = nx
    msg.height = ny
    msg.num_cells = nx * ny
    msg.heights = terrain.heights.ravel().tolist()
    if terrain.obstacles is not None and bool(terrain.obstacles.any()):
        msg.num_obstacle_cells = nx * ny
        msg.obstacle_mask = [bool(v) for v in terrain.obstacles.ravel()]
    else:
        msg.num_obstacle_cells = 0
        msg.obstacle_mask = []
    msg.known_mask = [bool(v) for v in _per_cell(known, terrain, "known-cell mask")]
    msg.num_known_cells = len(msg.known_mask)
    msg.unknown_traversability = float(unknown_traversability)
    msg.height_variances = [float(v) for v in _per_cell(variances, terrain, "height variances")]
    msg.num_variance_cells = len(msg.height_variances)
    return msg


def _per_cell(values: NDArray[np.generic] | None, terrain: Terrain, what: str) -> NDArray[np.generic]:
    """An optional per-cell array of the map, row-major (empty when absent: the wire's "none")."""
    if values is None:
        return np.zeros(0)
    if values.shape != terrain.shape:
        raise PlannerError(f"{what} of shape {values.shape} differs from the map's {terrain.shape}")
    return values.ravel()


def plan_from_reply(reply: Any) -> Plan:
    samples = reply.samples
    method = method_name(reply.method)
    m = reply.metrics
    plan = Plan(
        method=method,
        t=np.array([s.t for s in samples], dtype=np.float64),
        x=np.array([s.x for s in samples], dtype=np.float64),
        y=np.array([s.y for s in samples], dtype=np.float64),
        z=np.array([s.z for s in samples], dtype=np.float64),
        yaw=np.array([s.yaw for s in samples], dtype=np.float64),
        vx=np.array([s.vx for s in samples], dtype=np.float64),
        vy=np.array([s.vy for s in samples], dtype=np.float64),
        yaw_rate=np.array([s.yaw_rate for s in samples], dtype=np.float64),
        metrics={
            "cost": float(m.cost),
            "length": float(m.length),
            "duration": float(m.duration),
            "solve_time": float(m.solve_time),
            "objective": float(m.objective),
            "lp_status": float(m.lp_status),
            "reached_goal": float(bool(m.reached_goal)),
        },
    )
    plan.validate()
    return plan


class PlannerClient:
    """Talks to one planner service on an LCM bus; use as a context manager."""

    def __init__(
        self,
        lcm_url: str = DEFAULT_LCM_URL,
        channel_prefix: str = DEFAULT_CHANNEL_PREFIX,
        service_binary: Path | None = None,
        service_log: Path | None = None,
        startup_timeout: float = 10.0,
        footprint_radius: float = ROBOT_FOOTPRINT_RADIUS,
        max_slope_deg: float | None = None,
        traversability: dict[str, float] | None = None,
    ) -> None:
        """`footprint_radius`, `max_slope_deg` (None: no limit) and further fields of the planner's
        traversability model (`traversability`, e.g. {"slope_weight": 1.0}) configure a started
        service's cost model."""
        self._pfnav = _import_types()
        self.footprint_radius = footprint_radius
        self.max_slope_deg = max_slope_deg
        self.traversability = dict(traversability or {})
        lcm = _import_lcm()
        self.lcm_url = lcm_url
        self.prefix = channel_prefix
        try:
            self.lc = lcm.LCM(lcm_url)
        except Exception as err:  # the lcm module raises a bare RuntimeError/IOError subclass
            raise PlannerError(f"cannot open LCM at {lcm_url}: {err} (udpm:// needs a multicast route: run inside scripts/netns.sh)") from err
        self._replies: dict[int, Any] = {}
        self._fields: dict[int, Any] = {}
        self._status: Any = None
        self._status_count = 0
        self._next_request_id = int(time.time()) % 1_000_000 * 1000 + 1
        # Map sequence numbers rise across client restarts too (milliseconds since the epoch), so a
        # long-running service never takes a new client's first map for a stale update.
        self._map_seq = time.time_ns() // 1_000_000
        self._published_map: Any = None
        self._subs = [
            self.lc.subscribe(self.prefix + PLANNER.plan_reply, self._on_reply),
            self.lc.subscribe(self.prefix + PLANNER.service_status, self._on_status),
            self.lc.subscribe(self.prefix + PLANNER.feedback_field, self._on_field),
        ]
        self.process: subprocess.Popen[bytes] | None = None
        self._service_log_path = service_log
        self._service_log: Any = None
        if service_binary is not None:
            self._start_service(service_binary, startup_timeout)

    # --- LCM plumbing -------------------------------------------------------------------------
    def _on_reply(self, _channel: str, data: bytes) -> None:
        try:
            reply = self._pfnav.plan_reply_t.decode(data)
        except ValueError:
            return
        self._replies[int(reply.request_id)] = reply

    def _on_field(self, _channel: str, data: bytes) -> None:
        try:
            message = self._pfnav.feedback_field_t.decode(data)
        except ValueError:
            return
        self._fields[int(message.request_id)] = message
        # Fields of requests nobody waits for any more must not pile up.
        while len(self._fields) > 16:
            self._fields.pop(next(iter(self._fields)))

    def _on_status(self, _channel: str, data: bytes) -> None:
        try:
            self._status = self._pfnav.service_status_t.decode(data)
        except ValueError:
            return
        self._status_count += 1

    def _handle_for(self, seconds: float) -> None:
        """Dispatches incoming messages for up to `seconds`."""
        deadline = time.monotonic() + seconds
        fd = self.lc.fileno()
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return
            ready, _, _ = select.select([fd], [], [], remaining)
            if ready:
                self.lc.handle()
                return

    # --- service process ----------------------------------------------------------------------
    def _start_service(self, binary: Path, timeout: float) -> None:
        args = [str(binary), "--lcm-url", self.lcm_url, "--channel-prefix", self.prefix, f"--footprint-radius={self.footprint_radius!r}"]
        if self.max_slope_deg is not None:
            args.append(f"--max-slope-deg={self.max_slope_deg!r}")
        if self.traversability:
            args.append(f"--traversability={json.dumps(self.traversability)}")
        if self._service_log_path is not None:
            self._service_log_path.parent.mkdir(parents=True, exist_ok=True)
            self._service_log = open(self._service_log_path, "wb")  # noqa: SIM115 (closed in close())
            out: Any = self._service_log
        else:
            out = subprocess.DEVNULL
        try:
            self.process = subprocess.Popen(args, stdout=out, stderr=out, env={**os.environ, "RUST_LOG": os.environ.get("RUST_LOG", "info")})
        except OSError as err:
            raise PlannerError(f"cannot start {binary}: {err}") from err
        deadline = time.monotonic() + timeout
        while self._status_count == 0:
            if self.process.poll() is not None:
                raise PlannerError(f"pf-planner-service exited with code {self.process.returncode} at start-up{self._log_hint()}")
            if time.monotonic() > deadline:
                raise PlannerError(
                    f"pf-planner-service started but published no status on {self.prefix}SERVICE_STATUS within "
                    f"{timeout:.0f} s (is multicast routed on lo? run inside scripts/netns.sh){self._log_hint()}"
                )
            self._handle_for(0.1)

    def _log_hint(self) -> str:
        if self._service_log_path is None:
            return ""
        if self._service_log is not None:
            self._service_log.flush()
        try:
            tail = self._service_log_path.read_text(errors="replace").strip().splitlines()[-5:]
        except OSError:
            return ""
        return ("; service log tail:\n  " + "\n  ".join(tail)) if tail else ""

    def wait_for_service(self, timeout: float) -> None:
        """Waits for a status message from an already running service."""
        deadline = time.monotonic() + timeout
        while self._status_count == 0:
            if time.monotonic() > deadline:
                raise PlannerError(f"no planner service answers on {self.lcm_url} (no {self.prefix}SERVICE_STATUS within {timeout:.0f} s)")
            self._handle_for(0.1)

    def close(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(Exception):  # closing: nothing useful to do on failure
                self.lc.unsubscribe(sub)
        self._subs = []
        stop_processes([self.process], timeout=5.0)
        self.process = None
        if self._service_log is not None:
            self._service_log.close()
            self._service_log = None

    def __enter__(self) -> PlannerClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- requests -----------------------------------------------------------------------------
    def publish_map(
        self,
        terrain: Terrain,
        known: NDArray[np.bool_] | None = None,
        unknown_traversability: float = 0.0,
        variances: NDArray[np.float64] | None = None,
    ) -> int:
        """Publishes the terrain on `<prefix>MAP` with a new sequence number and returns it."""
        seq = self.reserve_map_seq()
        self._published_map = terrain_map_message(terrain, seq, known=known, unknown_traversability=unknown_traversability, variances=variances)
        self.lc.publish(self.prefix + PLANNER.map, self._published_map.encode())
        return seq

    def reserve_map_seq(self) -> int:
        """A new map sequence number (the next map published gets a higher one)."""
        self._map_seq += 1
        return self._map_seq

    def publish_raw_map(self, message: Any) -> None:
        """Publishes a prepared `terrain_map_t` as is (tests of how the service treats bad updates)."""
        self.lc.publish(self.prefix + PLANNER.map, message.encode())

    def _republish_map(self) -> None:
        if self._published_map is not None:
            self.lc.publish(self.prefix + PLANNER.map, self._published_map.encode())

    def send_request(self, pose: StartPose, goal: GoalRegion, method: str, map_seq: int, options: RequestOptions | None = None) -> int:
        """Publishes one plan request and returns its id without waiting for the answer."""
        code = method_code(method)
        options = options or RequestOptions()
        pfnav = self._pfnav
        request_id = self._next_request_id
        self._next_request_id += 1
        req = pfnav.plan_request_t()
        req.header.utime = int(time.time() * 1e6)
        req.header.seq = request_id
        req.header.frame_id = "world"
        req.request_id = request_id
        req.num_inline_maps = 0
        req.inline_map = []
        req.map_seq = map_seq
        req.start_x, req.start_y = pose.x, pose.y
        req.start_yaw = pose.yaw
        req.goal_x, req.goal_y = goal.center
        req.goal_radius = goal.radius
        req.method = code
        req.options.directions = options.directions
        req.options.speed = options.speed
        req.options.sample_period = options.sample_period
        req.options.max_solve_time = options.max_solve_time
        req.options.confidence_sigmas = options.confidence_sigmas
        req.options.start_density = options.start_density
        req.options.basis = options.basis
        if options.generators:
            # Stale generated types lack the appended field; only a request that needs it fails.
            if "generators" not in getattr(req.options, "__slots__", ("generators",)):
                raise HarnessError("the generated LCM Python types have no plan_options_t.generators: run `bash lcm_types/gen_python.sh`")
            req.options.generators = options.generators
        req.start_sigma = pose.sigma
        self.lc.publish(self.prefix + PLANNER.plan_request, req.encode())
        return request_id

    def await_answer(self, request_id: int, timeout: float) -> PlanAnswer | None:
        """The service's answer to `request_id`, or None after `timeout` seconds of silence.

        The feedback field of a P-F plan is published just before its reply; an answer whose
        field was lost on the bus comes back with `field` None.
        """
        deadline = time.monotonic() + timeout
        while request_id not in self._replies:
            if self.process is not None and self.process.poll() is not None:
                raise PlannerError(f"pf-planner-service died (exit code {self.process.returncode}){self._log_hint()}")
            if time.monotonic() > deadline:
                self._fields.pop(request_id, None)
                return None
            self._handle_for(0.05)
        received = time.time()
        reply = self._replies.pop(request_id)
        field_message = self._fields.pop(request_id, None)
        pfnav = self._pfnav
        if reply.status != pfnav.plan_reply_t.STATUS_OK:
            return PlanAnswer(request_id, int(reply.status), str(reply.error), None, None, int(reply.header.utime), received)
        plan = plan_from_reply(reply)
        field = None
        if field_message is not None:
            field = FeedbackField.from_message(field_message)
            field.validate()
        return PlanAnswer(request_id, int(reply.status), "", plan, field, int(reply.header.utime), received)

    def status_is_retryable(self, status: int) -> bool:
        """BUSY (queue full) and INVALID_MAP (the map may have been lost on the bus) are worth a retry."""
        reply_type = self._pfnav.plan_reply_t
        return status in (reply_type.STATUS_BUSY, reply_type.STATUS_INVALID_MAP)

    def request_plan(
        self,
        scenario: Scenario,
        method: str,
        map_seq: int,
        speed: float = 0.0,
        directions: int = 0,
        sample_period: float = 0.0,
        timeout: float = 60.0,
        retries: int = 3,
        max_solve_time: float = 0.0,
    ) -> Plan:
        """Asks for a plan from the scenario's start on the published map `map_seq`; retries on silence and on a lost map."""
        return self.request_answer(
            StartPose(scenario.start[0], scenario.start[1], scenario.start_yaw),
            scenario.goal,
            method,
            map_seq,
            RequestOptions(speed=speed, directions=directions, sample_period=sample_period, max_solve_time=max_solve_time),
            timeout=timeout,
            retries=retries,
            context=f"'{scenario.name}'",
        ).plan_or_raise(method)

    def request_answer(
        self,
        pose: StartPose,
        goal: GoalRegion,
        method: str,
        map_seq: int,
        options: RequestOptions | None = None,
        timeout: float = 60.0,
        retries: int = 3,
        context: str = "",
    ) -> PlanAnswer:
        """A successful answer for the request, retried on silence and on retryable statuses."""
        last_error = "no reply"
        for attempt in range(retries + 1):
            request_id = self.send_request(pose, goal, method, map_seq, options)
            answer = self.await_answer(request_id, timeout)
            if answer is None:
                last_error = f"no reply within {timeout:.0f} s"
                self._republish_map()
                continue
            if answer.ok:
                return answer
            last_error = f"status {answer.status}: {answer.error}"
            if not self.status_is_retryable(answer.status):
                break
            self._republish_map()
            time.sleep(min(2.0, 0.2 * (attempt + 1)))
        raise PlannerError(f"the planner gave no {method} plan for {context or 'the request'} after {retries + 1} attempt(s): {last_error}")


def plan_answers(
    scenario: Scenario,
    methods: Sequence[str],
    lcm_url: str = DEFAULT_LCM_URL,
    channel_prefix: str = DEFAULT_CHANNEL_PREFIX,
    service_binary: Path | None = None,
    service_log: Path | None = None,
    speed: float = 0.0,
    timeout: float = 60.0,
    retries: int = 3,
    footprint_radius: float = ROBOT_FOOTPRINT_RADIUS,
    service_wait: float = 5.0,
) -> dict[str, PlanAnswer]:
    """Publishes the scenario's map once and asks for one plan per method: each method's answer
    (its plan, and the feedback field of a P-F plan). Raises PlannerError for a method without a plan.

    Without `service_binary` a running service is used; it must answer within `service_wait` s
    (at most `timeout`)."""
    start = StartPose(scenario.start[0], scenario.start[1], scenario.start_yaw)
    with PlannerClient(lcm_url, channel_prefix, service_binary, service_log, footprint_radius=footprint_radius) as client:
        if service_binary is None:
            client.wait_for_service(timeout=min(timeout, service_wait))
        seq = client.publish_map(scenario.terrain)
        # Give the service a moment to ingest the map before the first request references it.
        client._handle_for(0.05)
        answers = {}
        for method in methods:
            answer = client.request_answer(
                start, scenario.goal, method, seq, RequestOptions(speed=speed), timeout=timeout, retries=retries, context=f"'{scenario.name}'"
            )
            answer.plan_or_raise(method)
            answers[method] = answer
        return answers


def plan_scenario(
    scenario: Scenario,
    methods: Sequence[str],
    lcm_url: str = DEFAULT_LCM_URL,
    channel_prefix: str = DEFAULT_CHANNEL_PREFIX,
    service_binary: Path | None = None,
    service_log: Path | None = None,
    speed: float = 0.0,
    timeout: float = 60.0,
    retries: int = 3,
    footprint_radius: float = ROBOT_FOOTPRINT_RADIUS,
) -> dict[str, Plan]:
    """Publishes the scenario's map once and requests one plan per method."""
    answers = plan_answers(scenario, methods, lcm_url, channel_prefix, service_binary, service_log, speed, timeout, retries, footprint_radius)
    return {method: answer.plan_or_raise(method) for method, answer in answers.items()}
