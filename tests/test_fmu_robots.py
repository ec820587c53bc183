"""FMUs of third-party robots made by `bundle-fmu --robot CONFIG --binaries-from FMU` (issue 19).

For each robot config in robot/third_party: the bundled modelDescription describes that robot (joint
ranges and effort limits of its URDF or its config's overrides, stand height, start pose at that
height), the resources carry its config, URDF and every mesh the URDF names, the FMU stands the robot
up from its start values, and a state saved by one robot's FMU is refused by another's. Bad robot
descriptions stop bundle-fmu with a message naming the item and the file, and leave no FMU behind.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sysconfig
import tomllib
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Any

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

REPO = Path(__file__).resolve().parents[1]
THIRD_PARTY = sorted((REPO / "robot" / "third_party").glob("*.toml"))
PACKAGE_ROOTS = os.environ.get(
    "PFNAV_PACKAGE_PATH", str(Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share")
)


def bundle_fmu_bin() -> Path:
    path = Path(os.environ.get("PFNAV_BUNDLE_FMU", REPO / "target" / "release" / "bundle-fmu"))
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it with `cargo build --release -p quad-controller-fmu`", pytrace=False)
    return path


def bundle(config: Path, fmu_file: Path, out: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(bundle_fmu_bin()), "--robot", str(config), "--binaries-from", str(fmu_file), "--out", str(out)],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PFNAV_PACKAGE_PATH": PACKAGE_ROOTS},
    )


@pytest.fixture(scope="module")
def robot_fmus(fmu_file: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("robot_fmus")
    fmus = {}
    for config in THIRD_PARTY:
        out = folder / f"{config.stem}.fmu"
        done = bundle(config, fmu_file, out)
        assert done.returncode == 0, done.stderr
        fmus[config.stem] = out
    return fmus


def resolve(reference: str, relative_to: Path) -> Path:
    """A `package://` or relative file name, as the robot config format resolves it."""
    if reference.startswith("package://"):
        inner = reference.removeprefix("package://")
        for root in PACKAGE_ROOTS.split(":"):
            if (Path(root) / inner.split("/")[0]).is_dir():
                return Path(root) / inner
        raise AssertionError(f"{reference} in none of {PACKAGE_ROOTS}")
    return relative_to / reference


def urdf_limits(config: dict[str, Any], urdf: Path) -> list[tuple[float, float, float]]:
    """(lower, upper, effort) of the 12 actuated joints in FMU order, effort overridden by the config."""
    joints = {j.get("name"): j.find("limit") for j in ET.parse(urdf).getroot().findall("joint")}
    effort_override = config.get("limits", {}).get("effort")
    limits = []
    for leg in ("FR", "FL", "RR", "RL"):
        for role, name in enumerate(config["legs"][leg]["joints"]):
            limit = joints[name]
            assert limit is not None, name
            effort = effort_override[role] if effort_override else float(limit.get("effort", "nan"))
            limits.append((float(limit.get("lower", "nan")), float(limit.get("upper", "nan")), effort))
    return limits


@pytest.mark.parametrize("config_path", THIRD_PARTY, ids=lambda p: p.stem)
def test_the_bundled_description_is_the_robots(config_path: Path, robot_fmus: dict[str, Path]) -> None:
    fmu = robot_fmus[config_path.stem]
    config = tomllib.loads(config_path.read_text())
    urdf = resolve(config["urdf"], config_path.parent)
    md = read_model_description(str(fmu))
    by_name = {v.name: v for v in md.modelVariables}
    for i, (lower, upper, effort) in enumerate(urdf_limits(config, urdf), start=1):
        q = by_name[f"joint.q[{i}]"]
        assert (float(q.min), float(q.max)) == (lower, upper), q.name
        assert lower <= float(q.start) <= upper, q.name
        assert float(by_name[f"joint.tau[{i}]"].max) == effort
    assert float(by_name["stand.bodyHeight"].start) == config["stand_height"]
    assert float(by_name["base.pos.z"].start) == config["stand_height"]
    # Parameter ranges are the robot's (the tuned envelope widened with its size): each start value,
    # the default scaled to the robot, lies inside its range (HyQ stands 0.6 m high, with stance
    # gains beyond the 12 kg robot's 1000 N·m/rad).
    for v in md.modelVariables:
        if v.causality == "parameter" and v.type == "Real":
            assert float(v.min) <= float(v.start) <= float(v.max), (v.name, v.min, v.start, v.max)
    with zipfile.ZipFile(fmu) as archive:
        names = set(archive.namelist())
        bundled_config = tomllib.loads(archive.read("resources/robot/robot.toml").decode())
        bundled_urdf = archive.read("resources/robot/robot.urdf").decode()
        controller = json.loads(archive.read("resources/controller.json"))
    assert bundled_config["urdf"] == "robot.urdf"
    assert bundled_config["legs"] == config["legs"]
    assert controller["body_height"] == config["stand_height"]
    meshes = {m.get("filename") for m in ET.fromstring(bundled_urdf).iter("mesh")}
    assert meshes, "every third-party robot here has meshes"
    for mesh in meshes:
        assert mesh is not None and not mesh.startswith("package://"), mesh
        assert f"resources/robot/{mesh}" in names, mesh
    original = {m.get("filename") for m in ET.parse(urdf).getroot().iter("mesh")}
    assert {m.removeprefix("package://") for m in original if m} == {m.removeprefix("meshes/") for m in meshes if m}


def slave_of(fmu: Path, name: str) -> tuple[FMU2Slave, Any]:
    md = read_model_description(str(fmu))
    slave = FMU2Slave(
        guid=md.guid, unzipDirectory=extract(str(fmu)), modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, md


@pytest.mark.parametrize("config_path", THIRD_PARTY, ids=lambda p: p.stem)
def test_each_robot_stands_up_from_its_start_values(config_path: Path, robot_fmus: dict[str, Path]) -> None:
    """The inputs stay at their start values (the robot held in its standing pose): the FSM stands up
    within the stand-up time and the torques hold the legs' weight without reaching the limits."""
    slave, md = slave_of(robot_fmus[config_path.stem], config_path.stem)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    states = {str(item.name): int(item.value) for t in md.typeDefinitions if t.name == "FsmState" for item in t.items}
    limits = [float(v.max) for v in md.modelVariables if v.name.startswith("joint.tau[")]
    try:
        for k in range(1500):
            slave.doStep(k * 0.001, 0.001)
        fsm = slave.getInteger([vr["fsm.state"]])[0]
        tau = slave.getReal([vr[f"joint.tau[{i}]"] for i in range(1, 13)])
    finally:
        slave.terminate()
        slave.freeInstance()
    assert fsm == states["Stand"], fsm
    assert all(math.isfinite(t) for t in tau)
    assert all(abs(t) < 0.9 * limit for t, limit in zip(tau, limits, strict=True)), (tau, limits)
    assert max(abs(t) for t in tau) > 0.01 * max(limits), "the legs carry the weight"


