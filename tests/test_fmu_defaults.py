"""The FMU as an FMI tool user meets it with no harness (issue 21).

* A standalone run with every start value (`fmpy.simulate_fmu(fmu, stop_time=3)`, no inputs) stands
  up and holds the stand: the start values are the robot standing on flat ground in its nominal
  stance, with mode Stand.
* `<ModelStructure>`: every output listed with empty dependencies (outputs change only in doStep)
  and as an initial unknown (initial="calculated").
* Ranges: every input and parameter with a URDF limit (joint position, velocity) and every joint
  torque output carries min/max equal to the URDF's; every variable has a description; the header
  has generationDateAndTime.
* A drop to damping is logged with its reason (the failed check and the value).

State codes are looked up by name in the modelDescription's FsmState enumeration.
"""

from __future__ import annotations

import datetime
import math
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fmu_support import logging_callbacks, new_slave
from pfnav_harness.fmu_runner import STAND_HEIGHT_PARAMETER

REPO = Path(__file__).resolve().parents[1]
LEGS = ("FR", "FL", "RR", "RL")
JOINTS = ("hip_abd", "hip_flex", "knee")
# fmi2Warning
STATUS_WARNING = 1


@pytest.fixture(scope="module")
def md_xml(fmu_file: Path) -> ET.Element:
    with zipfile.ZipFile(fmu_file) as archive:
        return ET.fromstring(archive.read("modelDescription.xml"))


@pytest.fixture(scope="module")
def fsm_codes(md_xml: ET.Element) -> dict[str, int]:
    for simple_type in md_xml.iter("SimpleType"):
        if simple_type.get("name") == "FsmState":
            return {item.get("name", ""): int(item.get("value", "")) for item in simple_type.iter("Item")}
    raise AssertionError("no FsmState enumeration in modelDescription.xml")


@pytest.fixture(scope="module")
def urdf_limits() -> list[dict[str, float]]:
    """URDF <limit> of each actuated joint in FMU order (index 3·leg + j)."""
    root = ET.parse(REPO / "robot" / "quadruped.urdf").getroot()
    by_name = {j.get("name"): j.find("limit") for j in root.iter("joint")}
    limits = []
    for leg in LEGS:
        for joint in JOINTS:
            limit = by_name[f"{leg}_{joint}_joint"]
            assert limit is not None
            limits.append({k: float(v) for k, v in limit.attrib.items()})
    return limits


def variables(md_xml: ET.Element) -> list[ET.Element]:
    model_variables = md_xml.find("ModelVariables")
    assert model_variables is not None
    return list(model_variables.iter("ScalarVariable"))


def type_element(v: ET.Element) -> ET.Element:
    return next(child for child in v if child.tag in ("Real", "Integer", "Boolean", "Enumeration"))


def test_defaults_stand_up_and_hold_the_stand(fmu_file: Path, fsm_codes: dict[str, int]) -> None:
    from fmpy import simulate_fmu

    torques = [f"joint.tau[{i}]" for i in range(1, 13)]
    result = simulate_fmu(str(fmu_file), stop_time=3.0, output=["fsm.state", *torques])
    states = result["fsm.state"]
    assert result["time"][-1] == pytest.approx(3.0)
    assert states[0] == fsm_codes["Passive"]
    assert fsm_codes["StandUp"] in states
    assert fsm_codes["Damping"] not in states
    assert states[-1] == fsm_codes["Stand"]
    # Once standing it stays standing, carrying the weight with finite, non-zero torques.
    standing = states == fsm_codes["Stand"]
    first = int(np.argmax(standing))
    assert standing[first:].all()
    tau = np.array([result[name] for name in torques]).T[first:]
    assert np.isfinite(tau).all()
    assert (np.abs(tau).max(axis=1) > 0.5).all()
    # The knees carry the weight (the same sign on every leg at every sample).
    knees = tau[:, 2::3]
    assert (np.abs(knees) > 0.1).all()


