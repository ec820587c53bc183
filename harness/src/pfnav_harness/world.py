"""The DART physics world: the scenario's terrain as a triangle mesh and the robot of a robot config on it.

dartpy 6.20 facts this module relies on (see shared notes): the PyPI wheel has no HeightmapShape
binding, so the terrain is an OBJ mesh in a one-link URDF with a fixed root; ODE is the only
detector that keeps spheres on meshes; FreeJoint velocities are world-frame; `setForces` is
cleared by every `world.step()`, so torques are written every physics step.

The robot comes from a `RobotDescription` (robot.py): its URDF loaded by DART with `package://`
resolved through the description's package folders, joints, feet and base by the config's names,
mapped by name (DART orders DOFs by its own rules). What the controller's model treats as a
massless frame (a link without `<inertial>`, or listed in `massless_links`) is made massless here
too: DART would give a link without `<inertial>` 1 kg. Collisions of the robot are its primitive
shapes (boxes, cylinders, spheres), a sphere per foot at the foot point (one of the config's
`foot_radius` where the URDF's foot has none) and, for mesh collision shapes, their bounding
boxes (none on the lower legs): ODE's mesh–mesh contact with the terrain mesh costs a standing
Solo-12 1.8× the time (measured in docs/robots.md).

`WorldSnapshot` (fork a run after stand-up) holds everything that decides the world's future as
plain arrays: every skeleton's generalized positions and velocities, the world time, the torques
held for the next step, the contacts of the last collision check. DART keeps no other state from
one step to the next that changes the physics: accelerations, constraint impulses and contacts are
computed afresh in every `world.step()`, external forces are cleared by it. Restoring it into a
fresh world gives the same trajectory bit for bit (test_hs_fork).
"""

from __future__ import annotations

import hashlib
import logging
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import dartpy as dart
import numpy as np
from numpy.typing import NDArray

from .engine import DEFAULT_FRICTION
from .errors import SimulationError
from .robot import NUM_JOINTS, RobotDescription
from .scenario import Terrain

log = logging.getLogger(__name__)

MESH_COLLISION_MODES = ("boxes", "meshes")


@dataclass(frozen=True)
class Payload:
    """Mass added to (or, negative, taken from) the trunk, as a point mass at `offset`.

    `mass_fraction` is relative to the trunk's mass (0.2 = 20 % heavier); `offset` (m) is in the
    base link's frame (x forward, y left, z up) from the trunk's centre of mass. The trunk is the
    base link and every link welded to it; the payload joins the heaviest of them, which stays one
    rigid body: its mass, centre of mass and inertia become those of it + payload, so the
    controller, which assumes the nominal trunk, sees a model error, as with a real load.
    """

    mass_fraction: float = 0.0
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass_fraction) and self.mass_fraction > -1.0):
            raise SimulationError(f"payload mass fraction must be finite and > -1 (the trunk keeps some mass), got {self.mass_fraction}")
        if len(self.offset) != 3 or not all(math.isfinite(v) for v in self.offset):
            raise SimulationError(f"payload offset must be 3 finite coordinates (m), got {self.offset}")
        object.__setattr__(self, "offset", tuple(float(v) for v in self.offset))


def add_payload(body: dart.dynamics.BodyNode, payload: Payload, trunk_mass: float, trunk_com: NDArray[np.float64], offset: NDArray[np.float64]) -> None:
    """Makes `body` the rigid union of itself and the payload's point mass (parallel-axis theorem).

    The point mass is `payload.mass_fraction · trunk_mass` at `trunk_com + offset`, both in `body`'s
    frame (`trunk_com`: the centre of mass of the whole trunk, `body` one of its links; `offset`:
    the payload's offset turned into `body`'s frame).
    """
    inertia = body.getInertia()
    mass = float(inertia.getMass())
    com = np.asarray(inertia.getLocalCOM(), dtype=np.float64)
    moment = np.asarray(inertia.getMoment(), dtype=np.float64)
    total, new_com, new_moment = loaded_inertia(body.getName(), mass, com, moment, payload, trunk_mass, trunk_com, offset)
    body.setInertia(dart.dynamics.Inertia(total, new_com, new_moment))


