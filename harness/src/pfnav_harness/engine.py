"""The physics engine interface of the co-simulation, and the engines behind it, chosen by name.

The co-simulation (cosim.py), the incline benchmark (incline.py) and the body sensors ask a physics
engine for the same few things: place the robot, step 1 ms, read the trunk and joint state in the
FMU's layout, hold joint torques, push the trunk, say which feet (and which other links) touch
something, and save/restore the state a fork continues from. `PhysicsEngine` is that contract;
`QuadrupedWorld` (world.py, DART) and `MujocoWorld` (mujoco_world.py, MuJoCo) implement it from
the same sources: the robot config and its URDF, the scenario's terrain heights, the friction.

DART is the default: every published result comes from it. MuJoCo is the second opinion
(`--engine mujoco`): a different contact model (soft constraints, elliptic friction cone) under
the same controller.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from .errors import SimulationError

if TYPE_CHECKING:
    # The engines' modules load their engines: imported where a world is made, not by the command line.
    from .robot import RobotDescription
    from .scenario import Terrain
    from .world import Payload, RobotState

ENGINE_NAMES = ("dart", "mujoco")
DEFAULT_ENGINE = "dart"
# How titles name each engine.
ENGINE_TITLES = {"dart": "DART", "mujoco": "MuJoCo"}
# How reports name each engine's physics.
ENGINE_LABELS = {"dart": "DART, ODE collision on the terrain mesh", "mujoco": "MuJoCo, terrain height field"}
# Coulomb friction of feet and ground unless a run sets its own: rubber feet on dry ground, above
# the coefficient the controller's MPC assumes (mpc.mu), so a default run has friction to spare.
DEFAULT_FRICTION = 0.8


@runtime_checkable
class PhysicsEngine(Protocol):
    """One robot on one terrain in one physics engine, stepped by the co-simulation.

    Conventions shared by every engine: world frame z up, gravity (0, 0, −9.81) m/s²; the state
    vector is the FMU's (position, quaternion w-x-y-z with w ≥ 0, world-frame linear and angular
    velocity of the base link's origin, joint angles and rates in the controller's order); joint
    torques are clamped to `effort_limits`; foot points are the foot spheres' centres.
    """

    name: str
    terrain: Terrain
    description: RobotDescription
    foot_radius: float
    effort_limits: NDArray[np.float64]

    @property
    def time(self) -> float: ...

    @property
    def time_step(self) -> float: ...

    @property
    def mass(self) -> float: ...

    def place(
        self,
        x: float,
        y: float,
        yaw: float,
        joint_positions: NDArray[np.float64] | None = None,
        clearance: float = 0.002,
        align_with_terrain: bool = True,
    ) -> None:
        """The robot at (x, y) facing `yaw` at rest, lowest foot `clearance` above the ground (tilted like the terrain)."""
        ...

    def set_state(self, state: RobotState) -> None:
        """Puts the robot in `state` (velocities in the world frame, as `state()` reports them)."""
        ...

    def state(self) -> RobotState: ...

    def state_vector(self, out: NDArray[np.float64]) -> None:
        """The 37 FMU state inputs into `out`: pos(3), quat(4), vel(3), omega(3), q(12), dq(12)."""
        ...

    def state_reader(self, out: NDArray[np.float64]) -> Callable[[], None]:
        """A function that writes `state_vector(out)` each time it is called (the hot loop's read-out)."""
        ...

    def apply_torques(self, torques: NDArray[np.float64]) -> None:
        """Joint torques (controller order), clamped to `effort_limits`, held for every step until the next call."""
        ...

    def apply_trunk_force(self, force: tuple[float, float, float] | NDArray[np.float64] | None) -> None:
        """A world-frame force (N) at the trunk's centre of mass for the next `step()` only (None: none)."""
        ...

    def step(self) -> None: ...

    def snapshot(self) -> object:
        """Everything the world's future depends on (picklable); `restore` in a world built the same way continues it bit for bit."""
        ...

    def restore(self, snapshot: object) -> None: ...

    def set_friction(self, mu: float) -> None: ...

    def linear_momentum(self) -> NDArray[np.float64]: ...

    def center_of_mass(self) -> NDArray[np.float64]:
        """The whole robot's centre of mass, world frame."""
        ...

    def foot_positions(self) -> NDArray[np.float64]: ...

    def foot_poses(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The foot links' world rotations (legs × 3 × 3) and the foot points (legs × 3)."""
        ...

    def foot_contacts(self) -> NDArray[np.bool_]:
        """Which feet touched anything in the last physics step's collision check."""
        ...

    def write_foot_contacts(self, out: NDArray[np.generic]) -> None: ...

    def write_foot_forces(self, out: NDArray[np.float64]) -> None:
        """The magnitude of the contact force on each foot in the last physics step (N, legs in
        the config's order; 0 in the air, and after a restore until the next step)."""
        ...

    def touching_links(self) -> list[str]:
        """Robot links other than the feet that touched anything in the last collision check."""
        ...

    def joint_position_limits(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lower and upper joint limits (controller order, rad; ±inf where a joint has none)."""
        ...

    def ground_height(self, x: float, y: float) -> float:
        """The height of the engine's own ground surface under (x, y) (what the feet stand on)."""
        ...


def make_engine(
    name: str,
    terrain: Terrain,
    robot: RobotDescription,
    cache_dir: Path,
    time_step: float = 0.001,
    friction: float = DEFAULT_FRICTION,
    payload: Payload | None = None,
) -> PhysicsEngine:
    """The physics world of engine `name` ("dart" or "mujoco") with `robot` on `terrain`."""
    if name == "dart":
        from .world import QuadrupedWorld

        return QuadrupedWorld(terrain, robot, cache_dir, time_step, friction, payload=payload)
    if name == "mujoco":
        # Imported here: DART-only runs never load MuJoCo.
        from .mujoco_world import MujocoWorld

        return MujocoWorld(terrain, robot, time_step, friction, payload=payload)
    raise SimulationError(f"unknown physics engine '{name}' (choose from {', '.join(ENGINE_NAMES)})")


def validate_engine_name(name: str) -> str:
    if name not in ENGINE_NAMES:
        raise SimulationError(f"unknown physics engine '{name}' (choose from {', '.join(ENGINE_NAMES)})")
    return name
