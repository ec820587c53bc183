"""The robot the harness simulates: a robot config (TOML) and the URDF it names, read into a `RobotDescription`.

The config format is the controller's (controller/src/robot_config/; the key table is in
robot/README.md) and is read by the controller's loader only: `pf-robot describe CONFIG` loads the
robot as the FMU will (every check of the config and of the URDF: keys, values, joints and links,
inertias, axes, limits, the stand pose) and prints what the physics side needs as JSON (resolved
URDF and mesh paths, foot radius, massless links, the legs). A config the loader refuses is a
`RobotConfigError` carrying the loader's message, which names the file and the key.

`package://NAME/PATH` resolves through package roots: those passed in, else `PFNAV_PACKAGE_PATH`
(':'-separated, empty entries ignored). When it is unset, the one root is where packages installed
into this Python environment put their share folder (`site-packages/cmeel.prefix/share`: `pip
install example-robot-data` puts the third-party robots there), so `--robot
robot/third_party/go1.toml` works after `scripts/setup.sh` with nothing set; the loader and the
bundler are given the same roots.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sysconfig
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import paths
from .errors import HarnessError

# The controller's leg names, in the order of its 12 joints (index 3·leg + role).
LEG_LABELS = ("FR", "FL", "RR", "RL")
JOINT_ROLES = ("abduction", "hip", "knee")
NUM_JOINTS = len(LEG_LABELS) * len(JOINT_ROLES)

PACKAGE_PATH_ENV = "PFNAV_PACKAGE_PATH"
# `pf-robot describe` reads one config and one URDF: seconds, not minutes, even for a large URDF.
DESCRIBE_TIMEOUT_S = 60.0
CROUCH_HINT = (
    "add `crouch = [abduction, hip, knee]` (rad) to the leg's table: the joint angles the robot is placed in before it "
    "stands up (feet roughly under the hips, below the base; see robot/README.md)"
)


class RobotConfigError(HarnessError):
    """The robot config, or a file it names, cannot describe the robot."""

    exit_code = 7


@dataclass(frozen=True)
class LegDescription:
    """One leg under the controller's leg name, in the URDF's own names."""

    label: str
    # Abduction, hip flexion, knee: the actuated joints from the base outwards.
    joints: tuple[str, str, str]
    foot_link: str
    # Foot point (sphere centre) in `foot_link`'s frame, m.
    foot_offset: tuple[float, float, float]
    # Joint angles (rad) the robot is placed in before its stand-up.
    crouch: tuple[float, float, float]
    knee_points: str
    # Whether the URDF gives `foot_link` a sphere collision centred on the foot point.
    has_foot_sphere: bool


@dataclass(frozen=True)
class RobotDescription:
    """A robot config and its URDF, resolved and checked (plain data: picklable for sweep workers)."""

    config_path: Path
    config_text: str
    urdf_path: Path
    package_roots: tuple[Path, ...]
    # Packages the URDF names by `package://NAME/...`, with the folder each resolves to.
    package_dirs: tuple[tuple[str, Path], ...]
    base_link: str
    stand_height: float
    foot_radius: float
    # The whole robot's mass as the controller models it, kg.
    mass: float
    # The config's `massless_links` and the URDF's links without `<inertial>`: frames without mass.
    massless_links: tuple[str, ...]
    legs: tuple[LegDescription, ...]
    # `limits.effort` of the config (abduction, hip, knee; N·m), overriding the URDF's; None: the URDF's.
    effort_limits: tuple[float, float, float] | None
    # Files the URDF names (meshes), resolved.
    mesh_files: tuple[Path, ...]
    # sha256 of the config text, the URDF and the mesh files: the robot by content.
    digest: str

    @classmethod
    def load(cls, config_path: Path | str, package_roots: Sequence[Path | str] | None = None) -> RobotDescription:
        """Reads `config_path` and the URDF it names through the controller's loader; `package_roots` default to `PFNAV_PACKAGE_PATH`."""
        path = Path(config_path).absolute()
        roots = tuple(Path(p).absolute() for p in package_roots) if package_roots is not None else package_roots_from_env()
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as err:
            raise RobotConfigError(f"robot config {path}: cannot read it ({err})") from err
        described = describe(path, roots)
        legs = []
        for leg in described["legs"]:
            if leg["crouch"] is None:
                raise RobotConfigError(f"robot config {path}: missing key `legs.{leg['label']}.crouch`; {CROUCH_HINT}")
            legs.append(
                LegDescription(
                    label=leg["label"],
                    joints=tuple(leg["joints"]),
                    foot_link=leg["foot_link"],
                    foot_offset=tuple(float(v) for v in leg["foot_offset"]),
                    crouch=tuple(float(v) for v in leg["crouch"]),
                    knee_points=leg["knee_points"],
                    has_foot_sphere=bool(leg["has_foot_sphere"]),
                )  # type: ignore[arg-type]
            )
        urdf_path = Path(described["urdf"]).absolute()
        mesh_files = tuple(Path(m).absolute() for m in described["mesh_files"])
        effort = described["effort_limits"]
        return cls(
            config_path=path,
            config_text=text,
            urdf_path=urdf_path,
            package_roots=roots,
            package_dirs=tuple((name, Path(folder).absolute()) for name, folder in described["package_dirs"]),
            base_link=described["base_link"],
            stand_height=float(described["stand_height"]),
            foot_radius=float(described["foot_radius"]),
            mass=float(described["mass"]),
            massless_links=tuple(described["massless_links"]),
            legs=tuple(legs),
            effort_limits=tuple(float(v) for v in effort) if effort is not None else None,  # type: ignore[arg-type]
            mesh_files=mesh_files,
            digest=_digest(text, urdf_path, mesh_files),
        )

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The 12 actuated joints in the controller's order (FR, FL, RR, RL × abduction, hip, knee)."""
        return tuple(name for leg in self.legs for name in leg.joints)

    @property
    def foot_links(self) -> tuple[str, ...]:
        return tuple(leg.foot_link for leg in self.legs)

    @property
    def foot_offsets(self) -> NDArray[np.float64]:
        """Foot points in their foot links' frames, one row per leg, m."""
        return np.array([leg.foot_offset for leg in self.legs], dtype=np.float64)

    @property
    def crouch(self) -> NDArray[np.float64]:
        """The 12 joint angles (controller order) the robot is placed in before its stand-up, rad."""
        return np.array([q for leg in self.legs for q in leg.crouch], dtype=np.float64)


