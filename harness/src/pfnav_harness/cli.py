"""`pfnav-demo` / `python -m pfnav_harness`: plan over LCM, co-simulate, report."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from . import paths
from .engine import DEFAULT_ENGINE, ENGINE_LABELS, ENGINE_NAMES
from .errors import HarnessError
from .fmu_runner import DEFAULT_ESTIMATOR, ESTIMATOR_MODES
from .planner_client import DEFAULT_CHANNEL_PREFIX, DEFAULT_LCM_URL, METHODS, ROBOT_FOOTPRINT_RADIUS, PlanAnswer, PlannerClient, RequestOptions, StartPose
from .realtime_demo import add_realtime_command, run_realtime
from .replay.command import add_replay_command, run_replay
from .robot_fmu import robot_and_fmu
from .scenario import paper_scenario_names
from .sensing import PLANNER_DEFAULT

if TYPE_CHECKING:
    from .body_sensors import BodySensorConfig
    from .cosim import CoSimConfig
    from .online import OnlineConfig
    from .pushes import PushSchedule
    from .replay.run_media import MediaQueue
    from .report import RunRecord
    from .results_page import Stamp
    from .robot import RobotDescription
    from .scenario import Scenario


SHORT_DURATION = 8.0
# Online runs plan with this walkable-slope limit unless --max-slope-deg says otherwise: the robot
# stands and trots on ≤ 20° (issue 19's slope work targets 30°); a ridge flank of 45° and more
# is not walkable however cheap the cost model makes it.
ONLINE_MAX_SLOPE_DEG = 30.0
# Online runs take each cell's slope from a plane fitted over this radius (weighted by the sensed
# heights' inverse variances) unless --traversability slope_fit_radius_m=… says otherwise: central
# differences let one outlier height block its four neighbours, and a robot detoured around them.
ONLINE_SLOPE_FIT_RADIUS_M = 0.25


def in_private_network_namespace() -> bool:
    """True when loopback is the only network interface (scripts/netns.sh or `unshare --net`).

    Reads /proc/self/net/dev (per network namespace); /sys/class/net shows the host's interfaces
    unless sysfs is remounted inside the namespace.
    """
    try:
        lines = Path("/proc/self/net/dev").read_text().splitlines()[2:]
    except OSError:
        return False
    interfaces = [line.split(":", 1)[0].strip() for line in lines if ":" in line]
    return interfaces == ["lo"]


def check_lcm_url(url: str, allow_host_network: bool) -> None:
    """Refuses udpm:// outside a private network namespace (the project's network rule)."""
    if url.startswith("udpm://") and not allow_host_network and not in_private_network_namespace():
        raise HarnessError(
            "LCM udpm:// is only used inside a private network namespace: run through `bash scripts/netns.sh ...` "
            "(or pass --allow-host-network if you really mean the host network)"
        )


