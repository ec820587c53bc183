"""Process-level faults of the real-time stack: pfnav-robot driving pfnav-sim over udpm:// (private network namespace).

The body's states reach the node through a relay in this test process (SIM_* → NODE_*), so the
test can hold, drop or garble them; commands go back the same way. The navigator is a stand-in
process sending Stand every 20 ms. Each fault must take the node to damping with its reason in
robot_status_t, no later than 25 ms after its timeout (the node's own measurement, in the
reason: "no low_state_t for 21.3 ms (timeout 20.0 ms)"), and the node must return to torque
control when the peer is back. The planner service is not in the control loop: killing it leaves
the node in torque control, and a restarted service answers again. Nothing may crash.
"""

from __future__ import annotations

import os
import random
import re
import signal
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import numpy as np
import pytest
from pfnav_harness import paths
from pfnav_harness.lcm_channels import ROBOT, udpm_url
from pfnav_harness.planner_client import (
    PlannerClient,
    PlannerError,
    StartPose,
    _import_lcm,
    _import_types,
)
from pfnav_harness.process_signals import stop_processes
from pfnav_harness.scenario import GoalRegion, Terrain

pytestmark = pytest.mark.timeout(600)

# Above the default 20 ms: the relay in this test process is not real-time scheduled, and a
# stall of the relay must not read as a fault; the bound checked is timeout + 25 ms either way.
STATE_TIMEOUT_MS = 50.0
NAV_TIMEOUT_MS = 300.0
# States later than this by the body's clock damp the node (its --max-state-delay-ms); as
# generous as the timeout, for the same reason.
MAX_STATE_DELAY_MS = 50.0
# The bound: damping no later than this after the timeout.
DAMPING_MARGIN_MS = 25.0
WAIT = 60.0

NAVIGATOR_SCRIPT = """
import sys, time
sys.path.insert(0, sys.argv[2])
import lcm
from pfnav import header_t, nav_cmd_t
bus = lcm.LCM(sys.argv[3])
seq = 0
while True:
    m = nav_cmd_t()
    m.header = header_t()
    m.header.seq = seq
    m.mode = nav_cmd_t.MODE_STAND
    bus.publish(sys.argv[1], m.encode())
    seq += 1
    time.sleep(0.02)
"""


@dataclass
class Relay:
    """Forwards the body's states to the node and the node's commands to the body, unless told otherwise."""

    hold_states: bool = False
    drop_every_other: bool = False
    # Each state forwarded this long after it came (seconds; 0: at once), in order.
    delay: float = 0.0
    delayed: list[tuple[float, bytes]] = field(default_factory=list)
    held: list[bytes] = field(default_factory=list)
    forwarded: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)


