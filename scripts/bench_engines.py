#!/usr/bin/env python3
"""Cross-engine table: the same P-F plans walked by the same controller FMU in DART and in MuJoCo.

Plans each paper scenario once with a started `pf-planner-service` (LCM: run inside
scripts/netns.sh), then co-simulates every scenario × estimator × engine one after the other in
this process (the wall times are comparable only so) and tabulates goal, fall, RMS tracking
error, effort ∫τ²dt and wall time, with MuJoCo's RMS and wall time relative to DART's.

    bash scripts/netns.sh .venv/bin/python scripts/bench_engines.py --out out/engines --results-page engines
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

ENGINES = ("dart", "mujoco")
ESTIMATORS = ("groundTruth", "kalman")


@dataclass(frozen=True)
class Row:
    scenario: str
    estimator: str
    engine: str
    goal: bool
    fell: bool
    rms: float
    effort: float
    sim_seconds: float
    wall_seconds: float
    physics_per_sim_second: float


def table(rows: list[Row]) -> str:
    by_key = {(r.scenario, r.estimator, r.engine): r for r in rows}
    lines = [
        (
            "| scenario | estimator | engine | goal | fell | RMS tracking, m | MuJoCo/DART RMS | effort ∫τ²dt, N²m²s | simulated, s | wall, s | "
            "wall per simulated s | physics per simulated s | DART/MuJoCo wall |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        dart = by_key.get((r.scenario, r.estimator, "dart"))
        rms_ratio = f"{r.rms / dart.rms:.2f}" if dart is not None and r.engine != "dart" and dart.rms > 0 else ""
        speed_ratio = (
            f"{(dart.wall_seconds / dart.sim_seconds) / (r.wall_seconds / r.sim_seconds):.2f}" if dart is not None and r.engine != "dart" else ""
        )
        lines.append(
            f"| {r.scenario} | {r.estimator} | {r.engine} | {'yes' if r.goal else 'no'} | {'yes' if r.fell else 'no'} | {r.rms:.3f} | {rms_ratio} | "
            f"{r.effort:.0f} | {r.sim_seconds:.1f} | {r.wall_seconds:.1f} | {r.wall_seconds / r.sim_seconds:.3f} | "
            f"{r.physics_per_sim_second:.3f} | {speed_ratio} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("out/engines"), help="logs, plans, cache (default out/engines)")
    parser.add_argument("--scenario", action="append", default=None, help="only this scenario (repeatable; default: the paper's)")
    parser.add_argument("--duration", type=float, default=None, help="cap on simulated seconds per run (default: the whole plan)")
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also write docs/results/NAME.md")
    args = parser.parse_args()

    from pfnav_harness import paths, results_page
    from pfnav_harness.cosim import CoSimConfig
    from pfnav_harness.pipeline import export_scenario, simulate
    from pfnav_harness.planner_client import plan_scenario
    from pfnav_harness.robot_fmu import robot_and_fmu
    from pfnav_harness.scenario import paper_scenario_names

    stamp = results_page.collect_stamp() if args.results_page else None
    out: Path = args.out
    robot, fmu = robot_and_fmu(None, out / "cache")
    names = tuple(args.scenario) if args.scenario else paper_scenario_names()
    rows: list[Row] = []
    for name in names:
        scenario = export_scenario(paths.pf_plan_path(), name, out / "scenarios")
        plan = plan_scenario(scenario, ["pf"], service_binary=paths.planner_service_path())["pf"]
        for estimator in ESTIMATORS:
            for engine in ENGINES:
                config = CoSimConfig(engine=engine, estimator=estimator, max_duration=args.duration)
                outcome = simulate(scenario, plan, fmu, robot, out / "cache", config, show_progress=False)
                m = outcome.metrics
                physics = outcome.result.timing.per_sim_second()["physics"]
                row = Row(name, estimator, engine, m.goal_reached, m.fell, m.rms_error, m.effort, m.duration, outcome.wall_seconds, physics)
                rows.append(row)
                print(f"{name:14s} {estimator:12s} {engine:7s} goal={row.goal} fell={row.fell} rms={row.rms:.3f} wall={row.wall_seconds:.1f} s", flush=True)
    text = "\n".join(
        [
            (
                "P-F plans of the paper scenarios (planned once, walked in both engines), our robot (robot/quadruped.toml), "
            "the default controller FMU, 1 ms communication step, 1 kHz physics. Engines: DART (terrain triangle mesh, ODE "
            "collision, box friction LCP) and MuJoCo (terrain height field of the same heights, soft contacts, elliptic "
            "friction cone, impratio 100); see harness/README.md, physics engines. Wall time includes the FMU and the "
                "harness's loop; both engines ran one after the other in one process."
            ),
            "",
            table(rows),
        ]
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / "engines.md").write_text(text + "\n")
    print(text)
    if args.results_page:
        command = results_page.regenerate_command(".venv/bin/python scripts/bench_engines.py", sys.argv[1:])
        title = "Cross-engine check: DART and MuJoCo under the same controller"
        print(f"results page: {results_page.write_results_page(args.results_page, title, text, command, stamp)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
