"""`pfnav-demo realtime`: the whole stack as four processes on the bus, walking a scenario in wall-clock time.

Per scenario, in the private network namespace: the planner service (pf-planner-service), the
robot node (pfnav-robot with the controller FMU, SCHED_FIFO where permitted), the body
(pfnav-sim, DART, real time, publishing its true state at 50 Hz for the evaluation) and the
navigator (pfnav_harness.realtime_nav: the feedback field followed on the robot's estimate), with
lcm-logger recording every channel. This process only watches: the true state decides goal
(the true trunk enters the goal disc, as the co-simulation judges it) and fall (the co-simulation's `FallThresholds`:
trunk height above the terrain, roll, pitch, or the node damped after the walk began), and the
run ends at either or after `--max-walk` seconds. With `--cosim` the same scenario is also
co-simulated (fmpy, simulated time, feedback mode, kalman estimator) for comparison: its path
deviation from the plan against the real-time one.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import HarnessError
from .fmu_runner import read_contract
from .lcm_channels import ROBOT, SIM_ROBOT_STATE_NAME
from .metrics import FallThresholds, distance_to_polyline, roll_pitch_yaw
from .process_signals import stop_processes

# The run ends once the robot has stood this long inside the goal disc, or this long after it
# first entered it (it may stop just outside by its own estimate).
SETTLE_AT_GOAL = 3.0
AFTER_GOAL = 10.0


@dataclass
class RealtimeOutcome:
    scenario: str
    reached: bool
    fell: bool
    fall_reason: str
    walk_seconds: float
    time_to_goal: float
    final_distance: float
    path_rms: float
    estimate_error: float
    robot_report: dict[str, Any]
    sim_report: dict[str, Any]
    cosim_path_rms: float | None = None
    cosim_reached: bool | None = None
    cosim_fell: bool | None = None


# pfnav-robot's --trigger values; the first is its default.
ROBOT_TRIGGERS = ("deadline", "state", "clock")


def run_scenario(
    name: str,
    out: Path,
    lcm_url: str,
    max_walk: float,
    cosim: bool,
    stand_time: float = 3.0,
    trigger: str = ROBOT_TRIGGERS[0],
    sim_priority: int = 70,
    command_wait: float = 0.5,
) -> RealtimeOutcome:
    from . import paths
    from .pipeline import export_scenario
    from .planner_client import PlannerClient, RequestOptions, StartPose, _import_lcm, _import_types

    scenario = export_scenario(paths.pf_plan_path(), name, out / "scenarios")
    types = _import_types()
    prefix = "PFNAV_RT_"
    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "LCM_DEFAULT_URL": lcm_url}
    processes: list[subprocess.Popen[bytes]] = []
    truth: list[tuple[float, Any]] = []
    estimates: list[Any] = []
    statuses: list[Any] = []
    bus = _import_lcm().LCM(lcm_url)
    bus.subscribe(prefix + SIM_ROBOT_STATE_NAME, lambda _c, d: truth.append((time.monotonic(), types.robot_state_t.decode(d))))
    bus.subscribe(prefix + ROBOT.robot_estimate, lambda _c, d: estimates.append(types.robot_estimate_t.decode(d)))
    bus.subscribe(prefix + ROBOT.robot_status, lambda _c, d: statuses.append(types.robot_status_t.decode(d)))
    robot_json, sim_json = logs / f"{name}_robot.json", logs / f"{name}_sim.json"

    def spawn(label: str, args: list[str]) -> subprocess.Popen[bytes]:
        process = subprocess.Popen(args, env=env, stdout=(logs / f"{name}_{label}.log").open("w"), stderr=subprocess.STDOUT)
        processes.append(process)
        return process

    client = PlannerClient(lcm_url, prefix, paths.planner_service_path(), service_log=logs / f"{name}_planner.log", startup_timeout=60.0)
    try:
        # The plan the navigator will get (the service answers the same request the same way):
        # this process keeps its path to measure the walked path's deviation from it.
        seq = client.publish_map(scenario.terrain)
        answer = client.request_answer(
            StartPose(scenario.start[0], scenario.start[1], scenario.start_yaw), scenario.goal, "pf", seq, RequestOptions(), timeout=180.0, retries=2
        )
        plan = answer.plan_or_raise("pf")
        # The patched liblcm's logger (scripts/build_liblcm.sh), like every receiver here.
        spawn(
            "logger",
            [str(paths.repo_root() / "build" / "lcm" / "bin" / "lcm-logger"), "--quiet", "--force", f"--lcm-url={lcm_url}", str(logs / f"{name}.lcmlog")],
        )
        sim = spawn(
            "sim",
            [
                sys.executable,
                "-m",
                "pfnav_harness.body_sim",
                "--scenario",
                name,
                "--channel-prefix",
                prefix,
                "--truth-rate",
                "50",
                "--priority",
                str(sim_priority),
                "--command-wait",
                str(command_wait),
                "--out",
                str(out),
                "--report-json",
                str(sim_json),
            ],
        )
        # The body settles on the ground before the node starts (motors idle: it sinks from its
        # crouch), as a robot lies before its controller is switched on.
        deadline = time.monotonic() + 120.0
        while not (len(truth) > 25 and max(abs(v) for v in truth[-1][1].linear_velocity) < 0.01):
            if sim.poll() is not None or time.monotonic() > deadline:
                raise HarnessError(f"pfnav-sim did not start or settle (log: {logs / f'{name}_sim.log'})")
            bus.handle_timeout(100)
        # The estimator starts from the body's pose in the world (the co-simulation gives it the
        # true first pose too): the controller, the navigator and the map share the world frame.
        initial = [f"{v:.6f}" for v in truth[-1][1].position]
        robot_args = [str(paths.pfnav_robot_path()), "--fmu", str(paths.fmu_path()), "--channel-prefix", prefix, "--report-json", str(robot_json)]
        robot = spawn("robot", [*robot_args, "--trigger", trigger, "--nav-timeout-ms", "1000", "--initial-position", *initial])
        navigator_args = [sys.executable, "-m", "pfnav_harness.realtime_nav", "--scenario", name, "--channel-prefix", prefix, "--planner-prefix", prefix]
        navigator = spawn("navigator", [*navigator_args, "--out", str(out), "--lcm-url", lcm_url, "--origin", "0", "0", "0", "--stand-time", str(stand_time)])
        terrain, goal, fall = scenario.terrain, scenario.goal, FallThresholds()
        # The walk begins when the node reports torque control in the FMU's locomotion state.
        safety_ok, locomotion = types.robot_status_t.SAFETY_OK, int(read_contract(paths.fmu_path()).fsm.Locomotion)
        walk_started: float | None = None
        in_goal_since: float | None = None
        reached = fell = False
        time_to_goal = math.nan
        fall_reason = ""
        end = time.monotonic() + max_walk + 180.0
        while time.monotonic() < end:
            bus.handle_timeout(50)
            for process, label in ((sim, "pfnav-sim"), (robot, "pfnav-robot"), (navigator, "the navigator")):
                if process.poll() is not None:
                    raise HarnessError(f"{label} exited with {process.returncode} (logs: {logs})")
            if walk_started is None and statuses and statuses[-1].safety == safety_ok and statuses[-1].fsm_state == locomotion:
                walk_started = time.monotonic()
            if not truth:
                continue
            now, state = truth[-1]
            x, y, z = state.position
            roll, pitch, _ = (float(a[0]) for a in roll_pitch_yaw(np.array([state.orientation])))
            height = z - terrain.height_at(x, y)
            if walk_started is not None and fall.fallen(height, roll, pitch):
                fell, fall_reason = True, f"base {height:.2f} m above ground, roll {math.degrees(roll):.0f}°, pitch {math.degrees(pitch):.0f}°"
                break
            if math.hypot(x - goal.center[0], y - goal.center[1]) <= goal.radius:
                # Reached as the co-simulation judges it: the true trunk entered the disc.
                if not reached and walk_started is not None:
                    reached, time_to_goal = True, now - walk_started
                in_goal_since = in_goal_since or now
                if now - in_goal_since >= SETTLE_AT_GOAL:
                    break
            else:
                in_goal_since = None
            if reached and walk_started is not None and now - walk_started > time_to_goal + AFTER_GOAL:
                break
            if walk_started is not None and now - walk_started > max_walk:
                break
        walk_seconds = 0.0 if walk_started is None else time.monotonic() - walk_started
    finally:
        # One after the other, the logger last: it records the others' final messages.
        for process in reversed(processes):
            stop_processes([process])
        client.close()
    states = [s for _, s in truth]
    if not states:
        raise HarnessError("no true state was received")
    xy = np.array([s.position[0:2] for s in states])
    final = xy[-1]
    path_rms = float(np.sqrt(np.mean(distance_to_polyline(xy[:, 0], xy[:, 1], plan.x, plan.y) ** 2)))
    estimate_error = math.nan
    if estimates:
        e = estimates[-1]
        estimate_error = math.hypot(e.position[0] - final[0], e.position[1] - final[1])
    outcome = RealtimeOutcome(
        name,
        reached,
        fell,
        fall_reason,
        walk_seconds,
        time_to_goal,
        float(math.hypot(final[0] - goal.center[0], final[1] - goal.center[1])),
        path_rms,
        estimate_error,
        json.loads(robot_json.read_text()) if robot_json.exists() else {},
        json.loads(sim_json.read_text()) if sim_json.exists() else {},
    )
    if cosim:
        from .cosim import CoSimConfig
        from .pipeline import simulate
        from .robot_fmu import robot_and_fmu

        robot_description, fmu = robot_and_fmu(None, out / "cache")
        config = CoSimConfig(follow="feedback", estimator="kalman")
        result = simulate(scenario, plan, fmu, robot_description, out / "cache", config, show_progress=False, feedback_field=answer.field)
        log = result.result.log
        walking = log["t"] >= float(log["walk_start"])
        pos = log["base_pos"][walking]
        outcome.cosim_path_rms = float(np.sqrt(np.mean(distance_to_polyline(pos[:, 0], pos[:, 1], plan.x, plan.y) ** 2)))
        outcome.cosim_reached = result.metrics.goal_reached
        outcome.cosim_fell = result.metrics.fell
    return outcome


def body_pace(sim_report: dict[str, Any]) -> str:
    """pfnav-sim's overrun ticks and its simulated time over wall time (an overrun holds the body's time back)."""
    factor = sim_report.get("real_time_factor")
    return f"{sim_report.get('overruns', '–')}" + ("" if factor is None else f" ({factor:.2f})")


def table(outcomes: list[RealtimeOutcome]) -> str:
    def us(report: dict[str, Any], key: str, q: str) -> str:
        return f"{report[key][q] * 1e6:.0f}" if report else "–"

    lines = [
        "| scenario | goal (time to it, s) | fell | walk, s | final distance to goal, m | path deviation RMS, m (co-sim) | estimate error at the end, m | "
        "period p99, µs | misses | latency p99, µs | damping entries | body overruns (real-time factor) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for o in outcomes:
        r = o.robot_report
        cosim = "" if o.cosim_path_rms is None else f" ({o.cosim_path_rms:.3f}{', goal' if o.cosim_reached else ''}{', fell' if o.cosim_fell else ''})"
        misses = f"{r['misses']} / {r['cycles']}" if r else "–"
        fell = "yes: " + o.fall_reason if o.fell else "no"
        lines.append(
            f"| {o.scenario} | {f'yes ({o.time_to_goal:.1f})' if o.reached else 'no'} | {fell} | {o.walk_seconds:.1f} | {o.final_distance:.2f} | "
            f"{o.path_rms:.3f}{cosim} | {o.estimate_error:.3f} | {us(r, 'period', 'p99')} | {misses} | {us(r, 'latency', 'p99')} | "
            f"{r.get('damping_entries', '–')} | {body_pace(o.sim_report)} |"
        )
    return "\n".join(lines)


def add_realtime_command(sub: Any) -> None:
    p = sub.add_parser("realtime", help="the stack as four processes (planner, pfnav-robot, pfnav-sim, navigator) walking scenarios in wall-clock time")
    p.add_argument("--scenario", action="append", default=None, help="only this scenario (repeatable; default: the paper's)")
    p.add_argument("--max-walk", type=float, default=150.0, help="wall seconds of walking before a run ends without the goal")
    p.add_argument(
        "--stand-time", type=float, default=3.0, help="seconds the navigator asks the robot to stand (after the node's first torque cycle) before walking"
    )
    p.add_argument("--cosim", action="store_true", help="also co-simulate each scenario (feedback mode, kalman) for comparison")
    p.add_argument("--trigger", choices=ROBOT_TRIGGERS, default=ROBOT_TRIGGERS[0], help="what starts pfnav-robot's cycles (its --trigger)")
    p.add_argument("--command-wait", type=float, default=0.5, help="pfnav-sim's --command-wait (fraction of a period it waits for the answer)")
    p.add_argument("--sim-priority", type=int, default=70, help="pfnav-sim's SCHED_FIFO priority (pfnav-robot runs at 80; 0: ordinary scheduling)")
    p.add_argument("--out", type=Path, default=Path("out/realtime"), help="output folder (logs, LCM logs, report.md)")
    p.add_argument("--results-page", metavar="NAME", help="also write docs/results/NAME.md (stamped)")


def run_realtime(args: Any) -> int:
    """Runs `pfnav-demo realtime` (re-run inside scripts/netns.sh when outside a private network namespace)."""
    from . import paths, results_page
    from .cli import in_private_network_namespace
    from .lcm_channels import udpm_url
    from .scenario import paper_scenario_names

    def stop_on_sigterm(_signum: int, _frame: object) -> None:
        # Through the `finally` of the run: its processes are stopped too.
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop_on_sigterm)
    if not in_private_network_namespace():
        os.execvp("bash", ["bash", str(paths.repo_root() / "scripts" / "netns.sh"), sys.executable, "-m", "pfnav_harness.cli", *args.argv])
    if not (math.isfinite(args.max_walk) and args.max_walk > 0):
        raise HarnessError(f"--max-walk must be positive, got {args.max_walk}")
    stamp = results_page.collect_stamp() if args.results_page else None
    out: Path = args.out.resolve()
    load_before = os.getloadavg()
    outcomes = []
    for name in args.scenario or paper_scenario_names():
        outcome = run_scenario(name, out, udpm_url(7667), args.max_walk, args.cosim, args.stand_time, args.trigger, args.sim_priority, args.command_wait)
        outcomes.append(outcome)
        print(table([outcome]).splitlines()[-1], flush=True)
    load_after = os.getloadavg()
    text = "\n".join(
        [
            (
                f"Planner service, pfnav-robot (controller FMU, 1 kHz, `--trigger {args.trigger}`), pfnav-sim (DART, real time, 1 kHz, "
                f"SCHED_FIFO priority {args.sim_priority}, `--command-wait {args.command_wait:g}`) and "
                "the navigator (feedback field on the robot's estimate, nav_cmd_t at 50 Hz) as four processes over udpm:// in a private "
                "network namespace; lcm-logger records each run (OUT/logs/SCENARIO.lcmlog). Goal: the true trunk enters the goal "
                "disc, as the co-simulation judges it; fall: the co-simulation's height and tilt thresholds. Path deviation: RMS "
                "distance of the walked (true) path "
                f"from the P-F plan's path. Period p99, misses (periods above 1.3 T) and latency p99 (state received to command sent): "
                "pfnav-robot's loop over the whole run. Body overruns: pfnav-sim's ticks whose work took longer than a period; the "
                "body's time stands still for the ticks lost (real-time factor: simulated over wall time), and the controller's "
                "with it, since it steps on the body's states. "
                f"Load average (1 min) {load_before[0]:.2f} before, {load_after[0]:.2f} after (the machine is shared)."
            ),
            "",
            table(outcomes),
        ]
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.md").write_text(text + "\n")
    print(text)
    if args.results_page:
        command = results_page.regenerate_command(".venv/bin/pfnav-demo", args.argv)
        print(f"results page: {results_page.write_results_page(args.results_page, 'Real time: the stack as four processes', text, command, stamp)}")
    return 0 if all(o.reached and not o.fell for o in outcomes) else 1