def _add_common(p: argparse.ArgumentParser) -> None:
    from .planner_client import BASES, GENERATORS

    p.add_argument("--out", type=Path, default=Path("out"), help="output folder (default: out)")
    p.add_argument(
        "--robot",
        type=Path,
        default=None,
        help="robot config: a TOML next to the robot's URDF (format in robot/README.md; package:// through $PFNAV_PACKAGE_PATH). "
        "Default $PFNAV_ROBOT, else robot/quadruped.toml. Another robot than ours runs on an FMU bundled for it "
        "(bundle-fmu, cached in OUT/cache)",
    )
    p.add_argument("--duration", type=float, default=None, help="cap on simulated seconds per run (default: whole plan + settle)")
    p.add_argument("--short", action="store_true", help=f"short run: at most {SHORT_DURATION:.0f} simulated seconds per run")
    p.add_argument("--comm-step", type=float, default=0.001, help="FMU communication step, s (multiple of 1 ms; default 0.001)")
    p.add_argument("--speed", type=float, default=0.0, help="planned walking speed, m/s (0 = the service's default)")
    p.add_argument("--lcm-url", default=os.environ.get("LCM_DEFAULT_URL", DEFAULT_LCM_URL), help=f"LCM URL (default {DEFAULT_LCM_URL})")
    p.add_argument("--channel-prefix", default=DEFAULT_CHANNEL_PREFIX, help=f"planner channel prefix (default {DEFAULT_CHANNEL_PREFIX})")
    p.add_argument("--connect", action="store_true", help="use an already running pf-planner-service instead of starting one")
    p.add_argument(
        "--footprint-radius",
        type=float,
        default=ROBOT_FOOTPRINT_RADIUS,
        help=f"footprint radius the started service plans with, m (default {ROBOT_FOOTPRINT_RADIUS}; 0 = the paper's point robot)",
    )
    p.add_argument(
        "--max-slope-deg",
        type=float,
        default=None,
        help=f"steepest walkable slope the started service plans with, degrees: steeper cells are obstacles "
        f"(default: none offline, as in the paper; {ONLINE_MAX_SLOPE_DEG:g} online, where unseen ground is priced at the prior "
        "and a ridge's cost alone would not keep the robot off it)",
    )
    p.add_argument(
        "--traversability",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="a field of the planner's traversability model for the started service and the ∫p ds metrics, e.g. "
        "slope_weight=1 or roughness_weight=0.5 (repeatable; field names as in `pf-plan scenario list --json`; "
        "--footprint-radius and --max-slope-deg set their own two)",
    )
    p.add_argument("--basis", choices=BASES, default=None, help="P-F basis: grid-cell indicators or Gaussian RBFs (default: the service's, indicator)")
    p.add_argument(
        "--generators",
        choices=GENERATORS,
        default=None,
        help="P-F RBF generators: the Markov partition-of-unity transfer or the paper's least-squares ANSDMD (default: the service's, transfer)",
    )
    p.add_argument("--plan-timeout", type=float, default=300.0, help="seconds to wait for each plan reply (default 300)")
    p.add_argument("--max-solve-time", type=float, default=240.0, help="solver time limit asked of the service, s (default 240)")
    p.add_argument("--service-timeout", type=float, default=15.0, help="seconds to wait for the started service's first status (default 15)")
    p.add_argument("--retries", type=int, default=2, help="plan request retries after a timeout (default 2)")
    p.add_argument("--lcm-log", action="store_true", help="also write OUT/logs/SCENARIO_METHOD.lcmlog (robot state, 100 Hz) for lcm-logplayer")
    p.add_argument(
        "--record",
        action="store_true",
        help="after each run, write its Rerun recording OUT/recordings/SCENARIO_LABEL.rrd from the log (open with `rerun FILE.rrd`)",
    )
    p.add_argument("--video", action="store_true", help="after each run, render its video OUT/videos/SCENARIO_LABEL.mp4 from the log (needs ffmpeg)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument(
        "--jobs",
        type=int,
        default=os.cpu_count() or 1,
        help="runs simulated at once, each in a process of its own (default: the number of CPUs); results do not depend on it",
    )
    p.add_argument(
        "--follow",
        choices=("trajectory", "feedback"),
        default=None,
        help="trajectory: track the plan's time-indexed reference (default offline); feedback: velocity and heading from the "
        "P-F feedback field at the robot's current position (default online)",
    )
    p.add_argument("--online", action="store_true", help="sense the terrain while walking, publish map updates and replan (P-F: feedback mode)")
    p.add_argument("--sensor-range", type=float, default=3.0, help="online, ideal sensor: range of the disc it reveals around the base, m (default 3)")
    p.add_argument(
        "--terrain-sensor",
        choices=("ideal", "depth_camera", "lidar"),
        default="depth_camera",
        help="online: a ray-cast depth camera or lidar with noise, fused into an elevation map at the estimated pose, "
        "or the ideal disc (true cells around the believed position; for comparison) (default depth_camera)",
    )
    p.add_argument("--terrain-sensor-seed", type=int, default=0, help="online: seed of the terrain sensor's noise, dropouts and outliers (default 0)")
    p.add_argument(
        "--no-belief-planning",
        action="store_true",
        help="online: plan as if the map and the position were exact (no start sigma, no height variances; for comparison)",
    )
    p.add_argument(
        "--unknown-traversability",
        type=float,
        default=PLANNER_DEFAULT,
        help="online: traversability p of unseen cells, in (0, 1] (default: the planner service's)",
    )
    p.add_argument("--update-period", type=float, default=0.5, help="online: simulated seconds between map updates (default 0.5 = 2 Hz)")
    p.add_argument("--replan-budget", type=float, default=0.2, help="online: simulated seconds from a map update to its plan in use (default 0.2)")
    p.add_argument(
        "--bad-map-updates",
        default="",
        help="online robustness check: comma-separated broken updates (nan, shape, stale) sent instead of regular ones",
    )
    p.add_argument("--push", action="append", default=[], help="force on the trunk: MAG@DIR:START+DURATION (N, degrees or 'side', walk-clock s); repeatable")
    p.add_argument("--random-pushes", type=int, default=0, help="this many seeded random pushes (see --push-seed, --push-magnitude)")
    p.add_argument("--push-seed", type=int, default=0, help="seed of --random-pushes (default 0)")
    p.add_argument("--push-magnitude", type=float, default=60.0, help="force of --random-pushes, N (default 60)")
    p.add_argument("--push-duration", type=float, default=0.2, help="duration of --random-pushes, s (default 0.2)")
    p.add_argument("--push-window", default="2,10", help="walk-clock window A,B of the random push start times, s (default 2,10)")
    p.add_argument(
        "--estimator",
        choices=ESTIMATOR_MODES,
        default=DEFAULT_ESTIMATOR,
        help="what the controller runs on: kalman (its own estimate from a simulated IMU, joint encoders and optional position "
        f"fixes, the way a real robot runs) or groundTruth (the simulated body's exact state); default {DEFAULT_ESTIMATOR}",
    )
    p.add_argument("--fix-rate", type=float, default=0.0, help="kalman: absolute position fixes per second (default 0 = none)")
    p.add_argument("--fix-noise", type=float, default=None, help="kalman: standard deviation of each fix coordinate, m (default 0.02)")
    p.add_argument("--sensor-seed", type=int, default=0, help="kalman: seed of the IMU, encoder and fix noise (default 0)")
    p.add_argument(
        "--contact-sensor",
        action="store_true",
        help="kalman: tell the estimator which feet touch the ground (the physics engine's contacts, an ideal sensor; "
        "default: it detects contact from the leg effort and its gait schedule)",
    )
    p.add_argument(
        "--engine",
        choices=ENGINE_NAMES,
        default=DEFAULT_ENGINE,
        help=f"physics engine the robot walks in: dart (triangle-mesh terrain, ODE collision) or mujoco (height field); default {DEFAULT_ENGINE}",
    )
    p.add_argument("--allow-host-network", action="store_true", help=argparse.SUPPRESS)