class Stack:
    def __init__(self, lcm_url: str, tmp: Path) -> None:
        self.url = lcm_url
        self.tmp = tmp
        self.types = _import_types()
        lcm_module = _import_lcm()
        self.bus = lcm_module.LCM(lcm_url)
        self.sim_prefix, self.node_prefix = "FSIM_", "FNODE_"
        self.relay = Relay()
        self.statuses: list[Any] = []
        self.status_lock = threading.Lock()
        self.bus.subscribe(self.sim_prefix + ROBOT.low_state, self._on_sim_state)
        self.bus.subscribe(self.node_prefix + ROBOT.low_cmd, self._on_node_command)
        self.bus.subscribe(self.node_prefix + ROBOT.robot_status, self._on_status)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()
        self.releaser = threading.Thread(target=self._release_delayed, daemon=True)
        self.releaser.start()
        self.logs = tmp / "logs"
        self.logs.mkdir(exist_ok=True)
        self.env = {**os.environ, "LCM_DEFAULT_URL": lcm_url}
        self.sim = self.start_sim()
        self.navigator = self.start_navigator()
        self.node = subprocess.Popen(
            [
                str(paths.pfnav_robot_path()),
                "--fmu",
                str(paths.fmu_path()),
                "--channel-prefix",
                self.node_prefix,
                "--state-timeout-ms",
                str(STATE_TIMEOUT_MS),
                "--nav-timeout-ms",
                str(NAV_TIMEOUT_MS),
                "--max-state-delay-ms",
                str(MAX_STATE_DELAY_MS),
                "--recover-cycles",
                "100",
                "--status-period",
                "0.05",
            ],
            env=self.env,
            stdout=(self.logs / "node.log").open("w"),
            stderr=subprocess.STDOUT,
        )

    def _spin(self) -> None:
        while not self.stop.is_set():
            self.bus.handle_timeout(20)

    def _on_sim_state(self, _channel: str, data: bytes) -> None:
        relay = self.relay
        with relay.lock:
            relay.forwarded += 1
            if relay.hold_states:
                relay.held.append(data)
                return
            if relay.drop_every_other and relay.forwarded % 2:
                return
            if relay.delay > 0.0 or relay.delayed:
                relay.delayed.append((time.monotonic() + relay.delay, data))
                return
        self.bus.publish(self.node_prefix + ROBOT.low_state, data)

    def _release_delayed(self) -> None:
        """Forwards the delayed states whose time has come (every millisecond)."""
        while not self.stop.wait(0.001):
            now = time.monotonic()
            with self.relay.lock:
                due = [data for at, data in self.relay.delayed if at <= now]
                self.relay.delayed = [
                    (at, data) for at, data in self.relay.delayed if at > now
                ]
            for data in due:
                self.bus.publish(self.node_prefix + ROBOT.low_state, data)

    def _on_node_command(self, _channel: str, data: bytes) -> None:
        self.bus.publish(self.sim_prefix + ROBOT.low_cmd, data)

    def _on_status(self, _channel: str, data: bytes) -> None:
        try:
            status = self.types.robot_status_t.decode(data)
        except (ValueError, struct.error, IndexError, UnicodeDecodeError):
            # The garbage this test sends on the status channel too.
            return
        with self.status_lock:
            self.statuses.append(status)

    def start_sim(self) -> subprocess.Popen[bytes]:
        return subprocess.Popen(
            [
                sys.executable,
                "-m",
                "pfnav_harness.body_sim",
                "--channel-prefix",
                self.sim_prefix,
                "--out",
                str(self.tmp / "sim"),
                "--imu-noise-scale",
                "0",
            ],
            env=self.env,
            stdout=(self.logs / "sim.log").open("a"),
            stderr=subprocess.STDOUT,
        )

    def start_navigator(self) -> subprocess.Popen[bytes]:
        return subprocess.Popen(
            [
                sys.executable,
                "-c",
                NAVIGATOR_SCRIPT,
                self.node_prefix + ROBOT.nav_cmd,
                str(paths.repo_root() / "build" / "lcm_python"),
                self.url,
            ],
            env=self.env,
            stdout=(self.logs / "navigator.log").open("a"),
            stderr=subprocess.STDOUT,
        )

    def last_seq(self) -> int:
        with self.status_lock:
            return self.statuses[-1].header.seq if self.statuses else -1

    def wait_status(
        self,
        what: str,
        after: int,
        predicate: Callable[[Any], bool],
        timeout: float = WAIT,
    ) -> Any:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert self.node.poll() is None, (
                f"{what}: pfnav-robot exited with {self.node.returncode}"
            )
            with self.status_lock:
                found = next(
                    (s for s in self.statuses if s.header.seq > after and predicate(s)),
                    None,
                )
            if found is not None:
                return found
            time.sleep(0.01)
        with self.status_lock:
            last = self.statuses[-1] if self.statuses else None
        raise AssertionError(
            f"{what}: not within {timeout} s; last status {last and (last.safety, last.reason)}"
        )

    def torque(self, what: str, after: int = -1) -> Any:
        return self.wait_status(
            what, after, lambda s: s.safety == self.types.robot_status_t.SAFETY_OK
        )

    def damping(self, what: str, after: int, reason: str) -> Any:
        return self.wait_status(
            what,
            after,
            lambda s: (
                s.safety == self.types.robot_status_t.SAFETY_DAMPING
                and reason in s.reason
            ),
        )

    def close(self) -> None:
        stop_processes([self.node, self.navigator, self.sim])
        self.stop.set()
        self.thread.join(timeout=5)
        self.releaser.join(timeout=5)


def test_the_demo_knows_the_node_s_triggers_and_its_default() -> None:
    """`pfnav-demo realtime --trigger` offers pfnav-robot's values, its default first."""
    from pfnav_harness.realtime_demo import ROBOT_TRIGGERS

    help_text = subprocess.run([str(paths.pfnav_robot_path()), "-h"], capture_output=True, text=True, check=True).stdout
    line = next(line for line in help_text.splitlines() if "[possible values:" in line and "[default:" in line and "`deadline`" in line)
    default = re.search(r"\[default: (\w+)\]", line)
    values = re.search(r"\[possible values: ([\w, ]+)\]", line)
    assert default and values, line
    assert ROBOT_TRIGGERS[0] == default.group(1)
    assert list(ROBOT_TRIGGERS) == [v.strip() for v in values.group(1).split(",")]


