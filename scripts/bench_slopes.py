#!/usr/bin/env python3
"""Incline benchmark (issue 19, part 5): stand up and walk 3 m on inclined planes, up / down / across.

For every angle × direction: the robot is placed on the plane (body aligned with it), stands up
for the harness's stand time, then follows a straight 3 m reference at the planner's nominal
speed. Printed per run (and written to OUT/table.md, OUT/results.json, OUT/progress.png):
how far the centre of mass lies inside the feet's support polygon in
the pose the robot is placed in, stood up, distance walked along the direction, fall (time and reason), largest stance-foot slip
(during the walk, and during stand-up), base slide during stand-up, largest pitch / roll error
against a body levelled with the plane, peak |torque| / effort limit, the share of control steps
with a saturated joint, and which links other than the feet touched the ground (knees, trunk).

No planner or LCM is involved (the reference is built directly); the controller is the bundled
FMU (`target/fmu/QuadController.fmu`, or $PFNAV_FMU). `--set NAME=VALUE` changes an FMU parameter
(e.g. `--set mpc.mu=0.8`) to try a tuning without rebuilding.

Usage:
    .venv/bin/python scripts/bench_slopes.py                      # 10/20/30° × up/down/across, μ = 0.8
    .venv/bin/python scripts/bench_slopes.py --angles 20 --directions across --set stand.kp[1]=200
    .venv/bin/python scripts/bench_slopes.py --robot robot/third_party/go1.toml   # another robot (PFNAV_PACKAGE_PATH)
    .venv/bin/python scripts/bench_slopes.py --results-page slopes-quadruped      # also docs/results/slopes-quadruped.md
    .venv/bin/python scripts/bench_slopes.py --engine mujoco --results-page slopes-quadruped-mujoco   # in MuJoCo
    .venv/bin/python scripts/bench_slopes.py --engine mujoco --contact-time-constant 0.005   # on a stiffer MuJoCo ground

Another robot than ours runs on an FMU bundled for it by bundle-fmu (cached in OUT/cache).
"""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import json
import math
import os
import platform
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from pfnav_harness import results_page
from pfnav_harness.engine import (
    DEFAULT_ENGINE,
    ENGINE_LABELS,
    ENGINE_NAMES,
    ENGINE_TITLES,
)
from pfnav_harness.errors import HarnessError
from pfnav_harness.incline import (
    DIRECTIONS,
    MIN_WALKED,
    NOMINAL_SPEED,
    WALK_DISTANCE,
    InclineOutcome,
    InclineRun,
    run_incline,
)
from pfnav_harness.robot_fmu import robot_and_fmu
from pfnav_harness.world import DEFAULT_FRICTION
from tqdm import tqdm

# Links listed in the table: those touching the ground until this long after a fall, the first few.
LINKS_AFTER_FALL = 0.1
MAX_LINKS_LISTED = 4


def number_list(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{what} must be comma-separated numbers, got {text!r}"
        ) from None
    if not values or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{what} must be finite numbers, got {text!r}")
    return values


def direction_list(text: str) -> list[str]:
    names = [v.strip() for v in text.split(",") if v.strip()]
    unknown = [n for n in names if n not in DIRECTIONS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(
            f"directions must be among {', '.join(DIRECTIONS)}, got {text!r}"
        )
    return names


def parameter(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if not sep or not name or not math.isfinite(number):
        raise argparse.ArgumentTypeError(
            f"--set takes NAME=NUMBER (an FMU parameter), got {text!r}"
        )
    return name.strip(), number


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.node()}, {cpu}, {os.cpu_count()} logical CPUs, {platform.system()} {platform.release()}, Python {platform.python_version()}"


def file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:12]


def yes_no(flag: bool) -> str:
    return "yes" if flag else "**no**"


