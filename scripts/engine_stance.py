#!/usr/bin/env python3
"""How a stance foot moves in DART and in MuJoCo, and what the state estimator makes of it.

The controller's estimator (controller/src/estimator) takes the trunk velocity from the legs of
the feet in stance, assuming those feet stand still, and drops a stance foot whose implied
velocity fails its slip gate (flag footSlip, 0x80). Whatever the physics lets a stance foot do
(sink into a soft contact, slide, bounce at touch-down) shows up there. This script walks the
same straight reference on flat ground (the incline benchmark's 0° plane) on the estimate in
each engine, records every foot's position at every physics step (`incline.WorldProbe`), and
reports per engine:
- stance-foot velocity RMS (horizontal, vertical) over the physical stance steps, and in the
  first `TOUCHDOWN_WINDOW` after each touch-down;
- the foot sphere's depth below the ground in stance (mean, largest);
- the estimator's velocity error RMS per axis and its RMS tracking error;
- the share of walking steps with footSlip raised, and how long after the latest touch-down.
A third run in MuJoCo with a stiffer ground (contact time constant `--stiff-time-constant`
instead of MuJoCo's 20 ms) shows how much of the difference is the contact's softness; a fourth,
on MuJoCo's own ground with the ideal contact sensor (the estimator told which feet touch, instead
of judging it from leg effort and the gait schedule), how much is the contact's timing.

    .venv/bin/python scripts/engine_stance.py --results-page engines-stance
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pfnav_harness.robot import RobotDescription

# Seconds after a touch-down counted as the touch-down (the impact and the foot settling).
TOUCHDOWN_WINDOW = 0.02
WALK_DISTANCE = 3.0


@dataclass(frozen=True)
class StanceFigures:
    label: str
    stance_speed_horizontal: float
    stance_speed_vertical: float
    touchdown_speed_horizontal: float
    touchdown_speed_vertical: float
    depth_mean: float
    depth_max: float
    velocity_error_axes: tuple[float, float, float]
    height_error_final: float
    tracking_rms: float
    slip_share: float
    slip_after_touchdown_median: float


def rms(values: NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else float("nan")


def touchdowns(contact: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Steps where a foot's physical contact begins (per foot)."""
    started = np.zeros_like(contact)
    started[1:] = contact[1:] & ~contact[:-1]
    return started