def detection_delay_ms(reason: str) -> tuple[float, float]:
    """(age at the damping decision, timeout), both ms, from the node's reason."""
    match = re.search(r"for ([0-9.]+) ms \(timeout ([0-9.]+) ms\)", reason)
    assert match, reason
    return float(match.group(1)), float(match.group(2))


@pytest.fixture
def stack(lcm_url: str, tmp_path: Path) -> Iterator[Stack]:
    running = Stack(lcm_url, tmp_path)
    try:
        yield running
    finally:
        running.close()
    # A crash is a failure even when the test body passed.
    assert running.node.returncode in (0, -signal.SIGTERM), (
        tmp_path / "logs" / "node.log"
    ).read_text()[-3000:]


def test_killed_body_and_navigator_damp_within_the_timeout_and_recover_when_they_return(
    stack: Stack,
) -> None:
    ok = stack.torque("torque control at start")

    stack.sim.kill()
    stack.sim.wait()
    status = stack.damping("body killed", ok.header.seq, "no low_state_t for")
    age, timeout = detection_delay_ms(status.reason)
    assert timeout <= age <= timeout + DAMPING_MARGIN_MS, status.reason
    stack.sim = stack.start_sim()
    ok = stack.torque("recovery after the body restarts", status.header.seq)

    stack.navigator.kill()
    stack.navigator.wait()
    status = stack.damping("navigator killed", ok.header.seq, "no nav_cmd_t for")
    age, timeout = detection_delay_ms(status.reason)
    assert timeout <= age <= timeout + DAMPING_MARGIN_MS, status.reason
    stack.navigator = stack.start_navigator()
    ok = stack.torque("recovery after the navigator restarts", status.header.seq)
    assert ok.damping_entries >= 2
    assert stack.sim.poll() is None, "the restarted body keeps running"


def test_a_killed_planner_leaves_the_node_in_torque_control_and_a_restarted_one_answers(
    stack: Stack,
) -> None:
    terrain = Terrain((0.0, 0.0), 0.25, np.zeros((24, 24)))
    start, goal = StartPose(1.0, 1.0, 0.0), GoalRegion((4.5, 4.5), 0.3)
    binary = paths.planner_service_path()

    def planner() -> PlannerClient:
        return PlannerClient(
            stack.url,
            "FPLAN_",
            binary,
            service_log=stack.logs / "planner.log",
            startup_timeout=WAIT,
        )

    def plans(client: PlannerClient) -> bool:
        seq = client.publish_map(terrain)
        return client.request_answer(start, goal, "pf", seq, timeout=WAIT, retries=1).ok

    client = planner()
    try:
        assert plans(client), "the planner answers before the kill"
        ok = stack.torque("torque control with the planner up")
        assert client.process is not None
        client.process.kill()
        assert client.process.wait(timeout=10) == -signal.SIGKILL
        # A request to the dead service fails at once, naming the death.
        asked = time.monotonic()
        with pytest.raises(PlannerError, match=r"pf-planner-service died \(exit code -9\)"):
            client.request_answer(
                start, goal, "pf", client.publish_map(terrain), timeout=1.0, retries=0
            )
        assert time.monotonic() - asked < 5.0
        # A second of statuses after the kill: the node stayed in torque control throughout.
        later = stack.wait_status("statuses after the kill", ok.header.seq + 20, lambda _s: True)
        with stack.status_lock:
            since = [s for s in stack.statuses if ok.header.seq < s.header.seq <= later.header.seq]
        assert all(s.safety == stack.types.robot_status_t.SAFETY_OK for s in since), [
            (s.safety, s.reason) for s in since
        ]
        assert later.damping_entries == ok.damping_entries
    finally:
        client.close()
    restarted = planner()
    try:
        assert plans(restarted), "a restarted planner answers"
    finally:
        restarted.close()
    assert stack.node.poll() is None and stack.sim.poll() is None


