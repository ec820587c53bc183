#!/usr/bin/env python3
"""Robustness of the P-F runs: the same plan walked from slightly shifted start positions.

The co-simulation is deterministic, so one demo run says nothing about how close a run is to
falling. This plans a scenario once (P-F, over LCM) and repeats the co-simulation with the robot
placed `offset` metres off the plan's start along (+x, -y) for each offset, printing per run:
stop reason, RMS and maximum horizontal tracking error. `--seeds` repeats it on other terrains of
the same scenario family (the scenario generator's seed; the demo uses each scenario's own).

Usage (the plan comes from the service, so inside the private network namespace):
    bash scripts/netns.sh .venv/bin/python scripts/robustness_sweep.py --scenario mountain_pass
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pfnav_harness import paths
from pfnav_harness.cosim import CoSimConfig, CoSimulation
from pfnav_harness.errors import HarnessError
from pfnav_harness.pipeline import export_scenario
from pfnav_harness.planner_client import DEFAULT_LCM_URL, plan_scenario
from pfnav_harness.robot_fmu import robot_and_fmu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="mountain_pass")
    parser.add_argument("--offsets", default="0,0.002,-0.002,0.005,-0.005,0.01", help="start offsets, m")
    parser.add_argument("--seeds", default="", help="comma-separated terrain seeds (default: the scenario's own)")
    parser.add_argument("--comm-step", type=float, default=0.001)
    parser.add_argument("--lcm-url", default=DEFAULT_LCM_URL)
    args = parser.parse_args()
    try:
        offsets = [float(v) for v in args.offsets.split(",")]
        seeds: list[int | None] = [int(v) for v in args.seeds.split(",")] if args.seeds else [None]
    except ValueError:
        print(f"robustness_sweep: error: --offsets and --seeds must be comma-separated numbers, got {args.offsets!r}, {args.seeds!r}", file=sys.stderr)
        return 2
    try:
        with tempfile.TemporaryDirectory(prefix="pfnav_sweep_") as tmp:
            work = Path(tmp)
            robot, fmu = robot_and_fmu(None, work / "cache")
            falls = runs = 0
            for seed in seeds:
                scenario = export_scenario(paths.pf_plan_path(), args.scenario, work / f"scenarios_{seed}", seed=seed)
                plan = plan_scenario(scenario, ["pf"], args.lcm_url, service_binary=paths.planner_service_path())["pf"]
                label = args.scenario if seed is None else f"{args.scenario} seed {seed}"
                for offset in offsets:
                    config = CoSimConfig(comm_step=args.comm_step, estimator="groundTruth")
                    with CoSimulation(scenario, plan, fmu, robot, work / "cache", config) as sim:
                        sim.world.place(float(plan.x[0]) + offset, float(plan.y[0]) - offset, float(plan.yaw[0]))
                        start = time.perf_counter()
                        result = sim.run()
                    pos = result.log["base_pos"]
                    ref = result.log["ref"]
                    walking = result.log["t"] >= float(result.log["walk_start"])
                    error = np.hypot(pos[walking, 0] - ref[walking, 0], pos[walking, 1] - ref[walking, 1])
                    falls += result.stop_reason.startswith("fell")
                    runs += 1
                    print(
                        f"{label} offset {offset:+.3f} m: {result.stop_reason:22s} "
                        f"RMS {np.sqrt(np.mean(error**2)):.3f} m, max {error.max():.3f} m "
                        f"({time.perf_counter() - start:.1f} s wall)",
                        flush=True,
                    )
            print(f"{args.scenario}: {falls} of {runs} runs fell")
    except HarnessError as err:
        print(f"robustness_sweep: error: {err}", file=sys.stderr)
        return err.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