def loaded_inertia(
    name: str,
    mass: float,
    com: NDArray[np.float64],
    moment: NDArray[np.float64],
    payload: Payload,
    trunk_mass: float,
    trunk_com: NDArray[np.float64],
    offset: NDArray[np.float64],
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """Mass, centre of mass and inertia about it (body frame) of link `name` (`mass`, `com`, `moment`) with the payload's point mass.

    The arguments are those of `add_payload`; every engine loads its trunk link with these numbers.
    """
    extra = payload.mass_fraction * trunk_mass
    total = mass + extra
    point = trunk_com + offset
    if not total > 0.0:
        raise SimulationError(
            f"payload {payload.mass_fraction:+.0%} of the trunk's {trunk_mass:.3f} kg is more than its heaviest link '{name}' "
            f"({mass:.3f} kg) has: take less mass away"
        )
    new_com = (mass * com + extra * point) / total

    def shifted(m: float, d: NDArray[np.float64]) -> NDArray[np.float64]:
        return m * (float(d @ d) * np.eye(3) - np.outer(d, d))

    new_moment = moment + shifted(mass, com - new_com) + shifted(extra, point - new_com)
    if np.linalg.eigvalsh(new_moment).min() <= 0.0:
        raise SimulationError(
            f"payload {payload.mass_fraction:+.0%} at offset {payload.offset} m leaves the trunk without a positive inertia: "
            "take less mass away, or closer to the centre of mass"
        )
    return total, new_com, new_moment


def load_robot_skeleton(robot: RobotDescription) -> dart.dynamics.Skeleton:
    """The robot's URDF as a DART skeleton with a free root joint, `package://` files resolved.

    The `<visual>` elements are left out: nothing is rendered, and loading the visual meshes of a
    published model (Collada files of tens of MB) takes seconds. The text is parsed with the
    URDF's own location as base URI, so relative mesh paths resolve as in the file.
    """
    try:
        root = ET.parse(robot.urdf_path).getroot()
    except (ET.ParseError, OSError) as err:
        raise SimulationError(f"cannot read the robot URDF {robot.urdf_path}: {err}") from err
    for parent in list(root.iter()):
        for visual in parent.findall("visual"):
            parent.remove(visual)
    loader = dart.utils.DartLoader()
    for name, folder in robot.package_dirs:
        loader.addPackageDirectory(name, str(folder.resolve()))
    skeleton = loader.parseSkeletonString(ET.tostring(root, encoding="unicode"), dart.common.Uri(robot.urdf_path.resolve().as_uri()))
    if skeleton is None:
        raise SimulationError(f"DART could not parse the robot URDF {robot.urdf_path} (robot config {robot.config_path})")
    return skeleton


def make_massless(body: dart.dynamics.BodyNode) -> None:
    """A frame without mass, as the controller's model has it (welded to a body with mass, so DART stays well-posed)."""
    body.setInertia(dart.dynamics.Inertia(0.0, np.zeros(3), np.zeros((3, 3))))


@dataclass(frozen=True)
class MeshBox:
    """The bounding box standing in for a mesh collision shape of link `link` (box centre pose in the link's frame)."""

    link: str
    size: NDArray[np.float64]
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]


def mesh_collision_boxes(skeleton: dart.dynamics.Skeleton, lower_legs: set[str]) -> tuple[list[tuple[dart.dynamics.ShapeNode, MeshBox]], list[str]]:
    """The robot's mesh collision shapes with their bounding boxes, and the links whose meshes get none.

    The lower legs (`lower_legs`: the knees' child links and what is welded to them, feet
    included) collide through the foot spheres only: a box around a lower-leg mesh would reach the
    ground beside the foot. DART reads the meshes (Collada included), so every engine takes its
    stand-in boxes from here.
    """
    boxes: list[tuple[dart.dynamics.ShapeNode, MeshBox]] = []
    dropped: list[tuple[dart.dynamics.ShapeNode, str]] = []
    for i in range(skeleton.getNumBodyNodes()):
        body = skeleton.getBodyNode(i)
        for node in body.getShapeNodes():
            shape = node.getShape()
            if node.getCollisionAspect() is None or not isinstance(shape, dart.dynamics.MeshShape):
                continue
            bounds = shape.getBoundingBox()
            low, high = np.asarray(bounds.getMin()), np.asarray(bounds.getMax())
            if body.getName() in lower_legs or not np.all(high - low > 0.0):
                dropped.append((node, body.getName()))
                continue
            transform = node.getRelativeTransform()
            translation = transform.rotation() @ (0.5 * (low + high)) + transform.translation()
            boxes.append((node, MeshBox(body.getName(), high - low, np.asarray(transform.rotation()), np.asarray(translation))))
    return boxes, [name for _, name in dropped]


def lower_leg_links(skeleton: dart.dynamics.Skeleton, robot: RobotDescription) -> set[str]:
    """The knees' child links and every link welded to them (feet included)."""
    lower_legs: set[str] = set()
    for name in robot.joint_names[2::3]:
        lower_legs.update(body.getName() for body in welded_bodies(skeleton.getJoint(name).getChildBodyNode()))
    return lower_legs


def replace_mesh_collisions(skeleton: dart.dynamics.Skeleton, lower_legs: set[str]) -> tuple[list[str], list[str]]:
    """Mesh collision shapes become primitive stand-ins: their bounding box, or nothing on the links in `lower_legs`
    (`mesh_collision_boxes`). Returns the links given a box and the links left without their mesh."""
    boxes, dropped = mesh_collision_boxes(skeleton, lower_legs)
    for i in range(skeleton.getNumBodyNodes()):
        for node in skeleton.getBodyNode(i).getShapeNodes():
            if node.getCollisionAspect() is not None and isinstance(node.getShape(), dart.dynamics.MeshShape):
                node.removeCollisionAspect()
    for node, box in boxes:
        shape_node = node.getBodyNodePtr().createShapeNode(dart.dynamics.BoxShape(box.size))
        shape_node.setRelativeRotation(box.rotation)
        shape_node.setRelativeTranslation(box.translation)
        shape_node.createCollisionAspect()
        shape_node.createDynamicsAspect()
    return [box.link for _, box in boxes], dropped