def test_held_dropped_and_garbled_states_damp_or_pass_as_they_should(
    stack: Stack,
) -> None:
    ok = stack.torque("torque control at start")

    # Every other state dropped: the gaps (2 ms) stay far below the timeout.
    with stack.relay.lock:
        stack.relay.drop_every_other = True
    later = stack.wait_status("half the states", ok.header.seq + 10, lambda _s: True)
    with stack.relay.lock:
        stack.relay.drop_every_other = False
    assert later.damping_entries == ok.damping_entries, later.reason

    # States held back for 150 ms, then released at once (a delay spike): damping after the
    # timeout; the burst's states are old but in order, the node takes the newest and recovers.
    with stack.relay.lock:
        stack.relay.hold_states = True
    status = stack.damping("held states", later.header.seq, "no low_state_t for")
    age, timeout = detection_delay_ms(status.reason)
    assert timeout <= age <= timeout + DAMPING_MARGIN_MS, status.reason
    with stack.relay.lock:
        stack.relay.hold_states = False
        burst, stack.relay.held = stack.relay.held, []
    for data in burst:
        stack.bus.publish(stack.node_prefix + ROBOT.low_state, data)
    ok = stack.torque("recovery after the held states", status.header.seq)

    # Garbage on every channel of the node and the body, some behind the right fingerprints.
    types = stack.types
    fingerprints = [
        t._get_packed_fingerprint()
        for t in (
            types.low_state_t,
            types.low_cmd_t,
            types.nav_cmd_t,
            types.robot_status_t,
            types.robot_estimate_t,
        )
    ]
    rng = random.Random(37)
    channels = [
        prefix + name
        for prefix in (stack.node_prefix, stack.sim_prefix)
        for name in (
            ROBOT.low_state,
            ROBOT.low_cmd,
            ROBOT.nav_cmd,
            ROBOT.robot_status,
            ROBOT.robot_estimate,
        )
    ]
    for i in range(3000):
        junk = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 300)))
        if i % 3 == 0:
            junk = rng.choice(fingerprints) + junk
        stack.bus.publish(channels[i % len(channels)], junk)
    after = stack.wait_status(
        "garbage counted", ok.header.seq, lambda s: s.malformed_messages >= 500
    )
    final = stack.torque("torque control after the garbage", after.header.seq)
    assert stack.sim.poll() is None, "the body survives garbage commands"
    assert stack.navigator.poll() is None
    assert final.states_received > ok.states_received


def test_a_constant_delay_of_the_states_damps_above_the_limit_and_passes_below_it(
    stack: Stack,
) -> None:
    ok = stack.torque("torque control at start")

    # 10 ms late, every state: a gap of 10 ms at the onset and late states after it, both
    # within the limits.
    with stack.relay.lock:
        stack.relay.delay = 0.010
    later = stack.wait_status("10 ms of delay", ok.header.seq + 20, lambda _s: True)
    assert later.damping_entries == ok.damping_entries, later.reason
    assert later.safety == stack.types.robot_status_t.SAFETY_OK

    # 150 ms late: the onset is a gap (the state timeout), then the states flow again but late
    # by the body's clock, which keeps the motors damped.
    with stack.relay.lock:
        stack.relay.delay = 0.150
    delayed = stack.damping(
        "150 ms of delay", later.header.seq, "low_state_t delayed by"
    )
    match = re.search(r"delayed by ([0-9.]+) ms \(limit ([0-9.]+) ms\)", delayed.reason)
    assert match, delayed.reason
    assert 140.0 <= float(match.group(1)) <= 150.0 + DAMPING_MARGIN_MS + 20.0, (
        delayed.reason
    )
    still = stack.wait_status(
        "a second later", delayed.header.seq + 20, lambda _s: True
    )
    assert still.safety == stack.types.robot_status_t.SAFETY_DAMPING, (
        "no recovery on late states"
    )

    with stack.relay.lock:
        stack.relay.delay = 0.0
    recovered = stack.torque("recovery when the delay ends", still.header.seq)
    assert recovered.states_received > still.states_received


def _recorded_channels(log_file: Path) -> list[str]:
    """Channels of the events in an LCM log so far (a partly written last event ends the list)."""
    channels: list[str] = []
    if not log_file.exists():
        return channels
    try:
        for event in _import_lcm().EventLog(str(log_file), "r"):
            channels.append(event.channel)
    except (OSError, ValueError):
        pass
    return channels


