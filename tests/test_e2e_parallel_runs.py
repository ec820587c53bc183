"""`pfnav-demo demo --jobs N` runs the simulations side by side: the results must not depend on N.

One scenario × two methods, a few simulated seconds each, once one run at a time and once two at a
time; every metric (wall-clock timings aside) and every logged array must be identical.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

WALL_CLOCK_KEYS = {"wall_seconds", "timing_per_sim_second", "planner_solve_time"}
# Logged arrays that measure the machine, not the robot.
WALL_CLOCK_ARRAYS = {"mpc_solve_time"}


def _demo(out: Path, jobs: int, lcm_url: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "pfnav_harness",
            "demo",
            "--scenario",
            "pits",
            "--duration",
            "3",
            "--no-progress",
            "--jobs",
            str(jobs),
            "--lcm-url",
            lcm_url,
            # Channels of its own: the session's planner service (other tests) must not see this
            # demo's map publications.
            "--channel-prefix",
            "PFNAV_JOBS_",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def _runs(out: Path) -> list[dict[str, Any]]:
    runs = json.loads((out / "metrics.json").read_text())["runs"]
    return [{k: v for k, v in run.items() if k not in WALL_CLOCK_KEYS} for run in runs]


def test_results_do_not_depend_on_how_many_runs_go_at_once(lcm_url: str, tmp_path: Path) -> None:
    one, two = tmp_path / "one", tmp_path / "two"
    for out, jobs in ((one, 1), (two, 2)):
        proc = _demo(out, jobs, lcm_url)
        assert proc.returncode == 0, proc.stderr[-3000:]
    runs_one, runs_two = _runs(one), _runs(two)
    assert [(r["scenario"], r["method"]) for r in runs_one] == [
        ("pits", "pf"),
        ("pits", "astar"),
    ]
    assert runs_one == runs_two
    logs = sorted(p.name for p in (one / "logs").glob("*.npz"))
    assert len(logs) == 2
    for name in logs:
        with np.load(one / "logs" / name) as a, np.load(two / "logs" / name) as b:
            assert sorted(a.files) == sorted(b.files)
            for key in a.files:
                if key in WALL_CLOCK_ARRAYS:
                    continue
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name}:{key}")