def _results_page_name(text: str) -> str:
    from .results_page import PAGE_NAME

    # Checked before the runs: a bad name must not cost a whole demo.
    if not PAGE_NAME.match(text):
        raise argparse.ArgumentTypeError(f"a results page name is lower-case letters, digits and '-', got {text!r}")
    return text


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pfnav-demo",
        description="Plans with pf-planner-service over LCM and walks the plans with the controller FMU on a simulated body (DART or MuJoCo).",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="one scenario or map, one method")
    source = run.add_mutually_exclusive_group(required=True)
    source.add_argument("--scenario", help="scenario name (`pf-plan scenario list` lists the paper's)")
    source.add_argument("--map", type=Path, help="map file: the JSON sidecar `pf-plan import` or `pf-plan scenario export` writes")
    run.add_argument("--start", help="with --map: start X,Y in map coordinates, m (default: the sidecar's)")
    run.add_argument("--goal", help="with --map: goal centre X,Y in map coordinates, m (default: the sidecar's; radius from the sidecar)")
    run.add_argument("--method", default="pf", choices=METHODS, help="planning method (default pf)")
    _add_common(run)
    demo = sub.add_parser("demo", help="all scenarios × {P-F, A*}; writes OUT/report.md with PNGs")
    demo.add_argument("--scenario", action="append", default=None, help="only this scenario (repeatable; default: every scenario of `pf-plan scenario list`)")
    demo.add_argument("--methods", default=None, help="comma-separated methods (default pf,astar; online: pf)")
    demo.add_argument(
        "--results-page",
        type=_results_page_name,
        default=None,
        metavar="NAME",
        help="also publish the report's tables as docs/results/NAME.md, stamped with commit, machine and date",
    )
    _add_common(demo)
    add_replay_command(sub)
    add_realtime_command(sub)
    return parser


