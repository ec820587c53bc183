"""Replays of a run from its log: the Rerun recording, read back with Rerun's own reader."""

from __future__ import annotations

import dataclasses
import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from replay_logs import DURATION, synthetic_log
from rerun.chunk import RrdReader

from pfnav_harness import cli, paths
from pfnav_harness.feedback_field import FeedbackField
from pfnav_harness.replay.density import plan_density
from pfnav_harness.replay.kinematics import LegKinematics
from pfnav_harness.replay.recording import write_recording
from pfnav_harness.replay.run_log import frame_steps, load_run_log
from pfnav_harness.replay.video import FPS, HEIGHT, WIDTH, render_video
from pfnav_harness.robot import LEG_LABELS, RobotDescription
from pfnav_harness.scenario import Scenario, load_scenario, write_map


@pytest.fixture(scope="module")
def robot() -> RobotDescription:
    return RobotDescription.load(paths.default_robot_config_path())


def read_chunks(path: Path) -> dict[str, list[pa.RecordBatch]]:
    """The recording's chunks by entity path, through Rerun's own reader."""
    chunks: dict[str, list[pa.RecordBatch]] = {}
    for chunk in RrdReader(path).store().stream():
        chunks.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return chunks


def sim_times(batches: list[pa.RecordBatch]) -> np.ndarray:
    times = [b.column("sim_time").cast(pa.int64()).to_numpy() for b in batches if "sim_time" in b.schema.names]
    return np.sort(np.concatenate(times)) * 1e-9 if times else np.zeros(0)


def column(batches: list[pa.RecordBatch], name: str) -> list:
    return [value for b in batches if name in b.schema.names for value in b.column(name).to_pylist()]


