#!/usr/bin/env python3
"""The paper's numbers beside ours, published as a results page.

Runs `pf-plan paper-numbers --out OUT` (every figure quoted from the paper and from the formulation
note's prototype, with the planner's counterpart computed on the rebuilt terrains; OUT/report.md)
and writes it to docs/results/NAME.md with the stamp of `pfnav_harness.results_page` (commit,
machine, date, load).

    .venv/bin/python scripts/paper_numbers.py --results-page paper-numbers
    .venv/bin/python scripts/paper_numbers.py --out /tmp/p -- --grid 32 --rbf-grid 16 --skip-large
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(REPO / "harness" / "src"))
    from pfnav_harness.planner_client import ROBOT_FOOTPRINT_RADIUS
    from pfnav_harness.results_page import pf_plan_report_main

    return pf_plan_report_main(
        script="scripts/paper_numbers.py",
        subcommand="paper-numbers",
        title="The paper's numbers beside ours",
        description=__doc__ or "",
        default_out=Path("out/paper-numbers"),
        extra_help="--grid, --rbf-grid, --skip-large",
        argv=argv,
        echo_report=True,
        fixed_args=["--footprint-radius", repr(ROBOT_FOOTPRINT_RADIUS)],
    )


if __name__ == "__main__":
    sys.exit(main())