def _config(args: argparse.Namespace) -> CoSimConfig:
    from .cosim import CoSimConfig

    duration = args.duration
    if args.short:
        duration = min(duration, SHORT_DURATION) if duration is not None else SHORT_DURATION
    if duration is not None and not duration > 0:
        raise HarnessError(f"--duration must be positive, got {duration}")
    if not (math.isfinite(args.footprint_radius) and args.footprint_radius >= 0.0):
        raise HarnessError(f"--footprint-radius must be finite and >= 0, got {args.footprint_radius}")
    if args.max_slope_deg is not None and not (0.0 < args.max_slope_deg < 90.0):
        raise HarnessError(f"--max-slope-deg must lie in (0, 90) degrees, got {args.max_slope_deg}")
    _traversability_overrides(args)
    follow = args.follow or ("feedback" if args.online else "trajectory")
    return CoSimConfig(
        comm_step=args.comm_step,
        max_duration=duration,
        follow=follow,
        pushes=_pushes(args),
        estimator=args.estimator,
        body_sensors=_body_sensors(args),
        engine=args.engine,
    )


def _body_sensors(args: argparse.Namespace) -> BodySensorConfig:
    from .body_sensors import BodySensorConfig
    from .errors import SimulationError

    if args.estimator != "kalman" and (args.fix_rate != 0.0 or args.fix_noise is not None or args.sensor_seed != 0 or args.contact_sensor):
        raise HarnessError("--fix-rate, --fix-noise, --sensor-seed and --contact-sensor feed the estimator, which --estimator groundTruth turns off")
    fix_noise = BodySensorConfig.fix_noise if args.fix_noise is None else args.fix_noise
    config = BodySensorConfig(seed=args.sensor_seed, fix_rate=args.fix_rate, fix_noise=fix_noise, contact_sensor=args.contact_sensor)
    try:
        config.validate()
    except SimulationError as err:
        raise HarnessError(str(err)) from err
    return config


def _pushes(args: argparse.Namespace) -> PushSchedule | None:
    from .pushes import PushSchedule, parse_push, random_pushes

    pushes = [parse_push(text) for text in args.push]
    if args.random_pushes < 0:
        raise HarnessError(f"--random-pushes must be >= 0, got {args.random_pushes}")
    if args.random_pushes:
        try:
            first, last = (float(v) for v in args.push_window.split(","))
        except ValueError as err:
            raise HarnessError(f"--push-window must be two numbers A,B, got {args.push_window!r}") from err
        pushes.extend(random_pushes(args.push_seed, args.random_pushes, args.push_magnitude, args.push_duration, (first, last)).pushes)
    return PushSchedule(pushes) if pushes else None


def _online_config(args: argparse.Namespace) -> OnlineConfig:
    from .errors import SimulationError
    from .online import OnlineConfig
    from .sensing import SensorConfig

    perception = None
    if args.terrain_sensor != "ideal":
        from .perception import PerceptionConfig
        from .terrain_sensor import TerrainSensorConfig

        seed = args.terrain_sensor_seed
        sensor = TerrainSensorConfig.lidar(seed=seed) if args.terrain_sensor == "lidar" else TerrainSensorConfig(seed=seed)
        perception = PerceptionConfig(sensor=sensor, unknown_traversability=args.unknown_traversability)
    config = OnlineConfig(
        sensor=SensorConfig(range_m=args.sensor_range, unknown_traversability=args.unknown_traversability),
        perception=perception,
        update_period=args.update_period,
        apply_delay=args.replan_budget,
        options=_request_options(args),
        bad_updates=tuple(k.strip() for k in args.bad_map_updates.split(",") if k.strip()),
        belief_planning=not args.no_belief_planning,
    )
    try:
        config.validate()
    except SimulationError as err:
        raise HarnessError(str(err)) from err
    return config


