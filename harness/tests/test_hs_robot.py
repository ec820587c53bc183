"""Robot configs: the description read from each config, clear errors for bad ones, each robot in the DART world.

The third-party robots come from the PyPI package example-robot-data (scripts/requirements-robots.txt),
found through the package root of this interpreter's site-packages.
"""

from __future__ import annotations

import sysconfig
import xml.etree.ElementTree as ET
from pathlib import Path

import dartpy as dart
import numpy as np
import pytest

from pfnav_harness import paths
from pfnav_harness.robot import PACKAGE_PATH_ENV, RobotConfigError, RobotDescription, package_roots_from_env
from pfnav_harness.scenario import Terrain
from pfnav_harness.world import Payload, QuadrupedWorld

PACKAGE_ROOT = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share"
ROBOTS = paths.repo_root() / "robot"
THIRD_PARTY = ("go1", "a1", "solo12")
CLEARANCE = 0.002


def third_party(name: str) -> RobotDescription:
    if not (PACKAGE_ROOT / "example-robot-data").is_dir():
        pytest.fail(
            f"example-robot-data is not installed under {PACKAGE_ROOT}: .venv/bin/pip install --no-deps -r scripts/requirements-robots.txt",
            pytrace=False,
        )
    return RobotDescription.load(ROBOTS / "third_party" / f"{name}.toml", [PACKAGE_ROOT])


def flat_terrain() -> Terrain:
    return Terrain((0.0, 0.0), 0.125, np.zeros((24, 24)))


# --- the description --------------------------------------------------------------------------


def test_our_robot_is_described_by_its_config() -> None:
    robot = RobotDescription.load(paths.default_robot_config_path())
    assert robot.urdf_path == ROBOTS / "quadruped.urdf"
    assert robot.base_link == "base"
    assert robot.joint_names[:3] == ("FR_hip_abd_joint", "FR_hip_flex_joint", "FR_knee_joint")
    assert robot.joint_names[-1] == "RL_knee_joint" and len(set(robot.joint_names)) == 12
    assert robot.foot_links == ("FR_foot", "FL_foot", "RR_foot", "RL_foot")
    np.testing.assert_array_equal(robot.crouch, np.tile([0.0, 0.8, -1.6], 4))
    np.testing.assert_array_equal(robot.foot_offsets, np.zeros((4, 3)))
    assert robot.foot_radius == 0.02 and all(leg.has_foot_sphere for leg in robot.legs)
    assert robot.stand_height == 0.28 and robot.massless_links == () and robot.effort_limits is None
    assert robot.package_dirs == () and robot.mesh_files == ()
    assert robot.mass == pytest.approx(12.0, abs=1e-9)


@pytest.mark.parametrize(
    ("name", "base", "first_joint", "rear_right_foot", "radius", "from_sphere"),
    [
        ("go1", "base", "FR_hip_joint", "RR_foot", 0.02, True),
        ("a1", "base", "FR_hip_joint", "RR_foot", 0.02, True),
        ("solo12", "base_link", "FR_HAA", "HR_FOOT", 0.016, False),
    ],
)
def test_third_party_robots_are_described(name: str, base: str, first_joint: str, rear_right_foot: str, radius: float, from_sphere: bool) -> None:
    robot = third_party(name)
    assert robot.urdf_path.is_file() and robot.urdf_path.is_relative_to(PACKAGE_ROOT / "example-robot-data")
    assert robot.package_dirs == (("example-robot-data", PACKAGE_ROOT.absolute() / "example-robot-data"),)
    assert robot.base_link == base
    assert len(robot.joint_names) == 12 and len(set(robot.joint_names)) == 12
    assert robot.joint_names[0] == first_joint
    assert robot.foot_links[2] == rear_right_foot
    # Solo-12's feet are meshes: the radius is the config's; the others' is their sphere collision's.
    assert robot.foot_radius == radius
    assert all(leg.has_foot_sphere == from_sphere for leg in robot.legs)
    assert robot.crouch.shape == (12,)
    assert robot.mesh_files and all(mesh.is_file() for mesh in robot.mesh_files)


