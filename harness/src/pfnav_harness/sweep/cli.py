"""`pfnav-sweep`: Monte-Carlo robustness sweeps of the co-simulation on Dask (docs/sweeps.md).

    pfnav-sweep check SPEC.toml                 validate a spec, show its runs
    pfnav-sweep plan SPEC.toml --out DIR        export and plan each terrain seed (LCM planner service)
    pfnav-sweep run SPEC.toml --out DIR         plan what is missing, run every run not yet stored, report
    pfnav-sweep report DIR                      write DIR/REPORT.md and plots from the stored rows
    pfnav-sweep compare DIR... --out DIR        fall rates of several stores by push impulse (robots of other mass)

`run` and `report` take --results-page NAME to publish the report as docs/results/NAME.md.

Planning talks LCM udpm://, so `plan` and a first `run` go through `bash scripts/netns.sh ...`.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .. import paths
from ..engine import ENGINE_NAMES
from ..errors import HarnessError
from ..fmu_runner import ESTIMATOR_MODES
from ..planner_client import DEFAULT_LCM_URL, Plan, plan_scenario
from ..scenario import Scenario
from .spec import FACTORS, SweepSpec, load_spec
from .store import SweepStore

if TYPE_CHECKING:
    from ..results_page import Stamp
    from .driver import Planner
    from .runner import Course


def _lcm_planner(lcm_url: str, allow_host_network: bool) -> Planner:
    from ..cli import check_lcm_url

    def plan(scenario: Scenario, method: str) -> Plan:
        check_lcm_url(lcm_url, allow_host_network)
        return plan_scenario(scenario, [method], lcm_url, service_binary=paths.planner_service_path())[method]

    return plan


def _courses(spec: SweepSpec, store: SweepStore, args: argparse.Namespace, work: Path) -> dict[int, Course]:
    from .driver import prepare_courses

    return prepare_courses(spec, store, paths.pf_plan_path(), _lcm_planner(args.lcm_url, args.allow_host_network), work)


def _robot_override(text: str | None) -> str | None:
    """`--robot PATH` as a spec writes it: relative to the repository root when inside it."""
    if text is None:
        return None
    path = Path(text).absolute()
    try:
        return str(path.relative_to(paths.repo_root()))
    except ValueError:
        return str(path)


def _robot_config(spec: SweepSpec) -> Path | None:
    """The spec's robot config file (None: `$PFNAV_ROBOT`, else ours)."""
    if spec.robot is None:
        return None
    path = Path(spec.robot)
    return path if path.is_absolute() else paths.repo_root() / path


def _load(args: argparse.Namespace) -> SweepSpec:
    return load_spec(args.spec, args.estimator, args.engine, _robot_override(args.robot), args.runs)


def cmd_check(args: argparse.Namespace) -> int:
    spec = load_spec(args.spec)
    seeds = spec.terrain_seeds()
    print(f"{args.spec}: {spec.runs} runs of '{spec.scenario}' ({spec.sampling} sampling, seed {spec.seed}), {spec.duration:g} simulated s each")
    forks = "on (runs continue their group's post-stand-up state)" if spec.fork else "off"
    print(f"spec hash {spec.hash}; engine {spec.engine}; forks {forks}")
    scaling = "scaled by the robot's mass over ours" if spec.push_scaling == "mass" else "as given"
    print(f"robot {spec.robot or 'of $PFNAV_ROBOT, else ours'}; push magnitudes {scaling}")
    print(f"terrain seeds: {', '.join('scenario default' if s is None else str(s) for s in seeds)}")
    varied = [name for name in FACTORS if name in spec.factors]
    print(f"factors: {', '.join(varied) or 'none (every run the same)'}")
    for run_id in range(min(args.show, spec.runs)):
        row = spec.run_factors(run_id)
        print(f"  run {run_id}: " + ", ".join(f"{name}={row[name]:.4g}" if isinstance(row[name], float) else f"{name}={row[name]}" for name in varied))
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    spec = _load(args)
    store = SweepStore.create(args.out, spec)
    with tempfile.TemporaryDirectory(prefix="pfnav_sweep_plan_") as tmp:
        courses = _courses(spec, store, args, Path(tmp))
    print(f"{len(courses)} terrain(s) planned into {store.plans_dir}")
    return 0


def _publish(name: str, report: Path, argv: Sequence[str], stamp: Stamp | None, note: str = "") -> Path:
    """docs/results/NAME.md: the sweep report's tables; its plots stay in the store folder."""
    from ..results_page import regenerate_command, without_pictures, write_results_page

    body = (note + "\n\n" if note else "") + without_pictures(report.read_text(encoding="utf-8"))
    title = report.read_text(encoding="utf-8").splitlines()[0].removeprefix("# ")
    return write_results_page(name, title, body, regenerate_command(".venv/bin/pfnav-sweep", argv), stamp)