def _request_options(args: argparse.Namespace) -> RequestOptions:
    from .planner_client import option_code

    return RequestOptions(
        speed=args.speed,
        max_solve_time=args.max_solve_time,
        basis=0 if args.basis is None else option_code("BASIS", args.basis),
        generators=0 if args.generators is None else option_code("GENERATORS", args.generators),
    )


def _client(args: argparse.Namespace, out: Path, prefix: str | None = None, log_name: str = "pf-planner-service.log") -> PlannerClient:
    binary = None if args.connect else paths.planner_service_path()
    client = PlannerClient(
        args.lcm_url,
        args.channel_prefix if prefix is None else prefix,
        binary,
        service_log=out / "logs" / log_name,
        startup_timeout=args.service_timeout,
        footprint_radius=args.footprint_radius,
        max_slope_deg=_max_slope_deg(args),
        traversability=_service_traversability(args),
    )
    if args.connect:
        client.wait_for_service(timeout=args.service_timeout)
    return client


def _traversability_overrides(args: argparse.Namespace) -> dict[str, float]:
    """The --traversability FIELD=VALUE pairs (names are checked against the planner's model where
    the scenarios are known, values must be finite numbers)."""
    overrides: dict[str, float] = {}
    for item in args.traversability:
        name, sep, text = item.partition("=")
        name = name.strip()
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not sep or not name or not math.isfinite(value):
            raise HarnessError(f"--traversability takes FIELD=VALUE with a finite number, got {item!r}")
        if name in ("footprint_radius_m", "max_slope_deg"):
            raise HarnessError(f"--traversability {name}: use --{name.removesuffix('_m').replace('_', '-')} for it")
        overrides[name] = value
    return overrides


def _service_traversability(args: argparse.Namespace) -> dict[str, float]:
    """The overrides a started service plans with: --traversability, and online the slope fit."""
    overrides = _traversability_overrides(args)
    if args.online:
        overrides.setdefault("slope_fit_radius_m", ONLINE_SLOPE_FIT_RADIUS_M)
    return overrides


def _max_slope_deg(args: argparse.Namespace) -> float | None:
    if args.max_slope_deg is not None:
        return float(args.max_slope_deg)
    return ONLINE_MAX_SLOPE_DEG if args.online else None


def _plan_all(args: argparse.Namespace, scenarios: dict[str, Scenario], methods: Sequence[str], out: Path) -> dict[str, dict[str, PlanAnswer]]:
    answers: dict[str, dict[str, PlanAnswer]] = {}
    with _client(args, out) as client:
        for name, scenario in scenarios.items():
            seq = client.publish_map(scenario.terrain)
            answers[name] = {}
            for method in methods:
                print(f"planning {name} with {method} ...", file=sys.stderr, flush=True)
                answers[name][method] = client.request_answer(
                    StartPose(scenario.start[0], scenario.start[1], scenario.start_yaw),
                    scenario.goal,
                    method,
                    seq,
                    _request_options(args),
                    timeout=args.plan_timeout,
                    retries=args.retries,
                    context=f"'{name}'",
                )
    return answers


def _summary_line(rec: RunRecord) -> str:
    m = rec.metrics
    if str(rec.log.get("follow", "trajectory")) == "feedback":
        # The reference is the robot's own position: the distance from the plan's path says more.
        tracking = f"path dev={m.max_path_deviation:.2f} m"
    else:
        tracking = f"rms={m.rms_error:.3f} m max={m.max_error:.3f} m"
    return (
        f"{m.scenario:14s} {m.method:6s} goal={'yes' if m.goal_reached else 'no ':3s} fell={'yes' if m.fell else 'no ':3s} "
        f"{tracking} final={m.final_distance_to_goal:.2f} m "
        f"t_goal={'–' if m.time_to_goal is None else f'{m.time_to_goal:.1f} s'} "
        f"wall/sim={rec.timing_per_sim_second['total']:.3f}" + _estimation_summary(rec)
    )


def _estimation_summary(rec: RunRecord) -> str:
    e = rec.estimation
    if e is None:
        return ""
    return (
        f" | estimate: vel rms={e.velocity_rms:.3f} m/s drift={e.drift_percent:.2f} % of {e.path_length:.1f} m "
        f"pos rms={e.position_rms:.3f} m yaw final={e.yaw_error_final:+.3f} rad tracking rms={e.tracking_rms:.3f} m status={e.status_bits:#x}"
    )


