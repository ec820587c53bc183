#!/usr/bin/env python3
"""Cross-engine table: the same plans walked by the same controller FMU in DART and in MuJoCo.

Plans each paper scenario once with P-F and A* on a started `pf-planner-service` (LCM: run inside
scripts/netns.sh), then co-simulates, one run after the other in this process (the wall times are
comparable only so):
- our robot (robot/quadruped.toml): every scenario × {P-F, A*} × {groundTruth, kalman} × engine;
- Go1 and A1 (robot/third_party/*.toml, on FMUs bundled for them): every scenario × P-F ×
  kalman × engine (`--third-party-estimators` adds groundTruth).
Each row: goal, fall, RMS tracking error, effort ∫τ²dt, wall time, MuJoCo's RMS and speed
relative to DART's; on the estimate also the estimator's velocity error and the status flags it
raised while walking. The summary checks the issue's targets.

    bash scripts/netns.sh .venv/bin/python scripts/bench_engines.py --out out/engines --results-page engines
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ENGINES = ("dart", "mujoco")
ESTIMATORS = ("groundTruth", "kalman")
METHODS = ("pf", "astar")
# Third-party robots (robot/third_party/NAME.toml): P-F only, on the estimators `--third-party-estimators` names.
THIRD_PARTY = ("go1", "a1")
# The third-party robots walk on their own estimate (as a real robot does) unless told otherwise.
THIRD_PARTY_ESTIMATORS = ("kalman",)
# MuJoCo's RMS tracking may be at most this multiple of DART's (the target).
RMS_RATIO_TARGET = 1.5
# MuJoCo co-simulation speed against DART's, simulated seconds per wall second (the target).
SPEED_RATIO_TARGET = 1.5


@dataclass(frozen=True)
class Case:
    robot: str
    scenario: str
    method: str
    estimator: str


@dataclass(frozen=True)
class Row:
    case: Case
    engine: str
    goal: bool
    fell: bool
    rms: float
    effort: float
    sim_seconds: float
    wall_seconds: float
    physics_per_sim_second: float
    # Estimator figures (NaN / -1 on ground truth): velocity error RMS while walking, m/s; the status flags raised while walking.
    velocity_rms: float
    status_bits: int


def cases(scenarios: tuple[str, ...], third_party_estimators: tuple[str, ...]) -> list[Case]:
    ours = [Case("quadruped", s, m, e) for s in scenarios for m in METHODS for e in ESTIMATORS]
    others = [Case(r, s, "pf", e) for r in THIRD_PARTY for s in scenarios for e in third_party_estimators]
    return ours + others


def table(rows: list[Row], flag_names: Callable[[int], list[str]]) -> str:
    """The rows as markdown; `flag_names` names the bits of the estimator's status (the FMU's own documentation)."""
    by_key = {(r.case, r.engine): r for r in rows}
    lines = [
        (
            "| robot | scenario | method | estimator | engine | goal | fell | RMS tracking, m | MuJoCo/DART RMS | effort ∫τ²dt, N²m²s | "
            "simulated, s | wall, s | wall per simulated s | physics per simulated s | MuJoCo speed / DART's | "
            "estimate velocity RMS, m/s | estimator flags while walking |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        dart = by_key.get((r.case, "dart"))
        other = dart is not None and r.engine != "dart"
        rms_ratio = f"{r.rms / dart.rms:.2f}" if other and dart.rms > 0 else ""
        speed_ratio = f"{(dart.wall_seconds / dart.sim_seconds) / (r.wall_seconds / r.sim_seconds):.2f}" if other else ""
        kalman = r.case.estimator == "kalman"
        flags = f"{r.status_bits:#x} ({', '.join(flag_names(r.status_bits)) or 'none'})" if kalman else ""
        c = r.case
        lines.append(
            f"| {c.robot} | {c.scenario} | {c.method} | {c.estimator} | {r.engine} | {'yes' if r.goal else '**no**'} | {'**yes**' if r.fell else 'no'} | "
            f"{r.rms:.3f} | {rms_ratio} | {r.effort:.0f} | {r.sim_seconds:.1f} | {r.wall_seconds:.1f} | {r.wall_seconds / r.sim_seconds:.3f} | "
            f"{r.physics_per_sim_second:.3f} | {speed_ratio} | {f'{r.velocity_rms:.3f}' if kalman else ''} | "
            f"{flags} |"
        )
    return "\n".join(lines)


def summary(rows: list[Row]) -> list[str]:
    """The issue's targets, measured: P-F in MuJoCo on our robot, RMS against DART's, speed."""
    by_key = {(r.case, r.engine): r for r in rows}
    pf_ours = [r for r in rows if r.engine == "mujoco" and r.case.robot == "quadruped" and r.case.method == "pf"]
    reached = sum(r.goal and not r.fell for r in pf_ours)
    ratios = [r.rms / by_key[(r.case, "dart")].rms for r in pf_ours if (r.case, "dart") in by_key]
    lines = [
        f"- P-F, our robot, in MuJoCo: {reached} of {len(pf_ours)} runs reach the goal without a fall; "
        + (
            f"RMS tracking {min(ratios):.2f}–{max(ratios):.2f} × DART's (target ≤ {RMS_RATIO_TARGET:g} ×: "
            f"{'met' if max(ratios) <= RMS_RATIO_TARGET else 'not met'})."
            if ratios
            else "no DART rows to compare with."
        )
    ]
    for engine in ENGINES:
        chosen = [r for r in rows if r.engine == engine]
        if chosen:
            agree = sum(r.goal and not r.fell for r in chosen)
            lines.append(f"- {engine}: {agree} of {len(chosen)} runs reach the goal without a fall.")
    paired = [(by_key[(r.case, "dart")], r) for r in rows if r.engine == "mujoco" and (r.case, "dart") in by_key]
    if paired:
        dart_wall = sum(d.wall_seconds for d, _ in paired) / sum(d.sim_seconds for d, _ in paired)
        mujoco_wall = sum(m.wall_seconds for _, m in paired) / sum(m.sim_seconds for _, m in paired)
        lines.append(
            f"- Speed over all paired runs: DART {dart_wall:.3f}, MuJoCo {mujoco_wall:.3f} wall s per simulated s: MuJoCo {dart_wall / mujoco_wall:.2f} × "
            f"DART's speed (target ≥ {SPEED_RATIO_TARGET:g} ×: {'met' if dart_wall / mujoco_wall >= SPEED_RATIO_TARGET else 'not met'})."
        )
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("out/engines"), help="logs, plans, cache (default out/engines)")
    parser.add_argument("--scenario", action="append", default=None, help="only this scenario (repeatable; default: the paper's)")
    parser.add_argument("--duration", type=float, default=None, help="cap on simulated seconds per run (default: the whole plan)")
    parser.add_argument(
        "--third-party-estimators",
        default=",".join(THIRD_PARTY_ESTIMATORS),
        help=f"estimators Go1 and A1 run with, comma-separated from {', '.join(ESTIMATORS)} (default {','.join(THIRD_PARTY_ESTIMATORS)})",
    )
    parser.add_argument("--only-robot", default=None, help="only this robot (quadruped, go1 or a1)")
    parser.add_argument("--save-logs", action="store_true", help="also save every run's log as OUT/logs/ROBOT_SCENARIO_METHOD_ESTIMATOR_ENGINE.npz")
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also write docs/results/NAME.md")
    args = parser.parse_args()
    third_party_estimators = tuple(e.strip() for e in args.third_party_estimators.split(",") if e.strip())
    if not third_party_estimators or any(e not in ESTIMATORS for e in third_party_estimators):
        parser.error(f"--third-party-estimators: comma-separated from {', '.join(ESTIMATORS)}, got {args.third_party_estimators!r}")

    from pfnav_harness import paths, results_page
    from pfnav_harness.cosim import CoSimConfig
    from pfnav_harness.fmu_runner import read_contract
    from pfnav_harness.pipeline import export_scenario, simulate
    from pfnav_harness.planner_client import plan_scenario
    from pfnav_harness.robot_fmu import robot_and_fmu
    from pfnav_harness.scenario import paper_scenario_names

    stamp = results_page.collect_stamp() if args.results_page else None
    out: Path = args.out
    names = tuple(args.scenario) if args.scenario else paper_scenario_names()
    todo = [c for c in cases(names, third_party_estimators) if args.only_robot in (None, c.robot)]
    configs = {"quadruped": paths.default_robot_config_path(), **{name: paths.repo_root() / "robot" / "third_party" / f"{name}.toml" for name in THIRD_PARTY}}
    robots = {name: robot_and_fmu(configs[name], out / "cache") for name in dict.fromkeys(c.robot for c in todo)}
    scenarios = {name: export_scenario(paths.pf_plan_path(), name, out / "scenarios") for name in names}
    methods = sorted({c.method for c in todo})
    plans = {name: plan_scenario(scenario, methods, service_binary=paths.planner_service_path()) for name, scenario in scenarios.items()}
    rows: list[Row] = []
    for case in todo:
        robot, fmu = robots[case.robot]
        for engine in ENGINES:
            config = CoSimConfig(engine=engine, estimator=case.estimator, max_duration=args.duration)
            log_path = out / "logs" / f"{case.robot}_{case.scenario}_{case.method}_{case.estimator}_{engine}.npz" if args.save_logs else None
            outcome = simulate(scenarios[case.scenario], plans[case.scenario][case.method], fmu, robot, out / "cache", config, log_path, show_progress=False)
            m, e = outcome.metrics, outcome.estimation
            row = Row(
                case,
                engine,
                m.goal_reached,
                m.fell,
                m.rms_error,
                m.effort,
                m.duration,
                outcome.wall_seconds,
                outcome.result.timing.per_sim_second()["physics"],
                e.velocity_rms if e is not None else float("nan"),
                e.status_bits if e is not None else -1,
            )
            rows.append(row)
            print(
                f"{case.robot:9s} {case.scenario:14s} {case.method:5s} {case.estimator:12s} {engine:7s} goal={row.goal} fell={row.fell} "
                f"rms={row.rms:.3f} wall={row.wall_seconds:.1f} s",
                flush=True,
            )
    text = "\n".join(
        [
            (
                "Plans of the paper scenarios (P-F and A*, planned once, walked by every robot in both engines); our robot "
                "(robot/quadruped.toml) on the default controller FMU, Go1 and A1 (robot/third_party/) on FMUs bundled for them; "
                "1 ms communication step, 1 kHz physics. Engines: DART (terrain triangle mesh, ODE collision, box friction LCP) and "
                "MuJoCo (terrain height field of the same heights, soft contacts, elliptic friction cone, impratio 100); see "
                "docs/engines.md. Wall time includes the FMU and the harness's loop; the runs ran one after the other in one process. "
                "On the estimate (kalman) the controller runs on its own state estimate from simulated IMU and encoders (no position fixes)."
            ),
            "",
            *summary(rows),
            "",
            # Our robot's FMU documents the flags (the bundled ones carry the same controller).
            table(rows, read_contract(paths.fmu_path()).status_flag_names),
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