def table_rows(outcomes: list[InclineOutcome]) -> list[str]:
    header = (
        "| angle | direction | CoM margin placed (m) | stood up | walked (m) | fell | walk slip (m) | stand-up slip (m) | stand-up slide (m) "
        "| max pitch err (°) | max roll err (°) | peak τ/limit | saturated | other links on the ground (first, until 0.1 s after a fall) | passed |"
    )
    lines = [header, "|" + "|".join("---" for _ in range(header.count("|") - 1)) + "|"]
    for o in outcomes:
        fell = (
            f"at {o.fall_time:.2f} s ({o.fall_reason})"
            if o.fell and o.fall_time is not None
            else "no"
        )
        slip = f"{o.max_stance_slip:.3f}"
        if o.worst_slip is not None and o.max_stance_slip > 0.0:
            slip += f" ({o.worst_slip.foot.removesuffix('_foot')}, {o.worst_slip.time:.2f} s)"
        # Links that hit the ground after the fall are its consequence, not its cause.
        horizon = math.inf if o.fall_time is None else o.fall_time + LINKS_AFTER_FALL
        touched = [
            f"{name} {time:.2f} s"
            for name, time in o.non_foot_contacts.items()
            if time <= horizon
        ]
        links = (
            ", ".join(touched[:MAX_LINKS_LISTED])
            + (", …" if len(touched) > MAX_LINKS_LISTED else "")
            or "none"
        )
        walk = [
            f"{o.walked:.2f}",
            fell,
            slip,
            f"{o.stand_slip:.3f}",
            f"{o.stand_slide:.3f}",
            f"{o.max_pitch_error_deg:.1f}",
            f"{o.max_roll_error_deg:.1f}",
            f"{o.peak_torque_ratio:.2f} ({o.peak_torque_joint.removesuffix('_joint')})",
            f"{100.0 * o.torque_saturation:.1f} %",
        ]
        if o.fell_before_walk:
            # No walk: only the stand-up figures mean something.
            for i in (0, 2, 5, 6, 7, 8):
                walk[i] = "–"
        lines.append(
            "| "
            + " | ".join(
                [
                    f"{o.angle_deg:g}°",
                    o.direction,
                    f"{o.placed_margin:+.3f}",
                    yes_no(o.stood_up),
                    *walk,
                    links,
                    yes_no(o.passed),
                ]
            )
            + " |"
        )
    return lines