def test_crouches_are_inside_the_joint_limits() -> None:
    for name in THIRD_PARTY:
        robot = third_party(name)
        joints = {j.get("name"): j for j in ET.parse(robot.urdf_path).getroot().iter("joint") if j.get("type")}
        for joint, angle in zip(robot.joint_names, robot.crouch, strict=True):
            limit = joints[joint].find("limit")
            assert limit is not None
            assert float(limit.get("lower", "nan")) < angle < float(limit.get("upper", "nan")), (name, joint, angle)


def test_the_digest_follows_the_content(tmp_path: Path) -> None:
    ours = RobotDescription.load(paths.default_robot_config_path())
    copy = copy_our_robot(tmp_path)
    assert RobotDescription.load(copy).digest == ours.digest
    copy.write_text(copy.read_text() + "\n# a comment is another config text\n")
    assert RobotDescription.load(copy).digest != ours.digest
    go1 = third_party("go1")
    assert go1.digest not in (ours.digest, third_party("a1").digest)


# --- package roots -------------------------------------------------------------------------------


def test_package_uris_resolve_through_the_first_root_holding_the_package(tmp_path: Path) -> None:
    """The URDF and its meshes by `package://` through the roots, as the controller's loader resolves them."""
    sphere = '<collision><origin xyz="0 0 0" rpy="0 0 0"/><geometry><sphere radius="0.02"/></geometry></collision>'
    mesh = '<collision><origin xyz="0 0 0" rpy="0 0 0"/><geometry><mesh filename="package://pkg/meshes/foot.stl"/></geometry></collision>'
    urdf = (ROBOTS / "quadruped.urdf").read_text().replace(sphere, mesh, 1)
    second = tmp_path / "second" / "pkg"
    (second / "urdf").mkdir(parents=True)
    (second / "meshes").mkdir()
    (second / "urdf" / "r.urdf").write_text(urdf)
    (second / "meshes" / "foot.stl").write_bytes(b"solid foot\nendsolid foot\n")
    (tmp_path / "first").mkdir()
    config = tmp_path / "robot.toml"
    config.write_text(OUR_CONFIG.replace('urdf = "quadruped.urdf"', 'urdf = "package://pkg/urdf/r.urdf"'))
    robot = RobotDescription.load(config, [tmp_path / "first", tmp_path / "second"])
    assert robot.urdf_path == second / "urdf" / "r.urdf"
    assert robot.package_dirs == (("pkg", second),)
    assert robot.mesh_files == (second / "meshes" / "foot.stl",)
    assert sorted(leg.has_foot_sphere for leg in robot.legs) == [False, True, True, True]
    with pytest.raises(RobotConfigError, match=f"robot.toml: key `urdf`: package `pkg`.*{PACKAGE_PATH_ENV}"):
        RobotDescription.load(config, [tmp_path / "first"])
    config.write_text(OUR_CONFIG.replace('urdf = "quadruped.urdf"', 'urdf = "package://pkg/../pkg/urdf/r.urdf"'))
    with pytest.raises(RobotConfigError, match="must not leave"):
        RobotDescription.load(config, [tmp_path / "second"])


def test_package_roots_come_from_the_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv(PACKAGE_PATH_ENV, raising=False)
    # Unset: this environment's installed packages (setup.sh installs the third-party robots there).
    assert package_roots_from_env() == (PACKAGE_ROOT.absolute(),)
    assert RobotDescription.load(ROBOTS / "third_party" / "a1.toml").package_roots == (PACKAGE_ROOT.absolute(),)
    monkeypatch.setenv(PACKAGE_PATH_ENV, "")
    assert package_roots_from_env() == ()
    monkeypatch.setenv(PACKAGE_PATH_ENV, f"{tmp_path / 'a'}::{tmp_path / 'b'}:")
    assert package_roots_from_env() == (tmp_path / "a", tmp_path / "b")
    monkeypatch.setenv(PACKAGE_PATH_ENV, str(PACKAGE_ROOT))
    assert RobotDescription.load(ROBOTS / "third_party" / "a1.toml").package_roots == (PACKAGE_ROOT.absolute(),)
    monkeypatch.setenv(PACKAGE_PATH_ENV, str(tmp_path))
    with pytest.raises(RobotConfigError, match=f"a1.toml: key `urdf`: package `example-robot-data`.*{PACKAGE_PATH_ENV}"):
        RobotDescription.load(ROBOTS / "third_party" / "a1.toml")