def _map_request(args: argparse.Namespace) -> tuple[Path | None, tuple[float, float] | None, tuple[float, float] | None]:
    """`run --map FILE [--start X,Y] [--goal X,Y]`, parsed before any work starts."""
    from .map_input import parse_point

    if args.map is None:
        if args.start is not None or args.goal is not None:
            raise HarnessError("--start and --goal place the robot on a --map file; a --scenario has its own")
        return None, None, None
    start = None if args.start is None else parse_point(args.start, "--start")
    goal = None if args.goal is None else parse_point(args.goal, "--goal")
    return Path(args.map), start, goal


@dataclass(frozen=True)
class RunJob:
    """One run of the demo: a scenario walked with one method's plan (offline: the plan is made)."""

    name: str
    scenario: Scenario
    method: str
    answer: PlanAnswer | None
    # Position in the report (scenario-major, as the runs are listed).
    index: int


@dataclass(frozen=True)
class RunContext:
    """What every run of one demo shares (picklable: runs execute in worker processes)."""

    args: argparse.Namespace
    out: Path
    fmu: Path
    robot: RobotDescription
    config: CoSimConfig
    online_config: OnlineConfig | None
    show_progress: bool


def _run_one(context: RunContext, job: RunJob) -> RunRecord:
    from .metrics import TraversabilityField
    from .pipeline import run_label, simulate, simulate_online

    args, out, config, online_config = context.args, context.out, context.config, context.online_config
    field = TraversabilityField(job.scenario.terrain, job.scenario.traversability)
    label = run_label(job.method, config, online_config is not None)
    log_file = out / "logs" / f"{job.name}_{label}.npz"
    if online_config is not None:
        # A service of its own per run, on channels of its own, so that runs side by side never
        # answer each other's requests (an already running service has one prefix: runs take turns).
        prefix = None if args.connect else f"{args.channel_prefix}R{job.index}_"
        log_name = "pf-planner-service.log" if args.connect else f"pf-planner-service_{job.name}_{label}.log"
        with _client(args, out, prefix, log_name) as client:
            outcome = simulate_online(
                client,
                job.scenario,
                context.fmu,
                context.robot,
                out / "cache",
                config,
                dataclasses.replace(online_config, method=job.method),
                args.plan_timeout,
                args.retries,
                log_file,
                context.show_progress,
                field,
            )
    else:
        assert job.answer is not None
        outcome = simulate(
            job.scenario,
            job.answer.plan_or_raise(job.method),
            context.fmu,
            context.robot,
            out / "cache",
            config,
            log_file,
            context.show_progress,
            field,
            feedback_field=job.answer.field,
        )
    return outcome.record(str(log_file.relative_to(out)))


def _run_all(context: RunContext, jobs: Sequence[RunJob], parallel: int, media: MediaQueue | None = None) -> dict[int, RunRecord]:
    """Every job's record by its index; `parallel` runs at once in worker processes (1: here); `media` gets each finished run's log."""
    records: dict[int, RunRecord] = {}

    def finished(job: RunJob, rec: RunRecord) -> None:
        records[job.index] = rec
        print(_summary_line(rec), file=sys.stderr, flush=True)
        if media is not None and rec.log_file is not None:
            media.submit(context.out / rec.log_file, job.scenario, job.answer.field if job.answer is not None else None)

    if parallel <= 1:
        for job in jobs:
            finished(job, _run_one(context, job))
        return records
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from tqdm import tqdm

    # spawn: a worker starts clean, without the parent's LCM or DART state.
    with ProcessPoolExecutor(max_workers=parallel, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(_run_one, context, job): job for job in jobs}
        with tqdm(total=len(jobs), unit="run", desc=f"runs ({parallel} at once)", disable=context.args.no_progress) as bar:
            for future in as_completed(futures):
                finished(futures[future], future.result())
                bar.update()
    return records


