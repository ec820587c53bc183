"""The robot the harness simulates: a robot config (TOML) and the URDF it names, read into a `RobotDescription`.

The config format is declared once, by the controller's reader (controller/src/robot_config/; the
key table is in robot/README.md). This module reads the same files for the DART side and checks
what it relies on itself (key names and shapes, the URDF's joints and links, the files), so a bad
file is a `RobotConfigError` naming the key and the file; the value checks of the controller's
model (inertias, axes, limits, IK) stay with the controller, which the FMU runs on the same files.

`package://NAME/PATH` is resolved like `PackagePath::resolve` in
controller/src/robot_config/package_path.rs: `ROOT/NAME/PATH` of the first package root that has
a folder `NAME`; the roots are those passed in, else `PFNAV_PACKAGE_PATH` (':'-separated, empty
entries ignored). When it is unset, the one root is where packages installed into this Python
environment put their share folder (`site-packages/cmeel.prefix/share`: `pip install
example-robot-data` puts the third-party robots there), so `--robot robot/third_party/go1.toml`
works after `scripts/setup.sh` with nothing set; the bundler is given the same roots.
"""

from __future__ import annotations

import hashlib
import math
import os
import sysconfig
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import HarnessError

# The controller's leg names, in the order of its 12 joints (index 3·leg + role).
LEG_LABELS = ("FR", "FL", "RR", "RL")
JOINT_ROLES = ("abduction", "hip", "knee")
NUM_JOINTS = len(LEG_LABELS) * len(JOINT_ROLES)

PACKAGE_PATH_ENV = "PFNAV_PACKAGE_PATH"
PACKAGE_SCHEME = "package://"
KNEE_DIRECTIONS = ("backward", "forward")

