"""The real-time benchmark of issue 37: pfnav-robot driving pfnav-sim over udpm:// in a private network namespace.

Each run starts the body (pfnav-sim, real time, 1 kHz, DART) and the robot node (pfnav-robot with
the controller FMU), and this script acts as the navigator (nav_cmd_t at 50 Hz: stand, or trot in
place with `--gait trot`). After `--duration` seconds pfnav-robot writes its whole-run figures
(--report-json) and the table is printed: loop period p50/p99/max, jitter |period − T| p99/max,
misses (period > 1.3 T) %, state-in → command-out latency p50/p99/max, runtime p99, which event
started the cycles, the body's tick overruns, SCHED_FIFO and mlockall. Runs of different
`--triggers` go back to back in one invocation, so they see the same machine.

    bash scripts/netns.sh .venv/bin/python scripts/bench_realtime.py --duration 30 --results-page realtime

(It re-runs itself inside scripts/netns.sh when started outside a private network namespace.)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


# pfnav-robot's --trigger values, as the table names them.
TRIGGER_LABELS = {
    "state": "state arrival (`--trigger state`)",
    "deadline": "phase-locked deadline (default)",
    "clock": "fixed deadline (`--trigger clock`)",
}


@dataclass
class Run:
    trigger: str
    robot: dict[str, Any]
    sim: dict[str, Any]
    statuses: int
    final_status: dict[str, Any]


def _navigator(
    lcm: Any, types: Any, channel: str, gait: str, stop: threading.Event
) -> None:
    """nav_cmd_t every 20 ms: Stand, or Locomotion with a zero velocity (trotting in place at the start)."""
    seq = 0
    while not stop.wait(0.02):
        m = types.nav_cmd_t()
        m.header = types.header_t()
        m.header.utime = time.time_ns() // 1000
        m.header.seq = seq
        m.header.frame_id = "world"
        m.mode = m.MODE_LOCOMOTION if gait == "trot" else m.MODE_STAND
        m.x = m.y = m.z = m.yaw = m.vx = m.vy = m.yaw_rate = 0.0
        m.body_height = m.terrain_dzdx = m.terrain_dzdy = 0.0
        lcm.publish(channel, m.encode())
        seq += 1


def _wait_for(predicate: Any, timeout: float, what: str, lcm: Any) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise SystemExit(f"bench_realtime: {what} not within {timeout:.0f} s")
        lcm.handle_timeout(50)


def run_once(args: argparse.Namespace, trigger: str, lcm_url: str, out: Path) -> Run:
    from pfnav_harness import paths
    from pfnav_harness.lcm_channels import ROBOT
    from pfnav_harness.planner_client import _import_lcm, _import_types
    from pfnav_harness.process_signals import stop_processes

    lcm_module, types = _import_lcm(), _import_types()
    prefix = f"BENCH{trigger.upper()}_"
    lcm = lcm_module.LCM(lcm_url)
    states: list[int] = []
    statuses: list[Any] = []
    lcm.subscribe(prefix + ROBOT.low_state, lambda _c, _d: states.append(1))
    lcm.subscribe(
        prefix + ROBOT.robot_status,
        lambda _c, d: statuses.append(types.robot_status_t.decode(d)),
    )
    out.mkdir(parents=True, exist_ok=True)
    robot_json, sim_json = out / f"robot_{trigger}.json", out / f"sim_{trigger}.json"
    env = {**os.environ, "LCM_DEFAULT_URL": lcm_url}
    sim_cmd = [
        sys.executable,
        "-m",
        "pfnav_harness.body_sim",
        "--channel-prefix",
        prefix,
        "--out",
        str(out / "sim"),
        "--report-json",
        str(sim_json),
    ]
    sim_cmd += ["--priority", str(args.sim_priority)]
    if args.scenario:
        sim_cmd += ["--scenario", args.scenario]
    with (
        (out / f"sim_{trigger}.log").open("w") as sim_log,
        (out / f"robot_{trigger}.log").open("w") as robot_log,
    ):
        sim = subprocess.Popen(
            sim_cmd, env=env, stdout=sim_log, stderr=subprocess.STDOUT
        )
        robot: subprocess.Popen[bytes] | None = None
        stop = threading.Event()
        navigator = threading.Thread(
            target=_navigator,
            args=(
                lcm_module.LCM(lcm_url),
                types,
                prefix + ROBOT.nav_cmd,
                args.gait,
                stop,
            ),
            daemon=True,
        )
        try:
            _wait_for(lambda: len(states) > 100, 120.0, "pfnav-sim's states", lcm)
            navigator.start()
            robot_cmd = [
                str(paths.pfnav_robot_path()),
                "--fmu",
                str(paths.fmu_path()),
                "--channel-prefix",
                prefix,
                "--trigger",
                trigger,
                "--duration",
                str(args.duration),
                "--status-period",
                "0.5",
                "--report-json",
                str(robot_json),
            ]
            robot = subprocess.Popen(
                robot_cmd, env=env, stdout=robot_log, stderr=subprocess.STDOUT
            )
            deadline = time.monotonic() + args.duration + 60.0
            while robot.poll() is None:
                if time.monotonic() > deadline:
                    raise SystemExit(
                        "bench_realtime: pfnav-robot did not stop after its --duration"
                    )
                lcm.handle_timeout(100)
            if robot.returncode != 0:
                raise SystemExit(
                    f"bench_realtime: pfnav-robot exited with {robot.returncode} (log: {out / f'robot_{trigger}.log'})"
                )
        finally:
            stop.set()
            stop_processes([robot, sim])
    final = statuses[-1] if statuses else None
    return Run(
        trigger,
        json.loads(robot_json.read_text()),
        json.loads(sim_json.read_text()) if sim_json.exists() else {},
        len(statuses),
        {}
        if final is None
        else {
            "safety": int(final.safety),
            "reason": final.reason,
            "fsm_state": int(final.fsm_state),
        },
    )


def measure_floor(args: argparse.Namespace, out: Path) -> dict[str, Any]:
    """`pfnav-robot --measure-floor`: a bare loop with the node's period, priority and sleep
    for `--duration` seconds, no FMU and no bus; the machine's own jitter and misses."""
    from pfnav_harness import paths

    out.mkdir(parents=True, exist_ok=True)
    report = out / "floor.json"
    with (out / "floor.log").open("w") as log:
        subprocess.run(
            [
                str(paths.pfnav_robot_path()),
                "--measure-floor",
                "--duration",
                str(args.duration),
                "--report-json",
                str(report),
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            check=True,
            timeout=args.duration + 60.0,
        )
    result: dict[str, Any] = json.loads(report.read_text())
    return result


def floor_row(floor: dict[str, Any]) -> str:
    """The bare loop's row of the table (the columns it has no figure for are dashes)."""
    p, j = floor["period"], floor["jitter"]
    cycles = max(1, int(floor["cycles"]))
    return (
        f"| the machine's floor: a bare loop, no FMU, no bus (`pfnav-robot --measure-floor`) | {floor['cycles']} | "
        f"{_us(p['p50'])} / {_us(p['p99'])} / {_us(p['max'])} | {_us(j['p99'])} / {_us(j['max'])} | "
        f"{floor['misses']} ({100.0 * floor['misses'] / cycles:.2f} %) | – | – | – | – | – | "
        f"{_yes(floor['realtime_priority'])} / {_yes(floor['memory_locked'])} |"
    )


def _yes(granted: bool) -> str:
    return "yes" if granted else "no"


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.0f}"