# --- bad configs ---------------------------------------------------------------------------------


def copy_our_robot(folder: Path, config_text: str | None = None, urdf_text: str | None = None) -> Path:
    """Our config and URDF copied into `folder` (optionally replaced); returns the config's path."""
    folder.mkdir(parents=True, exist_ok=True)
    ours = paths.default_robot_config_path()
    (folder / "quadruped.urdf").write_text(urdf_text if urdf_text is not None else (ROBOTS / "quadruped.urdf").read_text())
    config = folder / "robot.toml"
    config.write_text(config_text if config_text is not None else ours.read_text())
    return config


OUR_CONFIG = (ROBOTS / "quadruped.toml").read_text()
FR_JOINTS = 'joints = ["FR_hip_abd_joint", "FR_hip_flex_joint", "FR_knee_joint"]'


def without_last(text: str, line: str) -> str:
    head, found, tail = text.rpartition(line + "\n")
    assert found
    return head + tail


# The messages are the controller's loader's (`pf-robot describe`): TOML errors carry the line.
BAD_CONFIGS = {
    "missing key": (OUR_CONFIG.replace('base_link = "base"\n', ""), ["missing field `base_link`"]),
    "unknown key": (OUR_CONFIG.replace("stand_height = 0.28", "stand_height = 0.28\nfoot_radus = 0.02"), ["line 6", "unknown field `foot_radus`"]),
    "unknown leg key": (OUR_CONFIG.replace('foot_link = "FR_foot"', 'foot_link = "FR_foot"\nfoot = 1'), ["unknown field `foot`", "expected one of `joints`"]),
    "two joints": (OUR_CONFIG.replace(FR_JOINTS, 'joints = ["FR_hip_abd_joint", "FR_knee_joint"]'), ["line 10", "expected exactly 3 values, found 2"]),
    "missing urdf": (OUR_CONFIG.replace('urdf = "quadruped.urdf"', 'urdf = "elsewhere.urdf"'), ["key `urdf`", "elsewhere.urdf", "not a file"]),
    "package not found": (
        OUR_CONFIG.replace('urdf = "quadruped.urdf"', 'urdf = "package://no-such-package/robot.urdf"'),
        ["key `urdf`", "package `no-such-package`", PACKAGE_PATH_ENV],
    ),
    "one crouch missing": (without_last(OUR_CONFIG, "crouch = [0.0, 0.8, -1.6]"), ["key `legs.RL.crouch` is missing while other legs give one"]),
    "no crouch": (OUR_CONFIG.replace("crouch = [0.0, 0.8, -1.6]\n", ""), ["missing key `legs.FR.crouch`", "add `crouch = [abduction, hip, knee]`"]),
    "crouch of two angles": (OUR_CONFIG.replace("crouch = [0.0, 0.8, -1.6]", "crouch = [0.8, -1.6]", 1), ["crouch = [0.8, -1.6]", "expected exactly 3 values"]),
    "crouch not numbers": (OUR_CONFIG.replace("crouch = [0.0, 0.8, -1.6]", 'crouch = ["a", "b", "c"]', 1), ["crouch = [", 'invalid type: string "a"']),
    "crouch outside the limits": (
        OUR_CONFIG.replace("crouch = [0.0, 0.8, -1.6]", "crouch = [0.0, 0.8, 1.6]", 1),
        ["key `legs.FR.crouch`", "outside its limits"],
    ),
    "height as text": (OUR_CONFIG.replace("stand_height = 0.28", 'stand_height = "0.28"'), ["stand_height = \"0.28\"", "invalid type"]),
    "negative height": (OUR_CONFIG.replace("stand_height = 0.28", "stand_height = -0.28"), ["key `stand_height`", "positive"]),
    "unreachable height": (OUR_CONFIG.replace("stand_height = 0.28", "stand_height = 0.9"), ["key `stand_height` = 0.9"]),
    "joints not a list": (OUR_CONFIG.replace(FR_JOINTS, 'joints = "FR_hip_abd_joint"'), ["joints = \"FR_hip_abd_joint\"", "expected a sequence"]),
    "leg not a table": (OUR_CONFIG + "\n[other]\nlegs = 1\n", ["unknown field `other`"]),
    "missing leg": (OUR_CONFIG.split("[legs.RL]")[0], ["missing field `RL`"]),
    "unknown joint": (OUR_CONFIG.replace('"FR_knee_joint"', '"FR_elbow_joint"'), ["quadruped.urdf", "joint `FR_elbow_joint`"]),
    "unknown foot": (OUR_CONFIG.replace('foot_link = "FR_foot"', 'foot_link = "FR_toe"'), ["quadruped.urdf", "link `FR_toe`"]),
    "unknown base": (OUR_CONFIG.replace('base_link = "base"', 'base_link = "body"'), ["quadruped.urdf", "base link `body`"]),
    "fixed joint as a leg joint": (OUR_CONFIG.replace('"FR_knee_joint"', '"FR_foot_fixed"'), ["quadruped.urdf", "leg FR", "FR_foot_fixed"]),
    "joint named twice": (OUR_CONFIG.replace('"FL_knee_joint"', '"FR_knee_joint"'), ["joint `FR_knee_joint` is named by two legs"]),
    "knee direction": (OUR_CONFIG.replace('knee_points = "backward"', 'knee_points = "up"', 1), ["unknown variant `up`, expected `backward` or `forward`"]),
    "contradicting foot radius": (OUR_CONFIG.replace("stand_height = 0.28", "stand_height = 0.28\nfoot_radius = 0.03"), ["`foot_radius` = 0.03 contradicts"]),
    "limits of two values": (OUR_CONFIG + "\n[limits]\neffort = [1.0, 2.0]\n", ["effort = [1.0, 2.0]", "expected exactly 3 values"]),
    "unknown tuning field": (OUR_CONFIG + "\n[tuning]\nswing_hight = 0.1\n", ["key `tuning.swing_hight` is not a controller config field"]),
    "not TOML": (OUR_CONFIG.replace("stand_height = 0.28", "stand_height = "), ["TOML parse error at line 5"]),
}


