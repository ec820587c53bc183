#!/usr/bin/env python3
"""Fair baselines walked by the robot: every planner's plan of the paper scenarios, co-simulated.

Runs `pfnav-demo demo` (the user's command) once for the graph planners and the P-F indicator
plan (`--methods pf,astar,astar-admissible,dijkstra`) and once per RBF generator kind
(`--methods pf --basis rbf --generators transfer|ansdmd`), each on the default controller FMU and
the default estimator, and tabulates from each run's metrics.json: the plan's ∫p ds and length,
whether the robot reached the goal or fell, its RMS tracking error, the executed ∫p ds and the
effort ∫τ²dt. Planning-only figures (solve time, expanded nodes, max slope) are on the planner
page (docs/results/planner.md, `pf-plan demo`).

Planning needs the planner service (LCM): run inside the private network namespace:
    bash scripts/netns.sh .venv/bin/python scripts/baselines.py --out out/baselines --results-page baselines
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# (label, pfnav-demo arguments, the methods that invocation walks)
RUN_SETS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("graph", ("--methods", "pf,astar,astar-admissible,dijkstra")),
    ("rbf-transfer", ("--methods", "pf", "--basis", "rbf", "--generators", "transfer")),
    ("rbf-ansdmd", ("--methods", "pf", "--basis", "rbf", "--generators", "ansdmd")),
)
PLANNER_LABELS = {
    ("graph", "astar"): "A*, the paper's heuristic",
    ("graph", "astar-admissible"): "A*, admissible heuristic",
    ("graph", "dijkstra"): "Dijkstra",
    ("graph", "pf"): "P-F, indicator basis",
    ("rbf-transfer", "pf"): "P-F, RBF 32², transfer",
    ("rbf-ansdmd", "pf"): "P-F, RBF 32², ANSDMD",
}


@dataclass(frozen=True)
class Row:
    scenario: str
    planner: str
    planned_cost: float
    planned_length: float
    planned_max_slope_deg: float
    solve_time: float
    goal: bool
    fell: bool
    fall_time: float | None
    rms: float
    executed_cost: float
    effort: float


def run_set(label: str, arguments: tuple[str, ...], out: Path, extra: list[str]) -> list[Row]:
    """One `pfnav-demo demo` invocation; its runs as rows."""
    folder = out / label
    command = [str(ROOT / ".venv" / "bin" / "pfnav-demo"), "demo", "--out", str(folder), "--no-progress", *arguments, *extra]
    print("$ " + " ".join(command), flush=True)
    subprocess.run(command, check=True, cwd=ROOT)
    runs = json.loads((folder / "metrics.json").read_text())["runs"]
    rows = []
    for run in runs:
        rows.append(
            Row(
                scenario=run["scenario"],
                planner=PLANNER_LABELS[(label, run["method"])],
                planned_cost=float(run["planned_cost"]),
                planned_length=float(run["planned_length"]),
                planned_max_slope_deg=float(run["planned_max_slope_deg"]),
                solve_time=float(run["planner_solve_time"]),
                goal=bool(run["goal_reached"]),
                fell=bool(run["fell"]),
                fall_time=run["fall_time"],
                rms=float(run["rms_error"]),
                executed_cost=float(run["executed_cost"]),
                effort=float(run["effort"]),
            )
        )
    return rows


def table(rows: list[Row]) -> str:
    order = list(PLANNER_LABELS.values())
    lines = [
        (
            "| scenario | planner | planned ∫p ds | planned length, m | max slope on the plan, ° | service solve time, ms | goal | fell "
            "| RMS tracking, m | executed ∫p ds | effort ∫τ²dt, N²m²s |"
        ),
        "|---|---|---:|---:|---:|---:|---|---|---:|---:|---:|",
    ]
    for row in sorted(rows, key=lambda r: (r.scenario, order.index(r.planner))):
        fell = f"yes ({row.fall_time:.1f} s)" if row.fell and row.fall_time is not None else ("yes" if row.fell else "no")
        lines.append(
            f"| {row.scenario} | {row.planner} | {row.planned_cost:.3f} | {row.planned_length:.2f} | {row.planned_max_slope_deg:.1f} | "
            f"{1e3 * row.solve_time:.1f} | {'yes' if row.goal else 'no'} | "
            f"{fell} | {row.rms:.3f} | {row.executed_cost:.3f} | {row.effort:.0f} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "baselines", help="the demo outputs (default out/baselines)")
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also write docs/results/NAME.md")
    parser.add_argument("demo_args", nargs="*", help="passed on to every pfnav-demo demo (after --), e.g. --estimator groundTruth")
    args = parser.parse_args()

    from pfnav_harness import results_page

    stamp = results_page.collect_stamp() if args.results_page else None
    rows = [row for label, arguments in RUN_SETS for row in run_set(label, arguments, args.out, args.demo_args)]
    text = "\n".join(
        [
            (
                "Every planner's plan of the paper scenarios walked by our robot (robot/quadruped.toml) on the default controller FMU "
            "and estimator, DART, 1 kHz physics; each plan follows its reference trajectory. ∫p ds is the traversability cost along "
            "the path (the planners' common objective); the executed one is along the trunk's path; the max slope is the steepest "
                "terrain under the plan and the solve time the planner service's own, both as the planner measures them. The same "
                "planners by `pf-plan` alone, with expanded nodes and solve-time ranges: [planner.md](planner.md)."
            ),
            "",
            table(rows),
        ]
    )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "baselines.md").write_text(text + "\n")
    print(text)
    if args.results_page:
        command = results_page.regenerate_command(".venv/bin/python scripts/baselines.py", sys.argv[1:])
        title = "Fair baselines walked by the robot: every planner on the paper scenarios"
        print(f"results page: {results_page.write_results_page(args.results_page, title, text, command, stamp)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
