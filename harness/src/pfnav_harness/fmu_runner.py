"""The controller FMU through fmpy's FMU2Slave, with allocation-free per-step value exchange.

fmpy's `setReal`/`getReal` build fresh ctypes arrays on every call; at 1 kHz that overhead is
comparable to the controller itself. Here the value-reference and value arrays are allocated once,
the values are numpy views onto them, and the raw fmi2 functions are called directly (status
checked here, exactly as fmpy would).
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import SimulationError

STATE_INPUTS = (
    ["base.pos.x", "base.pos.y", "base.pos.z"]
    + ["base.quat.w", "base.quat.x", "base.quat.y", "base.quat.z"]
    + ["base.vel.x", "base.vel.y", "base.vel.z"]
    + ["base.omega.x", "base.omega.y", "base.omega.z"]
    + [f"joint.q[{i}]" for i in range(1, 13)]
    + [f"joint.dq[{i}]" for i in range(1, 13)]
)
REFERENCE_INPUTS = ["ref.x", "ref.y", "ref.z", "ref.yaw", "ref.vx", "ref.vy", "ref.yawRate", "ref.bodyHeight"]
TERRAIN_INPUTS = ["terrain.height", "terrain.dzdx", "terrain.dzdy"]
# Local elevation map around the robot (HEIGHT_MAP_SIZE² mesh vertices); optional.
HEIGHT_MAP_SIZE = 11
HEIGHT_MAP_INPUTS = ["terrain.map.x0", "terrain.map.y0", "terrain.map.spacing"] + [
    f"terrain.map.h[{i}]" for i in range(1, HEIGHT_MAP_SIZE * HEIGHT_MAP_SIZE + 1)
]
MODE_INPUT = "cmd.mode"
TORQUE_OUTPUTS = [f"joint.tau[{i}]" for i in range(1, 13)]
FORCE_OUTPUTS = [f"force[{k}].{c}" for k in range(1, 5) for c in "xyz"]
SOLVE_TIME_OUTPUT = "mpc.solveTime"
CONTACT_OUTPUTS = [f"contact[{k}]" for k in range(1, 5)]
FSM_OUTPUT = "fsm.state"

MODE_PASSIVE = 0
MODE_STAND = 1
MODE_LOCOMOTION = 2

# Index ranges inside the real-input vector.
N_STATE = len(STATE_INPUTS)
N_REF = len(REFERENCE_INPUTS)
N_TERRAIN = len(TERRAIN_INPUTS)
N_MAP = len(HEIGHT_MAP_INPUTS)
N_REAL_INPUTS = N_STATE + N_REF + N_TERRAIN + N_MAP
N_REAL_OUTPUTS = len(TORQUE_OUTPUTS) + len(FORCE_OUTPUTS) + 1


@dataclass
class FmuInfo:
    model_name: str
    model_identifier: str
    guid: str
    parameters: dict[str, str]


def _fmi_status_ok(status: int) -> bool:
    return status <= 1  # fmi2OK or fmi2Warning


class ControllerFmu:
    """One instance of the controller FMU, stepped with fixed input/output vectors."""

    def __init__(self, fmu_path: Path, instance_name: str = "controller") -> None:
        try:
            from fmpy import extract, read_model_description
            from fmpy.fmi2 import FMU2Slave
        except ImportError as err:
            raise SimulationError("fmpy is not installed: run scripts/setup.sh") from err
        self._unzipdir = Path(tempfile.mkdtemp(prefix="pfnav_fmu_"))
        try:
            md = read_model_description(str(fmu_path))
        except Exception as err:  # fmpy raises several exception types for a broken archive
            raise SimulationError(f"cannot read the model description of {fmu_path}: {err}") from err
        if md.coSimulation is None:
            raise SimulationError(f"{fmu_path} is not a co-simulation FMU")
        variables = {v.name: v for v in md.modelVariables}
        missing = [n for n in STATE_INPUTS + REFERENCE_INPUTS + [MODE_INPUT] + TORQUE_OUTPUTS if n not in variables]
        if missing:
            raise SimulationError(f"{fmu_path} lacks variables the harness needs: {', '.join(missing[:8])}")
        self.info = FmuInfo(
            model_name=md.modelName,
            model_identifier=md.coSimulation.modelIdentifier,
            guid=md.guid,
            parameters={v.name: str(v.start) for v in md.modelVariables if v.causality == "parameter"},
        )

        def vr(name: str) -> int | None:
            v = variables.get(name)
            return None if v is None else int(v.valueReference)

        real_in_names = STATE_INPUTS + REFERENCE_INPUTS + TERRAIN_INPUTS + HEIGHT_MAP_INPUTS
        # Terrain inputs and a few outputs are optional: an FMU without them still runs.
        self._real_in_mask = np.array([vr(n) is not None for n in real_in_names])
        in_vrs = [vr(n) for n in real_in_names if vr(n) is not None]
        self.missing_optional = [n for n in real_in_names if vr(n) is None]
        self.has_height_map = all(vr(n) is not None for n in HEIGHT_MAP_INPUTS)
        out_names = TORQUE_OUTPUTS + FORCE_OUTPUTS + [SOLVE_TIME_OUTPUT]
        self._real_out_mask = np.array([vr(n) is not None for n in out_names])
        out_vrs = [vr(n) for n in out_names if vr(n) is not None]
        self.missing_optional += [n for n in out_names if vr(n) is None]

        self._in_vr = (ctypes.c_uint * len(in_vrs))(*in_vrs)
        self._in_val = (ctypes.c_double * len(in_vrs))()
        self._in_np = np.ctypeslib.as_array(self._in_val)
        self._out_vr = (ctypes.c_uint * len(out_vrs))(*out_vrs)
        self._out_val = (ctypes.c_double * len(out_vrs))()
        self._out_np = np.ctypeslib.as_array(self._out_val)
        self._mode_vr = (ctypes.c_uint * 1)(vr(MODE_INPUT) or 0)
        self._mode_val = (ctypes.c_int * 1)(MODE_PASSIVE)
        contact_vrs = [vr(n) for n in CONTACT_OUTPUTS]
        self._has_contacts = all(v is not None for v in contact_vrs)
        self._contact_vr = (ctypes.c_uint * 4)(*(v or 0 for v in contact_vrs))
        self._contact_val = (ctypes.c_int * 4)()
        self._contact_np = np.ctypeslib.as_array(self._contact_val)
        fsm_vr = vr(FSM_OUTPUT)
        self._has_fsm = fsm_vr is not None
        self._fsm_vr = (ctypes.c_uint * 1)(fsm_vr or 0)
        self._fsm_val = (ctypes.c_int * 1)()
        # With every input present (our FMU), `real_inputs` *is* the ctypes buffer fmi2SetReal
        # reads: no per-step copy. Likewise for the outputs.
        self._inputs_complete = bool(self._real_in_mask.all())
        self.real_inputs = self._in_np if self._inputs_complete else np.zeros(N_REAL_INPUTS)
        self._outputs_complete = bool(self._real_out_mask.all())
        self.real_outputs = self._out_np if self._outputs_complete else np.zeros(N_REAL_OUTPUTS)

        try:
            extract(str(fmu_path), unzipdir=str(self._unzipdir))
            self._fmu: Any = FMU2Slave(
                guid=md.guid,
                unzipDirectory=str(self._unzipdir),
                modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName=instance_name,
            )
            self._fmu.instantiate(loggingOn=False)
        except Exception as err:
            self._cleanup_dir()
            raise SimulationError(f"cannot instantiate the FMU {fmu_path}: {err}") from err
        f = self._fmu._functions
        self._set_real = f["fmi2SetReal"]
        self._get_real = f["fmi2GetReal"]
        self._set_integer = f["fmi2SetInteger"]
        self._get_integer = f["fmi2GetInteger"]
        self._get_boolean = f["fmi2GetBoolean"]
        self._do_step = f["fmi2DoStep"]
        self._component = self._fmu.component
        self._initialized = False
        self._terminated = False

    def _check(self, status: int, what: str) -> None:
        if not _fmi_status_ok(status):
            raise SimulationError(f"FMU call {what} failed with status {status}")

    def set_parameters(self, values: dict[str, float]) -> None:
        """Sets real parameters by name before initialisation (e.g. gait period)."""
        if self._initialized:
            raise SimulationError("FMU parameters must be set before initialisation")
        from fmpy import read_model_description

        md = read_model_description(str(self._unzipdir))
        variables = {v.name: v for v in md.modelVariables}
        for name, value in values.items():
            v = variables.get(name)
            if v is None or v.causality != "parameter":
                raise SimulationError(f"the FMU has no parameter '{name}'")
            if v.type == "Real":
                self._fmu.setReal([v.valueReference], [float(value)])
            elif v.type == "Integer":
                self._fmu.setInteger([v.valueReference], [int(value)])
            else:
                raise SimulationError(f"parameter '{name}' has unsupported type {v.type}")

    def initialize(self, start_time: float = 0.0) -> None:
        try:
            self._fmu.setupExperiment(startTime=start_time)
            self.exchange_inputs(MODE_PASSIVE)
            self._fmu.enterInitializationMode()
            self._fmu.exitInitializationMode()
        except Exception as err:
            raise SimulationError(f"FMU initialisation failed: {err}") from err
        self._initialized = True

    def exchange_inputs(self, mode: int) -> None:
        """Writes `real_inputs` (state, reference, terrain) and the mode request into the FMU."""
        if not self._inputs_complete:
            self._in_np[:] = self.real_inputs[self._real_in_mask]
        self._check(self._set_real(self._component, self._in_vr, len(self._in_np), self._in_val), "fmi2SetReal")
        self._mode_val[0] = mode
        self._check(self._set_integer(self._component, self._mode_vr, 1, self._mode_val), "fmi2SetInteger")

    def do_step(self, time: float, step: float) -> None:
        self._check(self._do_step(self._component, time, step, 1), f"fmi2DoStep(t={time:.4f}, h={step})")

    def read_outputs(self) -> None:
        """Fills `real_outputs` (tau[12], force[12], solve time), `contacts` and `fsm_state`."""
        self._check(self._get_real(self._component, self._out_vr, len(self._out_np), self._out_val), "fmi2GetReal")
        if not self._outputs_complete:
            self.real_outputs[self._real_out_mask] = self._out_np
        if self._has_contacts:
            self._check(self._get_boolean(self._component, self._contact_vr, 4, self._contact_val), "fmi2GetBoolean")
        if self._has_fsm:
            self._check(self._get_integer(self._component, self._fsm_vr, 1, self._fsm_val), "fmi2GetInteger")

    @property
    def torques(self) -> NDArray[np.float64]:
        return self.real_outputs[0:12]

    @property
    def forces(self) -> NDArray[np.float64]:
        return self.real_outputs[12:24]

    @property
    def solve_time(self) -> float:
        return float(self.real_outputs[24])

    @property
    def contacts(self) -> list[int]:
        return list(self._contact_val)

    @property
    def contacts_array(self) -> NDArray[np.int32]:
        """Live numpy view of the contact flags (updated by every `read_outputs`)."""
        return self._contact_np

    @property
    def fsm_state(self) -> int:
        return int(self._fsm_val[0]) if self._has_fsm else -1

    def close(self) -> None:
        if not self._terminated:
            self._terminated = True
            try:
                if self._initialized:
                    self._fmu.terminate()
                self._fmu.freeInstance()
            except Exception:
                pass
        self._cleanup_dir()

    def _cleanup_dir(self) -> None:
        shutil.rmtree(self._unzipdir, ignore_errors=True)

    def __enter__(self) -> ControllerFmu:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
