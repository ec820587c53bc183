"""FMU of the controller stack (target/fmu/QuadController.fmu) driven through fmpy.

Checks: the standard checkers (fmpy validate, fmutool -check), the package layout, standing torques
that carry the robot's weight (independent URDF kinematics in numpy) and equal a direct Rust call
of the controller (target/release/fmu-direct-reference) to 1e-12, misuse handling with logged
reasons, and independence of two instances in one process.

Paths: PFNAV_FMU overrides the FMU, PFNAV_FMU_DIRECT_REFERENCE the reference binary; both are
built by scripts/setup.sh.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2FMUstate
from fmpy.validation import validate_fmu
from fmu_support import STATUS_ERROR, logging_callbacks, new_slave
from pfnav_harness.fmu_runner import FmuContract

REPO = Path(__file__).resolve().parents[1]
VENV_BIN = Path(sys.executable).parent
GRAVITY = 9.81
LEGS = ("FR", "FL", "RR", "RL")


def _path_from_env(variable: str, default: Path) -> Path:
    path = Path(os.environ.get(variable, default))
    if not path.is_file():
        pytest.fail(f"{path} does not exist: run scripts/setup.sh (or set {variable})")
    return path


@pytest.fixture(scope="module")
def direct_reference() -> Path:
    return _path_from_env(
        "PFNAV_FMU_DIRECT_REFERENCE", REPO / "target" / "release" / "fmu-direct-reference"
    )


@pytest.fixture(scope="module")
def fsm(fmu_contract: FmuContract) -> type[IntEnum]:
    """FSM state codes by name (the FsmState enumeration of the modelDescription)."""
    return fmu_contract.fsm


@pytest.fixture(scope="module")
def modes(fmu_contract: FmuContract) -> type[IntEnum]:
    """Mode request codes by name (the ModeRequest enumeration of the modelDescription)."""
    return fmu_contract.mode


@pytest.fixture(scope="module")
def value_refs(fmu_model_description: Any) -> dict[str, int]:
    return {v.name: v.valueReference for v in fmu_model_description.modelVariables}


# ---------------------------------------------------------------------------------------------
# A slave whose logger messages are captured.


@dataclass
class LoggedSlave:
    """An FMU2Slave plus the messages its instance sent to the logger callback."""

    slave: FMU2Slave
    messages: list[tuple[int, str, str]] = field(default_factory=list)
    callbacks: fmi2CallbackFunctions | None = None

    def errors_since(self, mark: int) -> list[str]:
        return [m for status, _, m in self.messages[mark:] if status == STATUS_ERROR]


def make_slave(
    unzip_dir: Path, md: Any, name: str, guid: str | None = None
) -> tuple[LoggedSlave, Callable[[], None]]:
    """Creates and instantiates a slave; returns it and a function that instantiates it."""
    logged = LoggedSlave(new_slave(unzip_dir, md, name, guid))
    callbacks = logging_callbacks(lambda *message: logged.messages.append(message))
    logged.callbacks = callbacks

    def instantiate() -> None:
        logged.slave.instantiate(callbacks=callbacks, loggingOn=True)

    return logged, instantiate


@pytest.fixture
def running(fmu_unzipped: Path, fmu_model_description: Any) -> Iterator[LoggedSlave]:
    logged, instantiate = make_slave(fmu_unzipped, fmu_model_description, "running")
    instantiate()
    s = logged.slave
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    yield logged
    s.freeInstance()


# ---------------------------------------------------------------------------------------------
# Inputs


@dataclass
class Inputs:
    position: list[float]
    quaternion: list[float]
    joints: list[float]
    joint_velocities: list[float] = field(default_factory=lambda: [0.0] * 12)
    reference: dict[str, float] = field(default_factory=dict)
    # A ModeRequest item name (the serde name of the direct call is the same).
    mode: str = "Stand"

    def fmu_reals(self, refs: dict[str, int]) -> tuple[list[int], list[float]]:
        names = [f"base.pos.{a}" for a in "xyz"] + [f"base.quat.{c}" for c in "wxyz"]
        values = self.position + self.quaternion
        names += [f"base.vel.{a}" for a in "xyz"] + [f"base.omega.{a}" for a in "xyz"]
        values += [0.0] * 6
        names += [f"joint.q[{i}]" for i in range(1, 13)] + [f"joint.dq[{i}]" for i in range(1, 13)]
        values += self.joints + self.joint_velocities
        for key, value in self.reference.items():
            names.append(key)
            values.append(value)
        return [refs[n] for n in names], values

    def apply(self, slave: FMU2Slave, refs: dict[str, int], modes: type[IntEnum]) -> None:
        vrs, values = self.fmu_reals(refs)
        slave.setReal(vrs, values)
        slave.setInteger([refs["cmd.mode"]], [modes[self.mode]])

    def direct_json(self) -> dict[str, Any]:
        r = self.reference
        return {
            "state": {
                "base_position": self.position,
                "base_orientation": self.quaternion,
                "base_linear_velocity": [0.0] * 3,
                "base_angular_velocity": [0.0] * 3,
                "joint_positions": self.joints,
                "joint_velocities": self.joint_velocities,
            },
            "reference": {
                "x": r.get("ref.x", 0.0),
                "y": r.get("ref.y", 0.0),
                "yaw": r.get("ref.yaw", 0.0),
                "vx": r.get("ref.vx", 0.0),
                "vy": r.get("ref.vy", 0.0),
                "yaw_rate": r.get("ref.yawRate", 0.0),
                "body_height": r.get("ref.bodyHeight", 0.0),
                "terrain": {
                    "height": r.get("ref.z", 0.0),
                    "slope_x": r.get("terrain.dzdx", 0.0),
                    "slope_y": r.get("terrain.dzdy", 0.0),
                },
                "mode": self.mode,
            },
        }


def run_direct(binary: Path, segments: list[tuple[Inputs, int, float]]) -> dict[str, Any]:
    """Segments of (inputs, ticks, communication step h of the FMU run it mirrors)."""
    request = {"segments": [dict(i.direct_json(), ticks=n, comm_step=h) for i, n, h in segments]}
    done = subprocess.run(
        [str(binary)], input=json.dumps(request), capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.fixture(scope="module")
def stand_pose(direct_reference: Path) -> list[float]:
    return run_direct(direct_reference, [])["stand_joint_positions"]


@pytest.fixture(scope="module")
def stand_height(fmu_contract: FmuContract) -> float:
    return fmu_contract.stand_height


def standing(stand_pose: list[float], stand_height: float, x: float = 0.0, yaw: float = 0.0) -> Inputs:
    return Inputs(
        position=[x, 0.0, stand_height],
        quaternion=[math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)],
        joints=list(stand_pose),
        reference={"ref.x": x, "ref.yaw": yaw},
    )


def outputs(slave: FMU2Slave, refs: dict[str, int]) -> dict[str, Any]:
    tau = slave.getReal([refs[f"joint.tau[{i}]"] for i in range(1, 13)])
    forces = slave.getReal([refs[f"force[{leg}].{a}"] for leg in range(1, 5) for a in "xyz"])
    contacts = slave.getBoolean([refs[f"stance[{leg}]"] for leg in range(1, 5)])
    (fsm,) = slave.getInteger([refs["fsm.state"]])
    (solved,) = slave.getBoolean([refs["mpc.solved"]])
    return {
        "tau": np.array(tau),
        "forces": np.array(forces).reshape(4, 3),
        "contacts": [bool(c) for c in contacts],
        "fsm": fsm,
        "solved": bool(solved),
    }


def assert_matches_direct(fmu: dict[str, Any], command: dict[str, Any], fsm: type[IntEnum]) -> None:
    np.testing.assert_allclose(fmu["tau"], command["joint_torques"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fmu["forces"], command["desired_forces"], rtol=0, atol=1e-12)
    assert fmu["contacts"] == command["contacts"]
    assert fmu["fsm"] == fsm[command["fsm_state"]]
    assert fmu["solved"] == command["mpc_solved"]


# ---------------------------------------------------------------------------------------------
# Independent kinematics of robot/quadruped.urdf (numpy): foot Jacobians and leg gravity torques.


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx


def _vec(element: ET.Element | None, attribute: str) -> np.ndarray:
    text = element.get(attribute) if element is not None else None
    return np.array([float(v) for v in text.split()]) if text else np.zeros(3)


class UrdfLegs:
    """Forward kinematics of each leg from the URDF text alone (no code shared with Rust)."""

    def __init__(self, urdf: Path) -> None:
        root = ET.parse(urdf).getroot()
        self.links = {}
        for link in root.findall("link"):
            inertial = link.find("inertial")
            mass = float(inertial.find("mass").get("value")) if inertial is not None else 0.0
            com = _vec(inertial.find("origin") if inertial is not None else None, "xyz")
            self.links[link.get("name")] = (mass, com)
        self.joint_to_child = {}
        for joint in root.findall("joint"):
            origin = joint.find("origin")
            axis = joint.find("axis")
            self.joint_to_child[joint.find("child").get("link")] = (
                joint.get("type"),
                joint.find("parent").get("link"),
                _vec(origin, "xyz"),
                _rpy_matrix(_vec(origin, "rpy")),
                _vec(axis, "xyz") if axis is not None else np.array([1.0, 0, 0]),
            )
        self.total_mass = sum(m for m, _ in self.links.values())

    def chain(self, leg: str) -> list[str]:
        links = [f"{leg}_foot"]
        while links[-1] != "base":
            links.append(self.joint_to_child[links[-1]][1])
        return links[::-1][1:]

    def frames(self, leg: str, q: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        rotation, position = np.eye(3), np.zeros(3)
        frames = {}
        k = 0
        for link in self.chain(leg):
            kind, _, xyz, rpy, axis = self.joint_to_child[link]
            position = position + rotation @ xyz
            rotation = rotation @ rpy
            if kind != "fixed":
                rotation = rotation @ _axis_angle(axis, q[k])
                k += 1
            frames[link] = (rotation, position)
        return frames

    def foot(self, leg: str, q: np.ndarray) -> np.ndarray:
        return self.frames(leg, q)[f"{leg}_foot"][1]

    def potential(self, leg: str, q: np.ndarray) -> float:
        return sum(
            self.links[link][0] * GRAVITY * (position + rotation @ self.links[link][1])[2]
            for link, (rotation, position) in self.frames(leg, q).items()
        )

    def jacobian_and_gravity(self, leg: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        eps = 1e-6
        jac = np.zeros((3, 3))
        grav = np.zeros(3)
        for j in range(3):
            dq = np.zeros(3)
            dq[j] = eps
            jac[:, j] = (self.foot(leg, q + dq) - self.foot(leg, q - dq)) / (2 * eps)
            grav[j] = (self.potential(leg, q + dq) - self.potential(leg, q - dq)) / (2 * eps)
        return jac, grav


# ---------------------------------------------------------------------------------------------
# Tests


def test_fmpy_validate_finds_no_problems(fmu_file: Path) -> None:
    assert validate_fmu(str(fmu_file)) == []
    done = subprocess.run(
        [str(VENV_BIN / "fmpy"), "validate", str(fmu_file)], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "No problems found" in done.stdout


def test_fmutool_check_finds_no_problems(fmu_file: Path) -> None:
    done = subprocess.run(
        [str(VENV_BIN / "fmutool"), "-input", str(fmu_file), "-check"],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
    )
    text = done.stdout + done.stderr
    assert done.returncode == 0, text
    assert "This FMU seems to be compliant with FMI-2.0" in text, text
    assert "No semantic error against the FMI-2 standard" in text, text
    assert "ERROR" not in text, text


def test_package_layout_and_description(fmu_file: Path, fmu_model_description: Any) -> None:
    with zipfile.ZipFile(fmu_file) as archive:
        names = set(archive.namelist())
        urdf = archive.read("resources/robot/robot.urdf")
        robot_config = archive.read("resources/robot/robot.toml").decode()
        config = json.loads(archive.read("resources/controller.json"))
    assert {
        "modelDescription.xml",
        "binaries/linux64/QuadController.so",
        "resources/robot/robot.toml",
        "resources/robot/robot.urdf",
        "resources/controller.json",
        "documentation/index.html",
    } <= names
    assert all("\\" not in n for n in names)
    # Our URDF has no meshes, so the bundled copy is the file itself; the config names the copy.
    assert urdf == (REPO / "robot" / "quadruped.urdf").read_bytes()
    assert 'urdf = "robot.urdf"' in robot_config
    md = fmu_model_description
    assert md.fmiVersion == "2.0"
    assert md.coSimulation.modelIdentifier == "QuadController"
    assert md.coSimulation.canHandleVariableCommunicationStepSize
    assert md.defaultExperiment is not None and md.defaultExperiment.stepSize == "0.001"
    by_name = {v.name: v for v in md.modelVariables}
    # Parameter start values are the shipped configuration.
    assert float(by_name["control.dt"].start) == config["control_dt"]
    assert float(by_name["gait.period"].start) == config["gait_period"]
    assert int(by_name["mpc.horizon"].start) == config["mpc_horizon"]
    assert float(by_name["mpc.q[6]"].start) == config["mpc_q"][5]
    assert by_name["cmd.mode"].type == "Enumeration" and by_name["stance[1]"].type == "Boolean"
    assert by_name["mpc.horizon"].type == "Integer" and by_name["gait.kind"].declaredType.name == "GaitKind"
    outputs_ = [u.variable.name for u in md.outputs]
    assert len(outputs_) == 47 and "joint.tau[12]" in outputs_ and "mpc.solveTime" in outputs_ and "est.posVar[3]" in outputs_


def test_standing_torques_hold_the_weight_and_equal_a_direct_call(
    running: LoggedSlave,
    value_refs: dict[str, int],
    direct_reference: Path,
    stand_pose: list[float],
    stand_height: float,
    fsm: type[IntEnum],
    modes: type[IntEnum],
) -> None:
    s = running.slave
    inputs = standing(stand_pose, stand_height)
    inputs.apply(s, value_refs, modes)
    # 1.2 s in 10 ms communication steps (the stand-up takes 1 s), then 0.3 s in 1.5 ms steps.
    t = 0.0
    for _ in range(120):
        s.doStep(t, 0.01)
        t += 0.01
    first = outputs(s, value_refs)
    for _ in range(200):
        s.doStep(t, 0.0015)
        t += 0.0015
    second = outputs(s, value_refs)
    total_ticks = round(t / 0.001)
    direct = run_direct(direct_reference, [(inputs, 1200, 0.01), (inputs, total_ticks - 1200, 0.0015)])
    assert_matches_direct(first, direct["commands"][0], fsm)
    assert_matches_direct(second, direct["commands"][1], fsm)
    assert second["fsm"] == fsm.Stand and second["contacts"] == [True] * 4

    legs = UrdfLegs(REPO / "robot" / "quadruped.urdf")
    assert legs.total_mass == pytest.approx(direct["total_mass"], rel=1e-12)
    q = np.array(stand_pose)
    ground_forces = []
    for index, leg in enumerate(LEGS):
        jac, grav = legs.jacobian_and_gravity(leg, q[3 * index : 3 * index + 3])
        tau = second["tau"][3 * index : 3 * index + 3]
        # Static leg: tau = J^T F_foot_on_ground + dV/dq, and the ground pushes back with -F.
        ground_forces.append(-np.linalg.solve(jac.T, tau - grav))
    ground_forces_arr = np.array(ground_forces)
    weight = legs.total_mass * GRAVITY
    assert ground_forces_arr[:, 2].sum() == pytest.approx(weight, rel=0.03)
    # The torques realise the MPC's desired ground forces.
    np.testing.assert_allclose(ground_forces_arr, second["forces"], atol=0.02 * weight / 4)


def test_simulate_fmu_runs_with_fmpy_master(fmu_file: Path, stand_pose: list[float], stand_height: float, fsm: type[IntEnum], modes: type[IntEnum]) -> None:
    from fmpy import simulate_fmu

    start = {f"joint.q[{i + 1}]": q for i, q in enumerate(stand_pose)}
    start.update({"base.pos.z": stand_height, "cmd.mode": int(modes.Stand)})
    result = simulate_fmu(
        str(fmu_file),
        stop_time=1.2,
        output_interval=0.004,
        start_values=start,
        output=["fsm.state", "joint.tau[3]", "force[1].z"],
    )
    assert result["time"][-1] == pytest.approx(1.2)
    assert result["fsm.state"][0] == fsm.Passive
    assert result["fsm.state"][-1] == fsm.Stand
    assert np.all(np.isfinite(result["joint.tau[3]"]))


MISUSE: list[tuple[str, Callable[[FMU2Slave, dict[str, int]], Any], str]] = [
    ("doStep before init", lambda s, r: s.doStep(0.0, 0.01), "fmi2DoStep is not allowed in state instantiated"),
    ("get before init", lambda s, r: s.getReal([r["joint.tau[1]"]]), "fmi2GetReal is not allowed in state instantiated"),
    ("exit before enter", lambda s, r: s.exitInitializationMode(), "fmi2ExitInitializationMode is not allowed in state instantiated"),
    ("terminate before init", lambda s, r: s.terminate(), "fmi2Terminate is not allowed in state instantiated"),
]

MISUSE_IN_INIT: list[tuple[str, Callable[[FMU2Slave, dict[str, int]], Any], str]] = [
    ("enter twice", lambda s, r: s.enterInitializationMode(), "fmi2EnterInitializationMode is not allowed in state initializationMode"),
    ("setup after enter", lambda s, r: s.setupExperiment(startTime=0.0), "fmi2SetupExperiment is not allowed in state initializationMode"),
    ("doStep in init", lambda s, r: s.doStep(0.0, 0.01), "fmi2DoStep is not allowed in state initializationMode"),
]

MISUSE_RUNNING: list[tuple[str, Callable[[FMU2Slave, dict[str, int]], Any], str]] = [
    ("enter after exit", lambda s, r: s.enterInitializationMode(), "fmi2EnterInitializationMode is not allowed in state stepComplete"),
    ("unknown vr get", lambda s, r: s.getReal([99999]), "valueReference 99999 does not refer to a Real variable"),
    ("unknown vr set", lambda s, r: s.setReal([99999], [1.0]), "valueReference 99999 does not refer to a Real variable"),
    ("type mismatch", lambda s, r: s.getBoolean([r["base.pos.x"]]), "does not refer to a Boolean variable"),
    ("string vr", lambda s, r: s.getString([0]), "does not refer to a String variable"),
    ("set output real", lambda s, r: s.setReal([r["joint.tau[1]"]], [1.0]), "cannot set joint.tau[1]: it is an output"),
    ("set output bool", lambda s, r: s.setBoolean([r["stance[2]"]], [True]), "cannot set stance[2]: it is an output"),
    ("set output int", lambda s, r: s.setInteger([r["fsm.state"]], [2]), "cannot set fsm.state: it is an output"),
    ("fixed param", lambda s, r: s.setReal([r["gait.period"]], [0.4]), "cannot set gait.period: it is a fixed parameter"),
    ("nan", lambda s, r: s.setReal([r["base.pos.x"]], [math.nan]), "invalid value for base.pos.x: NaN is not a finite number"),
    ("inf", lambda s, r: s.setReal([r["joint.q[5]"]], [math.inf]), "invalid value for joint.q[5]: inf is not a finite number"),
    ("-inf", lambda s, r: s.setReal([r["ref.vx"]], [-math.inf]), "invalid value for ref.vx: -inf is not a finite number"),
    ("mode range", lambda s, r: s.setInteger([r["cmd.mode"]], [3]), "invalid value for cmd.mode: 3 is above the maximum 2"),
    ("h zero", lambda s, r: s.doStep(0.0, 0.0), "communicationStepSize 0 must be finite and > 0"),
    ("h negative", lambda s, r: s.doStep(0.0, -0.001), "communicationStepSize -0.001 must be finite and > 0"),
    ("h nan", lambda s, r: s.doStep(0.0, math.nan), "communicationStepSize NaN must be finite and > 0"),
    ("wrong time", lambda s, r: s.doStep(0.25, 0.01), "currentCommunicationPoint 0.25 does not match the FMU time 0"),
    ("foreign fmu state", lambda s, r: s.setFMUstate(fmi2FMUstate(0xDEAD0)), "FMUstate is not a live state of this FMU"),
    ("debug category", lambda s, r: s.setDebugLogging(True, ["logNothing"]), 'unknown log category "logNothing"'),
]


def _expect_error(logged: LoggedSlave, call: Callable[[], Any], reason: str) -> None:
    mark = len(logged.messages)
    with pytest.raises(FMICallException) as caught:
        call()
    assert caught.value.status == STATUS_ERROR
    errors = logged.errors_since(mark)
    assert len(errors) == 1 and reason in errors[0], (reason, errors)


def test_misuse_gives_errors_with_reasons_and_the_instance_lives_on(
    fmu_unzipped: Path, fmu_model_description: Any, value_refs: dict[str, int], modes: type[IntEnum]
) -> None:
    logged, instantiate = make_slave(fmu_unzipped, fmu_model_description, "misuse")
    instantiate()
    s = logged.slave
    for _, call, reason in MISUSE:
        _expect_error(logged, lambda c=call: c(s, value_refs), reason)
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    for _, call, reason in MISUSE_IN_INIT:
        _expect_error(logged, lambda c=call: c(s, value_refs), reason)
    s.exitInitializationMode()
    for _, call, reason in MISUSE_RUNNING:
        _expect_error(logged, lambda c=call: c(s, value_refs), reason)
    # Still usable, and the rejected values were not stored.
    s.doStep(0.0, 0.01)
    starts = {v.name: v.start for v in fmu_model_description.modelVariables}
    expected = [float(starts["base.pos.x"]), float(starts["joint.q[5]"])]
    assert s.getReal([value_refs["base.pos.x"], value_refs["joint.q[5]"]]) == expected
    assert s.getInteger([value_refs["cmd.mode"]]) == [modes.Stand]
    s.terminate()
    _expect_error(logged, lambda: s.doStep(0.01, 0.01), "fmi2DoStep is not allowed in state terminated")
    _expect_error(logged, lambda: s.setReal([value_refs["ref.x"]], [1.0]), "fmi2SetReal is not allowed in state terminated")
    s.reset()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.doStep(0.0, 0.01)
    s.freeInstance()


def test_rejected_state_switches_to_damping(running: LoggedSlave, value_refs: dict[str, int], fsm: type[IntEnum]) -> None:
    s = running.slave
    s.setReal([value_refs[f"base.quat.{c}"] for c in "wxyz"], [0.0, 0.0, 0.0, 0.0])
    s.setReal([value_refs["joint.dq[4]"]], [1.5])
    _expect_error(running, lambda: s.doStep(0.0, 0.01), "base_orientation norm 0 is not")
    out = outputs(s, value_refs)
    assert out["fsm"] == fsm.Damping
    assert out["tau"][3] == pytest.approx(-2.0 * 1.5)
    assert s.getRealStatus(2) == 0.0  # fmi2LastSuccessfulTime
    assert s.getBooleanStatus(3) is False  # fmi2Terminated
    _expect_error(running, lambda: s.doStep(0.0, 0.01), "fmi2DoStep is not allowed in state stepFailed")
    s.terminate()


def test_wrong_guid_gives_null_with_a_reason(fmu_unzipped: Path, fmu_model_description: Any) -> None:
    # The GUID of another interface: one hex digit of this FMU's changed.
    ours = fmu_model_description.guid
    other = ours[:1] + ("1" if ours[1] == "0" else "0") + ours[2:]
    logged, instantiate = make_slave(fmu_unzipped, fmu_model_description, "guid", guid=other)
    with pytest.raises(Exception, match="Failed to instantiate"):
        instantiate()
    (message,) = [m for status, _, m in logged.messages if status == STATUS_ERROR]
    assert "GUID" in message and fmu_model_description.guid in message
    logged.slave.freeLibrary()


def test_missing_resources_give_null_with_a_reason(
    fmu_unzipped: Path, fmu_model_description: Any, tmp_path: Path
) -> None:
    copy = tmp_path / "no_resources"
    shutil.copytree(fmu_unzipped, copy)
    shutil.rmtree(copy / "resources")
    logged, instantiate = make_slave(copy, fmu_model_description, "nores")
    with pytest.raises(Exception, match="Failed to instantiate"):
        instantiate()
    (message,) = [m for status, _, m in logged.messages if status == STATUS_ERROR]
    assert "resources folder" in message and "does not exist" in message
    logged.slave.freeLibrary()


def test_two_instances_in_one_process_are_independent(
    fmu_unzipped: Path,
    fmu_model_description: Any,
    value_refs: dict[str, int],
    direct_reference: Path,
    stand_pose: list[float],
    stand_height: float,
    fsm: type[IntEnum],
    modes: type[IntEnum],
) -> None:
    a, instantiate_a = make_slave(fmu_unzipped, fmu_model_description, "a")
    b, instantiate_b = make_slave(fmu_unzipped, fmu_model_description, "b")
    instantiate_a()
    instantiate_b()
    inputs_a = standing(stand_pose, stand_height)
    inputs_b = standing(stand_pose, stand_height, x=3.0, yaw=0.7)
    inputs_b.joint_velocities = [0.3] * 12
    for logged, inputs in ((a, inputs_a), (b, inputs_b)):
        s = logged.slave
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        inputs.apply(s, value_refs, modes)
        s.exitInitializationMode()
    t = 0.0
    for _ in range(50):
        a.slave.doStep(t, 0.02)
        b.slave.doStep(t, 0.02)
        t += 0.02
    for logged, inputs in ((a, inputs_a), (b, inputs_b)):
        direct = run_direct(direct_reference, [(inputs, 1000, 0.02)])
        assert_matches_direct(outputs(logged.slave, value_refs), direct["commands"][0], fsm)
        logged.slave.terminate()
    a.slave.freeInstance()
    b.slave.freeInstance()