def steps_since(events: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Per step and foot: steps since the latest event (inf before the first)."""
    n, feet = events.shape
    since = np.full((n, feet), np.inf)
    for i in range(feet):
        last = -np.inf
        for k in range(n):
            if events[k, i]:
                last = k
            since[k, i] = k - last
    return since


def measure(
    label: str,
    engine: str,
    fmu: Path,
    robot: RobotDescription,
    cache: Path,
    seed: int,
    contact_time_constant: float | None = None,
    contact_sensor: bool = False,
) -> StanceFigures:
    """One walk in `engine` (MuJoCo: with contacts of `contact_time_constant`, None: MuJoCo's own), reported as `label`;
    `contact_sensor`: the estimator gets the physics' foot contacts."""
    from pfnav_harness.body_sensors import BodySensorConfig
    from pfnav_harness.cosim import CoSimConfig, CoSimulation
    from pfnav_harness.estimation_metrics import compute_estimation_metrics
    from pfnav_harness.incline import WorldProbe, incline_scenario, straight_plan
    from pfnav_harness.mujoco_world import MujocoWorld

    scenario = incline_scenario(0.0, "up", WALK_DISTANCE)
    plan = straight_plan(scenario)
    config = CoSimConfig(engine=engine, estimator="kalman", body_sensors=BodySensorConfig(seed=seed, contact_sensor=contact_sensor))
    with CoSimulation(scenario, plan, fmu, robot, cache, config) as sim:
        if contact_time_constant is not None:
            if not isinstance(sim.world, MujocoWorld):
                raise SystemExit(f"engine_stance: a contact time constant is MuJoCo's, not {engine}'s")
            sim.world.set_contact_time_constant(contact_time_constant)
        probe = WorldProbe(sim.world, round(sim.duration() / config.physics_dt) + 1)
        result = sim.run()
        radius = sim.world.foot_radius
    log = result.log
    dt = float(log["physics_dt"])
    n = min(probe.count, len(log["t"]))
    walking = np.asarray(log["t"][:n]) >= float(log["walk_start"])
    feet = probe.foot_position[:n]
    contact = np.asarray(log["contact_actual"][:n]) > 0
    velocity = np.zeros_like(feet)
    velocity[1:] = np.diff(feet, axis=0) / dt
    # Stance steps: touching now and in the step before (the velocity spans both), while walking.
    stance = contact.copy()
    stance[1:] &= contact[:-1]
    stance &= walking[:, None]
    since_touchdown = steps_since(touchdowns(contact)) * dt
    early = stance & (since_touchdown <= TOUCHDOWN_WINDOW)
    horizontal = np.hypot(velocity[..., 0], velocity[..., 1])
    depth = radius + scenario.terrain.height(feet[..., 0], feet[..., 1]) - feet[..., 2]
    estimate = compute_estimation_metrics(log)
    status = np.asarray(log["est_status"][:n]).astype(np.int64)
    slipping = walking & (status & 0x80 != 0)
    latest = since_touchdown.min(axis=1)
    return StanceFigures(
        label,
        rms(horizontal[stance]),
        rms(velocity[..., 2][stance]),
        rms(horizontal[early]),
        rms(velocity[..., 2][early]),
        float(depth[stance].mean()),
        float(depth[stance].max()),
        estimate.velocity_rms_axes,
        float(log["est_pos"][n - 1, 2] - log["base_pos"][n - 1, 2]),
        estimate.tracking_rms,
        float(slipping.sum() / max(walking.sum(), 1)),
        float(np.median(latest[slipping])) if slipping.any() else float("nan"),
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", type=Path, default=None, help="robot config (default $PFNAV_ROBOT, else robot/quadruped.toml)")
    parser.add_argument("--sensor-seed", type=int, default=0, help="seed of the IMU and encoder noise (default 0)")
    parser.add_argument(
        "--stiff-time-constant", type=float, default=0.005, help="contact time constant of the stiffer MuJoCo ground, s (default 0.005)"
    )
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also write docs/results/NAME.md")
    args = parser.parse_args()
    from pfnav_harness import results_page
    from pfnav_harness.engine import ENGINE_TITLES
    from pfnav_harness.mujoco_world import DEFAULT_CONTACT_TIME_CONSTANT
    from pfnav_harness.robot_fmu import robot_and_fmu

    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        parser.error(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    stamp = results_page.collect_stamp() if args.results_page else None
    with tempfile.TemporaryDirectory(prefix="pfnav_stance_") as tmp:
        robot, fmu = robot_and_fmu(args.robot, Path(tmp))
        ms = 1000.0
        runs = [
            (ENGINE_TITLES["dart"], "dart", None, False),
            (f"{ENGINE_TITLES['mujoco']} (contact time constant {DEFAULT_CONTACT_TIME_CONSTANT * ms:g} ms, MuJoCo's default)", "mujoco", None, False),
            (f"{ENGINE_TITLES['mujoco']}, stiffer ground (contact time constant {args.stiff_time_constant * ms:g} ms)", "mujoco", args.stiff_time_constant, False),
            (f"{ENGINE_TITLES['mujoco']} (default ground), ideal contact sensor", "mujoco", None, True),
        ]
        figures = [measure(label, engine, fmu, robot, Path(tmp), args.sensor_seed, constant, sensor) for label, engine, constant, sensor in runs]
    lines = [
        (
            f"{robot.config_path.stem} walks {WALK_DISTANCE:g} m straight on flat ground (the incline benchmark's 0° plane) at the planner's "
            f"nominal speed on its own estimate (IMU and encoder noise seed {args.sensor_seed}, no position fixes), once per engine. "
            f"Stance: a foot touching the ground in this physics step and the one before, while walking; touch-down: the first "
            f"{TOUCHDOWN_WINDOW * ms:.0f} ms of a stance. Depth: how far the foot sphere reaches below the ground (negative: above). "
            "Velocity error: the estimator's trunk velocity minus the true one, world frame, while walking."
        ),
        "",
        (
            "| engine | stance-foot speed RMS, horizontal / vertical, mm/s | at touch-down, mm/s | depth in stance, mean / largest, mm | "
            "estimate velocity error RMS x / y / z, m/s | estimate height error at the end, m | RMS tracking, m | walking steps with footSlip | footSlip after the latest touch-down, median |"
        ),
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for f in figures:
        vx, vy, vz = f.velocity_error_axes
        lines.append(
            f"| {f.label} | {f.stance_speed_horizontal * ms:.1f} / {f.stance_speed_vertical * ms:.1f} | "
            f"{f.touchdown_speed_horizontal * ms:.1f} / {f.touchdown_speed_vertical * ms:.1f} | {f.depth_mean * ms:.2f} / {f.depth_max * ms:.2f} | "
            f"{vx:.3f} / {vy:.3f} / {vz:.3f} | {f.height_error_final:+.3f} | {f.tracking_rms:.3f} | {100 * f.slip_share:.2f} % | "
            + (f"{f.slip_after_touchdown_median * ms:.0f} ms |" if np.isfinite(f.slip_after_touchdown_median) else "– |")
        )
    text = "\n".join(lines)
    print(text)
    if args.results_page:
        command = results_page.regenerate_command(".venv/bin/python scripts/engine_stance.py", sys.argv[1:])
        page = results_page.write_results_page(args.results_page, "Stance feet and the state estimate in DART and in MuJoCo", text, command, stamp)
        print(f"results page: {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
