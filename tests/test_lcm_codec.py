"""Python (lcm-gen bindings) <-> Rust (lcm-types codec) cross-decoding.

The Rust side is the `lcm-roundtrip` binary of the lcm-types crate (built by
`cargo build --release --workspace`; override with PFNAV_LCM_ROUNDTRIP). It decodes a payload to
JSON, encodes JSON to a payload, or re-encodes a payload. The Python side is the `pfnav` package
that `lcm_types/gen_python.sh` generates with lcm-gen into build/lcm_python.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]
if str(REPO / "build" / "lcm_python") not in sys.path:
    sys.path.insert(0, str(REPO / "build" / "lcm_python"))

import pfnav
from pfnav import (
    feedback_field_t,
    header_t,
    low_cmd_t,
    low_state_t,
    nav_cmd_t,
    plan_metrics_t,
    plan_options_t,
    plan_reply_t,
    plan_request_t,
    robot_estimate_t,
    robot_state_t,
    robot_status_t,
    service_status_t,
    terrain_map_t,
    trajectory_sample_t,
)

PRIMITIVES = {
    "int8_t",
    "int16_t",
    "int32_t",
    "int64_t",
    "byte",
    "float",
    "double",
    "string",
    "boolean",
}


def roundtrip_binary() -> Path:
    override = os.environ.get("PFNAV_LCM_ROUNDTRIP")
    candidates = [Path(override)] if override else []
    candidates += [
        REPO / "target" / "release" / "lcm-roundtrip",
        REPO / "target" / "debug" / "lcm-roundtrip",
    ]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    pytest.fail(
        "lcm-roundtrip not built: run `bash scripts/setup.sh --tests` (or set PFNAV_LCM_ROUNDTRIP)"
    )


def run_rust(mode: str, data: bytes) -> bytes:
    result = subprocess.run(
        [str(roundtrip_binary()), mode],
        input=data,
        capture_output=True,
        timeout=30,
        check=False,
    )
    if result.returncode != 0:
        raise RuntimeError(result.stderr.decode(errors="replace"))
    return result.stdout


def lcm_class(type_name: str) -> type:
    return getattr(pfnav, type_name.rsplit(".", 1)[1])


def to_json(value: Any, type_name: str) -> Any:
    """Plain JSON form of a generated LCM object, members by their LCM names."""
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [to_json(v, type_name) for v in value]
    if type_name in PRIMITIVES:
        return value
    cls = lcm_class(type_name)
    return {
        slot: to_json(getattr(value, slot), member_type)
        for slot, member_type in zip(cls.__slots__, cls.__typenames__)
    }


def header(seq: int) -> header_t:
    h = header_t()
    h.utime = 1_763_860_000_000_000 + seq
    h.seq = seq
    h.frame_id = "world"
    return h


def terrain_map(
    width: int, height: int, with_obstacles: bool, with_known: bool = False
) -> terrain_map_t:
    m = terrain_map_t()
    m.header = header(4)
    m.origin_x, m.origin_y, m.resolution = -3.2, 1.6, 0.1
    m.width, m.height = width, height
    m.num_cells = width * height
    # Row-major iy*width + ix, heights in metres with values that are not short decimals.
    m.heights = [
        math.sin(0.37 * ix) * math.cos(0.21 * iy) + 1e-9 * ix
        for iy in range(height)
        for ix in range(width)
    ]
    m.num_obstacle_cells = m.num_cells if with_obstacles else 0
    m.obstacle_mask = [(i % 7) == 3 for i in range(m.num_obstacle_cells)]
    # Partially known: the mask and the prior p of the unknown cells (0 = the service default).
    m.num_known_cells = m.num_cells if with_known else 0
    m.known_mask = [(i % 5) != 1 for i in range(m.num_known_cells)]
    m.unknown_traversability = 0.35 if with_known else 0.0
    # Height variances go with a sensed (partially known) map; 0 entries = exact heights.
    m.num_variance_cells = m.num_cells if with_known else 0
    m.height_variances = [1e-4 * (1 + i % 11) for i in range(m.num_variance_cells)]
    return m


def feedback_field(width: int, height: int) -> feedback_field_t:
    f = feedback_field_t()
    f.header = header(21)
    f.request_id = 2**40 + 5
    f.map_seq = 4
    f.origin_x, f.origin_y, f.resolution = -3.2, 1.6, 0.125
    f.width, f.height = width, height
    f.num_cells = width * height
    # float32 arrays: values exact in float32, so the JSON forms compare equal.
    f.dir_x = [(-1.0, 0.0, 0.5, 1.0)[i % 4] for i in range(f.num_cells)]
    f.dir_y = [(0.0, -0.75, 0.25, 1.0)[i % 4] for i in range(f.num_cells)]
    f.speed = [0.5 if i % 3 else 0.0 for i in range(f.num_cells)]
    f.cost_to_go = [-1.0 if i % 7 == 0 else 0.0625 * i for i in range(f.num_cells)]
    f.goal_x, f.goal_y, f.goal_radius = -2.6, 2.0, 0.15
    return f


def sample_messages() -> list[Any]:
    options = plan_options_t()
    options.basis = plan_options_t.BASIS_RBF
    options.grid_size = 32
    options.directions = 8
    options.speed = 0.45
    options.start_density = plan_options_t.START_DENSITY_UNIFORM
    options.sample_period = 0.05
    options.max_solve_time = 30.0
    options.solver = plan_options_t.SOLVER_CLARABEL

    request = plan_request_t()
    request.header = header(17)
    request.request_id = 2**40 + 5
    request.num_inline_maps = 1
    request.inline_map = [terrain_map(7, 5, True)]
    request.map_seq = -1
    request.start_x, request.start_y, request.start_yaw = -2.95, 1.85, -math.pi / 3
    request.goal_x, request.goal_y, request.goal_radius = -2.6, 2.0, 0.15
    request.method = plan_request_t.METHOD_PF
    request.options = options

    by_seq = plan_request_t()
    by_seq.request_id = 3
    by_seq.map_seq = 4
    by_seq.method = plan_request_t.METHOD_ASTAR

    samples = []
    for i in range(12):
        s = trajectory_sample_t()
        s.t = 0.05 * i
        s.x, s.y = -2.95 + 0.02 * i, 1.85 + 0.01 * i
        s.z = 0.3 * math.sin(s.x)
        s.yaw = math.atan2(0.01, 0.02)
        s.vx, s.vy, s.yaw_rate = 0.4, 0.2, 0.0
        samples.append(s)
    metrics = plan_metrics_t()
    metrics.cost, metrics.length, metrics.duration = 0.1234567891, 0.2459, 0.55
    metrics.solve_time, metrics.objective = 0.0421, 0.37
    metrics.lp_status, metrics.lp_iterations = plan_metrics_t.LP_SOLVED, 23
    metrics.expanded_nodes, metrics.reached_goal = 0, True
    metrics.lp_solver, metrics.certified, metrics.cache_hit = plan_metrics_t.SOLVER_DIJKSTRA, True, True
    metrics.primal_residual, metrics.dual_residual, metrics.duality_gap = 1e-15, 0.0, 3e-16
    metrics.certificate_tolerance, metrics.generator_time = 1e-6, 0.0
    metrics.solve_phase_time, metrics.path_time = 0.004, 0.002
    reply = plan_reply_t()
    reply.header = header(18)
    reply.request_id = request.request_id
    reply.status = plan_reply_t.STATUS_OK
    reply.method = request.method
    reply.map_seq = 4
    reply.num_samples = len(samples)
    reply.samples = samples
    reply.metrics = metrics

    failed = plan_reply_t()
    failed.request_id = 99
    failed.status = plan_reply_t.STATUS_INVALID_MAP
    failed.error = "heights[3] is NaN — map rejected (höhe ungültig) 🦀"

    status = service_status_t()
    status.header = header(19)
    status.uptime = 3601.25
    status.requests_received, status.requests_served, status.requests_failed = (
        1000,
        990,
        10,
    )
    status.requests_rejected_busy, status.malformed_messages = 4, 100_000
    status.maps_received, status.latest_map_seq = 2, 4
    status.last_solve_time, status.queue_depth, status.queue_capacity = 0.031, 3, 64
    status.cached_generators = 2

    state = robot_state_t()
    state.utime = 1_500_000
    state.position = [1.0, -2.0, 0.28]
    state.orientation = [math.cos(0.1), 0.0, 0.0, math.sin(0.1)]
    state.linear_velocity = [0.5, 0.01, -0.002]
    state.angular_velocity = [0.0, 0.02, 0.1]
    state.joint_positions = [0.01 * i for i in range(12)]
    state.joint_velocities = [-0.5 + 0.1 * i for i in range(12)]
    state.joint_torques = [3.0 - 0.25 * i for i in range(12)]
    state.foot_contact = [True, False, False, True]
    state.fsm_state = 3
    state.reference = [1.02, -2.0, 0.0, 0.2, 0.5, 0.0, 0.1]

    # Values exact in float32 (the motor and IMU fields are float), so both sides hold the same number.
    low_state = low_state_t()
    low_state.header = header(20)
    low_state.tick = 987_654
    low_state.imu_quaternion = [1.0, 0.0, 0.125, -0.25]
    low_state.imu_gyroscope = [0.5, -0.25, 0.0]
    low_state.imu_accelerometer = [0.0, 0.75, 9.75]
    low_state.q = [0.125 * i - 0.5 for i in range(12)]
    low_state.dq = [-1.5 + 0.25 * i for i in range(12)]
    low_state.tau_est = [4.0 - 0.5 * i for i in range(12)]
    low_state.foot_force = [40.0, 0.0, 38.5, 1.5]
    low_state.foot_contact = [1, 0, -1, 1]

    low_cmd = low_cmd_t()
    low_cmd.header = header(21)
    low_cmd.state_seq = 20
    low_cmd.mode = [low_cmd_t.MODE_SERVO] * 11 + [low_cmd_t.MODE_IDLE]
    low_cmd.q = [0.0] * 12
    low_cmd.dq = [0.0] * 12
    low_cmd.tau = [2.0 - 0.25 * i for i in range(12)]
    low_cmd.kp = [0.0] * 12
    low_cmd.kd = [0.0] * 11 + [2.5]

    nav = nav_cmd_t()
    nav.header = header(22)
    nav.mode = nav_cmd_t.MODE_LOCOMOTION
    nav.x, nav.y, nav.z, nav.yaw = 1.5, -0.25, 0.02, 0.3
    nav.vx, nav.vy, nav.yaw_rate = 0.5, 0.05, -0.1
    nav.body_height, nav.terrain_dzdx, nav.terrain_dzdy = 0.0, 0.1, -0.05

    robot_status = robot_status_t()
    robot_status.header = header(23)
    robot_status.uptime, robot_status.period = 61.5, 1e-3
    robot_status.window_cycles, robot_status.total_cycles = 500, 61_500
    robot_status.window_misses, robot_status.total_misses = 1, 7
    robot_status.period_p50, robot_status.period_p99, robot_status.period_max = 1.0e-3, 1.1e-3, 1.4e-3
    robot_status.runtime_p50, robot_status.runtime_p99, robot_status.runtime_max = 6e-5, 4e-4, 6e-4
    robot_status.latency_p99, robot_status.latency_max = 9.5e-4, 1.2e-3
    robot_status.safety = robot_status_t.SAFETY_DAMPING
    robot_status.safety_since = 60.25
    robot_status.reason = "no low_state_t for 20 ms"
    robot_status.damping_entries, robot_status.fsm_state = 2, 2
    robot_status.states_received, robot_status.states_out_of_order = 61_000, 3
    robot_status.states_non_finite, robot_status.nav_cmds_received = 1, 3_000
    robot_status.malformed_messages = 12
    robot_status.realtime_priority, robot_status.memory_locked = False, True
    robot_status.jitter_p99, robot_status.jitter_max = 6.5e-5, 4.0e-4
    robot_status.latency_p50 = 3.1e-4
    robot_status.window_overruns, robot_status.total_overruns = 1, 5

    estimate = robot_estimate_t()
    estimate.header = header(24)
    estimate.state_seq = 20
    estimate.position = [1.25, -0.5, 0.31]
    estimate.velocity = [0.4, 0.01, -0.02]
    estimate.rpy = [0.01, -0.03, 0.8]
    estimate.position_variance = [1e-4, 1e-4, 4e-6]
    estimate.estimator_status = 8
    estimate.fsm_state, estimate.safety = 3, robot_status_t.SAFETY_OK
    return [
        state,
        low_state,
        low_cmd,
        nav,
        robot_status,
        estimate,
        terrain_map(16, 9, False),
        terrain_map(3, 3, True),
        terrain_map(6, 4, True, with_known=True),
        feedback_field(5, 3),
        request,
        by_seq,
        reply,
        failed,
        status,
        header(1),
    ]


def type_name_of(msg: Any) -> str:
    return f"pfnav.{type(msg).__name__}"


def test_fingerprints_agree_for_every_type() -> None:
    rust = dict(
        line.split() for line in run_rust("fingerprints", b"").decode().splitlines()
    )
    python = {
        f"pfnav.{name}": "0x"
        + lcm_class(f"pfnav.{name}")._get_packed_fingerprint().hex()
        for name in (
            "header_t",
            "terrain_map_t",
            "feedback_field_t",
            "plan_options_t",
            "plan_request_t",
            "trajectory_sample_t",
            "plan_metrics_t",
            "plan_reply_t",
            "service_status_t",
            "robot_state_t",
            "low_state_t",
            "low_cmd_t",
            "nav_cmd_t",
            "robot_status_t",
            "robot_estimate_t",
        )
    }
    assert rust == python


@pytest.mark.parametrize("index", range(len(sample_messages())))
def test_rust_decodes_what_python_encodes(index: int) -> None:
    msg = sample_messages()[index]
    decoded = json.loads(run_rust("decode", msg.encode()))
    assert decoded["type"] == type_name_of(msg)
    assert decoded["value"] == to_json(msg, type_name_of(msg))


@pytest.mark.parametrize("index", range(len(sample_messages())))
def test_python_decodes_what_rust_encodes(index: int) -> None:
    msg = sample_messages()[index]
    tagged = {"type": type_name_of(msg), "value": to_json(msg, type_name_of(msg))}
    rust_bytes = run_rust("encode", json.dumps(tagged).encode())
    assert rust_bytes == msg.encode()
    back = type(msg).decode(rust_bytes)
    assert to_json(back, type_name_of(msg)) == tagged["value"]


@pytest.mark.parametrize("index", range(len(sample_messages())))
def test_rust_reencodes_python_bytes_identically(index: int) -> None:
    payload = sample_messages()[index].encode()
    assert run_rust("reencode", payload) == payload


def test_rust_rejects_corrupt_payloads_with_a_reason() -> None:
    payload = terrain_map(4, 4, True).encode()
    with pytest.raises(RuntimeError, match="truncated"):
        run_rust("decode", payload[:20])
    # Cut inside the obstacle mask (followed by num_known_cells, unknown_traversability and
    # num_variance_cells, 16 bytes): the declared length no longer fits the bytes left.
    with pytest.raises(RuntimeError, match="obstacle_mask: 16 elements cannot fit"):
        run_rust("decode", payload[: -(16 + 3)])
    with pytest.raises(RuntimeError, match="fingerprint"):
        run_rust("decode", b"\x00" * 8 + payload[8:])
    # num_cells claims 2^31-1 heights: refused before allocation, with the field named.
    offset = 8 + 8 + 8 + (4 + 6) + 8 * 3 + 4 + 4
    claimed = payload[:offset] + (2**31 - 1).to_bytes(4, "big") + payload[offset + 4 :]
    with pytest.raises(RuntimeError, match="heights"):
        run_rust("decode", claimed)
