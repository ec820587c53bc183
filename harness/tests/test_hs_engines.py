"""The physics engine interface (engine.PhysicsEngine): one suite that the DART and the MuJoCo world both pass.

Every test builds its world through `make_engine` and uses only the interface, so what is
checked here is what the co-simulation relies on, in either engine: the ground where the map says
it is, gravity and momentum, torque and push conventions, contacts, save and restore.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pfnav_harness import paths
from pfnav_harness.engine import ENGINE_NAMES, PhysicsEngine, make_engine
from pfnav_harness.errors import SimulationError
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Terrain
from pfnav_harness.world import RobotState, quaternion_to_rpy

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says.
ROBOT = RobotDescription.load(paths.default_robot_config_path())
CROUCH = ROBOT.crouch
GRAVITY = np.array([0.0, 0.0, -9.81])


def bumpy_terrain(seed: int = 4) -> Terrain:
    """A 4 m × 3 m map (0.1 m cells) of random bumps on a tilted plane: every cell non-planar, heights from about 0.1 to 0.6 m."""
    rng = np.random.default_rng(seed)
    ny, nx, res = 30, 40, 0.1
    xs = (np.arange(nx) + 0.5) * res
    ys = (np.arange(ny) + 0.5) * res
    plane = 0.2 + 0.05 * xs[None, :] + 0.03 * ys[:, None]
    return Terrain((0.0, 0.0), res, plane + 0.02 * rng.standard_normal((ny, nx)))


def airborne(world: PhysicsEngine, seed: int, tumbling: bool = True) -> RobotState:
    """Sets the robot 1.2 m above the ground, turned, and (`tumbling`) spinning with moving joints; returns the state set."""
    rng = np.random.default_rng(seed)
    quaternion = rng.normal(size=4)
    quaternion /= np.linalg.norm(quaternion)
    if quaternion[0] < 0.0:
        quaternion = -quaternion
    spin = 1.0 if tumbling else 0.0
    state = RobotState(
        position=np.array([2.0, 1.5, world.terrain.height_at(2.0, 1.5) + 1.2]),
        quaternion=quaternion,
        linear_velocity=rng.normal(scale=0.5, size=3),
        angular_velocity=spin * rng.normal(scale=1.0, size=3),
        joint_positions=CROUCH + rng.normal(scale=0.1, size=12),
        joint_velocities=spin * rng.normal(scale=0.5, size=12),
    )
    world.set_state(state)
    return state


@pytest.fixture(params=ENGINE_NAMES)
def engine(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def test_the_ground_is_the_map_s_triangulated_heights(engine: str, tmp_path: Path) -> None:
    """The engine's own ground surface (a ray in MuJoCo's height field) is `Terrain.height` inside the map:
    same vertices at the cell centres, same diagonal in every cell, rows along y, the offset of the lowest height."""
    terrain = bumpy_terrain()
    world = make_engine(engine, terrain, ROBOT, tmp_path)
    rng = np.random.default_rng(8)
    xs = rng.uniform(0.06, 3.94, 400)
    ys = rng.uniform(0.06, 2.94, 400)
    got = np.array([world.ground_height(float(x), float(y)) for x, y in zip(xs, ys, strict=True)])
    # MuJoCo keeps height fields in float32 (normalised to their height range of ~0.6 m).
    np.testing.assert_allclose(got, terrain.height(xs, ys), atol=1e-6)


def test_a_standing_robot_rests_on_the_map_s_surface(engine: str, tmp_path: Path) -> None:
    """Joint PD on the crouch holds the robot on bumpy ground: all four feet in contact, resting on the
    map's surface (penetration under 1 cm), levelled with the slope as placed, no slide."""
    terrain = bumpy_terrain()
    world = make_engine(engine, terrain, ROBOT, tmp_path)
    world.place(2.0, 1.5, 0.3)
    kp, kd = 120.0, 3.0
    for _ in range(1500):
        s = world.state()
        world.apply_torques(kp * (CROUCH - s.joint_positions) - kd * s.joint_velocities)
        world.step()
    s = world.state()
    assert world.foot_contacts().all()
    assert world.touching_links() == []
    # The feet carry the robot: every foot pushes, and together they hold its weight.
    forces = np.zeros(4)
    world.write_foot_forces(forces)
    assert (forces > 0.05 * world.mass * 9.81).all(), forces
    assert forces.sum() == pytest.approx(world.mass * 9.81, rel=0.1)
    assert 0.18 < s.position[2] - terrain.height_at(float(s.position[0]), float(s.position[1])) < 0.32
    assert math.hypot(s.position[0] - 2.0, s.position[1] - 1.5) < 0.1
    feet = world.foot_positions()
    gap = feet[:, 2] - world.foot_radius - terrain.height(feet[:, 0], feet[:, 1])
    assert np.abs(gap).max() < 0.01
    roll, pitch, yaw = quaternion_to_rpy(s.quaternion)
    assert yaw == pytest.approx(0.3, abs=0.05)
    assert abs(roll) < 0.1 and abs(pitch) < 0.1


