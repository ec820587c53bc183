"""A run as a Rerun recording (`.rrd`): the robot walking the terrain on the simulation clock.

Open one with `rerun FILE.rrd` (the viewer ships with the `rerun-sdk` package). What it holds,
by entity path:

- `world/terrain`: the terrain mesh (the map's triangulation through the cell centres, coloured by
  height, obstacle cells dark); `world/plan`, `world/start`, `world/goal`;
- `robot`: the URDF (Rerun's own loader: visuals and collisions, meshes where it can read them),
  posed by `robot/base_pose` and `robot/joints/JOINT` from the logged base pose and joint angles;
- `world/feet` (green: touching the ground in the physics engine), `world/ground_reaction_forces`
  (the MPC's commanded forces, world frame), `world/pushes` when the run was pushed;
- `world/walked` and `world/estimate/path` (the truth and the estimator's belief of the base path),
  `world/estimate/pose` (the believed trunk pose as axes);
- `world/pf_density` (the P-F LP's occupation density on the planning grid, from `pf-plan`, log
  colour scale) for offline P-F runs whose field is given;
- `world/feedback_field` (the P-F feedback law's directions over the terrain, coloured by
  cost-to-go) when the run's field is given; online runs: each field from the moment it was put in
  use, `world/replans` (each path likewise) and `world/sensed_map` (the map as each update sent
  it, coloured by its σ, or by height for the ideal sensor's exact map; its final state at the end);
- `plots/...`: tracking error, joint torques, MPC solve time, FSM state, estimate error;
  `fsm_state` (each change of the controller's FSM state, by the name the FMU declares) and
  `world/fsm_state` (that name floating above the robot);
- `notes`: what the log did not keep.

Poses are written at `pose_rate` (default 50 Hz) and time series at `series_rate` (100 Hz), not at
the log's 1 kHz: a 40 s run stays a few MB and is written in seconds.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
import rerun as rr
from numpy.typing import NDArray

from ..feedback_field import FeedbackField
from ..robot import JOINT_ROLES, LEG_LABELS, RobotDescription
from ..scenario import Scenario, Terrain, grid_triangles
from .density import DensityResult, OccupationDensity
from .kinematics import LegKinematics
from .run_log import RunLog, estimated_quaternions, frame_steps, fsm_state_names, fsm_transitions, horizontal_tracking_error, window_max

TIMELINE = "sim_time"
# Rerun's frame of the 3-D view's root (entities logged without a transform live in it).
ROOT_FRAME = "tf#/"
# Metres of arrow per newton of ground reaction force: a standing robot's ~30-60 N per foot is 10-20 cm.
FORCE_SCALE = 0.003
# Metres of arrow per newton of push.
PUSH_SCALE = 0.01
# Lines and markers float this far above the terrain so the mesh does not hide them.
LIFT = 0.02
TOUCHING = (40, 200, 60)
SWINGING = (150, 150, 150)
TRUTH = (220, 40, 40)
ESTIMATE = (40, 90, 230)
PLAN = (250, 250, 250)
# The occupation density's sheet covers the cells within this many decades of its largest value.
DENSITY_DECADES = 3.0
# The FSM state's label floats this far above the trunk.
FSM_LABEL_HEIGHT = 0.45
# Feedback-field arrows: at most this many along the map's longer side.
FIELD_ARROWS_ACROSS = 48
# The sensed map over time: at most one snapshot per this many simulated seconds, each with at
# most this many vertices along the map's longer side (its final state is drawn in full).
SENSED_MAP_PERIOD = 1.0
SENSED_MAP_VERTICES_ACROSS = 64


@dataclass(frozen=True)
class RecordingSummary:
    """What was written: the file, its size, the entities and the simulated time it spans."""

    path: Path
    bytes: int
    entities: tuple[str, ...]
    t_first: float
    t_last: float
    pose_frames: int


def terrain_colours(heights: NDArray[np.float64], obstacles: NDArray[np.bool_] | None) -> NDArray[np.uint8]:
    """RGB per cell: matplotlib's 'terrain' colour map over the height range, obstacle cells dark grey."""
    low, high = float(np.nanmin(heights)), float(np.nanmax(heights))
    scaled = (heights - low) / (high - low) if high > low else np.zeros_like(heights)
    rgb = (matplotlib.colormaps["terrain"](np.clip(scaled, 0.0, 1.0))[..., :3] * 255).astype(np.uint8)
    if obstacles is not None:
        rgb[obstacles] = (60, 60, 60)
    return rgb.reshape(-1, 3)