def test_start_values_are_the_nominal_stance(md_xml: ET.Element, urdf_limits: list[dict[str, float]]) -> None:
    starts = {v.get("name"): type_element(v).get("start") for v in variables(md_xml)}
    for i, limit in enumerate(urdf_limits):
        q = float(starts[f"joint.q[{i + 1}]"] or "nan")
        assert limit["lower"] < q < limit["upper"], (i, q, limit)
        assert float(starts[f"joint.dq[{i + 1}]"] or "nan") == 0.0
    # Standing at the controller's nominal height.
    assert float(starts["base.pos.z"] or "nan") == pytest.approx(float(starts[STAND_HEIGHT_PARAMETER] or "nan"))
    assert [float(starts[f"base.quat.{c}"] or "nan") for c in "wxyz"] == [1.0, 0.0, 0.0, 0.0]


def test_model_structure_lists_every_output_without_dependencies(md_xml: ET.Element) -> None:
    all_variables = variables(md_xml)
    outputs = {str(k + 1) for k, v in enumerate(all_variables) if v.get("causality") == "output"}
    structure = md_xml.find("ModelStructure")
    assert structure is not None
    for section in ("Outputs", "InitialUnknowns"):
        element = structure.find(section)
        assert element is not None, section
        unknowns = list(element.iter("Unknown"))
        assert {u.get("index") for u in unknowns} == outputs, section
        assert len(unknowns) == len(outputs), section
        for u in unknowns:
            assert u.get("dependencies") == "", (section, u.attrib)
    # The initial unknowns are exactly the calculated outputs, which have no start value.
    for k, v in enumerate(all_variables):
        if str(k + 1) in outputs:
            assert v.get("initial") == "calculated", v.get("name")
            assert type_element(v).get("start") is None, v.get("name")


def test_ranges_descriptions_and_generation_time(md_xml: ET.Element, urdf_limits: list[dict[str, float]]) -> None:
    by_name = {v.get("name"): v for v in variables(md_xml)}
    for v in by_name.values():
        assert (v.get("description") or "").strip(), v.get("name")
        if v.get("causality") == "parameter":
            element = type_element(v)
            assert element.get("min") is not None and element.get("max") is not None, v.get("name")

    def bounds(name: str) -> tuple[float, float]:
        element = type_element(by_name[name])
        return float(element.get("min") or "nan"), float(element.get("max") or "nan")

    for i, limit in enumerate(urdf_limits):
        assert bounds(f"joint.q[{i + 1}]") == (limit["lower"], limit["upper"])
        assert bounds(f"joint.dq[{i + 1}]") == (-limit["velocity"], limit["velocity"])
        assert bounds(f"joint.tau[{i + 1}]") == (-limit["effort"], limit["effort"])
    stamp = md_xml.get("generationDateAndTime") or ""
    parsed = datetime.datetime.fromisoformat(stamp)
    assert parsed.tzinfo is not None and parsed.year >= 2020


def test_a_drop_to_damping_logs_the_failed_check_and_value(
    fmu_unzipped: Path, fmu_model_description: Any, fsm_codes: dict[str, int]
) -> None:
    messages: list[tuple[int, str, str]] = []
    slave = new_slave(fmu_unzipped, fmu_model_description, "fault-log")
    callbacks = logging_callbacks(lambda *message: messages.append(message))
    # loggingOn=False: the fault is a warning, passed on even without debug logging.
    slave.instantiate(callbacks=callbacks, loggingOn=False)
    refs = {v.name: v.valueReference for v in fmu_model_description.modelVariables}
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        # A knee measured at -0.1 rad: outside its URDF range [-2.7, -0.5] (accepted: it is a
        # measurement; the controller's joint-limit check reacts to it).
        slave.setReal([refs["joint.q[3]"]], [-0.1])
        slave.exitInitializationMode()
        slave.doStep(0.0, 0.01)
        assert slave.getInteger([refs["fsm.state"]]) == [fsm_codes["Damping"]]
        warnings = [m for status, _, m in messages if status == STATUS_WARNING]
        assert len(warnings) == 1, messages
        text = warnings[0]
        assert "StandUp -> Damping" in text, text
        assert "joint-limit check" in text and "joint 2" in text and "-0.100 rad" in text, text
        assert "[-2.700, -0.500]" in text, text
        torques = slave.getReal([refs[f"joint.tau[{i}]"] for i in range(1, 13)])
        assert all(math.isfinite(t) for t in torques)
        slave.terminate()
    finally:
        slave.freeInstance()
