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

import argparse
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TITLE = "The paper's numbers beside ours"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/paper-numbers"),
        help="output folder of `pf-plan paper-numbers` (default out/paper-numbers)",
    )
    parser.add_argument(
        "--results-page",
        default=None,
        metavar="NAME",
        help="also publish the report as docs/results/NAME.md",
    )
    parser.add_argument(
        "extra",
        nargs="*",
        help="after --: more arguments of `pf-plan paper-numbers` (--grid, --rbf-grid, --skip-large)",
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
        print(f"paper_numbers: error: {err}", file=sys.stderr)
        return err.exit_code
    # Taken before the run: the commit that ran and the load it ran under (the page has times).
    stamp = results_page.collect_stamp() if args.results_page else None
    proc = subprocess.run(
        [str(pf_plan), "paper-numbers", "--out", str(args.out), *args.extra],
        check=False,
        stdout=subprocess.DEVNULL,
    )
    if proc.returncode != 0:
        return proc.returncode
    report = (args.out / "report.md").read_text(encoding="utf-8")
    if args.results_page:
        command = results_page.regenerate_command(
            ".venv/bin/python scripts/paper_numbers.py",
            argv if argv is not None else sys.argv[1:],
        )
        page = results_page.write_results_page(
            args.results_page,
            TITLE,
            results_page.without_pictures(report),
            command,
            stamp,
        )
        print(f"results page: {page}")
    else:
        print(report, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
