"""The FMU variables the harness uses exist in the bundled FMU; the contract refuses an FMU that lacks one."""

from __future__ import annotations

import copy
import re
from typing import Any

import numpy as np
import pytest
from fmpy import read_model_description

from pfnav_harness import fmu_runner as fr
from pfnav_harness import paths
from pfnav_harness.errors import MissingArtifactError, SimulationError


@pytest.fixture(scope="module")
def model_description() -> Any:
    try:
        return read_model_description(str(paths.fmu_path()))
    except MissingArtifactError as err:
        pytest.fail(str(err), pytrace=False)


def test_every_variable_the_harness_uses_is_in_the_bundled_fmu(model_description: Any) -> None:
    variables = {v.name: v for v in model_description.modelVariables}
    missing = [name for name in fr.USED_VARIABLES if name not in variables]
    assert not missing, f"the harness uses FMU variables the FMU lacks: {missing}"
    wrong = {name: variables[name].causality for name, causality in fr.USED_VARIABLES.items() if variables[name].causality != causality}
    assert not wrong, wrong
    # Every group the harness addresses is part of the one declaration.
    for group in (fr.REAL_INPUTS, fr.REAL_OUTPUTS, fr.CONTACT_OUTPUTS, (fr.MODE_INPUT, fr.FSM_OUTPUT)):
        assert set(group) <= set(fr.USED_VARIABLES)
    assert {variables[n].type for n in (*fr.REAL_INPUTS, *fr.REAL_OUTPUTS)} == {"Real"}
    assert {variables[n].type for n in fr.CONTACT_OUTPUTS} == {"Boolean"}


def test_enumerations_come_from_the_model_description(model_description: Any) -> None:
    types = {t.name: t for t in model_description.typeDefinitions}
    for type_name, items in fr.USED_ENUMERATIONS.items():
        assert types[type_name].type == "Enumeration"
        declared = {item.name: int(item.value) for item in types[type_name].items}
        assert set(items) <= set(declared), (type_name, declared)
    contract = fr.FmuContract(model_description, "bundled FMU")
    fsm = {item.name: int(item.value) for item in types[fr.FSM_TYPE].items}
    assert {s.name: int(s) for s in contract.fsm} == fsm
    assert len(set(fsm.values())) == len(fsm)
    variables = {v.name: v for v in model_description.modelVariables}
    for name, type_name in fr.ENUMERATION_VARIABLES.items():
        assert variables[name].declaredType.name == type_name


@pytest.mark.parametrize("name", ["ref.z", "terrain.dzdy", "fsm.state", "cmd.mode", "joint.dq[12]", "stance[4]"])
def test_an_fmu_without_a_used_variable_is_refused_at_load(model_description: Any, name: str) -> None:
    md = copy.copy(model_description)
    md.modelVariables = [v for v in model_description.modelVariables if v.name != name]
    with pytest.raises(SimulationError, match=f"no variable {re.escape(name)}"):
        fr.FmuContract(md, "stripped FMU")


def test_an_fmu_without_an_fsm_state_the_harness_names_is_refused(model_description: Any) -> None:
    md = copy.copy(model_description)
    fsm = next(t for t in model_description.typeDefinitions if t.name == fr.FSM_TYPE)
    stripped = copy.copy(fsm)
    stripped.items = [item for item in fsm.items if item.name != "Damping"]
    md.typeDefinitions = [stripped if t is fsm else t for t in model_description.typeDefinitions]
    with pytest.raises(SimulationError, match="enumeration FsmState has no item Damping"):
        fr.FmuContract(md, "stripped FMU")


def test_named_vectors_address_entries_by_name() -> None:
    v = fr.NamedVector(fr.REAL_INPUTS)
    v.view(fr.JOINT_Q)[:] = np.arange(12)
    assert v.values[v.index("joint.q[1]")] == 0.0 and v.values[v.index("joint.q[12]")] == 11.0
    assert v.span(fr.BASE_QUAT) == slice(3, 7)
    with pytest.raises(KeyError, match=r"terrain\.height"):
        v.index("terrain.height")
    with pytest.raises(KeyError, match="not consecutive"):
        v.span(("base.pos.x", "base.pos.z"))