def test_a_recorded_session_replays_through_lcm_logplayer_into_a_fresh_node(
    stack: Stack, tmp_path: Path
) -> None:
    """lcm-logger records the node's inputs while the stack stands; lcm-logplayer replays them on
    another bus, where a fresh pfnav-robot takes them as a body and a navigator: it enters torque
    control and answers the recorded states one by one."""
    bin_dir = paths.repo_root() / "build" / "lcm" / "bin"
    log_file = tmp_path / "session.lcmlog"
    logger = subprocess.Popen(
        [
            str(bin_dir / "lcm-logger"),
            "--quiet",
            "--force",
            f"--lcm-url={stack.url}",
            str(log_file),
        ],
        stdout=(stack.logs / "logger.log").open("w"),
        stderr=subprocess.STDOUT,
    )
    states = stack.node_prefix + ROBOT.low_state
    try:
        stack.torque("torque control at start")
        # At least 1 000 states of standing in the log (about a second; longer on a loaded machine).
        deadline = time.monotonic() + WAIT
        while _recorded_channels(log_file).count(states) <= 1_000:
            assert time.monotonic() < deadline, "lcm-logger did not record 1 000 states"
            assert logger.poll() is None, "lcm-logger exited"
            time.sleep(0.1)
    finally:
        logger.send_signal(signal.SIGINT)
        logger.wait(timeout=20)
    recorded = _recorded_channels(log_file)
    assert recorded.count(states) > 1_000, "the logger recorded the states"
    assert stack.node_prefix + ROBOT.nav_cmd in recorded

    # Another port: the replay's bus is apart from the live stack's.
    replay_url = udpm_url((urlsplit(stack.url).port or 7600) + 100)
    replay_prefix = stack.node_prefix
    types = stack.types
    bus = _import_lcm().LCM(replay_url)
    commands: list[Any] = []
    statuses: list[Any] = []
    bus.subscribe(
        replay_prefix + ROBOT.low_cmd,
        lambda _c, d: commands.append(types.low_cmd_t.decode(d)),
    )
    bus.subscribe(
        replay_prefix + ROBOT.robot_status,
        lambda _c, d: statuses.append(types.robot_status_t.decode(d)),
    )
    node = subprocess.Popen(
        [
            str(paths.pfnav_robot_path()),
            "--fmu",
            str(paths.fmu_path()),
            "--lcm-url",
            replay_url,
            "--channel-prefix",
            replay_prefix,
            "--state-timeout-ms",
            str(STATE_TIMEOUT_MS),
            "--recover-cycles",
            "20",
            "--status-period",
            "0.05",
        ],
        stdout=(stack.logs / "replay_node.log").open("w"),
        stderr=subprocess.STDOUT,
    )

    def pump_until(predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline or node.poll() is not None:
                return False
            bus.handle_timeout(20)
        return True

    try:
        assert pump_until(lambda: bool(statuses), WAIT), "the fresh node's first status"
        # Played while this test keeps reading the node's commands (a socket buffer would not
        # hold seconds of them).
        player = subprocess.Popen(
            [
                str(bin_dir / "lcm-logplayer"),
                f"--lcm-url={replay_url}",
                "-e",
                f"{replay_prefix}(LOW_STATE|NAV_CMD)",
                str(log_file),
            ],
            stdout=(stack.logs / "logplayer.log").open("w"),
            stderr=subprocess.STDOUT,
        )
        try:
            assert pump_until(lambda: player.poll() is not None, 120.0), (
                "lcm-logplayer did not finish"
            )
        finally:
            if player.poll() is None:
                player.kill()
            player.wait()
        assert player.returncode == 0
        # The log has ended: the node falls back to damping for want of states.
        assert pump_until(
            lambda: (
                any(s.safety == types.robot_status_t.SAFETY_OK for s in statuses)
                and statuses[-1].safety == types.robot_status_t.SAFETY_DAMPING
            ),
            WAIT,
        ), [(s.safety, s.reason) for s in statuses[-3:]]
        assert node.poll() is None, "the replayed node keeps running"
    finally:
        stop_processes([node])
    assert node.returncode in (0, -signal.SIGTERM)
    assert any(s.safety == types.robot_status_t.SAFETY_OK for s in statuses), (
        "torque control on the replayed inputs"
    )
    answered = [
        c.state_seq
        for c in commands
        if c.state_seq >= 0 and any(t != 0.0 for t in c.tau)
    ]
    assert len(answered) > 1_000, f"{len(answered)} torque commands"
    steps = np.diff(answered)
    assert (steps >= 0).all(), "the replayed states keep their order"
    recorded_seqs = {
        types.low_state_t.decode(event.data).header.seq
        for event in _import_lcm().EventLog(str(log_file), "r")
        if event.channel == states
    }
    assert set(answered) <= recorded_seqs, "every command answers a recorded state"
    # A loaded machine may hand the replayed states over in bursts (the node then answers the
    # newest of a burst); more than half of them get their own answer.
    assert len(set(answered)) > 0.5 * len(recorded_seqs), (
        len(set(answered)),
        len(recorded_seqs),
    )
    # Torque on the recorded states, then damping once the log ends.
    assert statuses[-1].safety == types.robot_status_t.SAFETY_DAMPING
    assert "no low_state_t" in statuses[-1].reason
