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

import argparse
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/planner"),
        help="output folder of `pf-plan demo` (default out/planner)",
    )
    parser.add_argument(
        "--results-page",
        default=None,
        metavar="NAME",
        help="also publish the table as docs/results/NAME.md",
    )
    parser.add_argument(
        "demo_args",
        nargs="*",
        help="after --: more arguments of `pf-plan demo` (--grid, --rbf-grid, --speed, --repeats)",
    )
    args = parser.parse_args(argv)
    sys.path.insert(0, str(REPO / "harness" / "src"))
    from pfnav_harness import paths, results_page
    from pfnav_harness.errors import HarnessError

    if args.results_page is not None and not results_page.PAGE_NAME.match(
        args.results_page
    ):
        parser.error(
            f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}"
        )
    try:
        pf_plan = paths.pf_plan_path()
    except HarnessError as err:
        print(f"planner_demo: error: {err}", file=sys.stderr)
        return err.exit_code
    # Taken before the run: the commit that ran and the load it ran under (the table has solve times).
    stamp = results_page.collect_stamp() if args.results_page else None
    proc = subprocess.run(
        [str(pf_plan), "demo", "--out", str(args.out), *args.demo_args], check=False
    )
    if proc.returncode != 0:
        return proc.returncode
    if args.results_page:
        report = (args.out / "report.md").read_text(encoding="utf-8")
        command = results_page.regenerate_command(
            ".venv/bin/python scripts/planner_demo.py",
            argv if argv is not None else sys.argv[1:],
        )
        body = results_page.without_pictures(report)
        page = results_page.write_results_page(
            args.results_page,
            "Planner: P-F and fair graph baselines on the paper's scenarios",
            body,
            command,
            stamp,
        )
        print(f"results page: {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
