#!/usr/bin/env python3
"""The planner alone on the paper's scenarios, published as a results page.

Runs `pf-plan demo --out OUT` (A* with the paper's heuristic, A* admissible, Dijkstra, P-F indicator
and P-F RBF on every scenario, each planned `--repeats` times from scratch; OUT/report.md with ∫p ds,
length, max slope and solve-time ranges, and one PNG per scenario) and writes its table to docs/results/NAME.md with the stamp of
`pfnav_harness.results_page`. The stamp lives in one place (Python) instead of a second copy in
the planner's Rust CLI.

    .venv/bin/python scripts/planner_demo.py --results-page planner          # out/planner + docs/results/planner.md
    .venv/bin/python scripts/planner_demo.py --out /tmp/p -- --grid 128      # extra words go to `pf-plan demo`
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(REPO / "harness" / "src"))
    from pfnav_harness.results_page import pf_plan_report_main

    return pf_plan_report_main(
        script="scripts/planner_demo.py",
        subcommand="demo",
        title="Planner: P-F and fair graph baselines on the paper's scenarios",
        description=__doc__ or "",
        default_out=Path("out/planner"),
        extra_help="--grid, --rbf-grid, --speed, --repeats",
        argv=argv,
        echo_report=False,
    )


if __name__ == "__main__":
    sys.exit(main())