def test_state_set_is_state_read(engine: str, tmp_path: Path) -> None:
    """`set_state` and `state` / `state_vector` / `state_reader` use the same conventions (world-frame twist, w ≥ 0)."""
    world = make_engine(engine, bumpy_terrain(), ROBOT, tmp_path)
    state = airborne(world, seed=1)
    got = world.state()
    for name in ("position", "quaternion", "linear_velocity", "angular_velocity", "joint_positions", "joint_velocities"):
        np.testing.assert_allclose(getattr(got, name), getattr(state, name), atol=1e-12, err_msg=name)
    vector, fast = np.zeros(37), np.zeros(37)
    world.state_vector(vector)
    world.state_reader(fast)()
    expected = np.concatenate([state.position, state.quaternion, state.linear_velocity, state.angular_velocity, state.joint_positions, state.joint_velocities])
    np.testing.assert_allclose(vector, expected, atol=1e-12)
    np.testing.assert_array_equal(fast, vector)


def test_a_free_falling_robot_gains_momentum_m_g_t(engine: str, tmp_path: Path) -> None:
    """In the air, with the joints at rest, the whole robot's momentum grows by m·g·t and no foot touches."""
    world = make_engine(engine, bumpy_terrain(), ROBOT, tmp_path)
    airborne(world, seed=2, tumbling=False)
    start = world.linear_momentum()
    t0 = world.time
    for _ in range(200):
        world.apply_torques(np.zeros(12))
        world.step()
        assert not world.foot_contacts().any()
    forces = np.full(4, np.nan)
    world.write_foot_forces(forces)
    assert (forces == 0.0).all(), "no force in the air"
    elapsed = world.time - t0
    assert elapsed == pytest.approx(0.2)
    np.testing.assert_allclose(world.linear_momentum(), start + world.mass * GRAVITY * elapsed, atol=1e-9)


def test_the_engines_agree_in_free_flight(tmp_path: Path) -> None:
    """Without contacts the engines integrate the same multibody: a tumbling robot driven by the same
    torques follows the same path in both (up to their integrators: MuJoCo's is implicit in the joint damping)."""
    worlds = [make_engine(name, bumpy_terrain(), ROBOT, tmp_path) for name in ENGINE_NAMES]
    rng = np.random.default_rng(3)
    torques = rng.normal(scale=3.0, size=(200, 12))
    for world in worlds:
        airborne(world, seed=2)
        for tau in torques:
            world.apply_torques(tau)
            world.step()
    reference = worlds[0].state()
    for world in worlds[1:]:
        state = world.state()
        for name in ("position", "quaternion", "linear_velocity", "angular_velocity", "joint_positions", "joint_velocities"):
            np.testing.assert_allclose(getattr(state, name), getattr(reference, name), atol=1e-4, err_msg=name)