# `tuning` is the controller's (bundled into the robot's FMU by bundle-fmu, which checks it); the
# DART side does not read it.
TOP_LEVEL_KEYS = ("urdf", "base_link", "stand_height", "foot_radius", "massless_links", "limits", "tuning", "legs")
LEG_KEYS = ("joints", "foot_link", "foot_offset", "knee_points", "crouch")
LIMIT_KEYS = ("effort", "velocity")
# A foot sphere counts when its centre is this close to the foot point (controller/src/model/urdf.rs).
FOOT_SPHERE_TOLERANCE = 1e-6


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
        """Reads `config_path` and the URDF it names; `package_roots` default to `PFNAV_PACKAGE_PATH`."""
        path = Path(config_path).absolute()
        roots = tuple(Path(p).absolute() for p in package_roots) if package_roots is not None else package_roots_from_env()
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as err:
            raise RobotConfigError(f"robot config {path}: cannot read it ({err})") from err
        reader = _ConfigReader(path)
        try:
            table = tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            raise RobotConfigError(f"robot config {path}: not valid TOML ({err})") from err
        config = reader.config(table)
        urdf_path = reader.resolve(config.urdf, "urdf", roots, path.parent)
        urdf = _Urdf.parse(urdf_path)
        urdf.check_names(config, path)
        spheres = [urdf.foot_sphere_radius(leg.foot_link, leg.foot_offset) for leg in config.legs]
        foot_radius = _foot_radius(config, spheres, path, urdf_path)
        legs = tuple(
            LegDescription(leg.label, leg.joints, leg.foot_link, leg.foot_offset, leg.crouch, leg.knee_points, sphere is not None)
            for leg, sphere in zip(config.legs, spheres, strict=True)
        )
        package_dirs = []
        for name in urdf.package_names():
            folder = _package_dir(name, roots)
            if folder is None:
                raise RobotConfigError(
                    f"{urdf_path}: package `{name}` of its `package://` files is in none of the package roots "
                    f"{[str(r) for r in roots]}; install it and list the folder that contains `{name}/` in {PACKAGE_PATH_ENV}"
                )
            package_dirs.append((name, folder))
        meshes = []
        for reference in urdf.mesh_references():
            try:
                meshes.append(resolve_file(reference, roots, urdf_path.parent))
            except ValueError as err:
                raise RobotConfigError(f"{urdf_path}: mesh {err}") from err
        mesh_files = tuple(sorted(set(meshes)))
        return cls(
            config_path=path,
            config_text=text,
            urdf_path=urdf_path,
            package_roots=roots,
            package_dirs=tuple(package_dirs),
            base_link=config.base_link,
            stand_height=config.stand_height,
            foot_radius=foot_radius,
            massless_links=config.massless_links + tuple(name for name in urdf.links_without_inertial() if name not in config.massless_links),
            legs=legs,
            effort_limits=config.effort_limits,
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


def _package_dir(name: str, roots: Sequence[Path]) -> Path | None:
    return next((root / name for root in roots if (root / name).is_dir()), None)


def resolve_file(reference: str, roots: Sequence[Path], relative_to: Path) -> Path:
    """The file `reference` names: `package://NAME/PATH` through `roots`, a relative path from `relative_to`,
    an absolute path (or `file://` URI) as is. The file must exist; ValueError says why not."""
    rest = reference.removeprefix(PACKAGE_SCHEME) if reference.startswith(PACKAGE_SCHEME) else None
    if rest is not None:
        package, _, inner = rest.partition("/")
        if not package or not inner:
            raise ValueError(f"`{reference}` is not of the form package://NAME/PATH")
        if inner.startswith("/") or any(part in (".", "..") for part in inner.split("/")):
            raise ValueError(f"`{reference}`: the path inside the package must be relative and must not leave it")
        folder = _package_dir(package, roots)
        if folder is None:
            raise ValueError(
                f"package `{package}` of `{reference}` is in none of the package roots {[str(r) for r in roots]}; "
                f"install it and list the folder that contains `{package}/` in {PACKAGE_PATH_ENV}"
            )
        path = folder / PurePosixPath(inner)
    else:
        path = relative_to / reference.removeprefix("file://")
    if not path.is_file():
        raise ValueError(f"`{reference}` resolves to {path}, which is not a file")
    return path


def _digest(config_text: str, urdf_path: Path, mesh_files: Sequence[Path]) -> str:
    h = hashlib.sha256()
    h.update(b"config\0" + config_text.encode() + b"\0urdf\0" + urdf_path.read_bytes())
    for mesh in mesh_files:
        h.update(b"\0mesh\0" + mesh.name.encode() + b"\0" + mesh.read_bytes())
    return h.hexdigest()


def _foot_radius(config: _Config, spheres: Sequence[float | None], config_path: Path, urdf_path: Path) -> float:
    """The feet's sphere radius, else the config's `foot_radius` (the rule of the controller's URDF reader)."""
    found = [(leg.foot_link, r) for leg, r in zip(config.legs, spheres, strict=True) if r is not None]
    for link, radius in found:
        if not (math.isfinite(radius) and radius > 0.0):
            raise RobotConfigError(f"{urdf_path}: the sphere collision of foot link `{link}` has radius {radius}")
        if abs(radius - found[0][1]) > 1e-9:
            raise RobotConfigError(f"{urdf_path}: foot spheres differ: `{found[0][0]}` has radius {found[0][1]}, `{link}` {radius}")
    if found and config.foot_radius is not None and abs(found[0][1] - config.foot_radius) > 1e-9:
        raise RobotConfigError(
            f"robot config {config_path}: key `foot_radius` = {config.foot_radius} contradicts the sphere collision of "
            f"`{found[0][0]}` (radius {found[0][1]}) in {urdf_path}; remove the key"
        )
    if found:
        return found[0][1]
    if config.foot_radius is None:
        links = ", ".join(f"`{leg.foot_link}`" for leg in config.legs)
        raise RobotConfigError(
            f"robot config {config_path}: no foot radius: the foot links ({links}) have no sphere collision at the foot point "
            f"in {urdf_path} and key `foot_radius` is not set"
        )
    return config.foot_radius


@dataclass(frozen=True)
class _Config:
    urdf: str
    base_link: str
    stand_height: float
    foot_radius: float | None
    massless_links: tuple[str, ...]
    legs: tuple[_LegConfig, ...]
    effort_limits: tuple[float, float, float] | None


@dataclass(frozen=True)
class _LegConfig:
    label: str
    joints: tuple[str, str, str]
    foot_link: str
    foot_offset: tuple[float, float, float]
    crouch: tuple[float, float, float]
    knee_points: str


class _ConfigReader:
    """Turns the parsed TOML into a `_Config`; every error names the key and the file."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def error(self, key: str, message: str) -> RobotConfigError:
        return RobotConfigError(f"robot config {self.path}: key `{key}`: {message}")

    def table(self, value: Any, key: str, allowed: Sequence[str]) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(key, f"must be a table, is {type(value).__name__}")
        unknown = sorted(set(value) - set(allowed))
        if unknown:
            name = f"{key}.{unknown[0]}" if key else unknown[0]
            raise RobotConfigError(f"robot config {self.path}: unknown key `{name}` (known here: {', '.join(allowed)})")
        return value

    def required(self, table: dict[str, Any], key: str, prefix: str, hint: str = "") -> Any:
        if key not in table:
            raise RobotConfigError(f"robot config {self.path}: missing key `{prefix}{key}`" + (f"; {hint}" if hint else ""))
        return table[key]

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(key, f"must be a non-empty string, is {value!r}")
        return value

    def number(self, value: Any, key: str, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self.error(key, f"must be a finite number, is {value!r}")
        if positive and not value > 0.0:
            raise self.error(key, f"must be positive, is {value!r}")
        return float(value)

    def numbers(self, value: Any, key: str, count: int, positive: bool = False) -> tuple[float, ...]:
        if not isinstance(value, list) or len(value) != count:
            found = f"{len(value)} values" if isinstance(value, list) else repr(value)
            raise self.error(key, f"expected exactly {count} numbers, found {found}")
        return tuple(self.number(v, key, positive) for v in value)

    def config(self, table: dict[str, Any]) -> _Config:
        self.table(table, "", TOP_LEVEL_KEYS)
        urdf = self.string(self.required(table, "urdf", ""), "urdf")
        base_link = self.string(self.required(table, "base_link", ""), "base_link")
        stand_height = self.number(self.required(table, "stand_height", ""), "stand_height", positive=True)
        foot_radius = self.number(table["foot_radius"], "foot_radius", positive=True) if "foot_radius" in table else None
        massless = table.get("massless_links", [])
        if not isinstance(massless, list):
            raise self.error("massless_links", f"must be a list of link names, is {massless!r}")
        massless_links = tuple(self.string(name, "massless_links") for name in massless)
        limits = self.table(table.get("limits", {}), "limits", LIMIT_KEYS)
        for key in LIMIT_KEYS:
            if key in limits:
                self.numbers(limits[key], f"limits.{key}", 3, positive=True)
        effort = self.numbers(limits["effort"], "limits.effort", 3, positive=True) if "effort" in limits else None
        legs_table = self.table(self.required(table, "legs", ""), "legs", LEG_LABELS)
        legs = tuple(self.leg(label, self.required(legs_table, label, "legs.")) for label in LEG_LABELS)
        joints = [j for leg in legs for j in leg.joints]
        twice = sorted({j for j in joints if joints.count(j) > 1})
        if twice:
            raise RobotConfigError(f"robot config {self.path}: joint `{twice[0]}` is named by two legs")
        return _Config(urdf, base_link, stand_height, foot_radius, massless_links, legs, effort)  # type: ignore[arg-type]

    def leg(self, label: str, value: Any) -> _LegConfig:
        prefix = f"legs.{label}."
        table = self.table(value, f"legs.{label}", LEG_KEYS)
        joints_value = self.required(table, "joints", prefix)
        if not isinstance(joints_value, list) or len(joints_value) != 3:
            found = f"{len(joints_value)}" if isinstance(joints_value, list) else repr(joints_value)
            raise self.error(f"{prefix}joints", f"expected exactly 3 joint names (abduction, hip, knee), found {found}")
        joints = tuple(self.string(j, f"{prefix}joints") for j in joints_value)
        foot_link = self.string(self.required(table, "foot_link", prefix), f"{prefix}foot_link")
        offset = self.numbers(table["foot_offset"], f"{prefix}foot_offset", 3) if "foot_offset" in table else (0.0, 0.0, 0.0)
        knee_points = self.required(table, "knee_points", prefix)
        if knee_points not in KNEE_DIRECTIONS:
            raise self.error(f"{prefix}knee_points", f"must be one of {', '.join(map(repr, KNEE_DIRECTIONS))}, is {knee_points!r}")
        crouch_value = self.required(
            table,
            "crouch",
            prefix,
            "add `crouch = [abduction, hip, knee]` (rad) to the leg's table: the joint angles the robot is placed in before it "
            "stands up (feet roughly under the hips, below the base; see robot/README.md)",
        )
        crouch = self.numbers(crouch_value, f"{prefix}crouch", 3)
        return _LegConfig(label, joints, foot_link, offset, crouch, knee_points)  # type: ignore[arg-type]

    def resolve(self, reference: str, key: str, roots: Sequence[Path], relative_to: Path) -> Path:
        try:
            return resolve_file(reference, roots, relative_to)
        except ValueError as err:
            raise self.error(key, str(err)) from err


class _Urdf:
    """The parts of a URDF the harness checks before DART loads it: link and joint names, foot spheres, files."""

    def __init__(self, path: Path, root: ET.Element) -> None:
        self.path = path
        self.root = root
        self.links = {link.get("name", ""): link for link in root.iter("link")}
        self.joints = {joint.get("name", ""): joint for joint in root.iter("joint") if joint.get("type") is not None}

    @classmethod
    def parse(cls, path: Path) -> _Urdf:
        try:
            root = ET.parse(path).getroot()
        except (ET.ParseError, OSError) as err:
            raise RobotConfigError(f"URDF {path}: cannot parse it ({err})") from err
        if root.tag != "robot":
            raise RobotConfigError(f"URDF {path}: the root element is <{root.tag}>, not <robot>")
        return cls(path, root)

    def check_names(self, config: _Config, config_path: Path) -> None:
        def missing(what: str, name: str, key: str) -> RobotConfigError:
            return RobotConfigError(f"robot config {config_path}: key `{key}`: {what} `{name}` is not in {self.path}")

        if config.base_link not in self.links:
            raise missing("link", config.base_link, "base_link")
        for name in config.massless_links:
            if name not in self.links:
                raise missing("link", name, "massless_links")
        for leg in config.legs:
            for name in leg.joints:
                joint = self.joints.get(name)
                if joint is None:
                    raise missing("joint", name, f"legs.{leg.label}.joints")
                if joint.get("type") not in ("revolute", "continuous"):
                    raise RobotConfigError(
                        f"robot config {config_path}: key `legs.{leg.label}.joints`: joint `{name}` is {joint.get('type')}, not revolute, in {self.path}"
                    )
            if leg.foot_link not in self.links:
                raise missing("link", leg.foot_link, f"legs.{leg.label}.foot_link")

    def foot_sphere_radius(self, link_name: str, offset: Sequence[float]) -> float | None:
        """Radius of `link_name`'s sphere collision centred on the foot point, if it has one."""
        for collision in self.links[link_name].findall("collision"):
            sphere = collision.find("geometry/sphere")
            if sphere is None:
                continue
            origin = collision.find("origin")
            try:
                centre = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
                radius = float(sphere.get("radius", "nan"))
            except ValueError as err:
                raise RobotConfigError(f"URDF {self.path}: link `{link_name}`: malformed sphere collision ({err})") from err
            if len(centre) == 3 and math.dist(centre, offset) < FOOT_SPHERE_TOLERANCE:
                return radius
        return None

    def links_without_inertial(self) -> list[str]:
        return [name for name, link in self.links.items() if link.find("inertial") is None]

    def mesh_references(self) -> list[str]:
        return [mesh.get("filename", "") for mesh in self.root.iter("mesh")]

    def package_names(self) -> list[str]:
        names = []
        for reference in self.mesh_references():
            if reference.startswith(PACKAGE_SCHEME):
                name = reference.removeprefix(PACKAGE_SCHEME).partition("/")[0]
                if name and name not in names:
                    names.append(name)
        return names
