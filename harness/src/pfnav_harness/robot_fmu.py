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
import subprocess
from pathlib import Path

from . import paths
from .errors import MissingArtifactError, SimulationError
from .robot import PACKAGE_PATH_ENV, RobotDescription

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
    command = [str(bundler), "--robot", str(robot.config_path), "--binaries-from", str(default_fmu), "--out", str(partial)]
    # bundle-fmu resolves the config's package:// names through the same roots as the harness.
    # No backtrace: the error's own text names the item and the file.
    env = {
        **os.environ,
        PACKAGE_PATH_ENV: os.pathsep.join(str(root) for root in robot.package_roots),
        "RUST_BACKTRACE": "0",
        "RUST_LIB_BACKTRACE": "0",
    }
    try:
        done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=BUNDLE_TIMEOUT, check=False)
    except (OSError, subprocess.TimeoutExpired) as err:
        partial.unlink(missing_ok=True)
        raise SimulationError(f"bundle-fmu could not bundle the FMU for {robot.config_path}: {err}") from err
    if done.returncode != 0 or not partial.is_file():
        partial.unlink(missing_ok=True)
        detail = " / ".join(line.strip() for line in (done.stderr or done.stdout).strip().splitlines() if line.strip())
        raise SimulationError(
            f"bundle-fmu failed (exit {done.returncode}) for the robot config {robot.config_path}: {detail}\ncommand: {' '.join(command)}"
        )
    os.replace(partial, target)
    return target


def robot_and_fmu(config: Path | None, cache_dir: Path) -> tuple[RobotDescription, Path]:
    """The robot of the config `config` (None: `$PFNAV_ROBOT`, else ours) and the controller FMU for it."""
    robot = RobotDescription.load(config if config is not None else paths.robot_config_path())
    return robot, fmu_for_robot(robot, cache_dir)
