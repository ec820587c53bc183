#!/usr/bin/env python3
"""Why pushes knock the robot over: a grid of pushes on a scenario (mountain_pass by default), each run taken apart.

Every combination of push magnitude × direction (relative to the heading) × walk time, for 0.2 s,
on the P-F plan of the scenario (`--scenario`), at the ground friction of `--friction`, per variant (estimator, and optionally a Raibert foothold gain
other than the FMU's own). Each run lasts until 3 s after its push. Per run, in the window from the
push to the fall (or 2 s after the push), from the co-simulation log:

- the impulse (N·s) and the largest horizontal velocity change of the trunk it caused (against the
  mean over the 0.5 s before the push), and what a capture step would need, Δv·√(h/g);
- torque saturation: the share of ticks with a joint at ≥ 95 % of its effort limit;
- feet that missed the ground: the share of scheduled-stance foot ticks without contact (a foot
  that touched down late, short or off an edge), and swing feet that hit it (scheduled swing, in
  contact: a trip);
- the estimator: the largest horizontal velocity error of the estimate (kalman only);
- the attitude at the end of the window (roll, pitch).

Planning needs the planner service (LCM): run inside the private network namespace:
    bash scripts/netns.sh .venv/bin/python scripts/push_diagnosis.py --out out/push-diagnosis --results-page push-diagnosis
The fall-rate plot goes to OUT/push_diagnosis.png (and with --figure, to that path as well).
"""

from __future__ import annotations

import argparse
import itertools
import math
import multiprocessing
import shutil
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
WINDOW_WITHOUT_FALL = 2.0
AFTER_PUSH = 3.0
PUSH_DURATION = 0.2
SATURATION = 0.95
RAIBERT_GAIN_PARAMETER = "gait.raibertGain"
GRAVITY = 9.81
NUMERIC_FIELDS = (
    "fall_after",
    "dv",
    "capture_step",
    "saturated",
    "missed",
    "tripped",
    "estimate_error",
    "roll",
    "pitch",
)


@dataclass(frozen=True)
class Variant:
    """What the controller runs on, and FMU parameters other than the FMU's own (name, value)."""

    estimator: str
    parameters: tuple[tuple[str, float], ...] = ()

    @property
    def label(self) -> str:
        if (
            len(self.parameters) == 1
            and self.parameters[0][0] == RAIBERT_GAIN_PARAMETER
        ):
            return f"{self.estimator}, Raibert gain {self.parameters[0][1]:g} s"
        return ", ".join(
            [self.estimator, *(f"{name} {value:g}" for name, value in self.parameters)]
        )


def parse_variant(text: str) -> Variant:
    """A kalman variant from 'NAME=VALUE[,NAME=VALUE…]' (FMU parameter names, e.g. gait.period=0.2)."""
    parameters = []
    for item in text.split(","):
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(
                f"--variant: expected NAME=VALUE[,NAME=VALUE…], got {text!r}"
            )
        parameters.append((name.strip(), float(value)))
    return Variant("kalman", tuple(parameters))


@dataclass(frozen=True)
class Task:
    variant: Variant
    magnitude: float
    direction: str
    walk_time: float


@dataclass(frozen=True)
class Shared:
    """What every run needs (picklable: sent to the worker processes once per task)."""

    scenario: Any
    plan: Any
    fmu: Path
    robot: Any
    cache: Path
    friction: float
    follow: str
    field: Any


def run_one(shared: Shared, task: Task) -> dict[str, Any]:
    from pfnav_harness.cosim import CoSimConfig, CoSimulation
    from pfnav_harness.pushes import HEADING_DIRECTIONS, PushSchedule, horizontal_push

    push = horizontal_push(
        task.magnitude,
        HEADING_DIRECTIONS[task.direction],
        task.walk_time,
        PUSH_DURATION,
        heading_relative=True,
    )
    config = CoSimConfig(
        max_duration=CoSimConfig().stand_time + task.walk_time + AFTER_PUSH,
        pushes=PushSchedule([push]),
        estimator=task.variant.estimator,
        friction=shared.friction,
        follow=shared.follow,
    )
    with CoSimulation(
        shared.scenario,
        shared.plan,
        shared.fmu,
        shared.robot,
        shared.cache,
        config,
        field=shared.field,
    ) as sim:
        if task.variant.parameters:
            sim.fmu.set_parameters(dict(task.variant.parameters))
        result = sim.run()
        limits = np.asarray(sim.world.effort_limits, dtype=np.float64)
    row = diagnose(
        result.log, result.fall_step, limits, float(shared.robot.stand_height)
    )
    row.update(
        variant=task.variant.label,
        magnitude=task.magnitude,
        direction=task.direction,
        walk_time=task.walk_time,
    )
    return row


