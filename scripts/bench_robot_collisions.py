#!/usr/bin/env python3
"""Cost of the robot's collision shapes in DART: mesh collisions kept vs their bounding boxes.

For each robot config: the robot on a flat terrain mesh (3 m × 3 m, 0.125 m cells), (1) standing
1 s with joint PD on its crouch (gains 150·(q* − q) − 3·dq scaled by mass / 12 kg) and (2) limp
(no torque) from its crouch 5 cm up for 1.5 s, lying on the ground at the end. Printed: wall
seconds per simulated second, the base height at the end, and which links touched the ground.

Usage (third-party robots need their package root):
    PFNAV_PACKAGE_PATH=.venv/lib/python3.11/site-packages/cmeel.prefix/share \\
        nice -n 10 .venv/bin/python scripts/bench_robot_collisions.py robot/third_party/solo12.toml robot/third_party/go1.toml
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pfnav_harness.errors import HarnessError
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Terrain
from pfnav_harness.world import MESH_COLLISION_MODES, QuadrupedWorld


def measure(
    robot: RobotDescription, mode: str, limp: bool, cache: Path
) -> tuple[float, float, list[str]]:
    world = QuadrupedWorld(
        Terrain((0.0, 0.0), 0.125, np.zeros((24, 24))),
        robot,
        cache,
        mesh_collisions=mode,
    )
    world.place(1.5, 1.5, 0.0, clearance=0.05 if limp else 0.002)
    scale = world.mass / 12.0
    steps = 1500 if limp else 1000
    touched: set[str] = set()
    begin = time.perf_counter()
    for _ in range(steps):
        if limp:
            world.apply_torques(np.zeros(12))
        else:
            s = world.state()
            world.apply_torques(
                150.0 * scale * (robot.crouch - s.joint_positions)
                - 3.0 * scale * s.joint_velocities
            )
        world.step()
        touched |= {
            body.getName()
            for body in world.world.getLastCollisionResult().getCollidingBodyNodes()
        }
    wall = (time.perf_counter() - begin) / (steps * world.time_step)
    return wall, float(world.state().position[2]), sorted(touched - {"terrain"})


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("configs", nargs="+", type=Path, help="robot configs")
    args = parser.parse_args()
    print(
        f"{'robot':<14} {'collisions':<10} {'case':<9} {'wall s / sim s':>14} {'base z [m]':>10}  links touching the ground"
    )
    try:
        with tempfile.TemporaryDirectory(prefix="pfnav_collisions_") as tmp:
            for config in args.configs:
                robot = RobotDescription.load(config)
                for mode in MESH_COLLISION_MODES:
                    for limp in (False, True):
                        wall, height, touched = measure(robot, mode, limp, Path(tmp))
                        case = "limp" if limp else "standing"
                        print(
                            f"{config.stem:<14} {mode:<10} {case:<9} {wall:>14.3f} {height:>10.3f}  {', '.join(touched)}",
                            flush=True,
                        )
    except HarnessError as err:
        print(f"bench_robot_collisions: error: {err}", file=sys.stderr)
        return err.exit_code
    return 0


if __name__ == "__main__":
    sys.exit(main())
