"""The co-simulation master loop as it was before its fast path: the oracle of test_hs_fast_loop.

`advance_reference` is `CoSimulation._advance` of commit 93568a0: it reads the state through
DART's transform and velocity getters, samples the reference one step at a time, rebuilds and
sends the whole height map at every communication point and clamps torques with `np.clip`. A
run with it in place of `_advance` must log exactly what the fast loop logs. One rule came later
and is the model's, not the loop's: the map is registered at the belief offset once that has
moved more than `MAP_REGISTRATION_TOLERANCE` from where it was last registered.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pfnav_harness import fmu_runner as fr
from pfnav_harness.cosim import MAP_REGISTRATION_TOLERANCE, REFERENCE_COLUMNS, CoSimulation
from pfnav_harness.errors import SimulationError
from pfnav_harness.reference import N_COLUMNS
from pfnav_harness.reference_source import FieldSource
from pfnav_harness.robot import NUM_JOINTS
from pfnav_harness.world import QuadrupedWorld


def _apply_torques_as_before(world: QuadrupedWorld, torques: NDArray[np.float64]) -> None:
    world._forces[world.joint_dofs] = np.clip(torques, -world.effort_limits, world.effort_limits)


def _yaw_as_before(quaternion: NDArray[np.float64]) -> float:
    w, x, y, z = (float(v) for v in quaternion)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def advance_reference(self: CoSimulation, loop: Any, end: int, progress: Any) -> None:
    """`CoSimulation._advance` as it was before the fast path (93568a0), word for word but for
    the three calls marked "as before"."""
    c = self.config
    dt = c.physics_dt
    ratio = round(c.comm_step / dt)
    n_steps = loop.n_steps
    walk_start = c.stand_time

    fmu = self.fmu
    world = self.world
    fsm, modes = fmu.contract.fsm, fmu.contract.mode
    inputs, outputs = fmu.inputs, fmu.outputs
    log_state, log_outputs, log_ref, log_flags, log_push = loop.log_state, loop.log_outputs, loop.log_ref, loop.log_flags, loop.log_push
    state = inputs.view(fr.STATE_INPUTS)
    ref_in = inputs.indices(list(REFERENCE_COLUMNS))
    ref_columns = np.array(list(REFERENCE_COLUMNS.values()), dtype=np.intp)
    body_height_in = inputs.index("ref.bodyHeight")
    map_origin = inputs.view(fr.HEIGHT_MAP_ORIGIN)
    map_spacing = inputs.index(fr.HEIGHT_MAP_SPACING)
    map_heights = inputs.view(fmu.contract.height_map_heights)
    map_size = fmu.contract.height_map_size
    input_values = inputs.values
    terrain = self.scenario.terrain
    use_map = c.height_map
    ref_row = np.zeros(N_COLUMNS)
    torques = np.zeros(NUM_JOINTS)
    source = self.source
    online = self.online
    pushes = c.pushes
    push_force = np.zeros(3)
    goal_since = loop.goal_since
    fall_step = loop.fall_step
    mode = loop.mode
    timing = loop.timing
    contacts_view = fmu.contacts_array
    perf = time.perf_counter
    estimator = loop.estimator
    offset = loop.belief_offset
    map_offset = loop.map_offset
    # The pose the robot's navigation works with: x, y, yaw (truth + offset).
    pose = np.zeros(3)
    stop_reason: str | None = None
    progress_every = max(1, n_steps // 200)
    t_begin = perf()
    k = loop.k
    for k in range(loop.k, end):
        t = k * dt
        world.state_vector_reference(state)  # as before
        if not math.isfinite(float(state.sum())):
            stop_reason = f"physics state became non-finite at t={t:.3f} s"
            break
        walking = t >= walk_start
        tau = t - walk_start
        true_yaw = _yaw_as_before(state[3:7])  # as before
        pose[0] = state[0] + offset[0]
        pose[1] = state[1] + offset[1]
        pose[2] = true_yaw + offset[3]
        if online is not None and walking and k % ratio == 0:
            answer = online.tick(tau, float(pose[0]), float(pose[1]), float(pose[2]))
            if answer is not None:
                if isinstance(source, FieldSource):
                    assert answer.field is not None  # the navigator only passes on P-F answers with a field
                    source.replace(answer.field)
                else:
                    assert answer.plan is not None
                    source.replace(answer.plan, online.replans[-1].t_publish)
        source.sample(tau, pose, offset, walking, ref_row)
        if pushes is not None and walking:
            force = pushes.force_at(tau, true_yaw)
            if force is not None:
                push_force[:] = force
                world.apply_trunk_force(force)
                assert log_push is not None
                log_push[k] = push_force
        # The truth is logged before the body sensors overwrite joint angles with their readings.
        log_state[k] = state
        if k % ratio == 0:
            input_values[ref_in] = ref_row[ref_columns]
            input_values[body_height_in] = c.body_height
            # The elevation map a perception stack would give: the mesh vertices around the base,
            # in the robot's estimated frame (perception measures the ground relative to the body).
            if np.max(np.abs(offset[0:3] - map_offset)) > MAP_REGISTRATION_TOLERANCE:
                map_offset[:] = offset[0:3]
            grid = terrain.local_grid(float(state[0]), float(state[1]), map_size) if use_map else None
            if grid is None:
                input_values[map_spacing] = 0.0
            else:
                map_origin[0], map_origin[1] = grid[0] + map_offset[0], grid[1] + map_offset[1]
                input_values[map_spacing] = terrain.resolution
                map_heights[:] = grid[2].ravel() + map_offset[2]
            if estimator is not None:
                estimator.write_inputs(t, state)
            mode = modes.Locomotion if walking else modes.Stand
            t0 = perf()
            fmu.exchange_inputs(mode)
            fmu.do_step(t, c.comm_step)
            fmu.read_outputs()
            timing.fmu += perf() - t0
            torques[:] = fmu.torques
            if not math.isfinite(float(torques.sum())):
                raise SimulationError(f"the FMU returned non-finite torques at t={t:.3f} s")
            if estimator is not None:
                estimator.belief_offset(state, true_yaw, offset)
            _apply_torques_as_before(world, torques)  # as before
        t0 = perf()
        world.step()
        timing.physics += perf() - t0

        log_outputs[k] = outputs.values
        log_ref[k] = ref_row
        flags = log_flags[k]
        flags[0:4] = contacts_view
        flags[4:8] = world.foot_contacts()
        flags[8] = fmu.fsm_state
        flags[9] = mode
        if estimator is not None:
            estimator.log_step(k)

        # The controller's damping state is its own verdict that the robot is down.
        if walking and fall_step is None and k % c.fall.every_steps == 0 and (flags[8] == fsm.Damping or self._fallen(state)):
            fall_step = k
        if fall_step is not None and (k - fall_step) * dt >= c.after_fall:
            stop_reason = f"fell at t={fall_step * dt:.2f} s"
            break
        if source.finished:
            goal_since = t if goal_since is None else goal_since
            if t - goal_since >= c.settle_time:
                stop_reason = "completed: stood at the goal"
                break
        else:
            goal_since = None
        if progress is not None and k % progress_every == 0:
            progress(t)
    timing.total += perf() - t_begin
    # Rows 0 … loop.k − 1 are the log: a stopped run keeps the step it stopped in.
    loop.k = k + 1 if stop_reason is not None else max(end, loop.k)
    loop.stop_reason = stop_reason
    loop.mode = int(mode)
    loop.fall_step = fall_step
    loop.goal_since = goal_since