def diagnose(
    log: dict[str, Any],
    fall_step: int | None,
    effort_limits: np.ndarray,
    stand_height: float,
) -> dict[str, Any]:
    """The figures of one pushed run (module text): `fall_step` is the log row of the fall (None:
    it stood); `stand_height` (m) sets the capture step's √(h/g)."""
    from pfnav_harness.world import quaternion_to_rpy

    dt = float(log["physics_dt"])
    pushed = np.flatnonzero(np.any(log["push_force"] != 0.0, axis=1))
    fell = fall_step is not None
    if pushed.size == 0:
        if not fell:
            raise ValueError("the run has no push")
        # A variant that cannot walk falls before its push: a fall, with nothing to take apart.
        return {
            "fell": True,
            "before_push": True,
            **{key: math.nan for key in NUMERIC_FIELDS},
        }
    k0 = int(pushed[0])
    k1 = min(
        len(log["t"]),
        fall_step if fall_step is not None else k0 + round(WINDOW_WITHOUT_FALL / dt),
    )
    window = slice(k0, max(k1, k0 + 1))
    velocity = log["base_vel"][:, :2]
    before = velocity[max(0, k0 - round(0.5 / dt)) : k0].mean(axis=0)
    dv = float(np.max(np.linalg.norm(velocity[window] - before, axis=1)))
    tau = np.abs(log["tau"][window])
    saturated = float(np.mean(np.any(tau >= SATURATION * effort_limits, axis=1)))
    scheduled = log["contact_scheduled"][window].astype(bool)
    actual = log["contact_actual"][window].astype(bool)
    missed = float(np.sum(scheduled & ~actual) / max(1, np.sum(scheduled)))
    tripped = float(np.sum(~scheduled & actual) / max(1, np.sum(~scheduled)))
    estimate_error = math.nan
    if "est_vel" in log:
        estimate_error = float(
            np.max(
                np.linalg.norm(
                    log["est_vel"][window, :2] - log["base_vel"][window, :2], axis=1
                )
            )
        )
    roll, pitch, _ = (
        math.degrees(a) for a in quaternion_to_rpy(log["base_quat"][window.stop - 1])
    )
    return {
        "fell": fell,
        "before_push": False,
        "fall_after": (fall_step - k0) * dt if fall_step is not None else math.nan,
        "dv": dv,
        "capture_step": dv * math.sqrt(stand_height / GRAVITY),
        "saturated": saturated,
        "missed": missed,
        "tripped": tripped,
        "estimate_error": estimate_error,
        "roll": roll,
        "pitch": pitch,
    }


def fmt(value: float, digits: int = 2) -> str:
    return "–" if not math.isfinite(value) else f"{value:.{digits}f}"


def falls_per_level(
    rows: list[dict[str, Any]], factor: str, levels: list[Any]
) -> list[str]:
    """'falls/runs' of `rows` at each level of `factor`."""
    cells = []
    for level in levels:
        at = [r for r in rows if r[factor] == level]
        cells.append(f"{sum(r['fell'] for r in at)}/{len(at)}")
    return cells