def add_foot_sphere(foot: dart.dynamics.BodyNode, radius: float, offset: NDArray[np.float64]) -> None:
    """A collision sphere of `radius` centred on the foot point (`offset` in the foot link's frame)."""
    node = foot.createShapeNode(dart.dynamics.SphereShape(radius))
    node.setRelativeTranslation(np.asarray(offset, dtype=np.float64))
    node.createCollisionAspect()
    node.createDynamicsAspect()


def welded_bodies(root: dart.dynamics.BodyNode) -> list[dart.dynamics.BodyNode]:
    """`root` and every body fixed to it through weld joints (fixed URDF joints), root first."""
    bodies = [root]
    for body in bodies:
        for k in range(body.getNumChildBodyNodes()):
            child = body.getChildBodyNode(k)
            if isinstance(child.getParentJoint(), dart.dynamics.WeldJoint):
                bodies.append(child)
    return bodies


@dataclass
class RobotState:
    """Base and joint state in the conventions of the FMU inputs (world frame, quaternion w,x,y,z)."""

    position: NDArray[np.float64]
    quaternion: NDArray[np.float64]
    linear_velocity: NDArray[np.float64]
    angular_velocity: NDArray[np.float64]
    joint_positions: NDArray[np.float64]
    joint_velocities: NDArray[np.float64]