def terrain_mesh(terrain: Terrain) -> rr.Mesh3D:
    """The terrain as the physics walks on it (`Terrain.vertices`/`triangles`), coloured by height."""
    return rr.Mesh3D(
        vertex_positions=terrain.vertices().astype(np.float32),
        triangle_indices=terrain.triangles().astype(np.uint32),
        vertex_colors=terrain_colours(terrain.heights, terrain.obstacles),
    )


def sensed_map_mesh(
    terrain: Terrain, heights: NDArray[np.floating], variances: NDArray[np.floating], vertices_across: int | None = None
) -> rr.Mesh3D | None:
    """The sensed elevation map's known cells as a mesh coloured by σ (viridis, 0 to the largest σ;
    a map of exact heights, the ideal sensor's, by height instead); None if nothing is known.

    `vertices_across` thins the mesh to at most that many vertices along the map's longer side
    (every n-th cell centre): a map drawn at every update would otherwise dominate a recording.
    """
    ny, nx = heights.shape
    stride = 1 if vertices_across is None else max(1, math.ceil(max(nx, ny) / vertices_across))
    heights = np.asarray(heights, dtype=np.float64)[::stride, ::stride]
    variances = np.asarray(variances, dtype=np.float64)[::stride, ::stride]
    known = np.isfinite(heights) & np.isfinite(variances)
    if not known.any():
        return None
    res = terrain.resolution
    xs = terrain.origin[0] + (np.arange(0, nx, stride) + 0.5) * res
    ys = terrain.origin[1] + (np.arange(0, ny, stride) + 0.5) * res
    gx, gy = np.meshgrid(xs, ys)
    vertices = np.stack([gx.ravel(), gy.ravel(), np.where(known, heights, 0.0).ravel()], axis=1)
    triangles = grid_triangles(*heights.shape)
    # Only triangles whose three corners were sensed.
    triangles = triangles[known.ravel()[triangles].all(axis=1)]
    sigma = np.sqrt(np.where(known, variances, 0.0))
    top = float(sigma.max())
    if top > 0.0:
        colours = (matplotlib.colormaps["viridis"](sigma / top)[..., :3] * 255).astype(np.uint8).reshape(-1, 3)
    else:
        colours = terrain_colours(np.where(known, heights, np.nan), None)
    return rr.Mesh3D(vertex_positions=vertices.astype(np.float32), triangle_indices=triangles.astype(np.uint32), vertex_colors=colours)


def density_mesh(density: OccupationDensity, terrain: Terrain) -> rr.Mesh3D | None:
    """The occupation density as a sheet just above the terrain over the cells the flow visits
    (ρ above `DENSITY_DECADES` decades below its largest value), coloured on a log scale
    (inferno: dark = rarely, bright = most visited); None where it has no positive value."""
    rho = np.asarray(density.density, dtype=np.float64)
    top = float(rho.max()) if rho.size else 0.0
    if not top > 0.0:
        return None
    ny, nx = rho.shape
    xs = density.origin[0] + (np.arange(nx) + 0.5) * density.resolution
    ys = density.origin[1] + (np.arange(ny) + 0.5) * density.resolution
    gx, gy = np.meshgrid(xs, ys)
    vertices = np.stack([gx.ravel(), gy.ravel(), terrain.height(gx.ravel(), gy.ravel()) + 0.5 * LIFT], axis=1)
    visited = (rho >= top * 10.0**-DENSITY_DECADES).ravel()
    triangles = grid_triangles(ny, nx)
    triangles = triangles[visited[triangles].all(axis=1)]
    scaled = 1.0 + np.log10(np.maximum(rho, top * 10.0**-DENSITY_DECADES) / top) / DENSITY_DECADES
    colours = (matplotlib.colormaps["inferno"](np.clip(scaled, 0.0, 1.0))[..., :3] * 255).astype(np.uint8).reshape(-1, 3)
    return rr.Mesh3D(vertex_positions=vertices.astype(np.float32), triangle_indices=triangles.astype(np.uint32), vertex_colors=colours)