def tables(
    rows: list[dict[str, Any]],
    variants: list[Variant],
    magnitudes: list[float],
    directions: list[str],
) -> str:
    from pfnav_harness.sweep.stats import wilson_interval

    out: list[str] = []
    out.append("## Fall rate by impulse\n")
    out.append(
        "| variant | "
        + " | ".join(f"{m * PUSH_DURATION:g} N·s ({m:g} N)" for m in magnitudes)
        + " | all (95 % Wilson) |"
    )
    out.append("|---|" + "---:|" * (len(magnitudes) + 1))
    for v in variants:
        mine = [r for r in rows if r["variant"] == v.label]
        cells = falls_per_level(mine, "magnitude", magnitudes)
        k = sum(r["fell"] for r in mine)
        lo, hi = wilson_interval(k, len(mine))
        out.append(
            f"| {v.label} | "
            + " | ".join(cells)
            + f" | {k}/{len(mine)} ({100 * lo:.0f}–{100 * hi:.0f} %) |"
        )
    out.append("\n## Fall rate by direction\n")
    out.append("| variant | " + " | ".join(directions) + " |")
    out.append("|---|" + "---:|" * len(directions))
    for v in variants:
        cells = falls_per_level(
            [r for r in rows if r["variant"] == v.label], "direction", directions
        )
        out.append(f"| {v.label} | " + " | ".join(cells) + " |")
    out.append("\n## Every run, push to fall (or 2 s after the push)\n")
    out.append(
        "| variant | push | dir | walk t [s] | fell | fall after [s] | Δv [m/s] | capture step [m] | "
        "torque-saturated ticks | stance ticks without contact | swing ticks in contact | estimate velocity error [m/s] | roll / pitch at end [°] |"
    )
    out.append("|---|---:|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|")
    for r in sorted(
        rows,
        key=lambda r: (r["variant"], r["magnitude"], r["direction"], r["walk_time"]),
    ):
        head = f"| {r['variant']} | {r['magnitude']:g} N | {r['direction']} | {r['walk_time']:g} | "
        if r["before_push"]:
            out.append(head + "yes, before the push |" + " – |" * 7 + " – / – |")
            continue
        out.append(
            head + f"{'yes' if r['fell'] else 'no'} | "
            f"{fmt(r['fall_after'])} | {r['dv']:.2f} | {r['capture_step']:.2f} | {100 * r['saturated']:.0f} % | {100 * r['missed']:.0f} % | "
            f"{100 * r['tripped']:.0f} % | {fmt(r['estimate_error'])} | {r['roll']:+.0f} / {r['pitch']:+.0f} |"
        )
    return "\n".join(out) + "\n"