def execute(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    if args.jobs < 1:
        raise HarnessError(f"--jobs must be >= 1, got {args.jobs}")
    results_page = getattr(args, "results_page", None)
    # The stamp names the commit and the load the measurement started with.
    stamp = _start_stamp() if results_page else None
    out: Path = args.out
    # The robot and its FMU first: a bad robot config fails before any other work.
    robot, fmu = robot_and_fmu(args.robot, out / "cache")
    map_file: Path | None = None
    map_start = map_goal = None
    if args.command == "run":
        names = [] if args.scenario is None else [args.scenario]
        methods = [args.method]
        map_file, map_start, map_goal = _map_request(args)
    else:
        methods = [m.strip() for m in (args.methods or ("pf" if args.online else "pf,astar")).split(",") if m.strip()]
        unknown = [m for m in methods if m not in METHODS]
        if unknown or not methods:
            raise HarnessError(f"unknown method(s) {', '.join(unknown) or '(none)'}; choose from {', '.join(METHODS)}")
        names = args.scenario or list(paper_scenario_names())
    if args.duration is not None and not args.duration > 0:
        raise HarnessError(f"--duration must be positive, got {args.duration}")
    # Fail on missing build products before any planning work.
    pf_plan = paths.pf_plan_path()

    from .pipeline import export_scenario
    from .report import write_report

    config = _config(args)
    if config.follow == "feedback" and any(m != "pf" for m in methods):
        raise HarnessError("feedback mode follows the P-F feedback field: use --method pf (graph planners give only a path)")
    online_config = _online_config(args) if args.online else None
    scenarios = {name: export_scenario(pf_plan, name, out / "scenarios") for name in names}
    if map_file is not None:
        from .map_input import load_map_scenario

        map_scenario = load_map_scenario(map_file, map_start, map_goal)
        scenarios[map_scenario.name] = map_scenario
    if not args.connect:
        # ∫p ds on the field the started service plans with (a running service's is unknown).
        overrides = _traversability_overrides(args)
        service_overrides = _service_traversability(args)
        for scenario in scenarios.values():
            # A map that declares its model names the fields; the service refuses unknown ones too.
            unknown = sorted(set(overrides) - set(scenario.traversability))
            if scenario.traversability and unknown:
                known = ", ".join(sorted(scenario.traversability))
                raise HarnessError(f"--traversability: no field {', '.join(unknown)} in the planner's model ({known})")
            scenario.traversability.update(service_overrides)
            scenario.traversability["footprint_radius_m"] = args.footprint_radius
            max_slope = _max_slope_deg(args)
            if max_slope is not None:
                scenario.traversability["max_slope_deg"] = max_slope
    if config.estimator == "kalman":
        from .fmu_runner import read_contract

        # Before any planning (the scenarios are checked first): an FMU without the estimator cannot run this.
        read_contract(fmu).require_estimation()
    check_lcm_url(args.lcm_url, args.allow_host_network)
    answers = {} if online_config is not None else _plan_all(args, scenarios, methods, out)
    plan_time = time.perf_counter() - started

    jobs = [
        RunJob(name, scenario, method, None if online_config is not None else answers[name][method], i * len(methods) + k)
        for i, (name, scenario) in enumerate(scenarios.items())
        for k, method in enumerate(methods)
    ]
    # An already running service (--connect) listens on one channel prefix: its online runs share it, one at a time.
    parallel = min(args.jobs, len(jobs)) if not (args.connect and online_config is not None) else 1
    context = RunContext(args, out, fmu, robot, config, online_config, show_progress=not args.no_progress and parallel == 1)
    media = None
    if args.record or args.video:
        from .replay.density import DensityOptions
        from .replay.run_media import MediaQueue

        # After each run, from its log, beside the other runs: the co-simulation loop pays nothing for it.
        media = MediaQueue(out, robot, args.record, args.video, workers=parallel, density_options=DensityOptions(args.basis, args.generators))
    records = _run_all(context, jobs, parallel, media)
    runs: dict[str, list[RunRecord]] = {name: [] for name in scenarios}
    for job in jobs:
        rec = records[job.index]
        runs[job.name].append(rec)
    total = time.perf_counter() - started
    sim_seconds = sum(r.metrics.duration for rs in runs.values() for r in rs)
    sim_wall = sum(r.wall_seconds for rs in runs.values() for r in rs)
    header = [
        f"Command: `pfnav-demo {' '.join(sys.argv[1:]) if sys.argv[1:] else args.command}`; FMU `{fmu.name}`, "
        f"communication step {config.comm_step * 1000:.0f} ms, physics 1 kHz ({ENGINE_LABELS[config.engine]}).",
        "",
        f"Robot: config `{robot.config_path}`, URDF `{robot.urdf_path}`.",
        "",
        (
            f"State estimate in the loop (kalman): {config.body_sensors.imu.name} IMU, {config.body_sensors.encoder.name} "
            f"{config.body_sensors.encoder.bits}-bit joint encoders, position fixes "
            + (f"at {config.body_sensors.fix_rate:g} Hz, σ {config.body_sensors.fix_noise:g} m" if config.body_sensors.fix_rate > 0 else "off")
            + f", foot contact {'from the physics engine (ideal sensor)' if config.body_sensors.contact_sensor else 'from the gait schedule'}"
            + f", sensor seed {config.body_sensors.seed}."
            if config.estimator == "kalman"
            else "The controller runs on the simulated body's exact state (estimator groundTruth)."
        ),
        "",
        (
            "Plans from a running service (`--connect`); ∫p ds on the scenarios' own traversability model."
            if args.connect
            else f"Robot footprint radius {args.footprint_radius:.2f} m: the service plans on p maximised over that radius "
            "(0 = the paper's point robot), and every ∫p ds below uses the same field."
        ),
        "",
        f"Total wall time {total:.1f} s (planning incl. service start {plan_time:.1f} s); "
        f"{sim_seconds:.1f} simulated seconds in {sim_wall:.1f} s wall = {sim_wall / max(sim_seconds, 1e-9):.3f} wall s per simulated s.",
    ]
    report = write_report(out, scenarios, runs, header_lines=header)
    if media is not None:
        media.wait(show_progress=not args.no_progress)
    from .replay.html_report import run_names, write_html_report

    print(f"HTML report: {write_html_report(out, report, run_names(runs))}", file=sys.stderr)
    metrics_json = out / "metrics.json"
    metrics_json.write_text(
        json.dumps(
            {
                "runs": [
                    {
                        **r.metrics.as_dict(),
                        "wall_seconds": r.wall_seconds,
                        "timing_per_sim_second": r.timing_per_sim_second,
                        "stop_reason": r.stop_reason,
                        **({"online": r.online.as_dict()} if r.online is not None else {}),
                        **({"estimation": r.estimation.as_dict()} if r.estimation is not None else {}),
                    }
                    for rs in runs.values()
                    for r in rs
                ],
                "total_wall_seconds": total,
                "engine": config.engine,
            },
            indent=2,
        )
    )
    print(f"report: {report}", file=sys.stderr)
    if results_page:
        argv = getattr(args, "argv", None) or sys.argv[1:]
        print(f"results page: {_publish(results_page, report, argv, online_config is not None, stamp)}", file=sys.stderr)
    return 0


def _start_stamp() -> Stamp:
    from .results_page import collect_stamp

    return collect_stamp()


def _publish(name: str, report: Path, argv: Sequence[str], online: bool, stamp: Stamp | None) -> Path:
    """docs/results/NAME.md: the report's tables and notes; its pictures stay in the output folder."""
    from .results_page import regenerate_command, without_pictures, write_results_page

    title = "Online navigation: sensing, replanning, feedback field" if online else "Co-simulation: the scenarios walked end to end"
    command = regenerate_command(".venv/bin/pfnav-demo", argv)
    return write_results_page(name, title, without_pictures(report.read_text(encoding="utf-8")), command, stamp)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    # The words the results page names as the command that regenerates it.
    args.argv = list(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(format="pfnav-demo: %(message)s")
    logging.getLogger("pfnav_harness").setLevel(logging.INFO)
    try:
        if args.command == "replay":
            return run_replay(args)
        if args.command == "realtime":
            return run_realtime(args)
        return execute(args)
    except HarnessError as err:
        print(f"pfnav-demo: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print("pfnav-demo: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
