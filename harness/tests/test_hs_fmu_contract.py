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
    for group in (fr.FIXED_REAL_INPUTS, fr.REAL_OUTPUTS, fr.CONTACT_OUTPUTS, (fr.MODE_INPUT, fr.FSM_OUTPUT)):
        assert set(group) <= set(fr.USED_VARIABLES)
    real_inputs = fr.FmuContract(model_description, "bundled FMU").real_inputs
    assert {variables[n].type for n in (*real_inputs, *fr.REAL_OUTPUTS)} == {"Real"}
    assert {variables[n].causality for n in real_inputs} == {"input"}


def test_the_height_map_size_is_counted_from_the_fmu(model_description: Any) -> None:
    contract = fr.FmuContract(model_description, "bundled FMU")
    samples = [v.name for v in model_description.modelVariables if v.name.startswith("terrain.map.h[")]
    assert contract.height_map_size**2 == len(samples) > 1
    assert contract.height_map_heights == fr.height_map_heights(contract.height_map_size)
    assert contract.real_inputs[-len(samples) :] == contract.height_map_heights


@pytest.mark.parametrize("kept", [0, 120])
def test_an_fmu_whose_height_map_is_not_square_is_refused(model_description: Any, kept: int) -> None:
    md = copy.copy(model_description)
    samples = [v for v in model_description.modelVariables if v.name.startswith("terrain.map.h[")]
    dropped = {v.name for v in samples[kept:]}
    md.modelVariables = [v for v in model_description.modelVariables if v.name not in dropped]
    with pytest.raises(SimulationError, match=f"{kept} height-map samples .*perfect square"):
        fr.FmuContract(md, "stripped FMU")


def test_a_gap_in_the_height_map_samples_is_named(model_description: Any) -> None:
    md = copy.copy(model_description)
    md.modelVariables = [copy.copy(v) for v in model_description.modelVariables]
    next(v for v in md.modelVariables if v.name == "terrain.map.h[7]").name = "terrain.map.h[9999]"
    with pytest.raises(SimulationError, match=re.escape("no variable terrain.map.h[7]")):
        fr.FmuContract(md, "renumbered FMU")


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


def test_named_vectors_address_entries_by_name(model_description: Any) -> None:
    v = fr.NamedVector(fr.FmuContract(model_description, "bundled FMU").real_inputs)
    v.view(fr.JOINT_Q)[:] = np.arange(12)
    assert v.values[v.index("joint.q[1]")] == 0.0 and v.values[v.index("joint.q[12]")] == 11.0
    assert v.span(fr.BASE_QUAT) == slice(3, 7)
    with pytest.raises(KeyError, match=r"terrain\.height"):
        v.index("terrain.height")
    with pytest.raises(KeyError, match="not consecutive"):
        v.span(("base.pos.x", "base.pos.z"))


def test_the_estimator_status_flags_are_named_from_the_fmu_s_documentation(model_description: Any) -> None:
    """`est.status`'s bits by the names the FMU documents (controller/src/estimator/status.rs writes them): nine flags, one bit each."""
    contract = fr.FmuContract(model_description, "bundled FMU")
    flags = contract.status_flags
    assert len(flags) == 9 and sorted(flags) == [1 << k for k in range(9)]
    assert flags[0x80] == "footSlip" and flags[0x100] == "odometryDoubtful"
    assert contract.status_flag_names(0x80 | 0x1 | 0x400) == ["gyroInvalid", "footSlip", "bit 0x400"]
    assert contract.status_flag_names(0) == []