def plot(
    rows: list[dict[str, Any]],
    variants: list[Variant],
    magnitudes: list[float],
    scenario: str,
    path: Path,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5))
    for v in variants:
        mine = [r for r in rows if r["variant"] == v.label]
        rates = [
            np.mean([r["fell"] for r in mine if r["magnitude"] == m])
            for m in magnitudes
        ]
        left.plot([m * PUSH_DURATION for m in magnitudes], rates, "o-", label=v.label)
    left.set_xlabel("push impulse [N·s] (0.2 s pushes)")
    left.set_ylabel("fall rate")
    left.set_ylim(-0.05, 1.05)
    left.grid(alpha=0.3)
    left.legend(fontsize=8)
    left.set_title(f"falls by impulse, {scenario}")
    for v, marker in zip(variants, "os^vD", strict=False):
        mine = [r for r in rows if r["variant"] == v.label]
        for fell, colour in ((False, "tab:green"), (True, "tab:red")):
            at = [r for r in mine if r["fell"] == fell and not r["before_push"]]
            right.scatter(
                [r["dv"] for r in at],
                [100 * r["missed"] for r in at],
                c=colour,
                marker=marker,
                s=25,
                alpha=0.7,
            )
    right.set_xlabel("largest trunk velocity change after the push [m/s]")
    right.set_ylabel("stance foot ticks without contact [%]")
    right.set_title("red: fell, green: stood (marker: variant, as left)")
    right.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "push-diagnosis")
    parser.add_argument(
        "--magnitudes", default="60,90,120,150", help="push magnitudes, N (0.2 s each)"
    )
    parser.add_argument("--directions", default="left,right,front,back")
    parser.add_argument(
        "--walk-times", default="4,9", help="push start, s into the walk"
    )
    parser.add_argument("--estimators", default="kalman,groundTruth")
    parser.add_argument(
        "--raibert-gains",
        default="",
        help="extra kalman variants with this Raibert foothold gain, s (comma-separated)",
    )
    parser.add_argument(
        "--variant",
        action="append",
        default=[],
        metavar="NAME=VALUE[,NAME=VALUE…]",
        help="an extra kalman variant with these FMU parameters, e.g. gait.period=0.2 (repeatable)",
    )
    parser.add_argument(
        "--friction",
        type=float,
        default=None,
        help="ground and foot friction coefficient (default: the simulation's)",
    )
    parser.add_argument(
        "--scenario",
        default="mountain_pass",
        help="the scenario walked (pf-plan scenario list)",
    )
    parser.add_argument(
        "--follow",
        choices=("trajectory", "feedback"),
        default="trajectory",
        help="track the plan's time-indexed reference, or the P-F feedback field at the robot's position",
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--figure",
        type=Path,
        default=None,
        help="also copy the plot here (e.g. docs/img/push_diagnosis.png)",
    )
    parser.add_argument("--results-page", default=None, metavar="NAME")
    args = parser.parse_args()

    from pfnav_harness import paths, results_page
    from pfnav_harness.engine import DEFAULT_FRICTION
    from pfnav_harness.fmu_runner import read_contract
    from pfnav_harness.pipeline import export_scenario
    from pfnav_harness.planner_client import DEFAULT_LCM_URL, plan_answers
    from pfnav_harness.robot_fmu import robot_and_fmu
    from tqdm import tqdm

    stamp = results_page.collect_stamp() if args.results_page else None
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    magnitudes = [float(m) for m in args.magnitudes.split(",")]
    directions = args.directions.split(",")
    walk_times = [float(t) for t in args.walk_times.split(",")]
    variants = [Variant(e) for e in args.estimators.split(",") if e]
    variants += [
        Variant("kalman", ((RAIBERT_GAIN_PARAMETER, float(g)),))
        for g in args.raibert_gains.split(",")
        if g
    ]
    try:
        variants += [parse_variant(text) for text in args.variant]
    except ValueError as err:
        parser.error(str(err))
    robot, fmu = robot_and_fmu(None, out / "cache")
    known = read_contract(fmu).parameters
    unknown = sorted({name for v in variants for name, _ in v.parameters} - set(known))
    if unknown:
        parser.error(f"the FMU has no parameter {', '.join(unknown)}")
    scenario = export_scenario(paths.pf_plan_path(), args.scenario, out / "scenarios")
    answer = plan_answers(
        scenario, ["pf"], DEFAULT_LCM_URL, service_binary=paths.planner_service_path()
    )["pf"]
    plan = answer.plan_or_raise("pf")
    friction = DEFAULT_FRICTION if args.friction is None else args.friction
    if not friction > 0.0:
        parser.error(f"--friction must be > 0, got {friction:g}")
    shared = Shared(
        scenario,
        plan,
        fmu,
        robot,
        out / "cache",
        friction,
        args.follow,
        answer.field if args.follow == "feedback" else None,
    )
    tasks = [
        Task(v, m, d, t)
        for v, m, d, t in itertools.product(
            variants, magnitudes, directions, walk_times
        )
    ]
    with ProcessPoolExecutor(
        max_workers=args.workers, mp_context=multiprocessing.get_context("spawn")
    ) as pool:
        rows = list(
            tqdm(
                pool.map(run_one, [shared] * len(tasks), tasks),
                total=len(tasks),
                unit="run",
            )
        )
    text = (
        f"Scenario {args.scenario}, ground friction {friction:g}, following the {args.follow}.\n\n"
        + tables(rows, variants, magnitudes, directions)
    )
    figure = out / "push_diagnosis.png"
    plot(rows, variants, magnitudes, args.scenario, figure)
    if args.figure is not None:
        shutil.copyfile(figure, args.figure)
    (out / "summary.md").write_text(text)
    print(text)
    if args.results_page:
        command = results_page.regenerate_command(
            ".venv/bin/python scripts/push_diagnosis.py", sys.argv[1:]
        )
        title = f"Push diagnosis: what fails when a push knocks the robot over ({args.scenario})"
        print(
            f"results page: {results_page.write_results_page(args.results_page, title, text, command, stamp)}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
