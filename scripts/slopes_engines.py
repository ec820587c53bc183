#!/usr/bin/env python3
"""The incline grid in DART beside MuJoCo, per robot: which cases pass in both, which differ, and the figures that say why.

Reads the `results.json` that `scripts/bench_slopes.py` wrote for each robot in each engine
(OUT/ROBOT for DART, OUT/ROBOT-mujoco for MuJoCo: the folders the slopes pages are generated
into) and writes one table per robot: pass, distance walked, largest stance-foot slip during the
walk and during the stand-up, peak torque against the effort limit, the share of saturated control
steps, and the links other than the feet that touched the ground while walking, each as
DART / MuJoCo.

    for r in quadruped go1 a1 solo12 hyq anymal_c; do ... bench_slopes.py [--robot robot/third_party/$r.toml] --out out/slopes/$r [--engine mujoco --out out/slopes/$r-mujoco] ...; done
    .venv/bin/python scripts/slopes_engines.py --results-page slopes-engines
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from pfnav_harness import results_page
from pfnav_harness.incline import MIN_WALKED, InclineOutcome, SlipEvent

# Our robot, the Unitree robots of the paper, and the other robots with an incline grid (docs/robots.md).
ROBOTS = ("quadruped", "go1", "a1", "solo12", "hyq", "anymal_c")
ENGINES = ("dart", "mujoco")


def results_folder(out: Path, robot: str, engine: str) -> Path:
    """Where bench_slopes.py wrote `robot`'s grid in `engine` (the commands of the slopes pages)."""
    return out / robot if engine == "dart" else out / f"{robot}-{engine}"


def load_outcomes(folder: Path) -> tuple[dict[str, Any], list[InclineOutcome]]:
    """The run's header fields and its outcomes, rebuilt as `InclineOutcome` (its `passed` is the benchmark's criterion)."""
    path = folder / "results.json"
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise SystemExit(f"slopes_engines: cannot read {path}: {err} (run scripts/bench_slopes.py into {folder} first)") from err
    outcomes = []
    for run in data["runs"]:
        worst = run.get("worst_slip")
        outcomes.append(InclineOutcome(**{**run, "worst_slip": SlipEvent(**worst) if worst else None}))
    return data, outcomes


def walk_links(outcome: InclineOutcome) -> str:
    return ", ".join(f"{name.removesuffix('_link')} {time:.2f} s" for name, time in outcome.walk_contacts.items()) or "none"


def failure(outcome: InclineOutcome) -> str:
    """Which part of the pass criterion (`InclineOutcome.passed`) a run missed, in words ("" when it passed)."""
    if outcome.passed:
        return ""
    if not outcome.stood_up:
        return "did not stand up" + (f" (fell at {outcome.fall_time:.2f} s: {outcome.fall_reason})" if outcome.fell and outcome.fall_time is not None else "")
    missed = []
    if outcome.fell:
        missed.append(f"fell at {outcome.fall_time:.2f} s ({outcome.fall_reason})" if outcome.fall_time is not None else f"fell ({outcome.fall_reason})")
    if outcome.walked < MIN_WALKED:
        missed.append(f"walked {outcome.walked:.2f} m of the {MIN_WALKED:g} m needed")
    if outcome.walk_contacts:
        missed.append(f"{walk_links(outcome)} on the ground while walking")
    return "; ".join(missed)


def pair(dart: str, mujoco: str) -> str:
    return dart if dart == mujoco else f"{dart} / {mujoco}"


def robot_section(robot: str, out: Path) -> tuple[list[str], int, int]:
    """The robot's comparison table, the number of cases with the same verdict in both engines, and the number of cases."""
    headers, grids = {}, {}
    for engine in ENGINES:
        header, outcomes = load_outcomes(results_folder(out, robot, engine))
        if header.get("engine", "dart") != engine:
            raise SystemExit(f"slopes_engines: {results_folder(out, robot, engine)} holds a {header.get('engine')} grid, expected {engine}")
        headers[engine] = header
        grids[engine] = {(o.angle_deg, o.direction): o for o in outcomes}
    cases = [case for case in grids["dart"] if case in grids["mujoco"]]
    same = sum(grids["dart"][c].passed == grids["mujoco"][c].passed for c in cases)
    passed = {engine: sum(grids[engine][c].passed for c in cases) for engine in ENGINES}
    lines = [
        f"## {robot}",
        "",
        (
            f"Passed: DART {passed['dart']} of {len(cases)}, MuJoCo {passed['mujoco']} of {len(cases)}; the same verdict in {same} of {len(cases)} cases. "
            f"Grids of {headers['dart']['date']} (DART) and {headers['mujoco']['date']} (MuJoCo), "
            f"friction μ = {headers['dart']['friction']:g} / {headers['mujoco']['friction']:g}."
        ),
        "",
        "| angle | direction | passed | walked (m) | walk slip (m) | stand-up slip (m) | peak τ/limit | saturated | other links on the ground while walking |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for case in cases:
        d, m = grids["dart"][case], grids["mujoco"][case]
        lines.append(
            "| "
            + " | ".join(
                [
                    f"{case[0]:g}°",
                    case[1],
                    pair("yes" if d.passed else "**no**", "yes" if m.passed else "**no**"),
                    f"{d.walked:.2f} / {m.walked:.2f}",
                    f"{d.max_stance_slip:.3f} / {m.max_stance_slip:.3f}",
                    f"{d.stand_slip:.3f} / {m.stand_slip:.3f}",
                    f"{d.peak_torque_ratio:.2f} / {m.peak_torque_ratio:.2f}",
                    f"{100 * d.torque_saturation:.1f} / {100 * m.torque_saturation:.1f} %",
                    pair(walk_links(d), walk_links(m)),
                ]
            )
            + " |"
        )
    differing = [case for case in cases if grids["dart"][case].passed != grids["mujoco"][case].passed]
    if differing:
        lines += ["", "Where the verdicts differ, what the failing run missed:", ""]
        for case in differing:
            d, m = grids["dart"][case], grids["mujoco"][case]
            engine, outcome = ("DART", d) if not d.passed else ("MuJoCo", m)
            lines.append(f"- {case[0]:g}° {case[1]}: {engine} {failure(outcome)}.")
    return lines + [""], same, len(cases)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("out/slopes"), help="folder of bench_slopes.py's result folders (default out/slopes)")
    parser.add_argument("--robots", default=",".join(ROBOTS), help=f"comma-separated robot names (default {','.join(ROBOTS)})")
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also write docs/results/NAME.md")
    args = parser.parse_args()
    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        parser.error(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    sections: list[str] = []
    agreeing = total = 0
    for robot in (r.strip() for r in args.robots.split(",") if r.strip()):
        lines, same, cases = robot_section(robot, args.out)
        sections += lines
        agreeing += same
        total += cases
    text = "\n".join(
        [
            (
                "The incline grid (scripts/bench_slopes.py: stand up from lying on a plane, walk 3 m up, down or across it; "
                "docs/slopes.md) walked by the same controller in DART and in MuJoCo. Each cell is DART / MuJoCo (one value: both). "
                f"The same verdict in {agreeing} of {total} cases. Why the figures differ: docs/engines.md."
            ),
            "",
            *sections,
        ]
    )
    print(text)
    if args.results_page:
        # The grids were measured by bench_slopes.py (their own pages carry their stamps): this stamp is when they were compared.
        command = results_page.regenerate_command(".venv/bin/python scripts/slopes_engines.py", sys.argv[1:])
        page = results_page.write_results_page(args.results_page, "Inclines in DART and in MuJoCo", text, command, results_page.collect_stamp())
        print(f"results page: {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
