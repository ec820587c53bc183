"""The FMU in a second importer: libcosim (Open Simulation Platform, `libcosimpy` from PyPI) and fmpy
give the same outputs (issue 21).

Both run the shipped FMU with its start values (no input is set: standalone, mode request Stand),
the same communication step (1 ms) for 2 s, from stand-up into the stand. libcosim's last-value
observer is read after every step; fmpy's FMU2Slave is stepped by hand. Every output is compared
bit for bit (IEEE-754 bit patterns, so even -0.0 vs 0.0 would count) at every step, except
`mpc.solveTime`, the wall time of the solve, which no two runs share.

libcosim (0.0.6 and its libcosim) ignores FMI 2.0 Enumeration variables: it logs "FMI 2.0
Enumeration variable type not supported, variable with name fsm.state will be ignored" and neither
lists nor observes them (likewise the input `cmd.mode` and the parameter `gait.kind`). So
`fsm.state` is compared on a copy of the FMU whose modelDescription declares the three
enumeration variables as plain Integer (same value references and start values; same binary):
on the shipped FMU, the test checks that fsm.state is the only output libcosim drops.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fmu_support import new_slave
from numpy.typing import NDArray

STEP_NS = 1_000_000  # 1 ms, libcosim counts time in nanoseconds
STEP = STEP_NS * 1e-9
STEPS = 2000  # 2 s
# Timing outputs: wall-clock measurements, different in every run.
TIMING_OUTPUTS = frozenset({"mpc.solveTime"})
FSM_OUTPUT = "fsm.state"

Series = dict[str, NDArray[Any]]


@pytest.fixture(scope="module")
def outputs(fmu_model_description: Any) -> list[Any]:
    """Every output of the FMU except the timing outputs (fmpy's model variables)."""
    found = [v for v in fmu_model_description.modelVariables if v.causality == "output" and v.name not in TIMING_OUTPUTS]
    assert {v.type for v in found} == {"Real", "Boolean", "Integer", "Enumeration"}, {v.type for v in found}
    return found


@pytest.fixture(scope="module")
def fsm_codes(fmu_model_description: Any) -> dict[str, int]:
    types = {t.name: t for t in fmu_model_description.typeDefinitions}
    return {str(item.name): int(item.value) for item in types["FsmState"].items}


def bits(values: NDArray[Any]) -> NDArray[Any]:
    """The values' bit patterns (float64 → uint64), so that equality is bit-for-bit."""
    array = np.asarray(values)
    return array.view(np.uint64) if array.dtype == np.float64 else array


def run_fmpy(unzipped: Path, md: Any, outputs: list[Any]) -> Series:
    """fmpy's FMU2Slave: start values only, doStep(k·1 ms, 1 ms), all outputs read after each step."""
    by_type: dict[str, list[Any]] = {"Real": [], "Boolean": [], "Integer": [], "Enumeration": []}
    for v in outputs:
        by_type[v.type].append(v)
    getters = {"Real": "getReal", "Boolean": "getBoolean", "Integer": "getInteger", "Enumeration": "getInteger"}
    series: dict[str, list[Any]] = {v.name: [] for v in outputs}
    slave = new_slave(unzipped, md, "fmpy")
    slave.instantiate(loggingOn=False)
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k in range(STEPS):
            slave.doStep(k * STEP, STEP)
            for type_name, variables in by_type.items():
                values = getattr(slave, getters[type_name])([v.valueReference for v in variables])
                for v, x in zip(variables, values, strict=True):
                    series[v.name].append(x)
        slave.terminate()
    finally:
        slave.freeInstance()
    return {name: np.array(values, dtype=np.float64 if isinstance(values[0], float) else np.int64) for name, values in series.items()}


def run_libcosim(fmu: Path) -> tuple[Series, float]:
    """libcosim: one local slave, fixed step 1 ms, its last-value observer read after every step.

    Returns the series of every output libcosim exposes (mpc.solveTime included) and the
    execution's simulated time at the end.
    """
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.WARNING)
    execution = CosimExecution.from_step_size(STEP_NS)
    index = execution.add_local_slave(CosimLocalSlave(fmu_path=str(fmu), instance_name="libcosim"))
    assert index >= 0, "libcosim could not add the FMU as a slave"
    observer = CosimObserver.create_last_value()
    assert execution.add_observer(observer)
    readers = {
        CosimVariableType.REAL.value: observer.last_real_values,
        CosimVariableType.INTEGER.value: observer.last_integer_values,
        CosimVariableType.BOOLEAN.value: observer.last_boolean_values,
    }
    output_causality = 2  # CosimVariableCausality.OUTPUT
    groups: dict[int, list[tuple[str, int]]] = {t: [] for t in readers}
    for v in execution.slave_variables(index):
        if v.causality == output_causality:
            groups[v.type].append((v.name.decode(), v.reference))
    series: dict[str, list[Any]] = {name: [] for group in groups.values() for name, _ in group}
    for _ in range(STEPS):
        assert execution.step(1), "libcosim step failed"
        for type_code, group in groups.items():
            if not group:
                continue
            values = readers[type_code](index, [ref for _, ref in group])
            for (name, _), x in zip(group, values, strict=True):
                series[name].append(x)
    end_time = execution.status().current_time * 1e-9
    arrays = {name: np.array(values, dtype=np.float64 if isinstance(values[0], float) else np.int64) for name, values in series.items()}
    return arrays, end_time