def rotation_to_quaternion(rot: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit quaternion (w, x, y, z) of a rotation matrix, w ≥ 0 (Shepperd's method)."""
    m = np.asarray(rot, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = math.sqrt(trace + 1.0) * 2.0
        q = np.array([0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s])
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2.0
        q = np.array([(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s])
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2.0
        q = np.array([(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s])
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2.0
        q = np.array([(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s])
    if q[0] < 0.0:
        q = -q
    return q / np.linalg.norm(q)


def _eigen_quaternion(
    m00: float, m01: float, m02: float, m10: float, m11: float, m12: float, m20: float, m21: float, m22: float
) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a rotation matrix (row-major entries) exactly as Eigen's `Quaterniond(Matrix3d)`.

    Shoemake's algorithm with Eigen's operation order, including its trace (an unrolled sum
    m00 + (m11 + m22)); `QuadrupedWorld.state_reader` relies on the result being DART's bit for bit.
    """
    t = m00 + (m11 + m22)
    if t > 0.0:
        t = math.sqrt(t + 1.0)
        w = 0.5 * t
        t = 0.5 / t
        return w, (m21 - m12) * t, (m02 - m20) * t, (m10 - m01) * t
    m = ((m00, m01, m02), (m10, m11, m12), (m20, m21, m22))
    i = 0
    if m11 > m00:
        i = 1
    if m22 > m[i][i]:
        i = 2
    j = (i + 1) % 3
    k = (j + 1) % 3
    t = math.sqrt(m[i][i] - m[j][j] - m[k][k] + 1.0)
    xyz = [0.0, 0.0, 0.0]
    xyz[i] = 0.5 * t
    t = 0.5 / t
    w = (m[k][j] - m[j][k]) * t
    xyz[j] = (m[j][i] + m[i][j]) * t
    xyz[k] = (m[k][i] + m[i][k]) * t
    return w, xyz[0], xyz[1], xyz[2]


def quaternion_to_rotation(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in q)
    return np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )


def quaternion_to_rpy(q: NDArray[np.float64]) -> tuple[float, float, float]:
    """Roll, pitch, yaw (ZYX convention) of a quaternion (w, x, y, z)."""
    w, x, y, z = q.tolist() if isinstance(q, np.ndarray) else (float(v) for v in q)
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def _identity_free_root(skeleton: dart.dynamics.Skeleton, base: dart.dynamics.BodyNode) -> bool:
    """Whether `base` hangs on a free joint with identity offsets, so its pose is the joint's coordinates."""
    joint = base.getParentJoint()
    if not isinstance(joint, dart.dynamics.FreeJoint) or skeleton.getRootBodyNode().getName() != base.getName():
        return False
    offsets = (joint.getTransformFromParentBodyNode(), joint.getTransformFromChildBodyNode())
    return all(np.array_equal(offset.matrix(), np.eye(4)) for offset in offsets)


def write_terrain_obj(terrain: Terrain, path: Path) -> None:
    """Writes the terrain mesh as Wavefront OBJ (1-based indices, counter-clockwise from +z)."""
    vertices = terrain.vertices()
    faces = terrain.triangles() + 1
    lines = ["# pfnav terrain mesh through the map's cell-centre heights"]
    lines.extend(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices)
    lines.extend(f"f {a} {b} {c}" for a, b, c in faces)
    path.write_text("\n".join(lines) + "\n")


def terrain_digest(terrain: Terrain) -> str:
    h = hashlib.sha256()
    h.update(np.asarray(terrain.origin, dtype=np.float64).tobytes())
    h.update(np.float64(terrain.resolution).tobytes())
    h.update(np.asarray(terrain.shape, dtype=np.int64).tobytes())
    h.update(terrain.heights.tobytes())
    return h.hexdigest()[:16]




def set_friction(skeleton: dart.dynamics.Skeleton, mu: float) -> None:
    """Friction coefficient of every collision shape of `skeleton` (restitution 0)."""
    if not (math.isfinite(mu) and mu > 0.0):
        raise SimulationError(f"friction coefficient must be > 0, got {mu}")
    for i in range(skeleton.getNumBodyNodes()):
        body = skeleton.getBodyNode(i)
        for node in body.getShapeNodes():
            if node.getCollisionAspect() is None:
                continue
            aspect = node.getDynamicsAspect()
            if aspect is None:
                aspect = node.createDynamicsAspect()
            aspect.setFrictionCoeff(mu)
            aspect.setRestitutionCoeff(0.0)


def load_terrain_skeleton(terrain: Terrain, cache_dir: Path, friction: float) -> dart.dynamics.Skeleton:
    """The terrain as a fixed one-link skeleton whose collision shape is the map's triangle mesh."""
    cache_dir.mkdir(parents=True, exist_ok=True)
    stem = f"terrain_{terrain_digest(terrain)}"
    obj = cache_dir / f"{stem}.obj"
    urdf = cache_dir / f"{stem}.urdf"
    if not obj.is_file():
        write_terrain_obj(terrain, obj)
    urdf.write_text(
        '<?xml version="1.0"?>\n<robot name="terrain"><link name="terrain">'
        f'<collision><geometry><mesh filename="{obj.name}"/></geometry></collision>'
        "</link></robot>\n"
    )
    loader = dart.utils.DartLoader()
    options = dart.utils.DartLoader.Options()
    options.mDefaultRootJointType = dart.utils.DartLoader.RootJointType.FIXED
    loader.setOptions(options)
    skeleton = loader.parseSkeleton(dart.common.Uri(urdf.resolve().as_uri()))
    if skeleton is None or skeleton.getNumBodyNodes() != 1:
        raise SimulationError(f"DART could not load the terrain mesh {obj}")
    body = skeleton.getBodyNode(0)
    if not any(node.getCollisionAspect() is not None for node in body.getShapeNodes()):
        raise SimulationError(f"the terrain mesh {obj} loaded without a collision shape")
    skeleton.setName("terrain")
    set_friction(skeleton, friction)
    return skeleton


@dataclass(frozen=True)
class WorldSnapshot:
    """The state of a `QuadrupedWorld` from which its future follows, as plain (picklable) arrays.

    `positions`/`velocities` per skeleton name (the fixed terrain has none), `held_torques` the
    generalized forces `step()` applies until the next `apply_torques`, `contacts` what
    `foot_contacts()` reported after the last step (the body sensors read it before the next one).
    Mass properties (payload) and friction are not part of it: they belong to the world a snapshot
    is restored into.
    """

    time: float
    positions: dict[str, NDArray[np.float64]]
    velocities: dict[str, NDArray[np.float64]]
    held_torques: NDArray[np.float64]
    contacts: NDArray[np.bool_]


class QuadrupedWorld:
    """DART world with terrain and robot, and the state/torque exchange the co-simulation needs
    (the DART implementation of engine.PhysicsEngine).

    `mesh_collisions`: "boxes" (default) turns the robot's mesh collision shapes into their bounding
    boxes (none on the lower legs), "meshes" keeps them as the URDF has them (slower; for comparing,
    scripts/bench_robot_collisions.py).
    """

    def __init__(
        self,
        terrain: Terrain,
        robot: RobotDescription,
        cache_dir: Path,
        time_step: float = 0.001,
        friction: float = DEFAULT_FRICTION,
        enforce_joint_limits: bool = True,
        payload: Payload | None = None,
        mesh_collisions: str = "boxes",
    ) -> None:
        self.name = "dart"
        if not (time_step > 0.0 and math.isfinite(time_step)):
            raise SimulationError(f"physics time step must be positive, got {time_step}")
        if mesh_collisions not in MESH_COLLISION_MODES:
            raise SimulationError(f"unknown mesh collision mode '{mesh_collisions}' (choose from {', '.join(MESH_COLLISION_MODES)})")
        self.terrain = terrain
        self.description = robot
        self.world = dart.simulation.World()
        self.world.setTimeStep(time_step)
        self.world.setGravity(np.array([0.0, 0.0, -9.81]))
        self.world.setCollisionDetector(dart.collision.OdeCollisionDetector())
        # DART's resting-body deactivation (on by default in dartpy 6.20) is meant for passive bodies:
        # a robot held by its controller is never left alone, and the speed checks it makes on
        # every body in every step were ~7 % of world.step (the runs are the same bit for bit).
        deactivation = self.world.getDeactivationOptions()
        deactivation.mEnabled = False
        self.world.setDeactivationOptions(deactivation)
        self.terrain_skeleton = load_terrain_skeleton(terrain, cache_dir, friction)
        self.world.addSkeleton(self.terrain_skeleton)

        skeleton = load_robot_skeleton(robot)
        self.robot = skeleton
        where = f"{robot.urdf_path} (robot config {robot.config_path})"
        self.base = skeleton.getBodyNode(robot.base_link)
        if self.base is None:
            raise SimulationError(f"{where}: no link named '{robot.base_link}'")
        if self.base.getParentBodyNode() is not None:
            raise SimulationError(f"{where}: base link '{robot.base_link}' is not the root of the URDF tree")
        for name in robot.massless_links:
            body = skeleton.getBodyNode(name)
            if body is None:
                raise SimulationError(f"{where}: no link named '{name}' (massless_links)")
            make_massless(body)
        self.joint_dofs = np.zeros(NUM_JOINTS, dtype=np.int64)
        for k, name in enumerate(robot.joint_names):
            joint = skeleton.getJoint(name)
            if joint is None or joint.getNumDofs() != 1:
                raise SimulationError(f"{where}: missing revolute joint '{name}'")
            joint.setLimitEnforcement(enforce_joint_limits)
            self.joint_dofs[k] = joint.getIndexInSkeleton(0)
        self.feet = []
        for name in robot.foot_links:
            foot = skeleton.getBodyNode(name)
            if foot is None:
                raise SimulationError(f"{where}: missing foot link '{name}'")
            self.feet.append(foot)
        self.foot_offsets = robot.foot_offsets
        self.foot_radius = robot.foot_radius
        lower_legs = lower_leg_links(skeleton, robot)
        boxed, dropped = replace_mesh_collisions(skeleton, lower_legs) if mesh_collisions == "boxes" else ([], [])
        if boxed or dropped:
            log.info(
                "%s: mesh collisions replaced by their bounding boxes on %d links (%s), dropped on the lower legs (%s)",
                robot.config_path,
                len(boxed),
                ", ".join(boxed) or "none",
                ", ".join(dropped) or "none",
            )
        for leg, foot, offset in zip(robot.legs, self.feet, self.foot_offsets, strict=True):
            if not leg.has_foot_sphere:
                add_foot_sphere(foot, self.foot_radius, offset)
        if not all(leg.has_foot_sphere for leg in robot.legs):
            log.info("%s: foot links without a sphere collision get a sphere of foot_radius %.4g m at the foot point", robot.config_path, self.foot_radius)
        # The collision shapes of each foot, by their (unique) shape node names, for the contact forces.
        self._leg_of_shape_frame = {
            foot.getShapeNode(k).getName(): leg for leg, foot in enumerate(self.feet) for k in range(foot.getNumShapeNodes())
        }
        self._leg_of_collision_object: dict[object, int] = {}
        # The trunk: the base and every link welded to it; a payload joins the heaviest of them.
        self.trunk_bodies = welded_bodies(self.base)
        self.trunk_body = max(self.trunk_bodies, key=lambda body: body.getMass())
        self.trunk_mass = float(sum(body.getMass() for body in self.trunk_bodies))
        if not self.trunk_mass > 0.0:
            raise SimulationError(f"{where}: the trunk ('{robot.base_link}' and the links welded to it) has no mass")
        if payload is not None:
            offset = np.asarray(payload.offset)
            if self.trunk_body.getName() != self.base.getName():
                # The offset is given in the base's frame.
                rotation = np.asarray(self.trunk_body.getWorldTransform().rotation()).T @ np.asarray(self.base.getWorldTransform().rotation())
                offset = rotation @ offset
            add_payload(self.trunk_body, payload, self.trunk_mass, self._trunk_com(), offset)
        # Pushes act at the trunk's centre of mass, a fixed point of the trunk body.
        self._push_point = self._trunk_com()
        set_friction(skeleton, friction)
        self.world.addSkeleton(skeleton)
        effort = np.array([skeleton.getJoint(n).getForceUpperLimit(0) for n in robot.joint_names])
        self.effort_limits = np.tile(robot.effort_limits, len(robot.legs)) if robot.effort_limits is not None else effort
        self._positive_limits = bool(np.all(self.effort_limits > 0.0))
        self._effort_low = -self.effort_limits
        self._clamped = np.zeros(NUM_JOINTS)
        self._forces = np.zeros(skeleton.getNumDofs())
        self._fast_state = _identity_free_root(skeleton, self.base)
        # Contacts restored from a snapshot, reported until the first step of this world.
        self._restored_contacts: NDArray[np.bool_] | None = None

    def _trunk_com(self) -> NDArray[np.float64]:
        """The trunk's centre of mass in `trunk_body`'s frame (the welded links keep their relative poses)."""
        body = self.trunk_body
        if len(self.trunk_bodies) == 1:
            # Exactly the body's own value (bit for bit as before trunks of several links).
            return np.asarray(body.getLocalCOM(), dtype=np.float64)
        to_body = np.linalg.inv(body.getWorldTransform().matrix())
        moment = np.zeros(3)
        for other in self.trunk_bodies:
            relative = to_body @ other.getWorldTransform().matrix()
            moment += other.getMass() * (relative[:3, :3] @ np.asarray(other.getLocalCOM()) + relative[:3, 3])
        return moment / sum(other.getMass() for other in self.trunk_bodies)

    @property
    def time(self) -> float:
        return float(self.world.getTime())

    @property
    def time_step(self) -> float:
        return float(self.world.getTimeStep())

    @property
    def mass(self) -> float:
        return float(self.robot.getMass())

    def place(
        self,
        x: float,
        y: float,
        yaw: float,
        joint_positions: NDArray[np.float64] | None = None,
        clearance: float = 0.002,
        align_with_terrain: bool = True,
    ) -> None:
        """Puts the robot at (x, y) facing `yaw`, lowest foot `clearance` above the ground.

        With `align_with_terrain` the body is tilted like the local terrain plane, so on a slope all
        four feet land together instead of the uphill pair carrying the robot first.
        """
        q_joints = self.description.crouch if joint_positions is None else np.asarray(joint_positions, dtype=np.float64)
        if q_joints.shape != (NUM_JOINTS,):
            raise SimulationError(f"expected {NUM_JOINTS} joint positions, got shape {q_joints.shape}")
        pitch = roll = 0.0
        if align_with_terrain:
            plane = self.terrain.plane(x, y)
            along = plane.dzdx * math.cos(yaw) + plane.dzdy * math.sin(yaw)
            across = -plane.dzdx * math.sin(yaw) + plane.dzdy * math.cos(yaw)
            pitch = -math.atan(along)
            roll = math.atan(across / math.sqrt(1.0 + along * along))
        transform = dart.math.Isometry3()
        transform.set_rotation(dart.math.eulerZYXToMatrix(np.array([yaw, pitch, roll])))
        transform.set_translation(np.array([x, y, self.terrain.height_at(x, y) + 1.0]))
        positions = np.zeros(self.robot.getNumDofs())
        positions[0:6] = dart.dynamics.FreeJoint.convertToPositions(transform)
        positions[self.joint_dofs] = q_joints
        self.robot.setPositions(positions)
        self.robot.setVelocities(np.zeros(self.robot.getNumDofs()))
        gaps = []
        for p in self.foot_positions():
            gaps.append(p[2] - self.foot_radius - self.terrain.height_at(float(p[0]), float(p[1])))
        positions[5] -= min(gaps) - clearance
        self.robot.setPositions(positions)

    def set_state(self, state: RobotState) -> None:
        """Puts the robot in `state`: base pose and world-frame twist, joint angles and rates."""
        joint = self.base.getParentJoint()
        if not isinstance(joint, dart.dynamics.FreeJoint):
            raise SimulationError(f"{self.description.config_path}: the base hangs on no free joint, its state cannot be set")
        w, x, y, z = (float(v) for v in state.quaternion)
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        transform = dart.math.Isometry3()
        transform.set_rotation(quaternion_to_rotation(np.array([w, x, y, z]) / norm))
        transform.set_translation(np.asarray(state.position, dtype=np.float64))
        joint.setTransform(transform, dart.dynamics.Frame.World())
        positions = self.robot.getPositions()
        positions[self.joint_dofs] = state.joint_positions
        self.robot.setPositions(positions)
        velocities = np.zeros(self.robot.getNumDofs())
        velocities[self.joint_dofs] = state.joint_velocities
        self.robot.setVelocities(velocities)
        world = dart.dynamics.Frame.World()
        joint.setSpatialVelocity(np.concatenate([state.angular_velocity, state.linear_velocity]), world, world)

    def center_of_mass(self) -> NDArray[np.float64]:
        return np.asarray(self.robot.getCOM(), dtype=np.float64)

    def touching_links(self) -> list[str]:
        """Robot links other than the feet that touched anything in the last collision check."""
        feet = set(self.description.foot_links)
        names = []
        for body in self.world.getLastCollisionResult().getCollidingBodyNodes():
            name = body.getName()
            if name not in feet and body.getSkeleton().getName() == self.robot.getName() and name not in names:
                names.append(name)
        return names

    def joint_position_limits(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        joints = [self.robot.getJoint(name) for name in self.description.joint_names]
        lower = np.array([j.getPositionLowerLimit(0) for j in joints], dtype=np.float64)
        upper = np.array([j.getPositionUpperLimit(0) for j in joints], dtype=np.float64)
        return lower, upper

    def ground_height(self, x: float, y: float) -> float:
        """The terrain mesh's height under (x, y): the mesh is the map's own triangulation (`Terrain.height`)."""
        return self.terrain.height_at(x, y)

    def state(self) -> RobotState:
        transform = self.base.getWorldTransform()
        q = self.robot.getPositions()
        dq = self.robot.getVelocities()
        return RobotState(
            position=np.array(transform.translation()),
            quaternion=rotation_to_quaternion(transform.rotation()),
            linear_velocity=np.array(self.base.getLinearVelocity()),
            angular_velocity=np.array(self.base.getAngularVelocity()),
            joint_positions=q[self.joint_dofs],
            joint_velocities=dq[self.joint_dofs],
        )

    def state_vector(self, out: NDArray[np.float64]) -> None:
        """Writes the 37 FMU state inputs in order pos(3), quat(4), vel(3), omega(3), q(12), dq(12).

        The co-simulation reads this every physics step; `state_reader` gives the same numbers
        (bit for bit) with a fraction of the binding calls.
        """
        self.state_reader(out)()

    def state_vector_reference(self, out: NDArray[np.float64]) -> None:
        """`state_vector` through DART's own base transform and velocity getters: the plain
        definition the fast read-out is checked against (tests)."""
        q = self.robot.getPositions()
        dq = self.robot.getVelocities()
        out[0:3] = q[3:6]
        quat = self.base.getWorldTransform().quaternion()
        # Same sign convention as rotation_to_quaternion: w ≥ 0.
        sign = -1.0 if quat.w() < 0.0 else 1.0
        out[3] = sign * quat.w()
        out[4] = sign * quat.x()
        out[5] = sign * quat.y()
        out[6] = sign * quat.z()
        out[7:10] = self.base.getLinearVelocity()
        out[10:13] = self.base.getAngularVelocity()
        out[13:25] = q[self.joint_dofs]
        out[25:37] = dq[self.joint_dofs]

    def state_reader(self, out: NDArray[np.float64]) -> Callable[[], None]:
        """A function that writes `state_vector(out)` into `out` each time it is called.

        dartpy's getters that return an Isometry3 (`getWorldTransform`) cost ~10 µs a call (its
        type conversion raises and catches internally), more than the rest of the read-out. With
        a free root joint placed by identity offsets (every URDF root here), the base rotation is
        exactly `expMapRot(q[0:3])` and its quaternion is Eigen's (`_eigen_quaternion`);
        `getSpatialVelocity(World, World)` is the angular and linear velocity the two separate
        getters return. Any other root joint falls back to `state_vector_reference`.
        """
        if not self._fast_state:
            return lambda: self.state_vector_reference(out)
        get_q = self.robot.getPositions
        get_dq = self.robot.getVelocities
        exp_map_rot = dart.math.expMapRot
        world_frame = dart.dynamics.Frame.World()
        spatial_velocity = self.base.getSpatialVelocity
        quaternion = _eigen_quaternion
        joints = self.joint_dofs
        position, velocity, omega = out[0:3], out[7:10], out[10:13]
        joint_q, joint_dq = out[13:25], out[25:37]

        def read() -> None:
            q = get_q()
            dq = get_dq()
            position[:] = q[3:6]
            (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = exp_map_rot(q[0:3]).tolist()
            w, x, y, z = quaternion(m00, m01, m02, m10, m11, m12, m20, m21, m22)
            # Same sign convention as rotation_to_quaternion: w ≥ 0.
            if w < 0.0:
                w, x, y, z = -w, -x, -y, -z
            out[3] = w
            out[4] = x
            out[5] = y
            out[6] = z
            twist = spatial_velocity(world_frame, world_frame)
            velocity[:] = twist[3:6]
            omega[:] = twist[0:3]
            joint_q[:] = q[joints]
            joint_dq[:] = dq[joints]

        return read

    def apply_torques(self, torques: NDArray[np.float64]) -> None:
        """Joint torques (canonical order), clamped to the URDF effort limits, for every following
        physics step until the next call."""
        if self._positive_limits:
            # np.clip's values (they differ at most in the sign of a zero, and only at a zero
            # limit) at a third of the cost of its Python wrapper.
            clamped = np.minimum(np.maximum(torques, self._effort_low, out=self._clamped), self.effort_limits, out=self._clamped)
        else:
            clamped = np.clip(torques, -self.effort_limits, self.effort_limits)
        self._forces[self.joint_dofs] = clamped

    def step(self) -> None:
        # DART clears the generalized forces in every step, so they are written again each time.
        self.robot.setForces(self._forces)
        self.world.step()
        self._restored_contacts = None

    def _skeletons(self) -> list[dart.dynamics.Skeleton]:
        return [self.world.getSkeleton(i) for i in range(self.world.getNumSkeletons())]

    def snapshot(self) -> WorldSnapshot:
        """The world's state now (copies; see `WorldSnapshot`)."""
        skeletons = [s for s in self._skeletons() if s.getNumDofs() > 0]
        return WorldSnapshot(
            time=self.time,
            positions={s.getName(): np.array(s.getPositions(), dtype=np.float64) for s in skeletons},
            velocities={s.getName(): np.array(s.getVelocities(), dtype=np.float64) for s in skeletons},
            held_torques=self._forces.copy(),
            contacts=self.foot_contacts(),
        )

    def restore(self, snapshot: object) -> None:
        """Puts the world in the state of `snapshot` (taken in this world or in one built the same way).

        Pending external forces (pushes) are cleared; this world's own payload and friction stay.
        """
        if not isinstance(snapshot, WorldSnapshot):
            raise SimulationError(f"a DART world cannot restore a {type(snapshot).__name__} (taken in another engine)")
        skeletons = {s.getName(): s for s in self._skeletons() if s.getNumDofs() > 0}
        if set(skeletons) != set(snapshot.positions) or set(skeletons) != set(snapshot.velocities):
            raise SimulationError(f"the snapshot holds skeletons {sorted(snapshot.positions)}, this world has {sorted(skeletons)}")
        for name, skeleton in skeletons.items():
            q, dq = snapshot.positions[name], snapshot.velocities[name]
            n = skeleton.getNumDofs()
            if q.shape != (n,) or dq.shape != (n,):
                raise SimulationError(f"snapshot of skeleton '{name}' has {q.shape[0]} positions and {dq.shape[0]} velocities, the skeleton {n} dofs")
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
                raise SimulationError(f"snapshot of skeleton '{name}' is not finite")
            skeleton.setPositions(q)
            skeleton.setVelocities(dq)
            skeleton.clearExternalForces()
            skeleton.clearInternalForces()
        if snapshot.held_torques.shape != self._forces.shape or snapshot.contacts.shape != (len(self.feet),):
            raise SimulationError("the snapshot's torques or contacts do not fit this robot")
        self._forces[:] = snapshot.held_torques
        self._trunk_force_applied = False
        self._restored_contacts = snapshot.contacts.copy()
        self.world.setTime(snapshot.time)

    def set_friction(self, mu: float) -> None:
        """Ground and foot friction coefficient from now on."""
        set_friction(self.terrain_skeleton, mu)
        set_friction(self.robot, mu)

    # Whether the trunk carries a force from `apply_trunk_force` that has not been cleared yet.
    _trunk_force_applied = False

    def apply_trunk_force(self, force: tuple[float, float, float] | NDArray[np.float64] | None) -> None:
        """External force (world frame, N) at the trunk's centre of mass for the next `step()` only.

        Call it before every physics step with that step's force (None: no force). dartpy 6.20's
        `world.step()` clears external forces itself (test_hs_pushes checks it); the previous force
        is cleared here as well, so a push acts on exactly the steps it was given for whatever a
        DART version does.
        """
        if force is None:
            if self._trunk_force_applied:
                self.trunk_body.clearExternalForces()
                self._trunk_force_applied = False
            return
        self.trunk_body.clearExternalForces()
        # Force in the world frame, point of application the trunk's centre of mass (body frame).
        self.trunk_body.addExtForce(np.asarray(force, dtype=np.float64), self._push_point, False, True)
        self._trunk_force_applied = True

    def linear_momentum(self) -> NDArray[np.float64]:
        """The whole robot's linear momentum (world frame, N·s)."""
        return self.mass * np.asarray(self.robot.getCOMLinearVelocity())

    def foot_positions(self) -> NDArray[np.float64]:
        """The foot points (sphere centres) in the world frame, one row per leg."""
        return self.foot_poses()[1]

    def foot_poses(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The foot links' world rotations (legs × 3 × 3) and the foot points (sphere centres, legs × 3)."""
        rotations = np.zeros((len(self.feet), 3, 3))
        points = np.zeros((len(self.feet), 3))
        for i, (foot, offset) in enumerate(zip(self.feet, self.foot_offsets, strict=True)):
            transform = foot.getWorldTransform()
            rotations[i] = transform.rotation()
            points[i] = rotations[i] @ offset + transform.translation()
        return rotations, points

    def foot_contacts(self) -> NDArray[np.bool_]:
        """Which feet touch anything, from the last collision check of the physics step."""
        touching = np.zeros(len(self.feet), dtype=bool)
        self.write_foot_contacts(touching)
        return touching

    def write_foot_forces(self, out: NDArray[np.float64]) -> None:
        out[:] = 0.0
        if self._restored_contacts is not None:
            return
        result = self.world.getLastCollisionResult()
        count = result.getNumContacts()
        if count == 0:
            return
        forces = np.zeros((len(self.feet), 3))
        for i in range(count):
            contact = result.getContact(i)
            # DART's contact force acts on the first object: a foot that is the second one gets
            # its opposite (a foot's contacts are summed as vectors, so the sign matters).
            leg = self._leg_of_object(contact.collisionObject1)
            if leg >= 0:
                forces[leg] += contact.force
                continue
            leg = self._leg_of_object(contact.collisionObject2)
            if leg >= 0:
                forces[leg] -= contact.force
        out[:] = np.linalg.norm(forces, axis=1)

    def _leg_of_object(self, collision_object: object) -> int:
        """The leg whose foot `collision_object` belongs to, −1 for none. dartpy hands out the same
        Python object for a collision object while one is alive, so the answer is kept by it (the
        name lookup behind it costs more than the rest of a contact)."""
        leg = self._leg_of_collision_object.get(collision_object)
        if leg is None:
            name = collision_object.getShapeFrame().getName()  # type: ignore[attr-defined]
            leg = self._leg_of_shape_frame.get(name, -1)
            self._leg_of_collision_object[collision_object] = leg
        return leg

    def write_foot_contacts(self, out: NDArray[np.generic]) -> None:
        """`foot_contacts()` into `out` (one entry per leg), without allocating."""
        if self._restored_contacts is not None:
            out[:] = self._restored_contacts
            return
        in_collision = self.world.getLastCollisionResult().inCollision
        out[:] = [in_collision(foot) for foot in self.feet]