def table(runs: list[Run], floor: dict[str, Any] | None) -> str:
    lines = [
        (
            "| cycles started by | cycles | period p50 / p99 / max, µs | jitter p99 / max, µs | misses (> 1.3 T) | "
            "latency p50 / p99 / max, µs | runtime p50 / p99, µs | arriving state / state waiting / no fresh state | "
            "body ticks (overruns) | damping entries | SCHED_FIFO / mlockall: node, body |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    if floor is not None:
        lines.append(floor_row(floor))
    for run in runs:
        r = run.robot
        cycles = max(1, int(r["cycles"]))
        p, j, lat, rt = r["period"], r["jitter"], r["latency"], r["runtime"]
        sim_ticks = f"{run.sim.get('ticks', 0)} ({run.sim.get('overruns', 0)})"
        label = TRIGGER_LABELS[run.trigger]
        lines.append(
            f"| {label} | {r['cycles']} | {_us(p['p50'])} / {_us(p['p99'])} / {_us(p['max'])} | {_us(j['p99'])} / {_us(j['max'])} | "
            f"{r['misses']} ({100.0 * r['misses'] / cycles:.2f} %) | {_us(lat['p50'])} / {_us(lat['p99'])} / {_us(lat['max'])} | "
            f"{_us(rt['p50'])} / {_us(rt['p99'])} | {r['cycles_state_arrived']} / {r['cycles_state_waiting']} / {r['cycles_watchdog']} | "
            f"{sim_ticks} | {r['damping_entries']} | {_yes(r['realtime_priority'])} / {_yes(r['memory_locked'])}, "
            f"{_yes(run.sim.get('realtime_priority', False))} / {_yes(run.sim.get('memory_locked', False))} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--duration",
        type=float,
        default=30.0,
        help="seconds of each pfnav-robot run (1–600 s)",
    )
    parser.add_argument(
        "--triggers",
        default="state,deadline,clock",
        help="comma-separated pfnav-robot --trigger values, run back to back",
    )
    parser.add_argument(
        "--gait",
        choices=("stand", "trot"),
        default="stand",
        help="what the navigator asks for",
    )
    parser.add_argument(
        "--sim-priority",
        type=int,
        default=70,
        help="pfnav-sim's SCHED_FIFO priority (0: ordinary scheduling); pfnav-robot runs at its default 80",
    )
    parser.add_argument(
        "--scenario", help="paper scenario the body stands on (default: pfnav-sim's)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/bench_realtime"),
        help="logs and JSON reports",
    )
    parser.add_argument(
        "--no-floor",
        action="store_true",
        help="skip the first row, the bare loop that measures the machine's own jitter and misses",
    )
    parser.add_argument(
        "--results-page",
        metavar="NAME",
        help="also write docs/results/NAME.md (stamped)",
    )
    args = parser.parse_args()
    if not (1.0 <= args.duration <= 600.0):
        parser.error("--duration must be in 1 ..= 600 s")
    triggers = [t.strip() for t in args.triggers.split(",") if t.strip()]
    if not triggers or any(t not in TRIGGER_LABELS for t in triggers):
        parser.error(f"--triggers: comma-separated from {', '.join(TRIGGER_LABELS)}")

    sys.path.insert(0, str(REPO / "harness" / "src"))
    from pfnav_harness import results_page
    from pfnav_harness.cli import in_private_network_namespace
    from pfnav_harness.lcm_channels import udpm_url

    if not in_private_network_namespace():
        # udpm:// only inside a private network namespace: run again inside one.
        os.execvp(
            "bash",
            ["bash", str(REPO / "scripts" / "netns.sh"), sys.executable, *sys.argv],
        )

    stamp = results_page.collect_stamp() if args.results_page else None
    load_before = os.getloadavg()
    lcm_url = udpm_url(7667)
    floor = None if args.no_floor else measure_floor(args, args.out.resolve())
    if floor is not None:
        print(
            f"machine floor: jitter p99 {_us(floor['jitter']['p99'])} µs, misses {floor['misses']}/{floor['cycles']}",
            flush=True,
        )
    runs = []
    for trigger in triggers:
        run = run_once(args, trigger, lcm_url, args.out.resolve())
        runs.append(run)
        r = run.robot
        print(
            f"{trigger}: period p99 {_us(r['period']['p99'])} µs, latency p99 {_us(r['latency']['p99'])} µs, "
            f"misses {r['misses']}/{r['cycles']}, final {run.final_status}",
            flush=True,
        )
    load_after = os.getloadavg()
    text = "\n".join(
        [
            (
                f"pfnav-robot (controller FMU, 1 kHz, `estimator = kalman`) driving pfnav-sim (DART, real time, 1 kHz, PD + feed-forward "
                f"motor model) over `udpm://` on loopback in a private network namespace; this script is the navigator "
                f"(nav_cmd_t every 20 ms: {'trot in place' if args.gait == 'trot' else 'stand'}). {args.duration:.0f} s per row, "
                f"rows run back to back. Latency: from the LCM thread's receipt of a low_state_t to the sending of the command "
                f"computed from it. A miss is a period longer than 1.3 T. The first row is the machine itself: a loop with the node's period, "
                f"SCHED_FIFO priority and sleep that does nothing else, the jitter and misses any loop here starts from. Load average (1 min) "
                f"{load_before[0]:.2f} before, {load_after[0]:.2f} after (the machine is shared)."
            ),
            "",
            table(runs, floor),
            "",
            "Targets of issue 37 (2-core machine, full stack): jitter p99 ≤ 250 µs, misses ≤ 0.1 %, latency p99 ≤ 1 ms.",
        ]
    )
    print(text)
    if args.results_page:
        command = results_page.regenerate_command(
            ".venv/bin/python scripts/bench_realtime.py", sys.argv[1:]
        )
        page = results_page.write_results_page(
            args.results_page,
            "Real-time loop: pfnav-robot and pfnav-sim on the bus",
            text,
            command,
            stamp,
        )
        print(f"results page: {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
