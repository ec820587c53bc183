"""The MuJoCo physics world: the scenario's terrain as a height field and the robot of a robot config on it.

Built from the same sources as the DART world (world.py), so the two differ in their contact and
joint models only:

* **Robot**: the robot config's URDF through `MjSpec` (MuJoCo's URDF reader) with the base link on
  a free joint, one torque motor per actuated joint limited to the effort limits the DART side
  clamps to (the config's `limits.effort`, else the URDF's), URDF joint limits and damping as the
  URDF gives them. Static links are kept as bodies of their own (MuJoCo would fuse them), so the
  feet are found by the config's names. Links the controller's model treats as massless
  (`RobotDescription.massless_links`) get no mass, as in DART.
* **Collisions**: the URDF's primitive collision shapes; a sphere of `foot_radius` at each foot
  point the URDF has none at; every mesh collision shape replaced by its bounding box, none on the
  lower legs: the same stand-ins the DART world uses by default, computed from the meshes DART
  reads (MuJoCo reads OBJ and STL but not the Collada `.dae` files the Unitree models come with).
  Robot links collide with the ground only, as DART's skeleton has no self-collision check.
* **Terrain**: a height field through exactly the map's cell-centre heights (vertices at the cell
  centres, rows along y; MuJoCo splits each cell along the same diagonal as `Terrain.triangles`,
  checked in test_hs_engines), stored as MuJoCo does in float32: heights agree with the map to
  ~1e-7 of its height range. MuJoCo scales the field's values to [0, 1] × size[2]; the field's
  geom sits at the lowest height, the top at the highest.
* **Physics**: 1 kHz (`time_step`), gravity (0, 0, −9.81), Coulomb friction `friction` on every
  contact (elliptic cone: the friction cone itself; DART's LCP uses a box), no restitution term
  (MuJoCo contacts are inelastic), the implicit-in-velocity integrator MuJoCo recommends.

The state read-out gives what the DART world gives: base position, quaternion (w ≥ 0), the base
origin's linear velocity and the angular velocity both in the world frame (MuJoCo's free joint
keeps the angular velocity in the body frame: it is rotated), joint angles and rates in the
controller's order. As in DART, the contacts `mj_step` reports are those of the state the step
started from.
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from .errors import SimulationError
from .robot import NUM_JOINTS, RobotDescription
from .scenario import Terrain
from .world import (
    DEFAULT_FRICTION,
    MeshBox,
    Payload,
    RobotState,
    load_robot_skeleton,
    loaded_inertia,
    lower_leg_links,
    mesh_collision_boxes,
    quaternion_to_rotation,
    rotation_to_quaternion,
)

log = logging.getLogger(__name__)

# Depth of the height field's base below its lowest point, m (MuJoCo's size[3]; only its bottom face).
HFIELD_BASE_DEPTH = 1.0
# Height range given to a flat height field (MuJoCo needs size[2] > 0; every value is 0 anyway).
FLAT_HFIELD_RANGE = 1e-3
# MuJoCo's default torsional and rolling friction (unused at condim 3, the default: sliding only).
TORSIONAL_FRICTION = 0.005
ROLLING_FRICTION = 0.0001
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 1, 0
GROUND_CONTYPE, GROUND_CONAFFINITY = 0, 1
STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
# MuJoCo's default contact softness (`solref` = time constant, damping ratio), which the worlds keep.
DEFAULT_CONTACT_TIME_CONSTANT = 0.02
CRITICAL_DAMPING_RATIO = 1.0
# Friction-to-normal impedance ratio: at MuJoCo's default (1) its soft friction lets a standing
# robot creep (a PD-held stance on a bumpy slope turned 0.18 rad in 3 s, 0.002 rad in DART); 100,
# as MuJoCo Menagerie's quadruped scenes use with the elliptic cone, leaves 0.02 rad.
FRICTION_IMPEDANCE_RATIO = 100.0
# Foot contact sensors: name prefix, and MuJoCo's contact-sensor parameters (intprm): the data
# field "found" (bit 0: the number of matching contacts) and no reduction of the matches.
FOOT_CONTACT_SENSOR = "foot_contacts:"
CONTACT_SENSOR_FOUND = 1
CONTACT_SENSOR_UNREDUCED = 0


@dataclass(frozen=True)
class MujocoSnapshot:
    """The state of a `MujocoWorld` its future follows from (picklable).

    `state` is MuJoCo's integration state (`mjSTATE_INTEGRATION`: time, positions, velocities,
    the solver's warm start, controls = held torques, applied forces); `contacts` what
    `foot_contacts()` reported after the last step. Mass properties and friction belong to the
    world it is restored into.
    """

    state: NDArray[np.float64]
    contacts: NDArray[np.bool_]


def urdf_for_mujoco(robot: RobotDescription) -> str:
    """The robot's URDF text as MuJoCo reads it: no visuals and no mesh collision shapes (their boxes are added to the spec)."""
    try:
        root = ET.parse(robot.urdf_path).getroot()
    except (ET.ParseError, OSError) as err:
        raise SimulationError(f"cannot read the robot URDF {robot.urdf_path}: {err}") from err
    for parent in list(root.iter()):
        for visual in parent.findall("visual"):
            parent.remove(visual)
        for collision in parent.findall("collision"):
            if collision.find("geometry/mesh") is not None:
                parent.remove(collision)
    return ET.tostring(root, encoding="unicode")