def with_integer_enumerations(fmu: Path, out: Path) -> Path:
    """A copy of the FMU whose enumeration variables are declared Integer (min/max/start kept)."""
    with zipfile.ZipFile(fmu) as source, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as target:
        for item in source.infolist():
            data = source.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                text, count = re.subn(r'<Enumeration declaredType="[^"]*"', "<Integer", text)
                assert count == 4, count
                data = text.encode()
            target.writestr(item, data)
    return out


@pytest.fixture(scope="module")
def fmpy_run(fmu_unzipped: Path, fmu_model_description: Any, outputs: list[Any]) -> Series:
    return run_fmpy(fmu_unzipped, fmu_model_description, outputs)


@pytest.fixture(scope="module")
def libcosim_runs(fmu_file: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Series, float]]:
    integer_copy = with_integer_enumerations(fmu_file, tmp_path_factory.mktemp("libcosim") / "QuadController.fmu")
    return {"shipped": run_libcosim(fmu_file), "integer": run_libcosim(integer_copy)}


def assert_bit_identical(name: str, ours: NDArray[Any], theirs: NDArray[Any]) -> None:
    assert ours.shape == theirs.shape == (STEPS,), (name, ours.shape, theirs.shape)
    differ = np.flatnonzero(bits(ours) != bits(theirs))
    if differ.size:
        k = int(differ[0])
        diff = float(np.max(np.abs(ours.astype(np.float64) - theirs.astype(np.float64))))
        raise AssertionError(
            f"{name}: {differ.size} of {STEPS} steps differ, first at t={(k + 1) * STEP:.3f} s "
            f"(fmpy {ours[k]!r}, libcosim {theirs[k]!r}); max |difference| {diff:g}"
        )


def test_libcosim_runs_the_shipped_fmu_like_fmpy(
    libcosim_runs: dict[str, tuple[Series, float]], fmpy_run: Series, outputs: list[Any], fsm_codes: dict[str, int]
) -> None:
    series, end_time = libcosim_runs["shipped"]
    assert end_time == pytest.approx(STEPS * STEP, abs=1e-12)
    # libcosim exposes every output but the enumeration fsm.state (it ignores Enumeration variables).
    assert set(series) - TIMING_OUTPUTS == {v.name for v in outputs} - {FSM_OUTPUT}
    for name in sorted(set(series) - TIMING_OUTPUTS):
        assert_bit_identical(name, fmpy_run[name], series[name])
    # The run compared is the stand-up into the stand, with the torques carrying the robot.
    states = fmpy_run[FSM_OUTPUT]
    assert states[0] == fsm_codes["StandUp"] and states[-1] == fsm_codes["Stand"]
    assert fsm_codes["Damping"] not in states
    knees = np.array([fmpy_run[f"joint.tau[{i}]"] for i in (3, 6, 9, 12)])
    assert (np.abs(knees[:, -1]) > 1.0).all()


def test_libcosim_fsm_state_through_an_integer_declaration(libcosim_runs: dict[str, tuple[Series, float]], fmpy_run: Series, outputs: list[Any]) -> None:
    series, _ = libcosim_runs["integer"]
    assert set(series) - TIMING_OUTPUTS == {v.name for v in outputs}
    for name in sorted(set(series) - TIMING_OUTPUTS):
        assert_bit_identical(name, fmpy_run[name], series[name])
