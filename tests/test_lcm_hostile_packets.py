"""The Python `lcm` module (the patched build, scripts/build_liblcm.sh) survives the packets that
crashed liblcm's receive path: a 139-byte LC03 fragment with fragment_offset 0xFFFFFFFF and a
17-byte LC02 packet whose channel has no NUL. The receiver runs in a subprocess so that a crash
is a test failure with its signal, not the end of the test session. udpm only inside the test
network namespace (the `lcm_url` fixture enforces it)."""

from __future__ import annotations

import re
import socket
import struct
import subprocess
import sys

import lcm
from pfnav_harness.lcm_channels import udpm_url

RECEIVER = r"""
import sys, lcm
lc = lcm.LCM(sys.argv[1])
got = []
lc.subscribe("PYHOSTILE", lambda channel, data: got.append(data))
print("ready", flush=True)
deadline_polls = 200
while b"valid" not in got and deadline_polls > 0:
    lc.handle_timeout(50)
    deadline_polls -= 1
print("received valid" if b"valid" in got else "no valid message", flush=True)
"""


def _group_and_port(url: str) -> tuple[str, int]:
    match = re.match(r"udpm://([\d.]+):(\d+)", url)
    assert match, url
    return match.group(1), int(match.group(2))


def _long_packet(offset: int, channel: bytes, payload: bytes) -> bytes:
    return struct.pack(">IIIIHH", 0x4C433033, 1, 1000, offset, 0, 2) + channel + payload


def test_the_lcm_module_is_the_patched_build() -> None:
    assert "build/lcm/python" in lcm.__file__, lcm.__file__


def test_regression_crafted_fragments_do_not_crash_a_python_receiver(lcm_url: str) -> None:
    group, port = _group_and_port(lcm_url)
    port += 150  # a port of its own, away from the planner fixtures
    url = udpm_url(port, recv_buf_size=False)
    receiver = subprocess.Popen(
        [sys.executable, "-c", RECEIVER, url],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert receiver.stdout is not None
        assert receiver.stdout.readline().strip() == "ready"
        channel = b"PYHOSTILE\x00"
        fragment = _long_packet(0xFFFFFFFF, channel, b"A" * (139 - 20 - len(channel)))
        assert len(fragment) == 139
        short = struct.pack(">II", 0x4C433032, 7) + b"PYHOSTILE"
        assert len(short) == 17
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        for _ in range(10):
            sender.sendto(fragment, (group, port))
            sender.sendto(short, (group, port))
        # The hostile datagrams are queued at the receiver's socket ahead of the valid message,
        # which is repeated only in case UDP drops it; the receiver exits once it has it.
        publisher = lcm.LCM(url)
        for _ in range(20):
            publisher.publish("PYHOSTILE", b"valid")
            try:
                receiver.wait(timeout=0.5)
                break
            except subprocess.TimeoutExpired:
                continue
        out, _ = receiver.communicate(timeout=20)
        assert receiver.returncode == 0, f"receiver died with {receiver.returncode}"
        assert "received valid" in out
    finally:
        if receiver.poll() is None:
            receiver.kill()
