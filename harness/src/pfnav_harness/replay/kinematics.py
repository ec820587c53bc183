"""Leg points of the logged robot: the URDF posed by DART at the logged base pose and joint angles.

The co-simulation logs the base pose and the 12 joint angles, not where the feet were; the same
URDF the run walked (`world.load_robot_skeleton`, `package://` resolved) gives them back.
"""

from __future__ import annotations

import dartpy as dart
import numpy as np
from numpy.typing import NDArray

from ..errors import SimulationError
from ..robot import JOINT_ROLES, RobotDescription
from ..world import load_robot_skeleton, quaternion_to_rotation

# Points of a leg's chain, base to ground: the abduction, hip and knee joints, then the foot point.
CHAIN_POINTS = (*JOINT_ROLES, "foot")


class LegKinematics:
    """Forward kinematics of a robot config's legs."""

    def __init__(self, robot: RobotDescription) -> None:
        self.robot = robot
        self.skeleton = load_robot_skeleton(robot)
        base = self.skeleton.getBodyNode(robot.base_link)
        if base is None or not isinstance(base.getParentJoint(), dart.dynamics.FreeJoint):
            raise SimulationError(f"{robot.urdf_path}: base link '{robot.base_link}' is not the free-floating root")
        self.base_joint = base.getParentJoint()
        self.joint_dofs = np.array([self.skeleton.getJoint(name).getIndexInSkeleton(0) for name in robot.joint_names], dtype=np.int64)
        # A URDF joint's frame is its child link's frame: the joint's world position is that link's origin.
        self.chain_bodies = [
            [self.skeleton.getJoint(name).getChildBodyNode() for name in leg.joints] + [self.skeleton.getBodyNode(leg.foot_link)] for leg in robot.legs
        ]
        self.foot_offsets = robot.foot_offsets

    def leg_chains(self, base_pos: NDArray[np.float64], base_quat: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        """World positions of every leg's chain points, shape (frames, legs, len(CHAIN_POINTS), 3).

        `base_pos` (frames, 3), `base_quat` (frames, 4; w, x, y, z) and `q` (frames, 12, the
        controller's joint order) as the co-simulation logs them.
        """
        frames = len(base_pos)
        chains = np.zeros((frames, len(self.chain_bodies), len(CHAIN_POINTS), 3))
        positions = self.skeleton.getPositions()
        world = dart.dynamics.Frame.World()
        for k in range(frames):
            positions[self.joint_dofs] = q[k]
            self.skeleton.setPositions(positions)
            transform = dart.math.Isometry3()
            transform.set_rotation(quaternion_to_rotation(base_quat[k] / np.linalg.norm(base_quat[k])))
            transform.set_translation(np.asarray(base_pos[k], dtype=np.float64))
            self.base_joint.setTransform(transform, world)
            positions = self.skeleton.getPositions()
            for leg, bodies in enumerate(self.chain_bodies):
                for point, body in enumerate(bodies[:-1]):
                    chains[k, leg, point] = body.getWorldTransform().translation()
                foot = bodies[-1].getWorldTransform()
                chains[k, leg, -1] = foot.rotation() @ self.foot_offsets[leg] + foot.translation()
        return chains