def plot_progress(runs: list[InclineRun], path: Path) -> None:
    """Per direction (columns): base displacement along the walking direction (top) and downhill
    (bottom) over time, one line per angle, × at a fall."""
    directions = list(dict.fromkeys(r.outcome.direction for r in runs))
    fig, axes = plt.subplots(
        2,
        len(directions),
        figsize=(5.0 * len(directions), 6.4),
        squeeze=False,
        sharex=True,
        sharey="row",
    )
    for column, direction in enumerate(directions):
        heading = DIRECTIONS[direction]
        top, bottom = axes[0][column], axes[1][column]
        for run in (r for r in runs if r.outcome.direction == direction):
            log = run.result.log
            shift = log["base_pos"][:, :2] - np.asarray(run.scenario.start)
            along = shift @ np.array([math.cos(heading), math.sin(heading)])
            # The planes rise along +x (incline.incline_terrain): downhill is −x.
            downhill = -shift[:, 0]
            t = log["t"] - float(log["walk_start"])
            label = f"{run.outcome.angle_deg:g}°"
            (line,) = top.plot(t, along, label=label)
            bottom.plot(t, downhill, color=line.get_color(), label=label)
            if run.outcome.fall_time is not None:
                k = min(
                    round(run.outcome.fall_time / float(log["physics_dt"])), len(t) - 1
                )
                for ax, values in ((top, along), (bottom, downhill)):
                    ax.plot(
                        t[k],
                        values[k],
                        "x",
                        color=line.get_color(),
                        markersize=10,
                        markeredgewidth=2,
                    )
        reference = runs[0].plan
        top.plot(
            reference.t,
            np.minimum(reference.t * float(reference.metrics["speed"]), WALK_DISTANCE),
            "k:",
            linewidth=1,
            label="reference",
        )
        top.axhline(MIN_WALKED, color="0.7", linewidth=0.8, linestyle="--")
        top.set_title(f"{direction} (× = fall)")
        bottom.set_xlabel("time since walk start (s)")
        for ax in (top, bottom):
            ax.axvline(0.0, color="0.7", linewidth=0.8)
            ax.grid(alpha=0.3)
        top.legend(loc="upper left", fontsize=8)
    axes[0][0].set_ylabel("along the direction (m)")
    axes[1][0].set_ylabel("downhill (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--angles",
        type=lambda s: number_list(s, "--angles"),
        default=[10.0, 20.0, 30.0],
        help="slope angles, degrees (default 10,20,30)",
    )
    parser.add_argument(
        "--directions",
        type=direction_list,
        default=list(DIRECTIONS),
        help="up, down, across (default: all)",
    )
    parser.add_argument(
        "--friction",
        type=float,
        default=DEFAULT_FRICTION,
        help=f"Coulomb friction coefficient of feet and ground (default {DEFAULT_FRICTION})",
    )
    parser.add_argument(
        "--speed",
        type=float,
        default=NOMINAL_SPEED,
        help=f"reference speed, m/s (default {NOMINAL_SPEED}, the planner's nominal speed)",
    )
    parser.add_argument(
        "--distance",
        type=float,
        default=WALK_DISTANCE,
        help=f"horizontal length of the walk, m (default {WALK_DISTANCE:g})",
    )
    parser.add_argument(
        "--set",
        dest="parameters",
        type=parameter,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="FMU parameter to change (repeatable)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/slopes"),
        help="output folder (default out/slopes)",
    )
    parser.add_argument(
        "--robot",
        type=Path,
        default=None,
        help="robot config (default $PFNAV_ROBOT, else robot/quadruped.toml)",
    )
    parser.add_argument(
        "--engine",
        choices=ENGINE_NAMES,
        default=DEFAULT_ENGINE,
        help=f"physics engine the robot walks in (default {DEFAULT_ENGINE})",
    )
    parser.add_argument(
        "--contact-time-constant",
        type=float,
        default=None,
        metavar="SECONDS",
        help="MuJoCo only: the contacts' time constant (a stiffer ground below MuJoCo's own 0.02 s; docs/engines.md)",
    )
    parser.add_argument(
        "--results-page",
        default=None,
        metavar="NAME",
        help="also publish the table as docs/results/NAME.md, stamped with commit, machine and date",
    )
    args = parser.parse_args()
    if not (math.isfinite(args.friction) and args.friction > 0.0):
        parser.error(f"--friction must be positive, got {args.friction}")
    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        parser.error(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    if args.contact_time_constant is not None and args.engine != "mujoco":
        parser.error("--contact-time-constant is MuJoCo's soft-contact setting: use it with --engine mujoco")
    # Taken before the runs: the commit that ran and the load it ran under.
    stamp = results_page.collect_stamp() if args.results_page else None
    parameters = dict(args.parameters)
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        robot, fmu = robot_and_fmu(args.robot, args.out / "cache")
        cases = [(a, d) for a in args.angles for d in args.directions]
        runs: list[InclineRun] = []
        with (
            tempfile.TemporaryDirectory(prefix="pfnav_slopes_") as tmp,
            tqdm(total=len(cases), unit="run", file=sys.stderr) as bar,
        ):
            for angle, direction in cases:
                bar.set_description(f"{angle:g}° {direction}")
                runs.append(
                    run_incline(
                        angle,
                        direction,
                        fmu,
                        robot,
                        Path(tmp),
                        friction=args.friction,
                        distance=args.distance,
                        speed=args.speed,
                        parameters=parameters,
                        engine=args.engine,
                        contact_time_constant=args.contact_time_constant,
                    )
                )
                bar.update(1)
    except HarnessError as err:
        print(f"bench_slopes: error: {err}", file=sys.stderr)
        return err.exit_code

    outcomes = [r.outcome for r in runs]
    now = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    changed = (
        ", ".join(f"{k} = {v:g}" for k, v in parameters.items())
        or "none (the FMU's defaults)"
    )
    header = [
        f"Incline benchmark, {now}",
        "",
        f"- machine: {machine()}",
        f"- robot: {robot.config_path} (URDF {robot.urdf_path})",
        f"- controller: {fmu} (sha256 {file_digest(fmu)}), parameters changed: {changed}",
        f"- physics: {ENGINE_LABELS[args.engine]}, 1 kHz"
        + ("" if args.contact_time_constant is None else f", contact time constant {args.contact_time_constant:g} s"),
        f"- friction μ = {args.friction:g} (feet and ground), walk {args.distance:g} m (horizontal) at {args.speed:g} m/s after the harness's stand-up",
        f"- passed: {sum(o.passed for o in outcomes)} of {len(outcomes)} (stood up, no fall, ≥ {MIN_WALKED:g} m walked, only the feet on the ground while walking); wall {sum(o.wall_time for o in outcomes):.1f} s",
        "",
    ]
    text = "\n".join(header + table_rows(outcomes)) + "\n"
    print(text)
    (args.out / "table.md").write_text(text)
    (args.out / "results.json").write_text(
        json.dumps(
            {
                "date": now,
                "machine": machine(),
                "parameters": parameters,
                "friction": args.friction,
                "engine": args.engine,
                "contact_time_constant": args.contact_time_constant,
                "runs": [o.as_dict() for o in outcomes],
            },
            indent=1,
        )
    )
    plot_progress(runs, args.out / "progress.png")
    print(
        f"wrote {args.out / 'table.md'}, {args.out / 'results.json'}, {args.out / 'progress.png'}"
    )
    if args.results_page:
        page = results_page.write_results_page(
            args.results_page,
            f"Inclines: {robot.config_path.stem} on 10°, 20°, 30° planes"
            # The DART pages keep their titles.
            + ("" if args.engine == DEFAULT_ENGINE else f", in {ENGINE_TITLES[args.engine]}")
            + ("" if args.contact_time_constant is None else f" (contact time constant {args.contact_time_constant:g} s)"),
            text,
            results_page.regenerate_command(
                ".venv/bin/python scripts/bench_slopes.py", sys.argv[1:]
            ),
            stamp,
        )
        print(f"results page: {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