def test_a_positive_torque_turns_the_joint_positively_and_the_limits_clamp(engine: str, tmp_path: Path) -> None:
    """A positive knee torque speeds the knee up in its positive direction (both engines read the URDF's axes
    the same way); torques beyond the effort limits act as the limits."""
    worlds = [make_engine(engine, bumpy_terrain(), ROBOT, tmp_path) for _ in range(2)]
    knee = 2
    limit = float(worlds[0].effort_limits[knee])
    for world, magnitude in zip(worlds, (limit, 50.0 * limit), strict=True):
        airborne(world, seed=5, tumbling=False)
        torques = np.zeros(12)
        torques[knee] = magnitude
        world.apply_torques(torques)
        for _ in range(5):
            world.step()
    first, second = worlds[0].state(), worlds[1].state()
    assert first.joint_velocities[knee] > 1.0
    # The other legs' joints stay near rest (they only feel the trunk's reaction).
    assert np.abs(first.joint_velocities[3:]).max() < 0.1 * first.joint_velocities[knee]
    np.testing.assert_array_equal(second.joint_velocities, first.joint_velocities)


def test_a_push_acts_for_the_step_it_is_given_for(engine: str, tmp_path: Path) -> None:
    """A world-frame force on the trunk for 50 steps changes the momentum by F·t (plus gravity) and ends with them."""
    world = make_engine(engine, bumpy_terrain(), ROBOT, tmp_path)
    airborne(world, seed=6, tumbling=False)
    force = np.array([40.0, -25.0, 10.0])
    before = world.linear_momentum()
    dt = world.time_step
    for _ in range(50):
        world.apply_trunk_force(force)
        world.step()
    pushed = world.linear_momentum()
    # The push turns the robot a little about its centre of mass: the time discretisation of that
    # motion is the tolerance (a missing or doubled step of the push would be 0.04 N·s).
    np.testing.assert_allclose(pushed - before, (force + world.mass * GRAVITY) * 50 * dt, atol=1e-3)
    for _ in range(50):
        world.apply_trunk_force(None)
        world.step()
    np.testing.assert_allclose(world.linear_momentum() - pushed, world.mass * GRAVITY * 50 * dt, atol=1e-3)


def test_a_snapshot_continues_bit_for_bit_in_a_fresh_world(engine: str, tmp_path: Path) -> None:
    """Snapshot in one world, restore into a new one: the same states and contacts from there on, and the
    contacts of the step before the snapshot reported until the first step."""

    def make() -> PhysicsEngine:
        world = make_engine(engine, bumpy_terrain(), ROBOT, tmp_path)
        world.place(2.0, 1.5, 0.3)
        return world

    def drive(world: PhysicsEngine, steps: int, k0: int) -> tuple[np.ndarray, np.ndarray]:
        states, contacts = np.zeros((steps, 37)), np.zeros((steps, 4), dtype=bool)
        state = np.zeros(37)
        for k in range(steps):
            world.state_vector(state)
            world.apply_torques(120.0 * (CROUCH - state[13:25]) - 3.0 * state[25:37] + 5.0 * np.sin(0.01 * (k0 + k) + np.arange(12)))
            if (k0 + k) % 97 < 10:
                world.apply_trunk_force((15.0, -5.0, 0.0))
            world.step()
            states[k], contacts[k] = state, world.foot_contacts()
        return states, contacts

    world = make()
    drive(world, 400, 0)
    snapshot = world.snapshot()
    expected = drive(world, 300, 400)
    fresh = make()
    fresh.restore(snapshot)
    assert fresh.time == pytest.approx(0.4)
    np.testing.assert_array_equal(fresh.foot_contacts(), world_contacts_at(snapshot))
    got = drive(fresh, 300, 400)
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_array_equal(got[1], expected[1])
    assert expected[1].any()


def world_contacts_at(snapshot: object) -> np.ndarray:
    contacts = getattr(snapshot, "contacts", None)
    assert isinstance(contacts, np.ndarray)
    return contacts


def test_the_engines_build_the_same_robot(tmp_path: Path) -> None:
    """Both engines read the same config and URDF: mass, centre of mass, feet, joint and effort limits agree."""
    terrain = bumpy_terrain()
    worlds = [make_engine(name, terrain, ROBOT, tmp_path) for name in ENGINE_NAMES]
    for world in worlds:
        world.place(2.0, 1.5, 0.3)
    reference = worlds[0]
    for world in worlds[1:]:
        assert world.mass == pytest.approx(reference.mass, rel=1e-12)
        np.testing.assert_allclose(world.center_of_mass(), reference.center_of_mass(), atol=1e-9)
        np.testing.assert_allclose(world.foot_positions(), reference.foot_positions(), atol=1e-9)
        np.testing.assert_allclose(world.state().position, reference.state().position, atol=1e-9)
        np.testing.assert_array_equal(world.effort_limits, reference.effort_limits)
        for mine, theirs in zip(world.joint_position_limits(), reference.joint_position_limits(), strict=True):
            np.testing.assert_array_equal(mine, theirs)


