"""Pushes: command-line text, seeded campaigns, and the impulse they deliver to the DART robot's trunk."""

from __future__ import annotations

import math
from pathlib import Path

import dartpy as dart
import numpy as np
import pytest

from pfnav_harness import paths
from pfnav_harness.errors import HarnessError
from pfnav_harness.pushes import Push, PushError, PushSchedule, parse_push, random_pushes
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Terrain
from pfnav_harness.world import QuadrupedWorld

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())


# --- text and schedules -------------------------------------------------------------------------
def test_parses_world_frame_pushes() -> None:
    push = parse_push("60@90:5.0+0.2")
    assert (push.start, push.duration, push.heading_relative) == (5.0, 0.2, False)
    assert push.force == pytest.approx((0.0, 60.0, 0.0), abs=1e-12)
    assert push.impulse == pytest.approx(12.0)
    push = parse_push(" 25.5 @ -135 : 1e1 + .05 ")
    assert push.force == pytest.approx((-25.5 / math.sqrt(2), -25.5 / math.sqrt(2), 0.0))
    assert (push.start, push.duration) == (10.0, 0.05)


@pytest.mark.parametrize(("name", "angle"), [("side", 90.0), ("left", 90.0), ("RIGHT", -90.0), ("front", 0.0), ("back", 180.0)])
def test_heading_relative_pushes_resolve_at_their_start(name: str, angle: float) -> None:
    schedule = PushSchedule.parse([f"40@{name}:1.0+0.5"])
    assert schedule.force_at(0.999, yaw=0.3) is None
    first = schedule.force_at(1.0, yaw=0.3)
    expected = (40.0 * math.cos(0.3 + math.radians(angle)), 40.0 * math.sin(0.3 + math.radians(angle)), 0.0)
    assert first == pytest.approx(expected, abs=1e-9)
    # The robot turns during the push; the shove keeps its world direction.
    assert schedule.force_at(1.2, yaw=2.0) == first
    assert schedule.resolved_forces() == [first]
    schedule.reset()
    assert schedule.resolved_forces() == [None]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("60@90:5.0", "expected MAG@DIR:START\\+DURATION"),
        ("60:5.0+0.2", "expected MAG@DIR:START\\+DURATION"),
        ("sixty@90:5+0.2", "expected"),
        ("", "expected"),
        ("60@up:5+0.2", "unknown direction 'up'"),
        ("0@90:5+0.2", "magnitude must be > 0"),
        ("-60@90:5+0.2", "magnitude must be > 0"),
        ("60@90:-1+0.2", "start must be a time >= 0"),
        ("60@90:5+0", "duration must be > 0"),
        ("60@90:5+-0.2", "duration must be > 0"),
        ("1e999@90:5+0.2", "magnitude must be > 0"),
    ],
)
def test_bad_push_text_is_refused_with_the_reason(text: str, message: str) -> None:
    with pytest.raises(PushError, match=message) as caught:
        parse_push(text)
    # One error type for the CLI (HarnessError) and for argparse's `type=` (ValueError).
    assert isinstance(caught.value, HarnessError) and isinstance(caught.value, ValueError)
    assert text.strip() == "" or repr(text)[1:-1] in str(caught.value)


def test_window_is_half_open_and_overlaps_add_up() -> None:
    schedule = PushSchedule([Push(0.2, 0.1, (10.0, 0.0, 0.0)), Push(0.25, 0.1, (0.0, 5.0, 1.0))])
    dt = 0.001
    active = [k for k in range(1000) if schedule.force_at(k * dt) is not None]
    # Steps 200 … 349: [0.2, 0.3) ∪ [0.25, 0.35), step times built the way the co-simulation builds them.
    assert active == list(range(200, 350))
    assert schedule.force_at(0.26) == pytest.approx((10.0, 5.0, 1.0))
    assert schedule.force_at(0.3) == pytest.approx((0.0, 5.0, 1.0))
    assert schedule.force_at(0.35) is None and schedule.force_at(99.0) is None
    steps_of_first = sum(1 for k in range(1000) if Push(0.2, 0.1, (1.0, 0.0, 0.0)).active(k * dt))
    assert steps_of_first == 100  # exactly duration / dt steps despite 0.1 / 0.001 rounding
    with pytest.raises(PushError, match="duration"):
        Push(0.0, -1.0, (1.0, 0.0, 0.0))
    with pytest.raises(PushError, match="finite"):
        Push(0.0, 1.0, (math.nan, 0.0, 0.0))


def test_random_pushes_are_reproducible() -> None:
    a = random_pushes(seed=4, count=12, magnitude=50.0, duration=0.1, window=(2.0, 20.0))
    b = random_pushes(seed=4, count=12, magnitude=50.0, duration=0.1, window=(2.0, 20.0))
    c = random_pushes(seed=5, count=12, magnitude=50.0, duration=0.1, window=(2.0, 20.0))
    assert list(a) == list(b)
    assert list(a) != list(c)
    assert len(a) == 12
    starts = np.array([p.start for p in a])
    assert np.all((starts >= 2.0) & (starts <= 20.0)) and np.all(np.diff(starts) >= 0.0)
    # Starts on the physics step, so each push acts for exactly duration / dt steps.
    np.testing.assert_allclose(starts / 0.001, np.round(starts / 0.001), atol=1e-6)
    for push in a:
        assert push.magnitude == pytest.approx(50.0) and push.force[2] == 0.0 and not push.heading_relative
    # Directions cover the circle (uniform: 200 draws leave no quadrant empty).
    many = random_pushes(seed=1, count=200, magnitude=1.0, duration=0.1, window=(0.0, 1.0), time_step=0.0)
    quadrants = {int(math.atan2(p.force[1], p.force[0]) // (math.pi / 2)) for p in many}
    assert quadrants == {-2, -1, 0, 1}
    with pytest.raises(PushError, match="window"):
        random_pushes(seed=1, count=1, magnitude=1.0, duration=0.1, window=(3.0, 1.0))
    assert len(random_pushes(seed=1, count=0, magnitude=1.0, duration=0.1, window=(0.0, 1.0))) == 0


# --- DART ---------------------------------------------------------------------------------------
def test_dart_step_clears_external_forces() -> None:
    """The dartpy fact `QuadrupedWorld.apply_trunk_force` is documented against (it does not rely on it)."""
    world = dart.simulation.World()
    world.setTimeStep(0.001)
    world.setGravity(np.zeros(3))
    skeleton = dart.dynamics.Skeleton("block")
    _, body = skeleton.createFreeJointAndBodyNodePair()
    body.setMass(2.0)
    world.addSkeleton(skeleton)
    body.addExtForce(np.array([4.0, 0.0, 0.0]), np.zeros(3), False, True)
    velocities = []
    for _ in range(3):
        world.step()
        velocities.append(float(body.getLinearVelocity()[0]))
    assert velocities == pytest.approx([0.002, 0.002, 0.002], abs=1e-15)


def test_push_changes_the_robots_momentum_by_its_impulse(tmp_path: Path) -> None:
    """60 N × 0.2 s on the trunk of the robot in free fall: horizontal momentum +12 N·s, only inside the window.

    In the air the push is the only horizontal external force, so the momentum change is the
    impulse; what remains is DART's constraint solver (joint limits of the limp legs), which
    moves the total momentum by ~1e-4 N·s over this run: the tolerance is 2e-3 N·s (0.02 %).
    """
    terrain = Terrain((0.0, 0.0), 0.25, np.zeros((12, 12)))
    world = QuadrupedWorld(terrain, ROBOT, tmp_path)
    world.place(1.5, 1.5, 0.7)
    positions = world.robot.getPositions()
    positions[5] += 1.0  # 1 m up: 0.3 s of free fall never reaches the ground
    world.robot.setPositions(positions)
    schedule = PushSchedule.parse(["60@30:0.05+0.2"])
    dt = world.time_step
    momentum = [world.linear_momentum()[:2]]
    for _ in range(300):
        world.apply_trunk_force(schedule.force_at(world.time, yaw=0.7))
        world.step()
        assert not world.foot_contacts().any()
        momentum.append(world.linear_momentum()[:2])
    p = np.array(momentum)
    impulse = 12.0 * np.array([math.cos(math.radians(30.0)), math.sin(math.radians(30.0))])
    np.testing.assert_allclose(p[250] - p[50], impulse, atol=2e-3)
    # Each of the 200 steps in [0.05, 0.25) adds force·dt; none outside adds anything.
    per_step = np.hypot(*np.diff(p, axis=0).T)
    np.testing.assert_allclose(per_step[50:250], 60.0 * dt, atol=1e-4)
    assert per_step[:50].max() < 1e-9
    assert per_step[250:].max() < 1e-4


def test_trunk_force_is_set_per_step_not_accumulated(tmp_path: Path) -> None:
    """`apply_trunk_force` replaces the previous step's force and None removes it, without relying on DART's own clearing."""
    terrain = Terrain((0.0, 0.0), 0.25, np.zeros((12, 12)))
    world = QuadrupedWorld(terrain, ROBOT, tmp_path)
    world.place(1.5, 1.5, 0.0)
    base = world.base
    world.apply_trunk_force((30.0, -10.0, 0.0))
    world.apply_trunk_force((30.0, -10.0, 0.0))
    wrench = np.asarray(base.getExternalForceGlobal())  # (torque, force) about the body origin, world frame
    np.testing.assert_allclose(wrench[3:], [30.0, -10.0, 0.0], atol=1e-12)
    world.apply_trunk_force(None)
    np.testing.assert_allclose(np.asarray(base.getExternalForceGlobal()), np.zeros(6), atol=1e-12)
