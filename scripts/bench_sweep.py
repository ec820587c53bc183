#!/usr/bin/env python3
"""Sweep throughput: runs per minute on LocalClusters of 1 and 2 workers, with and without forks, side by side.

Plans the spec's terrain once (planner service over LCM), then runs the same runs in each
configuration (cluster size × forks on/off) into a fresh store and prints a table (machine, date,
load) with runs/minute and the speedup over the first configuration, and per cluster size the
time forks save per run. The cluster start is timed apart: it is paid once per sweep, not per run.
Rows of the same fork setting are compared across cluster sizes (they must be the same; wall time
aside). Forked and unforked rows differ wherever a run has a payload or a friction other than the
prefix's (they act from the fork on), so those are not compared.

Usage (planning uses LCM udpm://, so inside the private network namespace):
    bash scripts/netns.sh .venv/bin/python scripts/bench_sweep.py [--spec sweeps/tiny.toml] [--runs 12] [--workers 1,2] [--fork on,off]
        [--results-page sweep-throughput]
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

from pfnav_harness import paths, results_page
from pfnav_harness.errors import HarnessError
from pfnav_harness.planner_client import DEFAULT_LCM_URL
from pfnav_harness.robot_fmu import robot_and_fmu
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
    parser.add_argument("--fork", default="on,off", help="fork settings to compare: on, off or both (default on,off)")
    parser.add_argument("--lcm-url", default=DEFAULT_LCM_URL)
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also publish the table as docs/results/NAME.md")
    args = parser.parse_args()
    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        parser.error(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    # Taken before the runs: the commit that ran and the load it ran under.
    stamp = results_page.collect_stamp() if args.results_page else None
    try:
        sizes = [int(v) for v in args.workers.split(",")]
        forks = [{"on": True, "off": False}[v.strip()] for v in args.fork.split(",")]
        if args.runs < 1 or not sizes or min(sizes) < 1 or not forks:
            raise ValueError
    except (ValueError, KeyError):
        print(
            f"bench_sweep: error: --runs must be >= 1, --workers a comma-separated list of sizes >= 1 and --fork of on/off, got {args.runs}, {args.workers!r}, {args.fork!r}",
            file=sys.stderr,
        )
        return 2
    try:
        spec = dataclasses.replace(load_spec(args.spec), runs=args.runs)
        with tempfile.TemporaryDirectory(prefix="pfnav_bench_sweep_") as tmp:
            work = Path(tmp)
            robot, fmu = robot_and_fmu(None, work / "cache")
            artifacts = Artifacts(fmu, robot, paths.pf_plan_path())
            planned = SweepStore.create(work / "planned", spec)
            courses = prepare_courses(spec, planned, artifacts.pf_plan or paths.pf_plan_path(), _lcm_planner(args.lcm_url, False), work / "scenarios")
            load_before = os.getloadavg()
            results = []
            tables: dict[bool, list[list[dict[str, object]]]] = {fork: [] for fork in forks}
            for n in sizes:
                for fork in forks:
                    variant = dataclasses.replace(spec, fork=fork)
                    store = SweepStore.create(work / f"workers_{n}_fork_{fork}", variant)
                    t0 = time.perf_counter()
                    with dask_client(workers=n) as client:
                        startup = time.perf_counter() - t0
                        summary = run_sweep(variant, store, courses, artifacts, client, show_progress=True)
                    table = store.table()
                    tables[fork].append(deterministic_rows(table))
                    wall = sum(table["wall_time"].to_pylist()) / table.num_rows
                    cpu = sum(table["cpu_time"].to_pylist()) / table.num_rows
                    forked = sum(bool(v) for v in table["forked"].to_pylist())
                    simulated = sum(table["simulated_time"].to_pylist()) / table.num_rows
                    results.append((n, fork, startup, summary, wall, cpu, forked, simulated))
            load_after = os.getloadavg()
    except HarnessError as err:
        print(f"bench_sweep: error: {err}", file=sys.stderr)
        return err.exit_code

    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    # Markdown as printed: the same text goes to the results page.
    lines: list[str] = [""]
    lines.append(f"- pfnav-sweep throughput, {now}, {platform.node()}: {cpu_model()}, {os.cpu_count()} cores")
    lines.append(f"- spec {args.spec.name} ({spec.scenario}, {spec.duration:g} simulated s per run, stand-up {spec.stand_time:g} s), {spec.runs} runs per cluster")
    lines.append(f"- load average (1 min) {load_before[0]:.2f} before, {load_after[0]:.2f} after (other work on the machine slows both columns)")
    lines.append("")
    # CPU share: how much of a core a worker's run got (1.0 on an idle machine; less when others load it).
    # Sweep wall includes the fork prefixes (a task per group); the per-run wall and CPU columns do not.
    lines.append(
        "| workers | forks | forked runs | cluster start (s) | sweep wall (s) | runs/min | speedup | mean simulated (s) "
        "| mean run wall (s) | mean run CPU (s) | CPU share |"
    )
    lines.append("| ---: | :---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    base = results[0][3].runs_per_minute
    for n, fork, startup, summary, wall, cpu, forked, simulated in results:
        speedup = summary.runs_per_minute / base if base > 0 else float("nan")
        lines.append(
            f"| {n} | {'on' if fork else 'off'} | {forked} | {startup:.1f} | {summary.wall_seconds:.1f} | {summary.runs_per_minute:.1f} | {speedup:.2f}x "
            f"| {simulated:.2f} | {wall:.2f} | {cpu:.2f} | {cpu / wall:.2f} |"
        )
    if len(forks) == 2:
        # Forked runs with a payload or another friction can fall (and stop) at other times than
        # unforked ones: the unforked cost is scaled to the forked runs' simulated time first.
        lines.append("")
        for n in sizes:
            on, off = (next(r for r in results if r[0] == n and r[1] == fork) for fork in (True, False))
            scale = on[7] / off[7]
            wall_on, wall_off = on[3].wall_seconds / on[3].ran, scale * off[3].wall_seconds / off[3].ran
            cpu_on, cpu_off = on[5], scale * off[5]
            lines.append(
                f"- {n} worker(s), per run of {on[7]:.2f} simulated s: forks save {wall_off - wall_on:.2f} s of sweep wall "
                f"({100 * (wall_off - wall_on) / wall_off:.0f} %, prefix tasks included) and {cpu_off - cpu_on:.2f} s of the run's CPU "
                f"({100 * (cpu_off - cpu_on) / cpu_off:.0f} %, prefix tasks aside)"
            )
    errors = sum(r[3].errors for r in results)
    same = all(t == group[0] for group in tables.values() for t in group[1:])
    lines.append("")
    lines.append(f"rows identical across cluster sizes for each fork setting (wall time aside): {'yes' if same else 'NO'}; runs with errors: {errors}")
    text = "\n".join(lines)
    print(text)
    if args.results_page:
        title = "Sweep throughput: runs per minute by cluster size, forks on and off"
        command = results_page.regenerate_command(".venv/bin/python scripts/bench_sweep.py", sys.argv[1:])
        print(f"results page: {results_page.write_results_page(args.results_page, title, text, command, stamp)}")
    return 0 if same and errors == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
