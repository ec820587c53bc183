#!/usr/bin/env python3
"""Co-simulation speed: wall seconds per simulated second, split into physics (the engine's step:
DART's setForces + world.step, MuJoCo's mj_step), FMU (set inputs + fmi2DoStep + get outputs
through ctypes) and Python (everything else in the master loop: state read-out, reference, height
map, logging; "Python %" is its share of the total), for several FMU communication steps and
each engine asked for.

The engines run one after the other for each communication step and the whole set `--repeats`
times, so their speeds are compared under the same machine load; the last table gives each
engine's speed relative to the first engine's per repeat (min–max over the repeats).

Usage (inside the private network namespace when the plan comes from the service):
    bash scripts/netns.sh .venv/bin/python scripts/bench_cosim.py [--scenario c_shape] [--seconds 10]
    .venv/bin/python scripts/bench_cosim.py --synthetic      # straight-line reference, no LCM needed
    .venv/bin/python scripts/bench_cosim.py --synthetic --engine dart,mujoco --repeats 3
The whole-demo time is printed by the demo itself (out/report.md header, out/metrics.json).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
from pfnav_harness import paths
from pfnav_harness.cosim import CoSimConfig, CoSimulation
from pfnav_harness.engine import ENGINE_TITLES, validate_engine_name
from pfnav_harness.errors import HarnessError
from pfnav_harness.pipeline import export_scenario
from pfnav_harness.planner_client import DEFAULT_LCM_URL, Plan, plan_scenario
from pfnav_harness.robot_fmu import robot_and_fmu
from pfnav_harness.scenario import Scenario


def straight_plan(scenario: Scenario, speed: float, seconds: float) -> Plan:
    """A straight walk from the start towards the goal at `speed` (benchmark reference only)."""
    sx, sy = scenario.start
    gx, gy = scenario.goal.center
    heading = math.atan2(gy - sy, gx - sx)
    t = np.arange(0.0, seconds + 0.05, 0.1)
    distance = np.minimum(speed * t, math.hypot(gx - sx, gy - sy))
    x = sx + distance * math.cos(heading)
    y = sy + distance * math.sin(heading)
    n = len(t)
    vx = np.gradient(x, t)
    vy = np.gradient(y, t)
    return Plan(
        "synthetic",
        t,
        x,
        y,
        scenario.terrain.height(x, y),
        np.full(n, heading),
        vx,
        vy,
        np.zeros(n),
    )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenario", default="c_shape")
    parser.add_argument(
        "--seconds", type=float, default=8.0, help="simulated seconds per measurement"
    )
    parser.add_argument(
        "--comm-steps",
        default="0.001,0.002,0.005",
        help="FMU communication steps to measure, s",
    )
    parser.add_argument(
        "--synthetic",
        action="store_true",
        help="straight-line reference instead of a P-F plan",
    )
    parser.add_argument(
        "--engine",
        default="dart",
        help="physics engines to measure, comma-separated (dart, mujoco); the first is the reference of the speed ratios",
    )
    parser.add_argument("--repeats", type=int, default=1, help="times every (comm step, engine) row is measured")
    parser.add_argument("--lcm-url", default=DEFAULT_LCM_URL)
    args = parser.parse_args()
    engines = [e.strip() for e in args.engine.split(",") if e.strip()]
    steps = [float(s) for s in args.comm_steps.split(",")]
    try:
        for engine in engines:
            validate_engine_name(engine)
        if args.repeats < 1:
            raise HarnessError("--repeats must be at least 1")
        with tempfile.TemporaryDirectory(prefix="pfnav_bench_") as tmp:
            work = Path(tmp)
            robot, fmu = robot_and_fmu(None, work / "cache")
            scenario = export_scenario(
                paths.pf_plan_path(), args.scenario, work / "scenarios"
            )
            if args.synthetic:
                plan = straight_plan(scenario, 0.4, args.seconds)
            else:
                plan = plan_scenario(
                    scenario,
                    ["pf"],
                    args.lcm_url,
                    service_binary=paths.planner_service_path(),
                )["pf"]
            print(
                f"scenario {args.scenario}, plan {plan.method} ({plan.duration:.1f} s), {args.seconds:.0f} simulated s per row"
            )
            print(
                f"{'repeat':>6} {'engine':>7} {'comm step':>10} {'total':>8} {'physics':>8} {'FMU':>8} {'Python':>8} {'Python %':>8} {'x realtime':>10}  result"
            )
            # (repeat, comm step, engine) → wall seconds per simulated second
            totals: dict[tuple[int, float, str], float] = {}
            for repeat in range(args.repeats):
                for step in steps:
                    for engine in engines:
                        config = CoSimConfig(comm_step=step, max_duration=args.seconds, estimator="groundTruth", engine=engine)
                        with CoSimulation(scenario, plan, fmu, robot, work / "cache", config) as sim:
                            result = sim.run()
                        per = result.timing.per_sim_second()
                        totals[repeat, step, engine] = per["total"]
                        print(
                            f"{repeat + 1:>6} {engine:>7} {step * 1000:>8.0f}ms {per['total']:>8.3f} {per['physics']:>8.3f} {per['fmu']:>8.3f} "
                            f"{per['overhead']:>8.3f} {100.0 * per['overhead'] / per['total']:>8.1f} {1.0 / per['total']:>10.1f}  {result.stop_reason}",
                            flush=True,
                        )
            if len(engines) > 1:
                reference = engines[0]
                print(f"\nspeed relative to {ENGINE_TITLES[reference]} (its wall time / the engine's, min–max over {args.repeats} repeats)")
                for step in steps:
                    for engine in engines[1:]:
                        ratios = [totals[r, step, reference] / totals[r, step, engine] for r in range(args.repeats)]
                        print(f"{step * 1000:>8.0f}ms {ENGINE_TITLES[engine]:>7}: {min(ratios):.2f}–{max(ratios):.2f}x")
    except HarnessError as err:
        print(f"bench_cosim: error: {err}", file=sys.stderr)
        return err.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
