"""Stopping the bus processes (`pfnav-sim`, the navigator) cleanly on SIGINT and SIGTERM."""

from __future__ import annotations

import signal
from collections.abc import Callable


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
