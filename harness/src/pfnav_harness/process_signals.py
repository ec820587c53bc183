"""Stopping processes cleanly: the bus processes (`pfnav-sim`, the navigator) on SIGINT and SIGTERM, and
the child processes a harness starts (SIGTERM, then SIGKILL after a grace time)."""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Callable, Iterable


def stop_requested_on_signals() -> Callable[[], bool]:
    """Installs SIGINT and SIGTERM handlers; returns a check that is True once either arrived.

    The loops poll the check each tick and end through their own cleanup instead of being killed mid-step.
    """
    requested = False

    def request_stop(_signum: int, _frame: object) -> None:
        nonlocal requested
        requested = True

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    return lambda: requested


def stop_processes(processes: Iterable[subprocess.Popen[bytes] | None], timeout: float = 20.0) -> None:
    """SIGTERM to every process still running (None: never started), then a wait of up to
    `timeout` s for each in turn; one that has not exited by then is killed."""
    running = [p for p in processes if p is not None and p.poll() is None]
    for process in running:
        process.send_signal(signal.SIGTERM)
    for process in running:
        try:
            process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
