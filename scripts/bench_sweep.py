#!/usr/bin/env python3
"""Sweep throughput: runs per minute on a LocalCluster of 1 worker and of 2, side by side.

Plans the spec's terrain once (planner service over LCM), then runs the same runs on each cluster
into a fresh store and prints a table (machine, date, load) with runs/minute and the speedup. The
cluster start is timed apart: it is paid once per sweep, not per run. The rows of both clusters are
compared as well (they must be the same; wall time aside).

Usage (planning uses LCM udpm://, so inside the private network namespace):
    bash scripts/netns.sh .venv/bin/python scripts/bench_sweep.py [--spec sweeps/tiny.toml] [--runs 12]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from pfnav_harness import paths
from pfnav_harness.errors import HarnessError
from pfnav_harness.planner_client import DEFAULT_LCM_URL
from pfnav_harness.sweep.cli import _lcm_planner
from pfnav_harness.sweep.cluster import dask_client
from pfnav_harness.sweep.driver import prepare_courses, run_sweep
from pfnav_harness.sweep.runner import Artifacts
from pfnav_harness.sweep.spec import load_spec
from pfnav_harness.sweep.store import SweepStore, deterministic_rows


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spec", type=Path, default=paths.repo_root() / "sweeps" / "tiny.toml")
    parser.add_argument("--runs", type=int, default=12, help="runs per cluster (default 12; overrides the spec's)")
    parser.add_argument("--workers", default="1,2", help="cluster sizes to compare (default 1,2)")
    parser.add_argument("--lcm-url", default=DEFAULT_LCM_URL)
    args = parser.parse_args()
    try:
        sizes = [int(v) for v in args.workers.split(",")]
        if args.runs < 1 or not sizes or min(sizes) < 1:
            raise ValueError
    except ValueError:
        print(f"bench_sweep: error: --runs must be >= 1 and --workers a comma-separated list of sizes >= 1, got {args.runs}, {args.workers!r}", file=sys.stderr)
        return 2
    try:
        spec = dataclasses.replace(load_spec(args.spec), runs=args.runs)
        artifacts = Artifacts(paths.fmu_path(), paths.urdf_path(), paths.pf_plan_path())
        with tempfile.TemporaryDirectory(prefix="pfnav_bench_sweep_") as tmp:
            work = Path(tmp)
            planned = SweepStore.create(work / "planned", spec)
            courses = prepare_courses(spec, planned, artifacts.pf_plan or paths.pf_plan_path(), _lcm_planner(args.lcm_url, False), work / "scenarios")
            load_before = os.getloadavg()
            results = []
            tables = []
            for n in sizes:
                store = SweepStore.create(work / f"workers_{n}", spec)
                t0 = time.perf_counter()
                with dask_client(workers=n) as client:
                    startup = time.perf_counter() - t0
                    summary = run_sweep(spec, store, courses, artifacts, client, show_progress=True)
                table = store.table()
                tables.append(deterministic_rows(table))
                wall = sum(table["wall_time"].to_pylist()) / table.num_rows
                cpu = sum(table["cpu_time"].to_pylist()) / table.num_rows
                results.append((n, startup, summary, wall, cpu))
            load_after = os.getloadavg()
    except HarnessError as err:
        print(f"bench_sweep: error: {err}", file=sys.stderr)
        return err.exit_code

    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    print()
    print(f"pfnav-sweep throughput, {now}, {platform.node()}: {cpu_model()}, {os.cpu_count()} cores")
    print(f"spec {args.spec.name} ({spec.scenario}, {spec.duration:g} simulated s per run), {spec.runs} runs per cluster")
    print(f"load average (1 min) {load_before[0]:.2f} before, {load_after[0]:.2f} after (other work on the machine slows both columns)")
    print()
    # CPU share: how much of a core a worker's run got (1.0 on an idle machine; less when others load it).
    print("| workers | cluster start (s) | sweep wall (s) | runs/min | speedup | mean run wall (s) | mean run CPU (s) | CPU share |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    base = results[0][2].runs_per_minute
    for n, startup, summary, wall, cpu in results:
        speedup = summary.runs_per_minute / base if base > 0 else float("nan")
        print(
            f"| {n} | {startup:.1f} | {summary.wall_seconds:.1f} | {summary.runs_per_minute:.1f} | {speedup:.2f}x | {wall:.2f} | {cpu:.2f} | {cpu / wall:.2f} |"
        )
    errors = sum(r[2].errors for r in results)
    same = all(t == tables[0] for t in tables[1:])
    print()
    print(f"rows identical across cluster sizes (wall time aside): {'yes' if same else 'NO'}; runs with errors: {errors}")
    return 0 if same and errors == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
