"""The controller FMU for a robot: the default FMU for ours, an FMU bundled for the robot otherwise.

`bundle-fmu --robot CONFIG --binaries-from FMU --out PATH` writes an FMU whose variable table,
start values, controller configuration and resources (URDF, config, meshes) are those of the robot,
with the binaries of the default FMU. The result is cached as `<cache>/fmu-<hash>.fmu`, the hash
taken over the robot (config, URDF and meshes by content) and the default FMU's bytes, so an edited
robot or a rebuilt controller gets a new FMU and an unchanged one is bundled once.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from . import paths
from .errors import HarnessError, MissingArtifactError, SimulationError
from .robot import PACKAGE_PATH_ENV, RobotDescription
from .tools import run_tool

BUNDLE_TIMEOUT = 300.0


def is_default_robot(robot: RobotDescription) -> bool:
    """Whether `robot` is the robot the default FMU is built for (same config, URDF and meshes by content)."""
    ours = paths.default_robot_config_path()
    if not ours.is_file():
        return False
    return RobotDescription.load(ours, robot.package_roots).digest == robot.digest


def robot_fmu_key(robot: RobotDescription, default_fmu: Path) -> str:
    h = hashlib.sha256()
    h.update(f"robot={robot.digest};fmu=".encode())
    h.update(default_fmu.read_bytes())
    return h.hexdigest()[:16]


def fmu_for_robot(robot: RobotDescription, cache_dir: Path) -> Path:
    """The controller FMU to simulate `robot` with; bundles it into `cache_dir` when it is not there yet."""
    default_fmu = paths.fmu_path()
    if is_default_robot(robot):
        return default_fmu
    target = cache_dir / f"fmu-{robot_fmu_key(robot, default_fmu)}.fmu"
    if target.is_file():
        return target
    try:
        bundler = paths.bundle_fmu_path()
    except MissingArtifactError as err:
        raise MissingArtifactError(f"the robot config {robot.config_path} is not ours, so its FMU has to be bundled: {err}") from err
    cache_dir.mkdir(parents=True, exist_ok=True)
    partial = cache_dir / f"{target.stem}.{os.getpid()}.partial.fmu"
    args = ["--robot", str(robot.config_path), "--binaries-from", str(default_fmu), "--out", str(partial)]
    # bundle-fmu resolves the config's package:// names through the same roots as the harness.
    package_path = {PACKAGE_PATH_ENV: os.pathsep.join(str(root) for root in robot.package_roots)}
    try:
        what = f"bundle-fmu failed for the robot config {robot.config_path}"
        run_tool(bundler, args, what=what, failure=SimulationError, timeout=BUNDLE_TIMEOUT, env=package_path)
    except HarnessError:
        partial.unlink(missing_ok=True)
        raise
    if not partial.is_file():
        raise SimulationError(f"bundle-fmu wrote no FMU for the robot config {robot.config_path} (expected {partial})")
    os.replace(partial, target)
    return target


def robot_and_fmu(config: Path | None, cache_dir: Path) -> tuple[RobotDescription, Path]:
    """The robot of the config `config` (None: `$PFNAV_ROBOT`, else ours) and the controller FMU for it."""
    robot = RobotDescription.load(config if config is not None else paths.robot_config_path())
    return robot, fmu_for_robot(robot, cache_dir)