def test_recording_holds_the_run_on_the_simulation_clock(tmp_path: Path, ramp_scenario: Scenario, robot: RobotDescription) -> None:
    log = synthetic_log(ramp_scenario, robot)
    summary = write_recording(log, ramp_scenario, robot, tmp_path / "ramp_pf.rrd", "ramp_pf")
    chunks = read_chunks(summary.path)
    expected = {
        "/world/terrain",
        "/world/plan",
        "/world/goal",
        "/world/feet",
        "/world/ground_reaction_forces",
        "/world/pushes",
        "/world/walked",
        "/world/estimate/path",
        "/world/estimate/pose",
        "/robot/base_pose",
        "/plots/tracking_error",
        "/plots/mpc_solve_time",
        "/plots/fsm_state",
        "/plots/estimate_error",
        "/notes",
        *(f"/robot/joints/{name}" for name in robot.joint_names),
        *(f"/plots/joint_torque/{label}" for label in LEG_LABELS),
    }
    assert expected <= set(chunks), sorted(expected - set(chunks))
    # The URDF's own geometry, base link included.
    assert any(path.startswith("/robot/") and f"/{robot.base_link}/" in path for path in chunks)
    # No feedback field was given and the run was offline: nothing claims otherwise.
    assert not {"/world/feedback_field", "/world/replans", "/world/sensed_map"} & set(chunks)

    steps = frame_steps(log["t"], 50.0)
    pose_times = sim_times(chunks["/robot/base_pose"])
    np.testing.assert_allclose(pose_times, log["t"][steps], atol=1e-9)
    assert pose_times[0] == pytest.approx(log["t"][0]) and pose_times[-1] == pytest.approx(log["t"][-1])
    assert summary.t_first == pytest.approx(log["t"][0]) and summary.t_last == pytest.approx(log["t"][-1])
    translations = np.array(column(chunks["/robot/base_pose"], "Transform3D:translation")).reshape(-1, 3)
    np.testing.assert_allclose(translations, log["base_pos"][steps], atol=1e-5)
    series_times = sim_times(chunks["/plots/tracking_error"])
    assert series_times[0] == pytest.approx(0.0) and series_times[-1] == pytest.approx(log["t"][-1])
    assert len(series_times) == len(frame_steps(log["t"], 100.0))
    # Every MPC spike (4 ms every 97 steps) survives the thinning to 100 Hz.
    solve_ms = np.array(column(chunks["/plots/mpc_solve_time"], "Scalars:scalars")).ravel()
    assert np.count_nonzero(solve_ms > 3.9) == len(np.unique(np.arange(0, len(log["t"]), 97) // 10))

    # Feet: four per frame, green exactly where the log says the foot touches, at the kinematics' points.
    feet = np.array(column(chunks["/world/feet"], "Points3D:positions")).reshape(len(steps), 4, 3)
    expected_feet = LegKinematics(robot).leg_chains(log["base_pos"][steps], log["base_quat"][steps], log["q"][steps])[:, :, -1]
    np.testing.assert_allclose(feet, expected_feet, atol=1e-5)
    colours = np.array(column(chunks["/world/feet"], "Points3D:colors")).reshape(len(steps), 4)
    touching = log["contact_actual"][steps].astype(bool)
    assert len(np.unique(colours[touching])) == 1 and len(np.unique(colours[~touching])) == 1
    assert colours[touching][0] != colours[~touching][0]

    # The FSM by the names the FMU declared: each change as a line, the name above the robot at every pose.
    fsm = chunks["/fsm_state"]
    np.testing.assert_allclose(sim_times(fsm), [0.0, 0.5])
    assert column(fsm, "TextLog:text") == [["Stand"], ["Locomotion"]]
    labels = [label for frame in column(chunks["/world/fsm_state"], "Points3D:labels") for label in frame]
    assert labels == ["Stand" if t < 0.5 else "Locomotion" for t in log["t"][steps]]
    assert "1 = Stand, 2 = Locomotion" in str(column(chunks["/plots/fsm_state"], "SeriesLines:names"))


def ramp_field(scenario: Scenario) -> FeedbackField:
    """A field along +x over the whole ramp, cost-to-go rising along the cells, cell (0, 0) unreachable."""
    shape = scenario.terrain.shape
    cost = np.linspace(0.0, 2.0, shape[0] * shape[1]).reshape(shape)
    cost[0, 0] = -1.0
    return FeedbackField(
        origin=scenario.origin,
        resolution=scenario.resolution,
        dir_x=np.ones(shape),
        dir_y=np.zeros(shape),
        speed=np.full(shape, 0.3),
        cost_to_go=cost,
        goal=(*scenario.goal.center, scenario.goal.radius),
    )


def test_recording_of_an_offline_run_with_its_field(tmp_path: Path, ramp_scenario: Scenario, robot: RobotDescription) -> None:
    log = synthetic_log(ramp_scenario, robot)
    shape = ramp_scenario.terrain.shape
    summary = write_recording(log, ramp_scenario, robot, tmp_path / "ramp_pf.rrd", "ramp_pf", ramp_field(ramp_scenario))
    chunks = read_chunks(summary.path)
    # One field for the whole run: static, no time.
    assert len(sim_times(chunks["/world/feedback_field"])) == 0
    arrows = np.array(column(chunks["/world/feedback_field"], "Arrows3D:vectors")).reshape(-1, 3)
    # Every reachable cell of the (small) map has its arrow, along +x.
    assert len(arrows) == shape[0] * shape[1] - 1
    np.testing.assert_allclose(arrows[:, 1:], 0.0)


def test_recording_of_an_online_run_shows_each_replan(tmp_path: Path, ramp_scenario: Scenario, robot: RobotDescription) -> None:
    log = synthetic_log(ramp_scenario, robot, online=True)
    ny, nx = ramp_scenario.terrain.shape
    # A field given besides the log's own is not drawn: the log says which field was in use when.
    summary = write_recording(log, ramp_scenario, robot, tmp_path / "ramp_pf-online.rrd", "ramp_pf-online", ramp_field(ramp_scenario))
    chunks = read_chunks(summary.path)
    # Each field from the moment it was put in use: the first along +x, the second along +y.
    field_batches = chunks["/world/feedback_field"]
    np.testing.assert_allclose(sim_times(field_batches), [0.7, 1.4])
    arrows = [np.array(column([b], "Arrows3D:vectors")).reshape(-1, 3) for b in field_batches if "Arrows3D:vectors" in b.schema.names]
    per_time = np.concatenate(arrows).reshape(2, -1, 3)
    assert per_time.shape[1] == ny * nx
    np.testing.assert_allclose(per_time[0, :, 1], 0.0)
    np.testing.assert_allclose(per_time[1, :, 0], 0.0)
    # The two replans put in use, each from the time it was applied.
    np.testing.assert_allclose(sim_times(chunks["/world/replans"]), [0.7, 1.4])
    # The sensed map as the updates sent it (the one 0.1 s after another left out), then its final state:
    # the triangles whose corners were all seen (the first 5, 10 columns, then 15 at the end).
    map_batches = chunks["/world/sensed_map"]
    np.testing.assert_allclose(sim_times(map_batches), [0.2, 1.2, log["t"][-1]])
    triangle_counts = [len(value) for value in column(map_batches, "Mesh3D:triangle_indices")]
    assert triangle_counts == [2 * (ny - 1) * (columns - 1) for columns in (5, 10, 15)]
    notes = column(chunks["/notes"], "TextDocument:text")[0][0]
    assert "only its state at the end" not in notes and "feedback field" not in notes


def test_the_offline_plans_density_comes_from_pf_plan_when_its_field_matches(
    tmp_path: Path, ramp_scenario: Scenario, robot: RobotDescription
) -> None:
    pf_plan = paths.pf_plan_path()
    # The run's field: pf-plan's own plan of the ramp on its full grid (as the service plans a map).
    map_json = write_map(ramp_scenario.terrain, tmp_path / "map", "ramp", start=ramp_scenario.start, goal=ramp_scenario.goal)
    field_file = tmp_path / "field.npz"
    subprocess.run(
        [str(pf_plan), "plan", "--map", str(map_json), "--method", "pf", "--grid", "30", "--out", str(tmp_path), "--field-out", str(field_file)],
        check=True,
        capture_output=True,
    )
    field = FeedbackField.from_npz(field_file)
    result = plan_density(pf_plan, ramp_scenario, field)
    assert result.density is not None, result.reason
    rho = result.density.density
    assert rho.shape == field.cost_to_go.shape
    # Mass wherever the goal is reached from, none in the goal itself.
    np.testing.assert_array_equal(rho > 0.0, field.cost_to_go > 0.0)

    # Another plan's field (another cost model): no density, and the reason.
    other = dataclasses.replace(field, cost_to_go=np.where(field.cost_to_go > 0.0, 1.5 * field.cost_to_go, field.cost_to_go))
    refused = plan_density(pf_plan, ramp_scenario, other)
    assert refused.density is None and "does not match" in refused.reason

    log = synthetic_log(ramp_scenario, robot)
    summary = write_recording(log, ramp_scenario, robot, tmp_path / "ramp_pf.rrd", "ramp_pf", field, density=result)
    chunks = read_chunks(summary.path)
    sheet = chunks["/world/pf_density"]
    # At the plan's time (the run's start), over the cells the flow visits.
    np.testing.assert_allclose(sim_times(sheet), [log["t"][0]])
    vertices = np.array(column(sheet, "Mesh3D:vertex_positions")).reshape(-1, 3)
    assert len(vertices) == rho.size
    triangles = np.array(column(sheet, "Mesh3D:triangle_indices")).reshape(-1, 3)
    visited = (rho >= rho.max() * 1e-3).ravel()
    assert len(triangles) > 0 and visited[triangles].all()
    assert "occupation density" not in column(chunks["/notes"], "TextDocument:text")[0][0]
    # Without it, the notes say why.
    bare = read_chunks(write_recording(log, ramp_scenario, robot, tmp_path / "bare.rrd", "bare", field, density=refused).path)
    assert "/world/pf_density" not in bare
    assert "does not match" in column(bare["/notes"], "TextDocument:text")[0][0]


def test_replay_command_writes_the_recording_beside_the_logs(
    tmp_path: Path, scenario_writer: Callable[..., Path], robot: RobotDescription, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    heights = np.tile(0.1 + 0.1 * np.arange(30) * 0.1, (20, 1))
    scenario = load_scenario(scenario_writer(out / "scenarios", "slope_test", heights, 0.1, start=(0.5, 1.0), goal=(2.5, 1.0)))
    log_file = out / "logs" / "slope_test_pf.npz"
    log_file.parent.mkdir(parents=True)
    np.savez_compressed(log_file, **synthetic_log(scenario, robot))
    video = tmp_path / "slope_test_pf.mp4"
    assert cli.main(["replay", str(log_file), "--robot", str(robot.config_path), "--video", str(video)]) == 0
    recording = out / "recordings" / "slope_test_pf.rrd"
    assert recording.is_file()
    assert int(str(video_stream(video)["nb_read_frames"])) > 0
    assert "rerun " in capsys.readouterr().err
    times = sim_times(read_chunks(recording)["/robot/base_pose"])
    assert times[-1] == pytest.approx(load_run_log(log_file)["t"][-1])


def test_replay_with_the_runs_field_shows_its_density_planned_with_the_logged_cost_model(
    tmp_path: Path, scenario_writer: Callable[..., Path], robot: RobotDescription
) -> None:
    out = tmp_path / "out"
    heights = np.tile(0.1 + 0.01 * np.arange(30), (20, 1))
    scenario = load_scenario(scenario_writer(out / "scenarios", "slope_test", heights, 0.1, start=(0.5, 1.0), goal=(2.5, 1.0)))
    # The run planned with a footprint the sidecar does not name (the demo's override): the log keeps it.
    model = {"footprint_radius_m": 0.2}
    map_json = write_map(scenario.terrain, tmp_path / "map", "slope_test", model, start=scenario.start, goal=scenario.goal)
    field_file = tmp_path / "field.npz"
    subprocess.run(
        [str(paths.pf_plan_path()), "plan", "--map", str(map_json), "--method", "pf", "--grid", "30", "--out", str(tmp_path), "--field-out", str(field_file)],
        check=True,
        capture_output=True,
    )
    log_file = out / "logs" / "slope_test_pf.npz"
    log_file.parent.mkdir(parents=True)
    log = synthetic_log(scenario, robot)
    np.savez_compressed(log_file, **log, traversability=np.array(json.dumps(model)))
    assert cli.main(["replay", str(log_file), "--robot", str(robot.config_path), "--field", str(field_file)]) == 0
    chunks = read_chunks(out / "recordings" / "slope_test_pf.rrd")
    assert "/world/pf_density" in chunks and "/world/feedback_field" in chunks
    # Without the logged cost model the plan differs (no footprint): no density, and the notes say why.
    np.savez_compressed(log_file, **log)
    assert cli.main(["replay", str(log_file), "--robot", str(robot.config_path), "--field", str(field_file)]) == 0
    chunks = read_chunks(out / "recordings" / "slope_test_pf.rrd")
    assert "/world/pf_density" not in chunks
    assert "does not match" in column(chunks["/notes"], "TextDocument:text")[0][0]


def test_replay_refuses_a_log_without_its_scenario(
    tmp_path: Path, ramp_scenario: Scenario, robot: RobotDescription, capsys: pytest.CaptureFixture[str]
) -> None:
    log_file = tmp_path / "logs" / "nowhere_pf.npz"
    log_file.parent.mkdir()
    np.savez_compressed(log_file, **synthetic_log(ramp_scenario, robot))
    assert cli.main(["replay", str(log_file)]) == 2
    assert "nowhere.json" in capsys.readouterr().err


def video_stream(path: Path) -> dict[str, object]:
    """Codec, size and decoded frame count of the video's stream (ffprobe decodes every frame)."""
    probe = subprocess.run(
        [
            "ffprobe",
            "-v",
            "error",
            "-count_frames",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=codec_name,width,height,nb_read_frames,pix_fmt",
            "-of",
            "json",
            str(path),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(probe.stdout)["streams"][0]


def test_video_has_a_frame_per_sampled_step(tmp_path: Path, ramp_scenario: Scenario, robot: RobotDescription) -> None:
    log = synthetic_log(ramp_scenario, robot)
    summary = render_video(log, ramp_scenario, robot, tmp_path / "ramp_pf.mp4", "ramp_pf")
    # A 2 s run fits into the longest video: it plays in real time (to a whole log step per frame), plus the last step.
    assert summary.speed == pytest.approx(1.0, rel=0.01)
    assert summary.frames == len(frame_steps(log["t"], FPS)) == round(DURATION * FPS) + 1
    stream = video_stream(summary.path)
    assert stream["codec_name"] == "h264" and stream["pix_fmt"] == "yuv420p"
    assert (stream["width"], stream["height"]) == (WIDTH, HEIGHT)
    assert int(str(stream["nb_read_frames"])) == summary.frames


def test_long_runs_play_faster_within_the_longest_video(tmp_path: Path, ramp_scenario: Scenario, robot: RobotDescription) -> None:
    log = synthetic_log(ramp_scenario, robot)
    # The same log on a 40× slower clock: 80 simulated seconds.
    log["t"] = log["t"] * 40.0
    summary = render_video(log, ramp_scenario, robot, tmp_path / "slow.mp4", "slow")
    # At most 10 s of video (plus the last step's frame), the clock running at the speed that takes.
    assert summary.frames / FPS <= 10.0 + 1.0 / FPS
    assert summary.speed >= log["t"][-1] / 10.0
    assert summary.frames == len(frame_steps(log["t"], FPS / summary.speed))
    assert int(str(video_stream(summary.path)["nb_read_frames"])) == summary.frames
