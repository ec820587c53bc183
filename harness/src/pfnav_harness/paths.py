"""Where the harness finds the repository's build products; every path has an env override."""

from __future__ import annotations

import os
from pathlib import Path

from .errors import MissingArtifactError

FMU_MODEL_IDENTIFIER = "QuadController"


def repo_root() -> Path:
    """The repository root: `PFNAV_ROOT`, else the folder above `harness/` (editable install)."""
    env = os.environ.get("PFNAV_ROOT")
    if env:
        return Path(env).resolve()
    return Path(__file__).resolve().parents[3]


def _artifact(env_name: str, default: Path, what: str, how: str) -> Path:
    override = os.environ.get(env_name)
    path = Path(override) if override else default
    if not path.is_file():
        source = f"${env_name}" if override else "the default location"
        raise MissingArtifactError(f"{what} not found at {path} ({source}); {how}, or set {env_name}")
    return path


def fmu_path() -> Path:
    return _artifact(
        "PFNAV_FMU",
        repo_root() / "target" / "fmu" / f"{FMU_MODEL_IDENTIFIER}.fmu",
        "controller FMU",
        "build it with `bash scripts/setup.sh` (bundles target/fmu/*.fmu)",
    )


def planner_service_path() -> Path:
    return _artifact(
        "PFNAV_PLANNER_SERVICE",
        repo_root() / "target" / "release" / "pf-planner-service",
        "pf-planner-service binary",
        "build it with `cargo build --release -p pf-planner-service`",
    )


def pf_plan_path() -> Path:
    return _artifact(
        "PFNAV_PF_PLAN",
        repo_root() / "target" / "release" / "pf-plan",
        "pf-plan binary",
        "build it with `cargo build --release -p pf-planner`",
    )


def pf_robot_path() -> Path:
    """`pf-robot`, whose `describe` reads robot configs for the harness (the controller's loader)."""
    return _artifact(
        "PFNAV_PF_ROBOT",
        repo_root() / "target" / "release" / "pf-robot",
        "pf-robot binary (it reads robot configs with the controller's loader)",
        "build it with `cargo build --release -p fmu-tools --bin pf-robot`",
    )


def pfnav_robot_path() -> Path:
    """`pfnav-robot`, the controller FMU as a real-time LCM node (robot_node/)."""
    return _artifact(
        "PFNAV_ROBOT_NODE",
        repo_root() / "target" / "release" / "pfnav-robot",
        "pfnav-robot binary",
        "build it with `cargo build --release -p pfnav-robot`",
    )


def default_robot_config_path() -> Path:
    """Our robot's config, the robot the default FMU is built for."""
    return repo_root() / "robot" / "quadruped.toml"


def robot_config_path() -> Path:
    """The robot config to simulate when none is given: `PFNAV_ROBOT`, else ours."""
    return _artifact(
        "PFNAV_ROBOT",
        default_robot_config_path(),
        "robot config",
        "it belongs to the repository (robot/); pass a robot config (TOML, format in robot/README.md)",
    )


def bundle_fmu_path() -> Path:
    """`bundle-fmu`, which writes the controller FMU for a robot config."""
    return _artifact(
        "PFNAV_BUNDLE_FMU",
        repo_root() / "target" / "release" / "bundle-fmu",
        "bundle-fmu binary (it builds the controller FMU for a robot other than ours)",
        "build it with `cargo build --release -p quad-controller-fmu --bin bundle-fmu`",
    )