def field_arrows(field: FeedbackField, terrain: Terrain) -> rr.Arrows3D:
    """The feedback law's direction on a thinned grid over the terrain, coloured by cost-to-go (unreachable cells left out)."""
    ny, nx = field.dir_x.shape
    stride = max(1, math.ceil(max(nx, ny) / FIELD_ARROWS_ACROSS))
    iy, ix = np.meshgrid(np.arange(0, ny, stride), np.arange(0, nx, stride), indexing="ij")
    iy, ix = iy.ravel(), ix.ravel()
    cost = field.cost_to_go[iy, ix]
    keep = (cost >= 0.0) & (field.speed[iy, ix] > 0.0)
    iy, ix, cost = iy[keep], ix[keep], cost[keep]
    x = field.origin[0] + (ix + 0.5) * field.resolution
    y = field.origin[1] + (iy + 0.5) * field.resolution
    z = terrain.height(x, y) + LIFT
    length = 0.8 * stride * field.resolution
    vectors = np.stack([field.dir_x[iy, ix] * length, field.dir_y[iy, ix] * length, np.zeros_like(x)], axis=1)
    top = float(cost.max()) if len(cost) else 1.0
    colours = (matplotlib.colormaps["magma"](cost / (top or 1.0))[:, :3] * 255).astype(np.uint8)
    return rr.Arrows3D(origins=np.stack([x, y, z], axis=1), vectors=vectors, colors=colours)