def test_a_state_saved_by_one_robot_is_refused_by_another(robot_fmus: dict[str, Path]) -> None:
    first, second = sorted(robot_fmus)[:2]
    saver, _ = slave_of(robot_fmus[first], "saver")
    loader, _ = slave_of(robot_fmus[second], "loader")
    try:
        blob = saver.serializeFMUstate(saver.getFMUstate())
        with pytest.raises(Exception, match="fmi2DeSerializeFMUstate"):
            loader.deSerializeFMUstate(blob)
        own = loader.serializeFMUstate(loader.getFMUstate())
        loader.setFMUstate(loader.deSerializeFMUstate(own))
    finally:
        for slave in (saver, loader):
            slave.terminate()
            slave.freeInstance()


def broken_copy(tmp_path: Path, edit: str, old: str, new: str) -> Path:
    """A copy of the Go1 config (and, for edit == "urdf", of its URDF) with `old` replaced by `new`."""
    source = REPO / "robot" / "third_party" / "go1.toml"
    text = source.read_text()
    if edit == "config":
        assert old in text
        text = text.replace(old, new)
    else:
        config = tomllib.loads(text)
        urdf = resolve(config["urdf"], source.parent).read_text()
        assert old in urdf
        (tmp_path / "go1.urdf").write_text(urdf.replace(old, new))
        text = text.replace(config["urdf"], "go1.urdf")
    path = tmp_path / "broken.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("edit", "old", "new", "needles"),
    [
        ("config", '"FL_calf_joint"', '"FL_elbow_joint"', ["FL_elbow_joint", "go1.urdf"]),
        ("config", "stand_height = 0.27", "stand_height = 0.27\nstand_hieght = 0.2", ["stand_hieght", "broken.toml"]),
        ("urdf", "meshes/calf.dae", "meshes/no_such_calf.dae", ["no_such_calf.dae", "go1.urdf", "calf"]),
        ("urdf", '<mass value="5.204"/>', '<mass value="-5.204"/>', ["go1.urdf", "mass"]),
        ("urdf", 'name="FR_hip_joint" type="revolute"', 'name="FR_hip_joint" type="prismatic"', ["FR_hip_joint", "go1.urdf"]),
    ],
    ids=["missing joint", "unknown key", "missing mesh", "negative mass", "prismatic joint"],
)
def test_bad_robot_descriptions_name_the_item_and_the_file(
    edit: str, old: str, new: str, needles: list[str], fmu_file: Path, tmp_path: Path
) -> None:
    config = broken_copy(tmp_path, edit, old, new)
    out = tmp_path / "broken.fmu"
    done = bundle(config, fmu_file, out)
    assert done.returncode != 0
    for needle in needles:
        assert needle in done.stderr, (needle, done.stderr)
    assert "panicked" not in done.stderr
    assert not out.exists() and not out.with_suffix(".fmu.partial").exists()


def pf_robot(*args: str) -> subprocess.CompletedProcess[str]:
    path = Path(os.environ.get("PFNAV_PF_ROBOT", REPO / "target" / "release" / "pf-robot"))
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it with `cargo build --release -p fmu-tools`", pytrace=False)
    return subprocess.run(
        [str(path), *args],
        check=False,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PFNAV_PACKAGE_PATH": PACKAGE_ROOTS},
    )


@pytest.mark.parametrize("config_path", THIRD_PARTY, ids=lambda p: p.stem)
def test_pf_robot_check_passes_every_shipped_config(config_path: Path) -> None:
    done = pf_robot("check", str(config_path))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "no problems" in done.stdout


def test_pf_robot_check_lists_every_fault_with_its_fix(tmp_path: Path) -> None:
    """Two faults of different kinds in one run (a placeholder inertial declared nowhere, a wrong knee
    branch), each with the line that fixes it; the stand height proposed from the SRDF."""
    config = broken_copy(tmp_path, "config", 'massless_links = ["base"]', "")
    text = config.read_text().replace('knee_points = "backward"', 'knee_points = "forward"', 1)
    config.write_text(text)
    done = pf_robot("check", str(config))
    assert done.returncode == 1, done.stdout + done.stderr
    for needle in [
        "2 problem(s)",
        '`massless_links`',
        'fix: massless_links = ["base"]',
        "`legs.FR.knee_points`",
        'fix: knee_points = "backward"',
        "stand_height = 0.27",
    ]:
        assert needle in done.stdout, (needle, done.stdout)
    assert "panicked" not in done.stderr