def urdf_mesh_boxes(robot: RobotDescription) -> tuple[list[MeshBox], list[str]]:
    """The bounding boxes standing in for the URDF's mesh collision shapes, and the lower-leg links left without (DART reads the meshes)."""
    if not robot.mesh_files:
        return [], []
    skeleton = load_robot_skeleton(robot)
    boxes, dropped = mesh_collision_boxes(skeleton, lower_leg_links(skeleton, robot))
    return [box for _, box in boxes], dropped


def hfield_layout(terrain: Terrain) -> tuple[NDArray[np.float64], list[float], list[float]]:
    """The height field's normalised values (rows along y), its size (rx, ry, range, base) and its geom position."""
    ny, nx = terrain.shape
    heights = np.asarray(terrain.heights, dtype=np.float64)
    if not np.all(np.isfinite(heights)):
        raise SimulationError("the terrain has non-finite heights: MuJoCo's height field needs a height in every cell")
    low, high = float(heights.min()), float(heights.max())
    span = high - low
    values = (heights - low) / span if span > 0.0 else np.zeros_like(heights)
    res = terrain.resolution
    rx, ry = 0.5 * (nx - 1) * res, 0.5 * (ny - 1) * res
    size = [rx, ry, span if span > 0.0 else FLAT_HFIELD_RANGE, HFIELD_BASE_DEPTH]
    # Vertex (row r, column c) lies at (−rx + c·res, −ry + r·res) from the geom: the cell centres.
    position = [terrain.origin[0] + 0.5 * res + rx, terrain.origin[1] + 0.5 * res + ry, low]
    return values, size, position


def _welded_children(spec_body: mujoco.MjsBody) -> list[mujoco.MjsBody]:
    """`spec_body` and every body fixed to it (no joints in between), root first."""
    bodies = [spec_body]
    for body in bodies:
        child = body.first_body()
        while child is not None:
            if child.first_joint() is None:
                bodies.append(child)
            child = body.next_body(child)
    return bodies