def on_ground(terrain: Terrain, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points (x, y) lifted onto the terrain surface (plus `LIFT`)."""
    return np.stack([x, y, terrain.height(x, y) + LIFT], axis=1)


def goal_circle(scenario: Scenario, segments: int = 48) -> NDArray[np.float64]:
    angle = np.linspace(0.0, 2.0 * math.pi, segments + 1)
    cx, cy = scenario.goal.center
    return on_ground(scenario.terrain, cx + scenario.goal.radius * np.cos(angle), cy + scenario.goal.radius * np.sin(angle))


def xyzw(wxyz: NDArray[np.float64]) -> NDArray[np.float64]:
    """The log's quaternions (w, x, y, z) in Rerun's order (x, y, z, w)."""
    return np.asarray(wxyz)[:, [1, 2, 3, 0]]


@contextlib.contextmanager
def ros_package_path(robot: RobotDescription) -> Iterator[None]:
    """`ROS_PACKAGE_PATH` set to the robot's package roots while Rerun's URDF loader resolves `package://` files."""
    before = os.environ.get("ROS_PACKAGE_PATH")
    os.environ["ROS_PACKAGE_PATH"] = os.pathsep.join(str(root) for root in robot.package_roots)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("ROS_PACKAGE_PATH", None)
        else:
            os.environ["ROS_PACKAGE_PATH"] = before


def missing_contents(log: RunLog, field: FeedbackField | None, density: DensityResult | None = None) -> list[str]:
    """What a viewer might look for that this run's log does not hold."""
    notes = ["Ground reaction forces are the MPC's commanded forces (controller output), not measured contact forces."]
    if density is None or density.density is None:
        if "replan_t_apply" in log:
            why = "an online run's replans were planned on the map sensed so far, which pf-plan does not take."
        elif density is not None:
            why = density.reason
        else:
            why = "the planner service publishes the plan and the feedback law, not the LP's density (pf-plan computes it when the run's field is given)."
        notes.insert(0, f"The P-F occupation density: {why}")
    if field is None and "replan_field_rows" not in log:
        notes.append(
            "The feedback field: not stored in the run log (offline P-F runs record it when the demo writes the recording; "
            "`pfnav-demo replay --field FILE.npz` adds one written by `pf-plan plan --field-out`)."
        )
    if "replan_t_apply" in log:
        if "replan_field_rows" not in log:
            notes.append("Replans: the paths are recorded, their feedback fields are not in the log.")
        if "map_snapshot_rows" not in log:
            if "map_heights_final" in log:
                notes.append("The sensed map: only its state at the end of the run is in the log, not its growth.")
            else:
                notes.append("The sensed map: the ideal sensor keeps no elevation map (only which cells were seen).")
    if "fsm_state_names" not in log:
        notes.append("FSM state names: the log has only their codes (it predates the names).")
    if "est_pos" not in log:
        notes.append("The estimate: the controller ran on ground truth (estimator groundTruth).")
    return notes


def write_recording(
    log: RunLog,
    scenario: Scenario,
    robot: RobotDescription,
    path: Path,
    run_name: str,
    field: FeedbackField | None = None,
    pose_rate: float = 50.0,
    series_rate: float = 100.0,
    density: DensityResult | None = None,
) -> RecordingSummary:
    """Writes the recording of one run to `path` (parents created) and summarises it.

    `field` is the offline plan's feedback field (online runs log their own); `density` what
    `density.plan_density` made of it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    terrain = scenario.terrain
    t = np.asarray(log["t"], dtype=np.float64)
    # A recording id from the run's name: the same run replayed twice is one recording to the viewer.
    rec = rr.RecordingStream("pfnav", recording_id=run_name, send_properties=False)
    rec.save(path)
    entities: list[str] = []

    def static(entity: str, archetype: rr.AsComponents) -> None:
        rec.log(entity, archetype, static=True)
        entities.append(entity)

    def columns(entity: str, times: NDArray[np.float64], data: rr.ComponentColumnList | list[rr.ComponentColumn]) -> None:
        rec.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=times)], columns=data)
        entities.append(entity)

    static("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
    static("world/terrain", terrain_mesh(terrain))
    static("world/plan", rr.LineStrips3D([on_ground(terrain, log["plan_x"], log["plan_y"])], colors=[PLAN], radii=0.015))
    static("world/start", rr.Points3D(on_ground(terrain, np.array([scenario.start[0]]), np.array([scenario.start[1]])), radii=0.08, colors=[(255, 255, 255)]))
    static("world/goal", rr.LineStrips3D([goal_circle(scenario)], colors=[(255, 215, 0)], radii=0.02))
    replan_fields = logged_replan_fields(log)
    if replan_fields:
        # An online run: every field put in use, from its time on (the log's own, not `field`).
        for t_apply, replan_field in replan_fields:
            rec.set_time(TIMELINE, duration=t_apply)
            rec.log("world/feedback_field", field_arrows(replan_field, terrain))
        rec.reset_time()
        entities.append("world/feedback_field")
    elif field is not None:
        static("world/feedback_field", field_arrows(field, terrain))
    if density is not None and density.density is not None:
        sheet = density_mesh(density.density, terrain)
        if sheet is not None:
            # The plan was made before the walk: its density is there from the first step on.
            rec.set_time(TIMELINE, duration=float(t[0]))
            rec.log("world/pf_density", sheet)
            rec.reset_time()
            entities.append("world/pf_density")
    if sensed_map_over_time(rec, log, terrain, float(t[-1])):
        entities.append("world/sensed_map")
    elif "map_heights_final" in log and "map_variances_final" in log:
        mesh = sensed_map_mesh(terrain, log["map_heights_final"], log["map_variances_final"])
        if mesh is not None:
            static("world/sensed_map", mesh)

    # The robot: its URDF once, then the base pose and every joint over time.
    with ros_package_path(robot):
        tree = rr.urdf.UrdfTree.from_file_path(robot.urdf_path, "robot")
        tree.log_urdf_to_recording(rec)
    entities.append("robot")
    steps = frame_steps(t, pose_rate)
    times = t[steps]
    root = tree.root_link().name
    columns(
        "robot/base_pose",
        times,
        rr.Transform3D.columns(
            translation=log["base_pos"][steps],
            quaternion=xyzw(log["base_quat"][steps]),
            parent_frame=[ROOT_FRAME] * len(steps),
            child_frame=[root] * len(steps),
        ),
    )
    q = log["q"][steps]
    for k, name in enumerate(robot.joint_names):
        joint = tree.get_joint_by_name(name)
        assert joint is not None, f"{name} is checked to be in {robot.urdf_path} by RobotDescription.load"
        # No clamping: the recording shows the angles the body had, limits or not.
        columns(f"robot/joints/{name}", times, joint.compute_transform_columns(q[:, k].tolist(), clamp=False))

    feet = LegKinematics(robot).leg_chains(log["base_pos"][steps], log["base_quat"][steps], q)[:, :, -1, :]
    legs = feet.shape[1]
    touching = np.asarray(log["contact_actual"][steps], dtype=bool)
    colours = np.where(touching[..., None], np.array(TOUCHING, dtype=np.uint8), np.array(SWINGING, dtype=np.uint8)).reshape(-1, 3)
    per_frame = [legs] * len(steps)
    columns(
        "world/feet",
        times,
        rr.Points3D.columns(positions=feet.reshape(-1, 3), colors=colours, radii=[robot.foot_radius * 1.5] * len(colours)).partition(per_frame),
    )
    forces = np.asarray(log["forces"][steps], dtype=np.float64).reshape(len(steps), legs, 3)
    columns(
        "world/ground_reaction_forces",
        times,
        rr.Arrows3D.columns(origins=feet.reshape(-1, 3), vectors=(forces * FORCE_SCALE).reshape(-1, 3)).partition(per_frame),
    )
    if "push_force" in log:
        push = np.asarray(log["push_force"][steps], dtype=np.float64)
        columns("world/pushes", times, rr.Arrows3D.columns(origins=log["base_pos"][steps], vectors=push * PUSH_SCALE, colors=[(255, 0, 255)] * len(steps)))
    static("world/walked", rr.LineStrips3D([log["base_pos"][steps]], colors=[TRUTH], radii=0.01))
    if "est_pos" in log:
        static("world/estimate/path", rr.LineStrips3D([log["est_pos"][steps]], colors=[ESTIMATE], radii=0.01))
        static("world/estimate/pose", rr.TransformAxes3D(axis_length=0.3))
        columns(
            "world/estimate/pose",
            times,
            rr.Transform3D.columns(translation=log["est_pos"][steps], quaternion=xyzw(estimated_quaternions(log["est_rpy"][steps]))),
        )
    if "replan_t_apply" in log and "replan_path_lengths" in log:
        replan_paths(rec, log, terrain)
        entities.append("world/replans")

    series = frame_steps(t, series_rate)
    series_times = t[series]
    static("plots/tracking_error", rr.SeriesLines(names="base to reference, horizontal [m]"))
    columns("plots/tracking_error", series_times, rr.Scalars.columns(scalars=horizontal_tracking_error(log)[series]))
    tau = np.asarray(log["tau"], dtype=np.float64)
    for leg, label in enumerate(LEG_LABELS):
        static(f"plots/joint_torque/{label}", rr.SeriesLines(names=[f"{label} {role} [N·m]" for role in JOINT_ROLES]))
        columns(f"plots/joint_torque/{label}", series_times, rr.Scalars.columns(scalars=tau[series, 3 * leg : 3 * leg + 3]))
    static("plots/mpc_solve_time", rr.SeriesLines(names="MPC solve time, largest per sample [ms]"))
    columns("plots/mpc_solve_time", series_times, rr.Scalars.columns(scalars=1000.0 * window_max(np.asarray(log["mpc_solve_time"], dtype=np.float64), series)))
    fsm_states(rec, log, steps, series, entities)
    if "est_pos" in log:
        error = np.linalg.norm(np.asarray(log["est_pos"], dtype=np.float64)[series] - np.asarray(log["base_pos"], dtype=np.float64)[series], axis=1)
        static("plots/estimate_error", rr.SeriesLines(names="estimated base position − truth [m]"))
        columns("plots/estimate_error", series_times, rr.Scalars.columns(scalars=error))
    notes = "\n".join(f"- {line}" for line in missing_contents(log, field, density))
    static("notes", rr.TextDocument(f"# {run_name}\n\nNot in this recording:\n\n{notes}\n", media_type=rr.MediaType.MARKDOWN))
    rec.flush()
    # Disconnecting finishes the file (its footer and index).
    rec.disconnect()
    return RecordingSummary(path, path.stat().st_size, tuple(entities), float(t[0]), float(t[-1]), len(steps))


def fsm_states(rec: rr.RecordingStream, log: RunLog, steps: NDArray[np.int64], series: NDArray[np.int64], entities: list[str]) -> None:
    """The controller FSM's state by its FMU name: the code as a plot (its legend names the codes), each
    change as a line of `fsm_state`, and a label floating above the robot at every pose."""
    t = np.asarray(log["t"], dtype=np.float64)
    codes = np.asarray(log["fsm"], dtype=np.int64)
    names = fsm_state_names(log)

    def name(code: int) -> str:
        return names.get(code, f"state {code}")

    legend = ", ".join(f"{code} = {state}" for code, state in sorted(names.items()))
    rec.log("plots/fsm_state", rr.SeriesLines(names=f"controller FSM state ({legend})" if legend else "controller FSM state code"), static=True)
    rec.send_columns(
        "plots/fsm_state", indexes=[rr.TimeColumn(TIMELINE, duration=t[series])], columns=rr.Scalars.columns(scalars=codes[series].astype(np.float64))
    )
    changes = fsm_transitions(codes)
    rec.send_columns(
        "fsm_state",
        indexes=[rr.TimeColumn(TIMELINE, duration=t[changes])],
        columns=rr.TextLog.columns(text=[name(int(code)) for code in codes[changes]], level=["INFO"] * len(changes)),
    )
    above = np.asarray(log["base_pos"], dtype=np.float64)[steps] + np.array([0.0, 0.0, FSM_LABEL_HEIGHT])
    rec.send_columns(
        "world/fsm_state",
        indexes=[rr.TimeColumn(TIMELINE, duration=t[steps])],
        columns=rr.Points3D.columns(positions=above, labels=[name(int(code)) for code in codes[steps]], radii=[0.005] * len(steps)),
    )
    entities.extend(["plots/fsm_state", "fsm_state", "world/fsm_state"])


def logged_replan_fields(log: RunLog) -> list[tuple[float, FeedbackField]]:
    """(time put in use, field) of every feedback field an online run's log holds (`replan_field_*`)."""
    if "replan_field_rows" not in log or "replan_t_apply" not in log:
        return []
    applied = np.asarray(log["replan_t_apply"], dtype=np.float64)
    origin = np.asarray(log["replan_field_origin"], dtype=np.float64)
    goal = np.asarray(log["replan_field_goal"], dtype=np.float64)
    fields = []
    for k, row in enumerate(np.asarray(log["replan_field_rows"], dtype=np.int64)):
        if not math.isfinite(applied[row]):
            continue
        fields.append(
            (
                float(applied[row]),
                FeedbackField(
                    origin=(float(origin[0]), float(origin[1])),
                    resolution=float(log["replan_field_resolution"]),
                    dir_x=log["replan_field_dir_x"][k],
                    dir_y=log["replan_field_dir_y"][k],
                    speed=log["replan_field_speed"][k],
                    cost_to_go=log["replan_field_cost_to_go"][k],
                    goal=(float(goal[0]), float(goal[1]), float(goal[2])),
                ),
            )
        )
    return fields


def snapshot_times(log: RunLog) -> NDArray[np.float64]:
    """Simulated time of each logged map snapshot (the update it was sent with)."""
    return np.asarray(log["replan_t_publish"], dtype=np.float64)[np.asarray(log["map_snapshot_rows"], dtype=np.int64)]


def sensed_map_over_time(rec: rr.RecordingStream, log: RunLog, terrain: Terrain, t_end: float) -> bool:
    """The map as sent with the updates (`map_snapshot_*`), thinned to at most one per
    `SENSED_MAP_PERIOD` and `SENSED_MAP_VERTICES_ACROSS` vertices across, then at the run's end
    its final state (`map_*_final`) at full resolution. False when the log has no snapshots."""
    if "map_snapshot_rows" not in log or "replan_t_publish" not in log:
        return False
    times = snapshot_times(log)
    heights, variances = log["map_snapshot_heights"], log["map_snapshot_variances"]
    last = -math.inf
    for k, t_snapshot in enumerate(times):
        if t_snapshot < last + SENSED_MAP_PERIOD - 1e-9:
            continue
        mesh = sensed_map_mesh(terrain, heights[k], variances[k], SENSED_MAP_VERTICES_ACROSS)
        if mesh is None:
            continue
        last = float(t_snapshot)
        rec.set_time(TIMELINE, duration=last)
        rec.log("world/sensed_map", mesh)
    if "map_heights_final" in log and "map_variances_final" in log:
        final = sensed_map_mesh(terrain, log["map_heights_final"], log["map_variances_final"])
        if final is not None:
            rec.set_time(TIMELINE, duration=t_end)
            rec.log("world/sensed_map", final)
    rec.reset_time()
    return True


def replan_paths(rec: rr.RecordingStream, log: RunLog, terrain: Terrain) -> None:
    """Each replan's path in `world/replans` from the moment it was put in use (replans never used are left out)."""
    lengths = np.asarray(log["replan_path_lengths"], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    applied = np.asarray(log["replan_t_apply"], dtype=np.float64)
    in_use = np.asarray(log.get("replan_in_use", np.ones(len(lengths), dtype=bool)), dtype=bool)
    xs, ys = np.asarray(log["replan_path_x"], dtype=np.float64), np.asarray(log["replan_path_y"], dtype=np.float64)
    for i in np.nonzero(in_use & np.isfinite(applied) & (lengths > 1))[0]:
        rec.set_time(TIMELINE, duration=float(applied[i]))
        strip = on_ground(terrain, xs[offsets[i] : offsets[i + 1]], ys[offsets[i] : offsets[i + 1]])
        rec.log("world/replans", rr.LineStrips3D([strip], colors=[(255, 140, 0)], radii=0.02))
    rec.reset_time()