def cmd_run(args: argparse.Namespace) -> int:
    from ..results_page import collect_stamp
    from .cluster import dask_client
    from .driver import SweepSummary, run_sweep
    from .report import write_report
    from .runner import Artifacts

    # Taken before the runs: the commit that ran and the load it ran under.
    stamp = collect_stamp() if args.results_page else None
    spec = _load(args)
    if args.no_fork:
        spec = dataclasses.replace(spec, fork=False)
    store = SweepStore.create(args.out, spec)
    from ..robot_fmu import robot_and_fmu

    # The spec's robot (else $PFNAV_ROBOT, else ours), on the FMU for it.
    robot, fmu = robot_and_fmu(_robot_config(spec), args.out / "cache")
    artifacts = Artifacts(fmu, robot, paths.pf_plan_path())
    # The exported scenarios live on while the workers run (a shared folder for remote workers).
    work = store.scenarios_dir
    courses = _courses(spec, store, args, work)
    if len(store.done_ids()) < spec.runs:
        with dask_client(args.workers, args.scheduler) as client:
            summary = run_sweep(spec, store, courses, artifacts, client, show_progress=not args.no_progress)
    else:
        summary = SweepSummary(spec.runs, spec.runs, 0, 0, 0.0)
    print(
        f"{summary.ran} run(s) done ({summary.errors} error(s)), {summary.skipped} already stored; "
        f"{summary.wall_seconds:.0f} s wall, {summary.runs_per_minute:.1f} runs/min"
    )
    if not args.no_report or args.results_page:
        report = write_report(store)
        print(f"report: {report}")
        if args.results_page:
            print(f"results page: {_publish(args.results_page, report, args.argv, stamp)}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from .report import write_report

    store = SweepStore.open_existing(args.store)
    report = write_report(store)
    print(f"report: {report}")
    if args.results_page:
        # The rows may be older than this commit: `run` stamps the measurement itself.
        note = "The stamp is when this report was written from the stored rows; `pfnav-sweep run` measured them, possibly on another commit."
        print(f"results page: {_publish(args.results_page, report, args.argv, None, note)}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from .report import write_comparison

    stores = [SweepStore.open_existing(folder) for folder in args.stores]
    report = write_comparison(stores, args.out)
    print(f"comparison: {report}")
    if args.results_page:
        note = "The stamp is when this comparison was written from the stored rows; `pfnav-sweep run` measured them, possibly on another commit."
        print(f"results page: {_publish(args.results_page, report, args.argv, None, note)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pfnav-sweep", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="validate a spec and show its first runs")
    check.add_argument("spec", type=Path)
    check.add_argument("--show", type=int, default=5, help="runs to show (default 5)")
    for name, text in (("plan", "export and plan each terrain seed of a spec"), ("run", "run a sweep (resumes a stopped one)")):
        p = sub.add_parser(name, help=text)
        p.add_argument("spec", type=Path)
        p.add_argument("--out", type=Path, required=True, help="store folder: rows (Parquet), plans, report")
        p.add_argument("--lcm-url", default=os.environ.get("LCM_DEFAULT_URL", DEFAULT_LCM_URL), help=f"LCM URL of the planner (default {DEFAULT_LCM_URL})")
        p.add_argument("--allow-host-network", action="store_true", help=argparse.SUPPRESS)
        p.add_argument(
            "--estimator", choices=ESTIMATOR_MODES, default=None, help="run on this estimator instead of the spec's `estimator` (a store of its own)"
        )
        p.add_argument("--engine", choices=ENGINE_NAMES, default=None, help="walk in this physics engine instead of the spec's `engine` (a store of its own)")
        p.add_argument("--robot", default=None, metavar="CONFIG", help="walk this robot config instead of the spec's `robot` (a store of its own)")
        p.add_argument("--runs", type=int, default=None, metavar="N", help="the spec's first N runs (random sampling: the same draws; a store of its own)")
        if name == "run":
            p.add_argument("--workers", type=int, default=None, help="local Dask worker processes (default: one per core)")
            p.add_argument(
                "--scheduler", default=None, metavar="ADDRESS", help="use the Dask scheduler at ADDRESS (e.g. tcp://host:8786) instead of a local cluster"
            )
            p.add_argument("--no-progress", action="store_true", help="no progress bar")
            p.add_argument("--no-fork", action="store_true", help="every run stands up by itself (as `fork = false` in the spec)")
            p.add_argument("--no-report", action="store_true", help="do not write the report at the end")
            _add_results_page(p)
    report = sub.add_parser("report", help="write the report of a store folder")
    report.add_argument("store", type=Path)
    _add_results_page(report)
    compare = sub.add_parser("compare", help="compare the fall rates of several stores by push impulse")
    compare.add_argument("stores", type=Path, nargs="+")
    compare.add_argument("--out", type=Path, required=True, help="folder for COMPARE.md and its plot")
    _add_results_page(compare)
    return parser


def _results_page_name(text: str) -> str:
    from ..results_page import PAGE_NAME

    if not PAGE_NAME.match(text):
        raise argparse.ArgumentTypeError(f"a results page name is lower-case letters, digits and '-', got {text!r}")
    return text


def _add_results_page(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--results-page",
        type=_results_page_name,
        default=None,
        metavar="NAME",
        help="also publish the report as docs/results/NAME.md, stamped with commit, machine and date",
    )


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # The words the results page names as the command that regenerates it.
    args.argv = list(sys.argv[1:] if argv is None else argv)
    if getattr(args, "workers", None) is not None and args.workers < 1:
        print(f"pfnav-sweep: error: --workers must be >= 1, got {args.workers}", file=sys.stderr)
        return 2
    if args.command == "run" and args.workers is not None and args.scheduler is not None:
        print("pfnav-sweep: error: --workers starts a local cluster; with --scheduler the cluster's own workers run the sweep", file=sys.stderr)
        return 2
    commands = {"check": cmd_check, "plan": cmd_plan, "run": cmd_run, "report": cmd_report, "compare": cmd_compare}
    try:
        return commands[args.command](args)
    except HarnessError as err:
        print(f"pfnav-sweep: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print("pfnav-sweep: interrupted; finished runs are stored, run again to continue", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
