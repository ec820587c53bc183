"""Stopping child processes: SIGTERM first, SIGKILL for one that ignores it past the grace time."""

from __future__ import annotations

import signal
import subprocess
import sys

from pfnav_harness.process_signals import stop_processes

IGNORES_SIGTERM = (
    "import signal, sys, time\n"
    "signal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
    "print('ready', flush=True)\n"
    "time.sleep(60)\n"
)


def test_a_process_that_ignores_sigterm_is_killed_after_the_grace_time() -> None:
    stubborn = subprocess.Popen([sys.executable, "-c", IGNORES_SIGTERM], stdout=subprocess.PIPE)
    polite = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    assert stubborn.stdout is not None and stubborn.stdout.readline() == b"ready\n"
    stop_processes([stubborn, None, polite], timeout=0.5)
    assert stubborn.returncode == -signal.SIGKILL
    assert polite.returncode == -signal.SIGTERM


def test_processes_that_already_exited_are_left_alone() -> None:
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    stop_processes([done])
    assert done.returncode == 0
