"""The LCM bus contract as Python reads it: the default URL and the channel names of
`lcm_types/channels.toml` (the one declaration; Rust generates `lcm_types::channels` from it)."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from urllib.parse import urlsplit

from .paths import repo_root

CHANNELS_FILE = repo_root() / "lcm_types" / "channels.toml"


def _load() -> dict[str, object]:
    with CHANNELS_FILE.open("rb") as f:
        return tomllib.load(f)


_CONTRACT = _load()


def _channel(group: str, name: str) -> str:
    table = _CONTRACT[group]
    assert isinstance(table, dict)
    return str(table[name][0])


@dataclass(frozen=True)
class PlannerChannels:
    """The planner service's channels (names without the prefix)."""

    map: str = _channel("planner", "map")
    plan_request: str = _channel("planner", "plan_request")
    plan_reply: str = _channel("planner", "plan_reply")
    feedback_field: str = _channel("planner", "feedback_field")
    service_status: str = _channel("planner", "service_status")


@dataclass(frozen=True)
class RobotChannels:
    """The robot node's and its body's channels (names without the prefix)."""

    low_state: str = _channel("robot", "low_state")
    low_cmd: str = _channel("robot", "low_cmd")
    nav_cmd: str = _channel("robot", "nav_cmd")
    robot_status: str = _channel("robot", "robot_status")
    robot_estimate: str = _channel("robot", "robot_estimate")


DEFAULT_LCM_URL = str(_CONTRACT["default_url"])
DEFAULT_CHANNEL_PREFIX = str(_CONTRACT["default_prefix"])


def _receive_thread_priority() -> int:
    value = _CONTRACT["receive_thread_priority"]
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 99:
        raise ValueError(f"{CHANNELS_FILE}: receive_thread_priority must be a SCHED_FIFO priority, 1..=99")
    return value


# SCHED_FIFO priority of liblcm's receive thread in the real-time processes (pfnav-robot, pfnav-sim).
RECEIVE_THREAD_PRIORITY = _receive_thread_priority()
PLANNER = PlannerChannels()
ROBOT = RobotChannels()
# Without the prefix: pfnav-sim publishes the true state under its own --channel-prefix.
SIM_ROBOT_STATE_NAME = _channel("simulation", "robot_state")
SIM_ROBOT_STATE = DEFAULT_CHANNEL_PREFIX + SIM_ROBOT_STATE_NAME


def udpm_url(port: int, recv_buf_size: bool = True) -> str:
    """A udpm:// URL on the default bus's multicast group (loopback only: ttl=0) at another port,
    e.g. for tests that keep their traffic apart."""
    group = urlsplit(DEFAULT_LCM_URL).hostname
    query = "ttl=0" + ("&recv_buf_size=4194304" if recv_buf_size else "")
    return f"udpm://{group}:{port}?{query}"