class MujocoWorld:
    """MuJoCo world with terrain and robot (the MuJoCo implementation of engine.PhysicsEngine)."""

    def __init__(
        self,
        terrain: Terrain,
        robot: RobotDescription,
        time_step: float = 0.001,
        friction: float = DEFAULT_FRICTION,
        payload: Payload | None = None,
    ) -> None:
        self.name = "mujoco"
        if not (time_step > 0.0 and math.isfinite(time_step)):
            raise SimulationError(f"physics time step must be positive, got {time_step}")
        if not (math.isfinite(friction) and friction > 0.0):
            raise SimulationError(f"friction coefficient must be > 0, got {friction}")
        self.terrain = terrain
        self.description = robot
        self.foot_radius = robot.foot_radius
        self.foot_offsets = robot.foot_offsets
        where = f"{robot.urdf_path} (robot config {robot.config_path})"
        spec = self._robot_spec(robot, where)
        self._add_terrain(spec, terrain)
        spec.option.timestep = time_step
        spec.option.gravity = [0.0, 0.0, -9.81]
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        spec.option.impratio = FRICTION_IMPEDANCE_RATIO
        # MuJoCo picks dense constraint Jacobians below 60 degrees of freedom; with a dozen or so
        # contacts on an 18-dof robot the sparse ones made mj_step about an eighth cheaper (states
        # replayed from a walk, 2026-11-29). The same equations, summed in another order.
        spec.option.jacobian = mujoco.mjtJacobian.mjJAC_SPARSE
        # One contact sensor per foot link: the number of contacts of its geoms, computed inside
        # mj_step from the contacts it reports (`write_foot_contacts` reads four numbers instead of
        # walking the contact list in Python every step).
        for foot in robot.foot_links:
            spec.add_sensor(
                name=f"{FOOT_CONTACT_SENSOR}{foot}",
                type=mujoco.mjtSensor.mjSENS_CONTACT,
                objtype=mujoco.mjtObj.mjOBJ_BODY,
                objname=foot,
                intprm=[CONTACT_SENSOR_FOUND, CONTACT_SENSOR_UNREDUCED, 1],
            )
        self._spec = spec
        model = self._compile(where)
        self.trunk_names = [b.name for b in _welded_children(spec.body(robot.base_link))]
        self.trunk_body = max(self.trunk_names, key=lambda name: float(model.body(name).mass[0]))
        self.trunk_mass = float(sum(float(model.body(name).mass[0]) for name in self.trunk_names))
        if not self.trunk_mass > 0.0:
            raise SimulationError(f"{where}: the trunk ('{robot.base_link}' and the links welded to it) has no mass")
        if payload is not None:
            self._load_payload(model, payload)
            model = self._compile(where)
        self.model = model
        self.data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, self.data)
        self._trunk_id = model.body(self.trunk_body).id
        # Pushes act at the trunk's centre of mass: its lever about the trunk body's own centre of
        # mass (where MuJoCo applies xfrc_applied) is fixed in the body.
        self._push_lever = self._trunk_com(model) - model.body_ipos[self._trunk_id]
        self._push_has_lever = bool(np.any(self._push_lever != 0.0))
        self._push_pending = False
        self.set_friction(friction)

        self._joint_ids = np.array([model.joint(name).id for name in robot.joint_names], dtype=np.int64)
        self._joint_qpos = model.jnt_qposadr[self._joint_ids].astype(np.int64)
        self._joint_dof = model.jnt_dofadr[self._joint_ids].astype(np.int64)
        self._actuators = np.array([model.actuator(name).id for name in robot.joint_names], dtype=np.int64)
        actuators = _as_slice(self._actuators)
        self._controls: NDArray[np.float64] = self.data.ctrl[actuators] if isinstance(actuators, slice) else self.data.ctrl
        self._write_controls: Callable[[NDArray[np.float64], NDArray[np.float64]], None] = (
            np.copyto if isinstance(actuators, slice) else lambda ctrl, torques: ctrl.__setitem__(self._actuators, torques)
        )
        self._foot_ids = np.array([model.body(name).id for name in robot.foot_links], dtype=np.int64)
        self._leg_of_body = {int(body): leg for leg, body in enumerate(self._foot_ids)}
        self._contact_wrench = np.zeros(6)
        # The foot contact sensors' counts, a live view of the data (legs in the config's order:
        # the sensors were added so, one value each).
        first = int(model.sensor_adr[model.sensor(f"{FOOT_CONTACT_SENSOR}{robot.foot_links[0]}").id])
        self._foot_contact_counts = self.data.sensordata[first : first + len(robot.foot_links)]
        self._robot_bodies = {model.body(i).name for i in range(1, model.nbody)}
        self._restored_contacts: NDArray[np.bool_] | None = None

    def _robot_spec(self, robot: RobotDescription, where: str) -> mujoco.MjSpec:
        try:
            spec = mujoco.MjSpec.from_string(urdf_for_mujoco(robot))
        except ValueError as err:
            raise SimulationError(f"MuJoCo cannot read {where}: {err}") from err
        # Static links stay bodies (the feet are looked up by name); nothing is rendered.
        spec.compiler.fusestatic = False
        spec.compiler.discardvisual = True
        base = spec.body(robot.base_link)
        if base is None:
            raise SimulationError(f"{where}: no link named '{robot.base_link}'")
        if base.parent.name != spec.worldbody.name:
            raise SimulationError(f"{where}: base link '{robot.base_link}' is not the root of the URDF tree")
        base.add_freejoint()
        for name in robot.massless_links:
            body = spec.body(name)
            if body is None:
                raise SimulationError(f"{where}: no link named '{name}' (massless_links)")
            body.explicitinertial = True
            body.mass = 0.0
            body.ipos = [0.0, 0.0, 0.0]
            body.iquat = [1.0, 0.0, 0.0, 0.0]
            body.inertia = [0.0, 0.0, 0.0]
            body.fullinertia = [math.nan, 0.0, 0.0, 0.0, 0.0, 0.0]
        effort = self._effort_limits(robot)
        self.effort_limits = effort
        for k, name in enumerate(robot.joint_names):
            joint = spec.joint(name)
            if joint is None:
                raise SimulationError(f"{where}: missing revolute joint '{name}'")
            # The motor's control range is the limit (the URDF's effort, or the config's override).
            joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_FALSE
            motor = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            motor.gainprm[0] = 1.0
            if math.isfinite(effort[k]):
                motor.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
                motor.ctrlrange = [-effort[k], effort[k]]
            else:
                motor.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        boxes, dropped = urdf_mesh_boxes(robot)
        for box in boxes:
            body = spec.body(box.link)
            geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=0.5 * box.size, pos=box.translation)
            geom.quat = rotation_to_quaternion(box.rotation)
        if boxes or dropped:
            log.info(
                "%s: mesh collisions replaced by their bounding boxes on %d links, dropped on the lower legs (%s)",
                robot.config_path,
                len(boxes),
                ", ".join(sorted(set(dropped))) or "none",
            )
        for leg, offset in zip(robot.legs, robot.foot_offsets, strict=True):
            foot = spec.body(leg.foot_link)
            if foot is None:
                raise SimulationError(f"{where}: missing foot link '{leg.foot_link}'")
            if not leg.has_foot_sphere:
                foot.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[robot.foot_radius, 0.0, 0.0], pos=offset)
        for geom in spec.geoms:
            geom.contype, geom.conaffinity = ROBOT_CONTYPE, ROBOT_CONAFFINITY
            geom.condim = 3
        return spec

    @staticmethod
    def _effort_limits(robot: RobotDescription) -> NDArray[np.float64]:
        """The limits the DART world clamps to: the config's `limits.effort` per role, else each joint's URDF
        effort (none: unlimited, as DART reads such a joint)."""
        if robot.effort_limits is not None:
            return np.tile(np.asarray(robot.effort_limits, dtype=np.float64), len(robot.legs))
        # The URDF's own joints (a <transmission> names joints too).
        joints = {joint.get("name"): joint for joint in ET.parse(robot.urdf_path).getroot().findall("joint")}
        limits = []
        for name in robot.joint_names:
            limit = joints[name].find("limit")
            effort = None if limit is None else limit.get("effort")
            limits.append(math.inf if effort is None else float(effort))
        return np.array(limits, dtype=np.float64)

    def _add_terrain(self, spec: mujoco.MjSpec, terrain: Terrain) -> None:
        values, size, position = hfield_layout(terrain)
        ny, nx = terrain.shape
        field = spec.add_hfield(name="terrain", nrow=ny, ncol=nx, size=size)
        field.userdata = values.ravel().tolist()
        geom = spec.worldbody.add_geom(name="terrain", type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname="terrain", pos=position)
        geom.contype, geom.conaffinity = GROUND_CONTYPE, GROUND_CONAFFINITY
        geom.condim = 3

    def _compile(self, where: str) -> mujoco.MjModel:
        try:
            return self._spec.compile()
        except ValueError as err:
            raise SimulationError(f"MuJoCo cannot compile the model of {where}: {err}") from err

    def _trunk_com(self, model: mujoco.MjModel) -> NDArray[np.float64]:
        """The trunk's centre of mass (all its welded links) in `trunk_body`'s frame, from the model's rest pose."""
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        body = model.body(self.trunk_body).id
        rotation, origin = data.xmat[body].reshape(3, 3), data.xpos[body]
        moment = np.zeros(3)
        total = 0.0
        for name in self.trunk_names:
            other = model.body(name).id
            moment += model.body_mass[other] * data.xipos[other]
            total += float(model.body_mass[other])
        return rotation.T @ (moment / total - origin)

    def _load_payload(self, model: mujoco.MjModel, payload: Payload) -> None:
        """Joins the payload's point mass to the trunk's heaviest link in the spec (`world.loaded_inertia`)."""
        body_id = model.body(self.trunk_body).id
        base_id = model.body(self.description.base_link).id
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        offset = np.asarray(payload.offset, dtype=np.float64)
        if body_id != base_id:
            # The offset is given in the base's frame.
            offset = data.xmat[body_id].reshape(3, 3).T @ data.xmat[base_id].reshape(3, 3) @ offset
        axes = quaternion_to_rotation(model.body_iquat[body_id])
        moment = axes @ np.diag(model.body_inertia[body_id]) @ axes.T
        total, com, loaded = loaded_inertia(
            self.trunk_body, float(model.body_mass[body_id]), model.body_ipos[body_id].copy(), moment, payload, self.trunk_mass, self._trunk_com(model), offset
        )
        body = self._spec.body(self.trunk_body)
        body.explicitinertial = True
        body.mass = total
        body.ipos = com
        body.fullinertia = [loaded[0, 0], loaded[1, 1], loaded[2, 2], loaded[0, 1], loaded[0, 2], loaded[1, 2]]

    # --- the engine interface -------------------------------------------------------------

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def time_step(self) -> float:
        return float(self.model.opt.timestep)

    @property
    def mass(self) -> float:
        return float(self.model.body_mass.sum())

    def place(
        self,
        x: float,
        y: float,
        yaw: float,
        joint_positions: NDArray[np.float64] | None = None,
        clearance: float = 0.002,
        align_with_terrain: bool = True,
    ) -> None:
        """Puts the robot at (x, y) facing `yaw` at rest, lowest foot `clearance` above the ground (as the DART world does)."""
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
        rotation = _rotation_zyx(yaw, pitch, roll)
        data = self.data
        data.qpos[:] = self.model.qpos0
        data.qpos[0:3] = [x, y, self.terrain.height_at(x, y) + 1.0]
        data.qpos[3:7] = rotation_to_quaternion(rotation)
        data.qpos[self._joint_qpos] = q_joints
        data.qvel[:] = 0.0
        gaps = [p[2] - self.foot_radius - self.terrain.height_at(float(p[0]), float(p[1])) for p in self.foot_positions()]
        data.qpos[2] -= min(gaps) - clearance
        mujoco.mj_kinematics(self.model, data)

    def set_state(self, state: RobotState) -> None:
        data = self.data
        quaternion = np.asarray(state.quaternion, dtype=np.float64)
        data.qpos[0:3] = state.position
        data.qpos[3:7] = quaternion / np.linalg.norm(quaternion)
        data.qpos[self._joint_qpos] = state.joint_positions
        data.qvel[:] = 0.0
        data.qvel[0:3] = state.linear_velocity
        # The free joint's angular velocity is in the body frame.
        data.qvel[3:6] = quaternion_to_rotation(data.qpos[3:7]).T @ np.asarray(state.angular_velocity, dtype=np.float64)
        data.qvel[self._joint_dof] = state.joint_velocities
        mujoco.mj_kinematics(self.model, data)

    def state(self) -> RobotState:
        out = np.zeros(37)
        self.state_vector(out)
        return RobotState(out[0:3], out[3:7], out[7:10], out[10:13], out[13:25], out[25:37])

    def state_vector(self, out: NDArray[np.float64]) -> None:
        self.state_reader(out)()

    def state_reader(self, out: NDArray[np.float64]) -> Callable[[], None]:
        qpos, qvel = self.data.qpos, self.data.qvel
        # Every source and target is a view made once (the read-out runs every physics step); a
        # slice where the model keeps the joints in the controller's order, else index arrays.
        joint_qpos, joint_dof = _as_slice(self._joint_qpos), _as_slice(self._joint_dof)
        pose, quaternion, velocity, omega = out[0:7], out[3:7], out[7:10], out[10:13]
        joint_q, joint_dq = out[13:25], out[25:37]
        # Position and quaternion lie side by side in both.
        free_pose, free_velocity, free_omega = qpos[0:7], qvel[0:3], qvel[3:6]
        rotate = mujoco.mju_rotVecQuat
        copy = np.copyto
        negative = np.negative
        if isinstance(joint_qpos, slice) and isinstance(joint_dof, slice):
            qpos_joints, qvel_joints = qpos[joint_qpos], qvel[joint_dof]

            def read() -> None:
                copy(pose, free_pose)
                # Same sign convention as the DART world: w ≥ 0 (either sign rotates alike, bit for bit).
                if quaternion[0] < 0.0:
                    negative(quaternion, out=quaternion)
                copy(velocity, free_velocity)
                rotate(omega, free_omega, quaternion)
                copy(joint_q, qpos_joints)
                copy(joint_dq, qvel_joints)

            return read

        def read_by_index() -> None:
            copy(pose, free_pose)
            if quaternion[0] < 0.0:
                negative(quaternion, out=quaternion)
            copy(velocity, free_velocity)
            rotate(omega, free_omega, quaternion)
            joint_q[:] = qpos[joint_qpos]
            joint_dq[:] = qvel[joint_dof]

        return read_by_index

    def apply_torques(self, torques: NDArray[np.float64]) -> None:
        # The motors' control ranges are the effort limits (`_robot_spec`): MuJoCo clamps the
        # controls to them itself in every step, with the same comparisons as np.clip.
        self._write_controls(self._controls, torques)

    def apply_trunk_force(self, force: tuple[float, float, float] | NDArray[np.float64] | None) -> None:
        applied = self.data.xfrc_applied[self._trunk_id]
        if force is None:
            if self._push_pending:
                applied[:] = 0.0
                self._push_pending = False
            return
        f = np.asarray(force, dtype=np.float64)
        applied[0:3] = f
        if self._push_has_lever:
            # MuJoCo applies the force at the body's centre of mass: add the moment about it.
            mujoco.mj_kinematics(self.model, self.data)
            lever = self.data.xmat[self._trunk_id].reshape(3, 3) @ self._push_lever
            applied[3:6] = np.cross(lever, f)
        else:
            applied[3:6] = 0.0
        self._push_pending = True

    def step(self) -> None:
        mujoco.mj_step(self.model, self.data)
        if self._push_pending:
            # A push acts for the step it was given for (as in the DART world).
            self.data.xfrc_applied[self._trunk_id] = 0.0
            self._push_pending = False
        self._restored_contacts = None

    def snapshot(self) -> MujocoSnapshot:
        state = np.zeros(mujoco.mj_stateSize(self.model, STATE_SPEC))
        mujoco.mj_getState(self.model, self.data, state, STATE_SPEC)
        return MujocoSnapshot(state, self.foot_contacts())

    def restore(self, snapshot: object) -> None:
        if not isinstance(snapshot, MujocoSnapshot):
            raise SimulationError(f"a MuJoCo world cannot restore a {type(snapshot).__name__} (taken in another engine)")
        size = mujoco.mj_stateSize(self.model, STATE_SPEC)
        if snapshot.state.shape != (size,) or snapshot.contacts.shape != (len(self._foot_ids),):
            raise SimulationError(f"the snapshot holds {snapshot.state.shape[0]} state values, this world has {size}: it was taken of another model")
        if not np.all(np.isfinite(snapshot.state)):
            raise SimulationError("the snapshot's state is not finite")
        mujoco.mj_setState(self.model, self.data, snapshot.state, STATE_SPEC)
        self.data.xfrc_applied[:] = 0.0
        self._push_pending = False
        self._restored_contacts = snapshot.contacts.copy()
        mujoco.mj_kinematics(self.model, self.data)

    def set_friction(self, mu: float) -> None:
        """Ground and foot friction coefficient from now on (MuJoCo takes the larger of the two geoms': both are `mu`)."""
        if not (math.isfinite(mu) and mu > 0.0):
            raise SimulationError(f"friction coefficient must be > 0, got {mu}")
        self.model.geom_friction[:] = [mu, TORSIONAL_FRICTION, ROLLING_FRICTION]

    def set_contact_time_constant(self, seconds: float) -> None:
        """Time constant of every contact's soft constraint from now on (MuJoCo's `solref[0]`, critically damped).

        MuJoCo's default, `DEFAULT_CONTACT_TIME_CONSTANT`, lets a standing foot sink a few millimetres
        and bob while its load changes (docs/engines.md); a smaller constant makes the ground stiffer.
        MuJoCo needs at least two physics steps.
        """
        if not (math.isfinite(seconds) and seconds >= 2.0 * self.time_step):
            raise SimulationError(f"contact time constant must be at least two physics steps ({2.0 * self.time_step:g} s), got {seconds}")
        self.model.geom_solref[:] = [seconds, CRITICAL_DAMPING_RATIO]

    def _com_quantities(self) -> None:
        model, data = self.model, self.data
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        mujoco.mj_subtreeVel(model, data)

    def linear_momentum(self) -> NDArray[np.float64]:
        self._com_quantities()
        return self.mass * np.array(self.data.subtree_linvel[0])

    def center_of_mass(self) -> NDArray[np.float64]:
        self._com_quantities()
        return np.array(self.data.subtree_com[0])

    def foot_positions(self) -> NDArray[np.float64]:
        return self.foot_poses()[1]

    def foot_poses(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        mujoco.mj_kinematics(self.model, self.data)
        rotations = self.data.xmat[self._foot_ids].reshape(-1, 3, 3).copy()
        points = np.einsum("kab,kb->ka", rotations, self.foot_offsets) + self.data.xpos[self._foot_ids]
        return rotations, points

    def foot_contacts(self) -> NDArray[np.bool_]:
        touching = np.zeros(len(self._foot_ids), dtype=bool)
        self.write_foot_contacts(touching)
        return touching

    def write_foot_contacts(self, out: NDArray[np.generic]) -> None:
        if self._restored_contacts is not None:
            out[:] = self._restored_contacts
            return
        # Into a boolean `out` without a cast (the co-simulation passes a boolean view of its log row).
        np.greater(self._foot_contact_counts, 0.0, out=out)

    def write_foot_forces(self, out: NDArray[np.float64]) -> None:
        out[:] = 0.0
        if self._restored_contacts is not None:
            return
        data, model = self.data, self.model
        if data.ncon == 0:
            return
        wrench = self._contact_wrench
        forces = np.zeros((len(self._foot_ids), 3))
        for i in range(data.ncon):
            contact = data.contact[i]
            # MuJoCo's contact force (normal and tangential components in the contact's frame,
            # whose rows are the axes) acts on the second geom; a foot that is the first one gets
            # its opposite (a foot's contacts are summed as vectors, so the sign matters).
            for geom, sign in ((contact.geom2, 1.0), (contact.geom1, -1.0)):
                leg = self._leg_of_body.get(int(model.geom_bodyid[geom]))
                if leg is not None:
                    mujoco.mj_contactForce(model, data, i, wrench)
                    forces[leg] += sign * (contact.frame.reshape(3, 3).T @ wrench[:3])
                    break
        out[:] = np.linalg.norm(forces, axis=1)

    def touching_links(self) -> list[str]:
        feet = set(self.description.foot_links)
        names: list[str] = []
        contact = self.data.contact
        for geom in np.concatenate([contact.geom1, contact.geom2]) if self.data.ncon else []:
            name = self.model.body(int(self.model.geom_bodyid[geom])).name
            if name in self._robot_bodies and name not in feet and name not in names:
                names.append(name)
        return names

    def joint_position_limits(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        ranges = self.model.jnt_range[self._joint_ids]
        limited = self.model.jnt_limited[self._joint_ids].astype(bool)
        lower = np.where(limited, ranges[:, 0], -np.inf)
        upper = np.where(limited, ranges[:, 1], np.inf)
        return lower, upper

    def ground_height(self, x: float, y: float) -> float:
        """The height field's surface under (x, y) by a vertical ray (NaN off the field)."""
        geom = self.model.geom("terrain").id
        top = float(self.model.geom_pos[geom][2] + self.model.hfield_size[0][2]) + 1.0
        distance = mujoco.mj_rayHfield(self.model, self.data, geom, np.array([x, y, top]), np.array([0.0, 0.0, -1.0]))
        return top - distance if distance >= 0.0 else math.nan


def _as_slice(indices: NDArray[np.int64]) -> slice | NDArray[np.int64]:
    """`indices` as the equal slice when they are consecutive and ascending, else unchanged."""
    if len(indices) and np.array_equal(indices, np.arange(indices[0], indices[0] + len(indices))):
        return slice(int(indices[0]), int(indices[0]) + len(indices))
    return indices


def _rotation_zyx(yaw: float, pitch: float, roll: float) -> NDArray[np.float64]:
    """Rz(yaw) · Ry(pitch) · Rx(roll)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )
