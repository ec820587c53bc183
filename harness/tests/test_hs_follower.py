"""The planner's feedback field (interpolation, checks, formats) and the follower that turns it into commands."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from pfnav_harness.errors import PlannerError
from pfnav_harness.feedback_field import FeedbackField
from pfnav_harness.follower import STATUS_APPROACH, STATUS_FALLBACK, STATUS_GOAL, STATUS_NO_FIELD, STATUS_OK, FieldFollower, FollowerCommand, FollowerLimits

RES = 0.25
ORIGIN = (-1.0, 2.0)


def field_from_velocity(vx: np.ndarray, vy: np.ndarray, cost: np.ndarray, goal: tuple[float, float, float] = (9.0, 9.0, 0.2)) -> FeedbackField:
    """A field whose direction·speed is (vx, vy) per cell; zero velocity gives direction (0, 0)."""
    speed = np.hypot(vx, vy)
    safe = np.where(speed > 0.0, speed, 1.0)
    return FeedbackField(ORIGIN, RES, vx / safe, vy / safe, speed, cost, goal)


def cell_centres(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    iy, ix = np.indices(shape)
    return ORIGIN[0] + (ix + 0.5) * RES, ORIGIN[1] + (iy + 0.5) * RES


def linear_field(shape: tuple[int, int] = (6, 8)) -> FeedbackField:
    x, y = cell_centres(shape)
    return field_from_velocity(0.4 + 0.05 * x, 0.1 - 0.03 * y, 2.0 + 0.5 * x + 0.25 * y)


def uniform_field(shape: tuple[int, int], direction: tuple[float, float], speed: float, goal: tuple[float, float, float]) -> FeedbackField:
    """Constant direction and speed, cost-to-go = distance to the goal edge (0 inside)."""
    x, y = cell_centres(shape)
    cost = np.maximum(np.hypot(x - goal[0], y - goal[1]) - goal[2], 0.0)
    inside = cost == 0.0
    dir_x = np.where(inside, 0.0, direction[0])
    dir_y = np.where(inside, 0.0, direction[1])
    return FeedbackField(ORIGIN, RES, dir_x, dir_y, np.where(inside, 0.0, speed), cost, goal)


def radial_field(shape: tuple[int, int], goal: tuple[float, float, float], speed: float = 0.5) -> FeedbackField:
    """The exact optimal law of p ≡ 1: straight at the goal centre, cost = distance to the goal edge."""
    x, y = cell_centres(shape)
    dx, dy = goal[0] - x, goal[1] - y
    dist = np.hypot(dx, dy)
    inside = dist <= goal[2]
    safe = np.where(dist > 0.0, dist, 1.0)
    return FeedbackField(
        ORIGIN,
        RES,
        np.where(inside, 0.0, dx / safe),
        np.where(inside, 0.0, dy / safe),
        np.where(inside, 0.0, speed),
        np.where(inside, 0.0, dist - goal[2]),
        goal,
    )


# --- FeedbackField ------------------------------------------------------------------------------
def test_interpolation_is_exact_on_linear_data() -> None:
    field = linear_field()
    field.validate()
    rng = np.random.default_rng(11)
    # Anywhere between the outermost cell centres all 4 cells exist and bilinear reproduces a linear field.
    lo = np.array(ORIGIN) + 0.5 * RES
    hi = np.array(ORIGIN) + (np.array([8, 6]) - 0.5) * RES
    for x, y in rng.uniform(lo, hi, size=(200, 2)):
        s = field.sample(float(x), float(y))
        assert s is not None
        assert s.vx == pytest.approx(0.4 + 0.05 * x, abs=1e-12)
        assert s.vy == pytest.approx(0.1 - 0.03 * y, abs=1e-12)
        assert s.cost_to_go == pytest.approx(2.0 + 0.5 * x + 0.25 * y, abs=1e-12)


def test_unreachable_cells_are_left_out() -> None:
    shape = (4, 4)
    x, _ = cell_centres(shape)
    vx = np.full(shape, 0.5)
    cost = 1.0 + x
    cost[1, 1] = -1.0
    vx[1, 1] = 0.0  # an obstacle cell has no action
    field = field_from_velocity(vx, np.zeros(shape), cost)
    field.validate()
    # Midway between the centres of cells (1,1), (2,1), (1,2), (2,2): the obstacle's weight goes to the other three.
    px, py = ORIGIN[0] + 2.0 * RES, ORIGIN[1] + 2.0 * RES
    s = field.sample(px, py)
    assert s is not None
    assert s.vx == pytest.approx(0.5)  # not 0.375: "no action" does not leak into the velocity
    assert s.cost_to_go == pytest.approx((cost[1, 2] + cost[2, 1] + cost[2, 2]) / 3.0)
    # All four around a point unreachable → None.
    cost[0:2, 0:2] = -1.0
    blocked = field_from_velocity(np.where(cost < 0, 0.0, vx), np.zeros(shape), cost)
    assert blocked.sample(ORIGIN[0] + RES, ORIGIN[1] + RES) is None
    # The nearest-centre weight dominates: a point on cell (2,0)'s centre takes exactly its values.
    centre = blocked.cell_center(2, 0)
    s = blocked.sample(*centre)
    assert s is not None and s.cost_to_go == pytest.approx(cost[0, 2])


def test_off_grid_is_none_and_the_border_band_uses_the_cells_that_exist() -> None:
    field = linear_field((3, 3))
    assert field.sample(ORIGIN[0] - 1e-9, ORIGIN[1] + 0.1) is None
    assert field.sample(ORIGIN[0] + 0.1, ORIGIN[1] + 3 * RES + 1e-9) is None
    assert field.sample(math.nan, 2.2) is None
    # Inside the outer half cell only the edge cells exist: their values, no extrapolation.
    s = field.sample(ORIGIN[0] + 0.01, ORIGIN[1] + 0.01)
    assert s is not None
    assert s.cost_to_go == pytest.approx(field.cost_to_go[0, 0])
    assert field.sample(ORIGIN[0] + 3 * RES, ORIGIN[1] + 3 * RES) is not None  # the far corner is on the grid


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        (lambda a: a.update(dir_y=a["dir_y"][:, :-1]), "dir_y has shape"),
        (lambda a: a.update(speed=np.where(a["speed"] == a["speed"].max(), np.nan, a["speed"])), "speed contains NaN"),
        (lambda a: a.update(resolution=0.0), "resolution must be a positive"),
        (lambda a: a.update(resolution=math.inf), "resolution must be a positive"),
        (lambda a: a.update(dir_x=a["dir_x"] * 0.5), "neither 0 nor 1"),
        (lambda a: a.update(cost_to_go=a["cost_to_go"] - 100.0), "only -1 marks unreachable"),
        (lambda a: a.update(speed=-a["speed"]), "negative speed"),
        (lambda a: a.update(goal=(0.0, 0.0, -1.0)), "goal radius"),
        (lambda a: a.update(dir_x=np.zeros((0, 3)), dir_y=np.zeros((0, 3)), speed=np.zeros((0, 3)), cost_to_go=np.zeros((0, 3))), "non-empty"),
    ],
)
def test_validate_names_the_reason(change, reason: str) -> None:
    base = linear_field()
    args = {
        "origin": base.origin,
        "resolution": base.resolution,
        "dir_x": base.dir_x,
        "dir_y": base.dir_y,
        "speed": base.speed,
        "cost_to_go": base.cost_to_go,
        "goal": base.goal,
    }
    change(args)
    with pytest.raises(PlannerError, match=reason):
        FeedbackField(**args).validate()


def test_direction_tolerance_accepts_float32_rounding() -> None:
    base = linear_field()
    as_float32 = FeedbackField(
        base.origin, base.resolution, base.dir_x.astype(np.float32), base.dir_y.astype(np.float32), base.speed, base.cost_to_go, base.goal
    )
    as_float32.validate()
    assert as_float32.dir_x.dtype == np.float64


def test_npz_and_message_give_the_same_field(tmp_path: Path) -> None:
    field = linear_field((5, 7))
    path = tmp_path / "field.npz"
    np.savez(
        path,
        dir_x=field.dir_x,
        dir_y=field.dir_y,
        speed=field.speed,
        cost_to_go=field.cost_to_go,
        origin=np.array(ORIGIN),
        resolution=np.float64(RES),
        goal=np.array(field.goal),
    )
    from_file = FeedbackField.from_npz(path)
    height, width = field.shape
    msg = SimpleNamespace(
        header=SimpleNamespace(utime=1, seq=2, frame_id="map"),
        request_id=42,
        map_seq=7,
        origin_x=ORIGIN[0],
        origin_y=ORIGIN[1],
        resolution=RES,
        width=width,
        height=height,
        num_cells=width * height,
        **{name: [float(v) for v in getattr(field, name).astype(np.float32).ravel()] for name in ("dir_x", "dir_y", "speed", "cost_to_go")},
        goal_x=field.goal[0],
        goal_y=field.goal[1],
        goal_radius=field.goal[2],
    )
    from_msg = FeedbackField.from_message(msg)
    assert (from_msg.request_id, from_msg.map_seq) == (42, 7)
    assert from_file.same_grid(from_msg) and from_msg.same_grid(field)
    for name in ("dir_x", "dir_y", "speed", "cost_to_go"):
        np.testing.assert_array_equal(getattr(from_file, name), getattr(field, name))
        np.testing.assert_allclose(getattr(from_msg, name), getattr(field, name), rtol=1e-6)  # float32 on the wire
    assert from_file.goal == field.goal
    # Row-major iy·width + ix: the message's cell (ix=3, iy=1) is the grid's [1, 3].
    assert from_msg.cost_to_go[1, 3] == pytest.approx(msg.cost_to_go[1 * width + 3])

    msg.num_cells = width * height - 1
    with pytest.raises(PlannerError, match="num_cells"):
        FeedbackField.from_message(msg)
    msg.num_cells = width * height
    msg.speed = msg.speed[:-1]
    with pytest.raises(PlannerError, match="speed has"):
        FeedbackField.from_message(msg)
    np.savez(tmp_path / "partial.npz", dir_x=field.dir_x)
    with pytest.raises(PlannerError, match="missing arrays dir_y"):
        FeedbackField.from_npz(tmp_path / "partial.npz")
    with pytest.raises(PlannerError, match="cannot read"):
        FeedbackField.from_npz(tmp_path / "absent.npz")


def test_same_grid() -> None:
    a = linear_field((4, 5))
    assert a.same_grid(linear_field((4, 5)))
    assert not a.same_grid(linear_field((5, 4)))
    shifted = FeedbackField((ORIGIN[0] + RES, ORIGIN[1]), RES, a.dir_x, a.dir_y, a.speed, a.cost_to_go, a.goal)
    assert not a.same_grid(shifted)


# --- FieldFollower ------------------------------------------------------------------------------
def walk(follower: FieldFollower, x: float, y: float, yaw: float, dt: float, steps: int) -> tuple[list[FollowerCommand], float, float]:
    """A robot that moves exactly as commanded (kinematic): returns the commands and the end position."""
    commands = []
    for _ in range(steps):
        cmd = follower.command(x, y, yaw, dt)
        commands.append(cmd)
        x += cmd.vx * dt
        y += cmd.vy * dt
        yaw = cmd.yaw
    return commands, x, y


def assert_within_limits(previous: FollowerCommand, cmd: FollowerCommand, dt: float, limits: FollowerLimits, speed_bound: float) -> None:
    slack = 1e-9
    assert math.hypot(cmd.vx, cmd.vy) <= speed_bound + slack
    assert math.hypot(cmd.vx - previous.vx, cmd.vy - previous.vy) <= limits.max_accel * dt + slack
    assert abs(cmd.yaw_rate) <= limits.max_yaw_rate + slack
    assert abs(cmd.yaw_rate - previous.yaw_rate) <= limits.max_yaw_accel * dt + slack
    # The heading moves by exactly the commanded rate (no jump, also not across ±π).
    assert math.remainder(cmd.yaw - previous.yaw - cmd.yaw_rate * dt, math.tau) == pytest.approx(0.0, abs=1e-9)


def random_field(seed: int, shape: tuple[int, int] = (24, 32)) -> FeedbackField:
    rng = np.random.default_rng(seed)
    angle = rng.uniform(-math.pi, math.pi, size=shape)
    speed = rng.uniform(0.1, 0.8, size=shape)
    cost = rng.uniform(0.5, 5.0, size=shape)
    blocked = rng.random(shape) < 0.15
    cost[blocked] = -1.0
    speed[blocked] = 0.0
    return FeedbackField(
        ORIGIN, RES, np.where(blocked, 0.0, np.cos(angle)), np.where(blocked, 0.0, np.sin(angle)), speed, cost, (ORIGIN[0] + 4.0, ORIGIN[1] + 3.0, 0.3)
    )


@pytest.mark.parametrize("max_speed", [None, 0.35])
def test_limits_hold_over_a_random_sequence(max_speed: float | None) -> None:
    """Random field, random jumps of the robot (pushes), heading noise and irregular dt: every limit holds every call."""
    field = random_field(3)
    limits = FollowerLimits(max_speed=max_speed)
    follower = FieldFollower(field, limits)
    speed_bound = field.max_speed() if max_speed is None else max_speed
    rng = np.random.default_rng(17)
    x, y, yaw = ORIGIN[0] + 1.0, ORIGIN[1] + 1.0, 0.3
    previous = follower.command(x, y, yaw, 0.001)
    statuses = set()
    for step in range(20000):
        dt = float(rng.uniform(0.0005, 0.005))
        if step % 500 == 0:  # a push somewhere else on (or just off) the map
            x, y = rng.uniform(np.array(ORIGIN) - 0.3, np.array(ORIGIN) + np.array([32, 24]) * RES + 0.3)
        cmd = follower.command(float(x), float(y), yaw, dt)
        assert_within_limits(previous, cmd, dt, limits, speed_bound)
        statuses.add(cmd.status)
        x += cmd.vx * dt
        y += cmd.vy * dt
        yaw = cmd.yaw + float(rng.normal(scale=0.05))
        previous = cmd
    assert {STATUS_OK, STATUS_FALLBACK} <= statuses


def test_command_is_continuous_across_a_field_swap() -> None:
    goal = (ORIGIN[0] + 9.0, ORIGIN[1] + 9.0, 0.3)
    east = uniform_field((48, 48), (1.0, 0.0), 0.6, goal)
    south = uniform_field((48, 48), (0.0, -1.0), 0.3, goal)
    limits = FollowerLimits()
    follower = FieldFollower(east, limits)
    dt = 0.001
    commands, x, y = walk(follower, ORIGIN[0] + 1.0, ORIGIN[1] + 8.0, 0.0, dt, 2000)
    before = commands[-1]
    assert before.vx == pytest.approx(0.6) and before.yaw == pytest.approx(0.0)
    follower.swap_field(south)
    after, x, y = walk(follower, x, y, before.yaw, dt, 4000)
    for previous, cmd in zip([before, *after[:-1]], after, strict=True):
        assert_within_limits(previous, cmd, dt, limits, 0.6)
    # It gets there: heading south, velocity the new field's.
    assert after[-1].yaw == pytest.approx(-math.pi / 2, abs=1e-3)
    assert (after[-1].vx, after[-1].vy) == pytest.approx((0.0, -0.3), abs=1e-6)


def test_slows_down_near_the_goal_and_stops_inside() -> None:
    goal = (ORIGIN[0] + 6.0, ORIGIN[1] + 3.0, 0.3)
    field = radial_field((24, 32), goal, speed=0.5)
    limits = FollowerLimits()
    follower = FieldFollower(field, limits)
    dt = 0.002
    x, y, yaw = ORIGIN[0] + 2.0, ORIGIN[1] + 3.0, 0.0
    reached_at = None
    for step in range(10000):
        cmd = follower.command(x, y, yaw, dt)
        distance_to_edge = math.hypot(x - goal[0], y - goal[1]) - (1.0 - limits.goal_stop_depth) * goal[2]
        speed = math.hypot(cmd.vx, cmd.vy)
        if 0.0 < distance_to_edge < limits.slow_radius:
            # Proportional slow-down (the acceleration limit lags it by at most a step's worth).
            assert speed <= max(0.5 * distance_to_edge / limits.slow_radius, limits.min_approach_speed) + limits.max_accel * dt + 1e-9
            assert not cmd.reached
        if distance_to_edge > limits.slow_radius + 0.5 and step > 500:
            # Full speed (interpolating neighbouring radial directions shortens the vector a little).
            assert speed == pytest.approx(0.5, rel=1e-2)
        if cmd.reached and reached_at is None:
            reached_at = step * dt
            assert cmd.status == STATUS_GOAL
        x += cmd.vx * dt
        y += cmd.vy * dt
        yaw = cmd.yaw
    assert reached_at is not None and reached_at < 15.0
    assert cmd.cost_to_go == 0.0
    assert (cmd.vx, cmd.vy, cmd.yaw_rate) == (0.0, 0.0, 0.0)
    assert cmd.reached and cmd.status == STATUS_GOAL
    # Stopped at the stop depth inside the disc, not overshooting through it.
    stop_radius = (1.0 - limits.goal_stop_depth) * goal[2]
    assert stop_radius - 0.02 < math.hypot(x - goal[0], y - goal[1]) <= stop_radius


def test_inside_the_goal_disc_it_walks_straight_at_the_centre_whatever_the_field_says() -> None:
    """The goal set has no direction (cost 0, zero velocity), and samples at its rim blend the
    approach cells' directions in: here they all point east, past the goal. A robot that believes
    it is inside the disc, north of the centre and short of the stop depth, walks to the centre
    and stops; following the blend it would leave the disc eastwards and never come back."""
    goal = (ORIGIN[0] + 6.0, ORIGIN[1] + 6.0, 0.5)
    field = uniform_field((48, 48), (1.0, 0.0), 0.5, goal)
    limits = FollowerLimits()
    follower = FieldFollower(field, limits)
    x, y, yaw = goal[0] + 0.1, goal[1] + 0.45, -math.pi / 2
    dt = 0.002
    first = follower.command(x, y, yaw, dt)
    assert first.status == STATUS_APPROACH and not first.reached
    farthest = 0.0
    for _ in range(5000):
        cmd = follower.command(x, y, yaw, dt)
        x += cmd.vx * dt
        y += cmd.vy * dt
        yaw = cmd.yaw
        farthest = max(farthest, math.hypot(x - goal[0], y - goal[1]))
    assert cmd.reached and cmd.status == STATUS_GOAL
    assert math.hypot(x - goal[0], y - goal[1]) <= (1.0 - limits.goal_stop_depth) * goal[2]
    assert farthest <= goal[2]


def test_turns_first_when_facing_away() -> None:
    goal = (ORIGIN[0] + 11.0, ORIGIN[1] + 6.0, 0.3)
    field = uniform_field((48, 48), (1.0, 0.0), 0.5, goal)
    limits = FollowerLimits()
    follower = FieldFollower(field, limits)
    dt = 0.001
    x0, y0 = ORIGIN[0] + 2.0, ORIGIN[1] + 6.0
    commands, x, _ = walk(follower, x0, y0, math.pi - 0.01, dt, 6000)
    # Velocity always along the field (+x), never sideways or backwards.
    assert all(c.vx >= 0.0 and c.vy == 0.0 for c in commands)
    # While facing more than 60° off, at most the turning fraction of the speed.
    turning = [c for c in commands if abs(math.remainder(c.yaw, math.tau)) > limits.turn_first_heading_error]
    assert len(turning) > 1500  # ~π − 60° at ≤ 1 rad/s: about 2 s
    assert max(c.vx for c in turning) <= limits.turning_speed_fraction * 0.5 + 1e-9
    # It turned the short way at the limit rate and then walked at full speed, facing the field.
    assert max(abs(c.yaw_rate) for c in commands) == pytest.approx(limits.max_yaw_rate)
    assert commands[-1].yaw == pytest.approx(0.0, abs=1e-3)
    assert commands[-1].vx == pytest.approx(0.5)
    # The turn cost little ground: well under what 3 s at full speed would be.
    assert x - x0 < 0.5 * 6.0 - 1.0


def test_fallback_descends_the_cost_and_stops_without_a_field() -> None:
    goal = (ORIGIN[0] + 5.0, ORIGIN[1] + 3.0, 0.3)
    field = radial_field((24, 32), goal, speed=0.4)
    cost = field.cost_to_go.copy()
    dir_x, dir_y, speed = field.dir_x.copy(), field.dir_y.copy(), field.speed.copy()
    # A 6×6-cell obstacle block (1.5 m): cells 4..9 in x and 8..13 in y.
    block = (slice(8, 14), slice(4, 10))
    for grid, value in ((cost, -1.0), (dir_x, 0.0), (dir_y, 0.0), (speed, 0.0)):
        grid[block] = value
    blocked = FeedbackField(ORIGIN, RES, dir_x, dir_y, speed, cost, goal)
    dt = 0.001

    # One cell inside the block's right edge: the nearest reachable cell is column 10, steepest descent towards the goal (+x).
    x, y = blocked.cell_center(8, 10)
    follower = FieldFollower(blocked)
    commands = [follower.command(x + 0.01, y, 0.0, dt) for _ in range(1000)]
    assert all(c.status == STATUS_FALLBACK for c in commands)
    assert commands[-1].cost_to_go == pytest.approx(blocked.cost_to_go[10, 10])  # the nearest reachable cell's
    ux, uy = commands[-1].vx, commands[-1].vy
    assert ux > 0.0 and abs(math.atan2(uy, ux)) <= math.radians(45.0) + 1e-9

    # The block's middle is 3 cells from any reachable cell: no field, and the velocity ramps down to zero.
    follower.swap_field(blocked)
    centre_x, centre_y = ORIGIN[0] + 7.0 * RES, ORIGIN[1] + 11.0 * RES
    commands = [follower.command(centre_x, centre_y, 0.0, dt) for _ in range(1000)]
    assert all(c.status == STATUS_NO_FIELD and not c.reached and math.isnan(c.cost_to_go) for c in commands)
    assert math.hypot(commands[0].vx, commands[0].vy) > 0.0  # still slowing from the fallback's motion ...
    assert (commands[-1].vx, commands[-1].vy) == (0.0, 0.0)  # ... then stopped
    # Far off the map, and at a NaN position: no field either.
    assert follower.command(ORIGIN[0] - 5.0, ORIGIN[1], 0.0, dt).status == STATUS_NO_FIELD
    assert follower.command(math.nan, 0.0, 0.0, dt).status == STATUS_NO_FIELD
    # Just off the map's edge, within two cells: steer back by the edge cells' descent.
    assert follower.command(ORIGIN[0] - 0.3, ORIGIN[1] + 3.0, 0.0, dt).status == STATUS_FALLBACK


def test_same_inputs_same_commands() -> None:
    field = random_field(8)
    runs = []
    for _ in range(2):
        follower = FieldFollower(field)
        commands, x, y = walk(follower, ORIGIN[0] + 2.0, ORIGIN[1] + 2.0, 1.0, 0.001, 3000)
        runs.append((commands, x, y))
    assert runs[0] == runs[1]


def test_rejects_bad_limits_and_steps() -> None:
    field = random_field(1)
    with pytest.raises(ValueError, match="max_yaw_rate"):
        FieldFollower(field, FollowerLimits(max_yaw_rate=0.0))
    with pytest.raises(ValueError, match="turn_first_heading_error"):
        FieldFollower(field, FollowerLimits(full_speed_heading_error=1.2, turn_first_heading_error=1.0))
    with pytest.raises(ValueError, match="dt must be positive"):
        FieldFollower(field).command(0.0, 0.0, 0.0, 0.0)
    bad = FeedbackField(ORIGIN, -1.0, field.dir_x, field.dir_y, field.speed, field.cost_to_go, field.goal)
    with pytest.raises(PlannerError, match="resolution"):
        FieldFollower(field).swap_field(bad)


def test_the_goal_latch_holds_through_sway_and_releases_outside_the_disc() -> None:
    goal = (ORIGIN[0] + 6.0, ORIGIN[1] + 3.0, 0.4)
    limits = FollowerLimits(goal_stop_depth=0.5)
    follower = FieldFollower(radial_field((24, 32), goal, speed=0.5), limits)
    gx, gy, r = goal
    assert not follower.command(gx - 0.3, gy, 0.0, 0.001).reached  # inside the disc, short of the stop depth
    assert follower.command(gx - 0.1, gy, 0.0, 0.001).reached
    # Sway back across the edge: still at the goal, no new walk.
    swayed = follower.command(gx - r - 0.1, gy, 0.0, 0.001)
    assert swayed.reached and (swayed.vx, swayed.vy) == (0.0, 0.0)
    # Pushed well out of the disc: the walk resumes.
    assert not follower.command(gx - r - limits.goal_release_margin - 0.05, gy, 0.0, 0.001).reached