def installed_package_root() -> Path:
    """Where packages installed into this Python environment put ROS-style package folders."""
    return Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share"


def package_roots_from_env() -> tuple[Path, ...]:
    """The package roots listed in `PFNAV_PACKAGE_PATH`; when unset, `installed_package_root()` if it exists."""
    value = os.environ.get(PACKAGE_PATH_ENV)
    if value is None:
        installed = installed_package_root()
        return (installed.absolute(),) if installed.is_dir() else ()
    return tuple(Path(p).absolute() for p in value.split(os.pathsep) if p)


def describe(config_path: Path, roots: Sequence[Path]) -> dict[str, Any]:
    """`pf-robot describe CONFIG` with `roots` as the package roots: the config as the controller's loader resolves it."""
    env = {**os.environ, PACKAGE_PATH_ENV: os.pathsep.join(str(r) for r in roots)}
    try:
        done = subprocess.run(
            [str(paths.pf_robot_path()), "describe", str(config_path)],
            capture_output=True,
            text=True,
            env=env,
            timeout=DESCRIBE_TIMEOUT_S,
            check=False,
        )
    except subprocess.TimeoutExpired as err:
        raise RobotConfigError(f"robot config {config_path}: pf-robot describe took more than {DESCRIBE_TIMEOUT_S:g} s") from err
    if done.returncode != 0:
        message = done.stderr.strip() or f"pf-robot describe exited with status {done.returncode}"
        raise RobotConfigError(message if str(config_path) in message else f"robot config {config_path}: {message}")
    try:
        described: dict[str, Any] = json.loads(done.stdout)
    except json.JSONDecodeError as err:
        raise RobotConfigError(f"robot config {config_path}: pf-robot describe wrote no JSON ({err})") from err
    return described


def _digest(config_text: str, urdf_path: Path, mesh_files: Sequence[Path]) -> str:
    h = hashlib.sha256()
    h.update(b"config\0" + config_text.encode() + b"\0urdf\0" + urdf_path.read_bytes())
    for mesh in mesh_files:
        h.update(b"\0mesh\0" + mesh.name.encode() + b"\0" + mesh.read_bytes())
    return h.hexdigest()