@pytest.mark.parametrize("case", list(BAD_CONFIGS))
def test_bad_configs_name_the_key_and_the_file(case: str, tmp_path: Path) -> None:
    text, expected = BAD_CONFIGS[case]
    config = copy_our_robot(tmp_path / "robot", text)
    with pytest.raises(RobotConfigError) as caught:
        RobotDescription.load(config)
    message = str(caught.value)
    assert str(config) in message
    for part in expected:
        assert part in message


def test_bad_urdfs_and_files_are_named(tmp_path: Path) -> None:
    urdf = (ROBOTS / "quadruped.urdf").read_text()
    with pytest.raises(RobotConfigError, match=r"robot.toml: cannot read it"):
        RobotDescription.load(tmp_path / "robot.toml")
    broken = copy_our_robot(tmp_path / "broken", urdf_text=urdf[: len(urdf) // 2])
    with pytest.raises(RobotConfigError, match=r"quadruped.urdf: cannot parse URDF"):
        RobotDescription.load(broken)
    meshed = urdf.replace('<sphere radius="0.02"/>', '<mesh filename="meshes/foot.stl"/>', 1)
    assert meshed != urdf
    missing_mesh = copy_our_robot(tmp_path / "mesh", urdf_text=meshed)
    with pytest.raises(RobotConfigError, match=r"quadruped.urdf: URDF is missing a mesh: `meshes/foot.stl` resolves to .*foot.stl, which is not a file"):
        RobotDescription.load(missing_mesh)


# --- DART ------------------------------------------------------------------------------------------


def welded_mass(urdf_path: Path, base_link: str, massless: tuple[str, ...]) -> float:
    """Mass of `base_link` and every link hanging from it by fixed joints, from the URDF text."""
    root = ET.parse(urdf_path).getroot()
    masses = {}
    for link in root.iter("link"):
        mass = link.find("inertial/mass")
        masses[link.get("name")] = 0.0 if mass is None or link.get("name") in massless else float(mass.get("value", "nan"))
    children: dict[str, list[str]] = {}
    for joint in root.iter("joint"):
        if joint.get("type") == "fixed":
            parent, child = joint.find("parent"), joint.find("child")
            assert parent is not None and child is not None
            children.setdefault(parent.get("link", ""), []).append(child.get("link", ""))
    trunk = [base_link]
    for name in trunk:
        trunk.extend(children.get(name, []))
    return sum(masses[name] for name in trunk)


@pytest.mark.parametrize("name", THIRD_PARTY)
def test_third_party_robot_is_placed_in_its_crouch_on_flat_ground(name: str, tmp_path: Path) -> None:
    robot = third_party(name)
    world = QuadrupedWorld(flat_terrain(), robot, tmp_path)
    world.place(1.5, 1.5, 0.3, clearance=CLEARANCE)
    state = world.state()
    np.testing.assert_allclose(state.joint_positions, robot.crouch)
    soles = world.foot_positions()[:, 2] - robot.foot_radius
    assert soles.min() == pytest.approx(CLEARANCE, abs=1e-9)
    assert soles.max() < 0.03, f"every foot within a few cm of the ground: {soles}"
    assert state.position[2] > world.foot_positions()[:, 2].max() + 0.1
    # Feet roughly under the hips: each foot point within 6 cm (horizontally) of its hip flexion joint.
    for leg, foot in zip(robot.legs, world.foot_positions(), strict=True):
        hip = world.robot.getJoint(leg.joints[1]).getChildBodyNode().getWorldTransform().translation()
        assert np.hypot(*(foot[:2] - hip[:2])) < 0.06, (leg.label, foot, hip)


@pytest.mark.parametrize("name", THIRD_PARTY)
def test_trunk_mass_is_the_base_and_the_links_welded_to_it(name: str, tmp_path: Path) -> None:
    robot = third_party(name)
    world = QuadrupedWorld(flat_terrain(), robot, tmp_path)
    assert world.trunk_mass == pytest.approx(welded_mass(robot.urdf_path, robot.base_link, robot.massless_links), abs=1e-9)
    # The whole robot weighs what the URDF says, without DART's 1 kg for a link without <inertial>.
    assert world.mass == pytest.approx(welded_mass_total(robot), abs=1e-9)
    # ... and what the controller's model (the description) says.
    assert robot.mass == pytest.approx(world.mass, abs=1e-9)
    heaviest = max(world.trunk_bodies, key=lambda body: body.getMass())
    loaded = QuadrupedWorld(flat_terrain(), robot, tmp_path, payload=Payload(0.2, (0.02, 0.0, 0.0)))
    assert loaded.trunk_body.getName() == heaviest.getName()
    assert loaded.mass == pytest.approx(world.mass + 0.2 * world.trunk_mass)
    assert loaded.trunk_body.getMass() == pytest.approx(heaviest.getMass() + 0.2 * world.trunk_mass)


def welded_mass_total(robot: RobotDescription) -> float:
    root = ET.parse(robot.urdf_path).getroot()
    total = 0.0
    for link in root.iter("link"):
        mass = link.find("inertial/mass")
        if mass is not None and link.get("name") not in robot.massless_links:
            total += float(mass.get("value", "nan"))
    return total


def test_go1_trunk_gets_the_payload_and_a1_base_is_massless(tmp_path: Path) -> None:
    go1 = QuadrupedWorld(flat_terrain(), third_party("go1"), tmp_path)
    assert go1.trunk_body.getName() == "trunk" and go1.base.getName() == "base"
    assert len(go1.trunk_bodies) > 2
    a1 = QuadrupedWorld(flat_terrain(), third_party("a1"), tmp_path)
    assert a1.base.getMass() == 0.0


def test_mesh_collisions_become_boxes_and_mesh_feet_get_spheres(tmp_path: Path) -> None:
    robot = third_party("solo12")
    world = QuadrupedWorld(flat_terrain(), robot, tmp_path)
    skeleton = world.robot
    for i in range(skeleton.getNumBodyNodes()):
        for node in skeleton.getBodyNode(i).getShapeNodes():
            assert node.getCollisionAspect() is None or not isinstance(node.getShape(), dart.dynamics.MeshShape)
    for foot, offset in zip(world.feet, robot.foot_offsets, strict=True):
        spheres = [n for n in foot.getShapeNodes() if n.getCollisionAspect() is not None and isinstance(n.getShape(), dart.dynamics.SphereShape)]
        assert len(spheres) == 1
        assert spheres[0].getShape().getRadius() == robot.foot_radius
        np.testing.assert_array_equal(spheres[0].getRelativeTranslation(), offset)
    base_shapes = [n.getShape() for n in world.base.getShapeNodes() if n.getCollisionAspect() is not None]
    assert [type(s) for s in base_shapes] == [dart.dynamics.BoxShape]
    lower_leg = skeleton.getBodyNode("FR_LOWER_LEG")
    assert all(n.getCollisionAspect() is None for n in lower_leg.getShapeNodes())
    np.testing.assert_allclose(world.effort_limits, np.full(12, 2.7))


@pytest.mark.parametrize("name", THIRD_PARTY)
def test_a_pd_crouch_holds_the_robot_up_after_a_drop(name: str, tmp_path: Path) -> None:
    """0.3 s from 2 cm above the ground with joint PD on the crouch (gains scaled to the robot's mass): it lands on its feet."""
    robot = third_party(name)
    world = QuadrupedWorld(flat_terrain(), robot, tmp_path)
    world.place(1.5, 1.5, 0.0, clearance=0.02)
    placed = world.state().position[2]
    scale = world.mass / 12.0
    touched: set[str] = set()
    for _ in range(300):
        s = world.state()
        world.apply_torques(150.0 * scale * (robot.crouch - s.joint_positions) - 3.0 * scale * s.joint_velocities)
        world.step()
        touched |= {body.getName() for body in world.world.getLastCollisionResult().getCollidingBodyNodes()}
    height = world.state().position[2]
    assert 0.7 * placed < height < placed + 0.01, (placed, height)
    assert world.foot_contacts().all()
    assert world.foot_positions()[:, 2].min() > robot.foot_radius - 0.005, "no foot sinks into the ground"
    assert touched <= {*robot.foot_links, "terrain"}, f"only the feet touch the ground: {sorted(touched)}"


def test_mangled_configs_load_or_fail_with_a_config_error(tmp_path: Path) -> None:
    """300 seeded mutations of our config (lines dropped, duplicated, values replaced by other TOML values): each loads or
    raises RobotConfigError naming the file, never another exception."""
    rng = np.random.default_rng(19)
    lines = OUR_CONFIG.splitlines()
    values = ['"x"', "0", "-1.5", "nan", "true", "[]", "[1, 2]", '["a", "b", "c"]', "{ a = 1 }", "[[1, 2, 3]]", '"package://"', '"/"']
    config = copy_our_robot(tmp_path / "robot")
    outcomes = {"loaded": 0, "refused": 0}
    for _ in range(300):
        mutated = list(lines)
        for _ in range(int(rng.integers(1, 4))):
            k = int(rng.integers(len(mutated)))
            kind = int(rng.integers(3))
            if kind == 0:
                del mutated[k]
            elif kind == 1:
                mutated.insert(k, mutated[k])
            elif "=" in mutated[k]:
                mutated[k] = mutated[k].split("=")[0] + "= " + values[int(rng.integers(len(values)))]
        config.write_text("\n".join(mutated) + "\n")
        try:
            RobotDescription.load(config)
            outcomes["loaded"] += 1
        except RobotConfigError as err:
            assert str(config) in str(err)
            outcomes["refused"] += 1
    assert outcomes["refused"] > 100 and outcomes["loaded"] > 10, outcomes