def test_a_snapshot_of_another_engine_is_refused(tmp_path: Path) -> None:
    worlds = [make_engine(name, bumpy_terrain(), ROBOT, tmp_path) for name in ENGINE_NAMES]
    with pytest.raises(SimulationError):
        worlds[1].restore(worlds[0].snapshot())
    with pytest.raises(SimulationError):
        worlds[0].restore(worlds[1].snapshot())


def test_an_unknown_engine_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SimulationError, match="unknown physics engine 'bullet'"):
        make_engine("bullet", bumpy_terrain(), ROBOT, tmp_path)


def test_a_stiffer_mujoco_ground_lets_the_standing_feet_sink_less(tmp_path: Path) -> None:
    """MuJoCo's contacts are soft (time constant `DEFAULT_CONTACT_TIME_CONSTANT`, MuJoCo's own): a robot held on
    its crouch sinks its feet millimetres into flat ground; a 5 ms constant holds them within a quarter of that."""
    from pfnav_harness.mujoco_world import DEFAULT_CONTACT_TIME_CONSTANT, MujocoWorld

    # Flat: the foot sphere's depth is then the gap below its centre.
    terrain = Terrain((0.0, 0.0), 0.1, np.full((30, 40), 0.2))
    depths = []
    for constant in (None, 0.005):
        world = make_engine("mujoco", terrain, ROBOT, tmp_path)
        assert isinstance(world, MujocoWorld)
        np.testing.assert_array_equal(world.model.geom_solref[:, 0], DEFAULT_CONTACT_TIME_CONSTANT)
        if constant is not None:
            world.set_contact_time_constant(constant)
        world.place(2.0, 1.5, 0.3)
        for _ in range(1000):
            s = world.state()
            world.apply_torques(120.0 * (CROUCH - s.joint_positions) - 3.0 * s.joint_velocities)
            world.step()
        feet = world.foot_positions()
        depths.append(float(np.mean(world.foot_radius + terrain.height(feet[:, 0], feet[:, 1]) - feet[:, 2])))
    assert depths[0] > 0.0015 and 0.0 < depths[1] < 0.25 * depths[0]
    with pytest.raises(SimulationError, match="at least two physics steps"):
        world.set_contact_time_constant(0.001)


def test_mujoco_s_foot_contact_sensors_say_what_its_contact_list_says(tmp_path: Path) -> None:
    """MuJoCo's foot contacts come from one contact sensor per foot link, computed inside the step: at every
    step of a drop onto bumpy ground and a stand with the legs lifted one after the other they name the
    feet whose geoms are in the step's contact list, and every foot both stands and is lifted."""
    from pfnav_harness.mujoco_world import MujocoWorld

    world = make_engine("mujoco", bumpy_terrain(), ROBOT, tmp_path)
    assert isinstance(world, MujocoWorld)
    model, data = world.model, world.data
    leg_of_body = {int(body): leg for leg, body in enumerate(world._foot_ids)}
    world.place(2.0, 1.5, 0.3, clearance=0.05)
    seen = np.zeros((2, 4), dtype=bool)
    for k in range(1600):
        s = world.state()
        target = CROUCH.copy()
        if k >= 400:
            # One leg at a time folds its knee, lifting its foot.
            target[3 * ((k - 400) // 300 % 4) + 2] -= 0.8
        world.apply_torques(120.0 * (target - s.joint_positions) - 3.0 * s.joint_velocities)
        world.step()
        listed = np.zeros(4, dtype=bool)
        for geoms in data.contact.geom[: data.ncon]:
            for geom in geoms:
                leg = leg_of_body.get(int(model.geom_bodyid[geom]))
                if leg is not None:
                    listed[leg] = True
        np.testing.assert_array_equal(world.foot_contacts(), listed, err_msg=f"step {k}")
        if k >= 400:
            seen[0] |= listed
            seen[1] |= ~listed
    assert seen.all()
