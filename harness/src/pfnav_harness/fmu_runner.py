"""The controller FMU through fmpy's FMU2Slave, with allocation-free per-step value exchange.

The FMU variables the harness uses are declared once, in this module (`USED_VARIABLES` collects
them with the causality each must have, `USED_ENUMERATIONS` the enumeration items). Value
references, types and enumeration codes (FSM states, mode requests) are read from the FMU's
modelDescription.xml at load time (`FmuContract`); a name the FMU lacks is an error then, never
silently skipped.

fmpy's `setReal`/`getReal` build fresh ctypes arrays on every call; at 1 kHz that overhead is
comparable to the controller itself. Here the value-reference and value arrays are allocated once,
the values are numpy views onto them (addressed by variable name through `NamedVector`), and the
raw fmi2 functions are called directly (status checked here, exactly as fmpy would).
"""

from __future__ import annotations

import ctypes
import functools
import math
import re
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import SimulationError

# --- The FMU variables the harness uses (the one declaration) ---------------------------------

BASE_POS = ("base.pos.x", "base.pos.y", "base.pos.z")
BASE_QUAT = ("base.quat.w", "base.quat.x", "base.quat.y", "base.quat.z")
BASE_VEL = ("base.vel.x", "base.vel.y", "base.vel.z")
BASE_OMEGA = ("base.omega.x", "base.omega.y", "base.omega.z")
JOINT_Q = tuple(f"joint.q[{i}]" for i in range(1, 13))
JOINT_DQ = tuple(f"joint.dq[{i}]" for i in range(1, 13))
# The order `QuadrupedWorld.state_vector` writes the measured state in.
STATE_INPUTS = BASE_POS + BASE_QUAT + BASE_VEL + BASE_OMEGA + JOINT_Q + JOINT_DQ
# Reference from the plan; ref.z is the height of the local terrain plane given by the slopes.
REFERENCE_INPUTS = (
    "ref.x",
    "ref.y",
    "ref.z",
    "ref.yaw",
    "ref.vx",
    "ref.vy",
    "ref.yawRate",
    "ref.bodyHeight",
    "terrain.dzdx",
    "terrain.dzdy",
)
# Local elevation map around the robot (size² mesh vertices); spacing ≤ 0: no map. The size is
# the controller's (HEIGHT_MAP_SIZE in controller/src/api.rs): the FMU publishes one
# terrain.map.h[i] per sample and `FmuContract` counts them.
HEIGHT_MAP_ORIGIN = ("terrain.map.x0", "terrain.map.y0")
HEIGHT_MAP_SPACING = "terrain.map.spacing"
HEIGHT_MAP_HEIGHT = re.compile(r"terrain\.map\.h\[\d+\]")


def height_map_heights(size: int) -> tuple[str, ...]:
    """The FMU's height-map sample inputs of a size×size map, row-major (x fastest)."""
    return tuple(f"terrain.map.h[{i}]" for i in range(1, size * size + 1))


# Real inputs before the height map (whose samples the FMU's contract adds: `FmuContract.real_inputs`).
FIXED_REAL_INPUTS = (*STATE_INPUTS, *REFERENCE_INPUTS, *HEIGHT_MAP_ORIGIN, HEIGHT_MAP_SPACING)
MODE_INPUT = "cmd.mode"

TORQUE_OUTPUTS = tuple(f"joint.tau[{i}]" for i in range(1, 13))
FORCE_OUTPUTS = tuple(f"force[{k}].{c}" for k in range(1, 5) for c in "xyz")
SOLVE_TIME_OUTPUT = "mpc.solveTime"
REAL_OUTPUTS = (*TORQUE_OUTPUTS, *FORCE_OUTPUTS, SOLVE_TIME_OUTPUT)
# The controller's scheduled stance per leg (named contact[k] before the estimator took that name
# for its measured-contact inputs).
CONTACT_OUTPUTS = tuple(f"stance[{k}]" for k in range(1, 5))
FSM_OUTPUT = "fsm.state"

# The controller's nominal stand height above the terrain: its start value is the robot's stand
# height (the controller's tuned default, scaled to the FMU's robot), `FmuContract.stand_height`.
STAND_HEIGHT_PARAMETER = "stand.bodyHeight"

# Enumeration types (modelDescription <TypeDefinitions>) and the items the harness refers to.
FSM_TYPE = "FsmState"
MODE_TYPE = "ModeRequest"
USED_ENUMERATIONS: dict[str, tuple[str, ...]] = {
    FSM_TYPE: ("Passive", "Stand", "Locomotion", "Damping"),
    MODE_TYPE: ("Passive", "Stand", "Locomotion"),
}
# Variables whose values are items of an enumeration type.
ENUMERATION_VARIABLES = {MODE_INPUT: MODE_TYPE, FSM_OUTPUT: FSM_TYPE}

# Every FMU variable the harness reads or writes, with the causality it must have.
# The height-map samples are checked by `FmuContract` once it has counted them.
USED_VARIABLES: dict[str, str] = (
    {name: "input" for name in (*FIXED_REAL_INPUTS, MODE_INPUT)}
    | {name: "output" for name in (*REAL_OUTPUTS, *CONTACT_OUTPUTS, FSM_OUTPUT)}
    | {STAND_HEIGHT_PARAMETER: "parameter"}
)

# State estimation (issue 18): body sensor inputs, the estimate, the mode parameter. Needed only
# when a run asks for the estimator (kalman mode); an FMU without them still runs on ground truth.
IMU_GYRO = tuple(f"imu.gyro[{i}]" for i in range(1, 4))
IMU_ACC = tuple(f"imu.acc[{i}]" for i in range(1, 4))
FIX_POS = tuple(f"fix.pos[{i}]" for i in range(1, 4))
FIX_VALID = "fix.valid"
# Measured foot contact per leg: −1 = unknown (the estimator uses the gait schedule), 0, 1.
CONTACT_INPUTS = tuple(f"contact[{k}]" for k in range(1, 5))
CONTACT_UNKNOWN = -1
ESTIMATION_REAL_INPUTS = IMU_GYRO + IMU_ACC + FIX_POS
EST_POS = tuple(f"est.pos[{i}]" for i in range(1, 4))
EST_VEL = tuple(f"est.vel[{i}]" for i in range(1, 4))
EST_RPY = tuple(f"est.rpy[{i}]" for i in range(1, 4))
# Variances of the position (world axes, m²) and of the attitude error (body axes, rad²).
EST_POS_VAR = tuple(f"est.posVar[{i}]" for i in range(1, 4))
EST_ATT_VAR = tuple(f"est.attVar[{i}]" for i in range(1, 4))
ESTIMATION_REAL_OUTPUTS = EST_POS + EST_VEL + EST_RPY + EST_POS_VAR + EST_ATT_VAR
EST_STATUS = "est.status"
ESTIMATOR_PARAMETER = "estimator"
# The estimator's model of a position fix's noise, m (per axis).
FIX_NOISE_PARAMETER = "est.fixNoise"
# Estimator modes by item name; the codes are read from the parameter's enumeration type.
ESTIMATOR_MODES = ("groundTruth", "kalman")
# What a run's controller works on unless told otherwise (CLI, sweeps, CoSimConfig): its own
# estimate from the body sensors, as on a real robot.
DEFAULT_ESTIMATOR = "kalman"
ESTIMATION_VARIABLES: dict[str, str] = (
    {name: "input" for name in (*ESTIMATION_REAL_INPUTS, FIX_VALID, *CONTACT_INPUTS)}
    | {name: "output" for name in (*ESTIMATION_REAL_OUTPUTS, EST_STATUS)}
    | {ESTIMATOR_PARAMETER: "parameter"}
)


class NamedVector:
    """A float vector whose entries are FMU variables, addressed by name (views, no copies)."""

    def __init__(self, names: Sequence[str], values: NDArray[np.float64] | None = None) -> None:
        self.names = tuple(names)
        self.values = np.zeros(len(self.names)) if values is None else values
        if self.values.shape != (len(self.names),):
            raise ValueError(f"{len(self.names)} names for a vector of shape {self.values.shape}")
        self._index = {name: i for i, name in enumerate(self.names)}

    def index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"{name} is not one of this vector's FMU variables") from None

    def indices(self, names: Sequence[str]) -> NDArray[np.intp]:
        return np.array([self.index(n) for n in names], dtype=np.intp)

    def span(self, names: Sequence[str]) -> slice:
        """The slice holding `names`, which must be consecutive in this vector."""
        first = self.index(names[0])
        if self.names[first : first + len(names)] != tuple(names):
            raise KeyError(f"{names[0]}…{names[-1]} are not consecutive in this vector")
        return slice(first, first + len(names))

    def view(self, names: Sequence[str]) -> NDArray[np.float64]:
        """A live view of the entries `names` (consecutive)."""
        return self.values[self.span(names)]


def enumeration(md: Any, type_name: str) -> type[IntEnum]:
    """The enumeration type `type_name` of fmpy's model description `md` as an IntEnum (item name → code)."""
    types = {t.name: t for t in md.typeDefinitions if t.type == "Enumeration"}
    if type_name not in types:
        raise SimulationError(f"the FMU has no enumeration type {type_name}")
    items = {str(item.name): int(item.value) for item in types[type_name].items}
    return IntEnum(type_name, items)  # type: ignore[return-value]


class FmuContract:
    """What the harness relies on in one FMU's modelDescription, checked when it is read."""

    def __init__(self, md: Any, source: str) -> None:
        variables = {v.name: v for v in md.modelVariables}
        types = {t.name: t for t in md.typeDefinitions}
        problems = _variable_problems(variables, USED_VARIABLES)
        self.height_map_size = _height_map_size(variables, problems)
        self.height_map_heights = height_map_heights(self.height_map_size)
        problems += _variable_problems(variables, dict.fromkeys(self.height_map_heights, "input"))
        # The order of the FMU input buffer; the height-map samples are its tail, so an exchange
        # that keeps the map sends only the head.
        self.real_inputs = FIXED_REAL_INPUTS + self.height_map_heights
        for type_name, items in USED_ENUMERATIONS.items():
            t = types.get(type_name)
            if t is None or t.type != "Enumeration":
                problems.append(f"no enumeration type {type_name}")
                continue
            missing = sorted(set(items) - {item.name for item in t.items})
            if missing:
                problems.append(f"enumeration {type_name} has no item {', '.join(missing)}")
        for name, type_name in ENUMERATION_VARIABLES.items():
            v = variables.get(name)
            declared = getattr(getattr(v, "declaredType", None), "name", None)
            if v is not None and declared != type_name:
                problems.append(f"{name} is not of type {type_name}")
        if problems:
            raise SimulationError(f"{source} lacks what the harness needs: {'; '.join(problems)}")
        self.source = source
        self.value_references = {name: int(variables[name].valueReference) for name in (*USED_VARIABLES, *self.height_map_heights)}
        self.parameters = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
        self.stand_height = float(self.parameters[STAND_HEIGHT_PARAMETER].start)
        self.fsm = enumeration(md, FSM_TYPE)
        self.mode = enumeration(md, MODE_TYPE)
        self.estimation_problems = _variable_problems(variables, ESTIMATION_VARIABLES)
        self.estimator_codes: dict[str, int] = {}
        if not self.estimation_problems:
            self.value_references |= {name: int(variables[name].valueReference) for name in ESTIMATION_VARIABLES}
            self.estimator_codes = _estimator_codes(variables[ESTIMATOR_PARAMETER])
            missing = [m for m in ESTIMATOR_MODES if m not in self.estimator_codes]
            if missing:
                self.estimation_problems.append(f"parameter {ESTIMATOR_PARAMETER} has no item {', '.join(missing)}")
        # Bit → name of the estimator's status flags, as the FMU documents `est.status` (none without the estimator).
        self.status_flags: dict[int, str] = _status_flags(variables[EST_STATUS]) if EST_STATUS in variables else {}

    def status_flag_names(self, bits: int) -> list[str]:
        """The names of the flags set in an `est.status` bit mask (an unnamed bit by its value)."""
        return [self.status_flags.get(1 << k, f"bit {1 << k:#x}") for k in range(bits.bit_length()) if bits >> k & 1]

    @property
    def has_estimation(self) -> bool:
        """Whether the FMU has the state estimator's inputs, outputs and mode parameter."""
        return not self.estimation_problems

    def require_estimation(self) -> None:
        if self.estimation_problems:
            raise SimulationError(
                f"{self.source} has no state estimator ({'; '.join(self.estimation_problems[:4])}"
                f"{'; …' if len(self.estimation_problems) > 4 else ''}): rebuild the FMU (`bash scripts/build_fmu_portable.sh`) "
                "or run with --estimator groundTruth"
            )

    def vrs(self, names: Sequence[str]) -> list[int]:
        return [self.value_references[n] for n in names]


def _status_flags(variable: Any) -> dict[int, str]:
    """`est.status`'s flags from its description ("... bits: 1 gyroInvalid: what it means; 2 ...")."""
    _, _, bits = str(getattr(variable, "description", "") or "").partition("bits:")
    return {int(value): name for value, name in re.findall(r"(?:^|;)\s*(\d+)\s+(\w+):", bits)}


def _variable_problems(variables: dict[str, Any], expected: dict[str, str]) -> list[str]:
    """What is missing or of another causality among the `expected` variables (name → causality)."""
    problems = []
    for name, causality in expected.items():
        v = variables.get(name)
        if v is None:
            problems.append(f"no variable {name}")
        elif v.causality != causality:
            problems.append(f"{name} is {v.causality}, not {causality}")
    return problems


def _height_map_size(variables: dict[str, Any], problems: list[str]) -> int:
    """The side of the FMU's square height map: √(number of terrain.map.h[i]); 0 (and a problem) when not a square."""
    count = sum(1 for name in variables if HEIGHT_MAP_HEIGHT.fullmatch(name))
    size = math.isqrt(count)
    if count == 0 or size * size != count:
        problems.append(f"{count} height-map samples terrain.map.h[i] (a square map needs a perfect square > 0)")
        return 0
    return size


def _estimator_codes(parameter: Any) -> dict[str, int]:
    """Estimator mode name → code: the items of the parameter's enumeration type (none when it has no such type)."""
    declared = getattr(parameter, "declaredType", None)
    return {str(item.name): int(item.value) for item in getattr(declared, "items", None) or ()}


@dataclass
class EstimationIo:
    """Live views of the estimator's FMU variables (written by `exchange_inputs`, read by `read_outputs`)."""

    gyro: NDArray[np.float64]
    acc: NDArray[np.float64]
    fix_pos: NDArray[np.float64]
    fix_valid: NDArray[np.int32]
    contact: NDArray[np.int32]
    est_pos: NDArray[np.float64]
    est_vel: NDArray[np.float64]
    est_rpy: NDArray[np.float64]
    est_pos_var: NDArray[np.float64]
    est_att_var: NDArray[np.float64]
    est_status: NDArray[np.int32]
    # gyro, acc, fix_pos and est_pos, est_vel, est_rpy as the one block each is (for logging).
    sensor_block: NDArray[np.float64]
    estimate_block: NDArray[np.float64]

    @classmethod
    def detached(cls) -> EstimationIo:
        """Arrays of the right shapes bound to no FMU (for stand-ins of the controller FMU)."""
        sensors, estimate = np.zeros(9), np.zeros(len(ESTIMATION_REAL_OUTPUTS))
        return cls(
            gyro=sensors[0:3],
            acc=sensors[3:6],
            fix_pos=sensors[6:9],
            fix_valid=np.zeros(1, dtype=np.int32),
            contact=np.full(4, -1, dtype=np.int32),
            est_pos=estimate[0:3],
            est_vel=estimate[3:6],
            est_rpy=estimate[6:9],
            est_pos_var=estimate[9:12],
            est_att_var=estimate[12:15],
            est_status=np.zeros(1, dtype=np.int32),
            sensor_block=sensors,
            estimate_block=estimate[0:9],
        )


def _read_model_description(fmu_path: Path) -> Any:
    try:
        from fmpy import read_model_description
    except ImportError as err:
        raise SimulationError("fmpy is not installed: run scripts/setup.sh") from err
    try:
        return read_model_description(str(fmu_path))
    except Exception as err:  # fmpy raises several exception types for a broken archive
        raise SimulationError(f"cannot read the model description of {fmu_path}: {err}") from err


@functools.cache
def read_contract(fmu_path: Path) -> FmuContract:
    """The contract of the FMU at `fmu_path` (read once per path)."""
    return FmuContract(_read_model_description(fmu_path), str(fmu_path))


@dataclass
class FmuInfo:
    model_name: str
    model_identifier: str
    guid: str
    parameters: dict[str, str]


@dataclass(frozen=True)
class FmuIoSnapshot:
    """The harness-side value buffers of a `ControllerFmu` (copies).

    The FMU's own state (`save_state`) does not include what the master last wrote into it or read
    from it; between communication points the master logs and applies those held values, so a fork
    taken there needs them as well.
    """

    inputs: NDArray[np.float64]
    outputs: NDArray[np.float64]
    mode: int
    contacts: NDArray[np.int32]
    fsm: int
    # The estimator's buffers in `enable_estimation` order (None without the estimator).
    estimation: tuple[NDArray[Any], ...] | None


_FMI2_WARNING = 1


def _fmi_status_ok(status: int) -> bool:
    return status <= _FMI2_WARNING  # fmi2OK or fmi2Warning


# fmi2Set*/fmi2Get*(component, vr[], nvr, value[]) and fmi2DoStep(component, t, h, noSetPrior),
# with every pointer passed as an address.
_VALUES_CALL = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
_DO_STEP_CALL = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)


def _lean(function: Any, prototype: Any) -> Any:
    """`function` (a ctypes function of the FMU) called through `prototype`."""
    return prototype(ctypes.cast(function, ctypes.c_void_p).value)


class ControllerFmu:
    """One instance of the controller FMU, stepped with fixed input/output vectors."""

    def __init__(self, fmu_path: Path, instance_name: str = "controller") -> None:
        try:
            from fmpy import extract
            from fmpy.fmi2 import FMU2Slave
        except ImportError as err:
            raise SimulationError("fmpy is not installed: run scripts/setup.sh") from err
        md = _read_model_description(fmu_path)
        if md.coSimulation is None:
            raise SimulationError(f"{fmu_path} is not a co-simulation FMU")
        self.contract = FmuContract(md, str(fmu_path))
        self.path = Path(fmu_path)
        # Both are needed: the fork's state travels between processes as bytes.
        self.can_save_state = bool(md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate)
        self.info = FmuInfo(
            model_name=md.modelName,
            model_identifier=md.coSimulation.modelIdentifier,
            guid=md.guid,
            parameters={name: str(v.start) for name, v in self.contract.parameters.items()},
        )
        vrs = self.contract.vrs
        real_inputs = self.contract.real_inputs
        self._in_vr = (ctypes.c_uint * len(real_inputs))(*vrs(real_inputs))
        self._in_val = (ctypes.c_double * len(real_inputs))()
        # `inputs.values` *is* the ctypes buffer fmi2SetReal reads: no per-step copy. Likewise
        # for the outputs.
        self.inputs = NamedVector(real_inputs, np.ctypeslib.as_array(self._in_val))
        self._out_vr = (ctypes.c_uint * len(REAL_OUTPUTS))(*vrs(REAL_OUTPUTS))
        self._out_val = (ctypes.c_double * len(REAL_OUTPUTS))()
        self.outputs = NamedVector(REAL_OUTPUTS, np.ctypeslib.as_array(self._out_val))
        self._mode_vr = (ctypes.c_uint * 1)(*vrs([MODE_INPUT]))
        self._mode_val = (ctypes.c_int * 1)(self.contract.mode.Passive)
        self._contact_vr = (ctypes.c_uint * len(CONTACT_OUTPUTS))(*vrs(CONTACT_OUTPUTS))
        self._contact_val = (ctypes.c_int * len(CONTACT_OUTPUTS))()
        self._contact_np = np.ctypeslib.as_array(self._contact_val)
        self._fsm_vr = (ctypes.c_uint * 1)(*vrs([FSM_OUTPUT]))
        self._fsm_val = (ctypes.c_int * 1)(self.contract.fsm.Passive)
        self._torques = self.outputs.span(TORQUE_OUTPUTS)
        self._forces = self.outputs.span(FORCE_OUTPUTS)
        self._solve_time = self.outputs.index(SOLVE_TIME_OUTPUT)

        self._unzipdir = Path(tempfile.mkdtemp(prefix="pfnav_fmu_"))
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
        # The per-step calls go through prototypes that take plain addresses: fmpy's own
        # prototypes check and convert every array argument on each call, which costs about as
        # much as the FMU's work for a small exchange.
        self._set_real = _lean(f["fmi2SetReal"], _VALUES_CALL)
        self._get_real = _lean(f["fmi2GetReal"], _VALUES_CALL)
        self._set_integer = _lean(f["fmi2SetInteger"], _VALUES_CALL)
        self._set_boolean = _lean(f["fmi2SetBoolean"], _VALUES_CALL)
        self._get_integer = _lean(f["fmi2GetInteger"], _VALUES_CALL)
        self._get_boolean = _lean(f["fmi2GetBoolean"], _VALUES_CALL)
        self._do_step = _lean(f["fmi2DoStep"], _DO_STEP_CALL)
        self._component = self._fmu.component
        # (value references, values) addresses of each exchanged block.
        self._in_real = (ctypes.addressof(self._in_vr), ctypes.addressof(self._in_val))
        self._in_count = len(self._in_vr)
        # The height map is the tail of the real inputs: without it, only the head is sent.
        self._in_count_without_map = len(FIXED_REAL_INPUTS)
        self._mode = (ctypes.addressof(self._mode_vr), ctypes.addressof(self._mode_val))
        # The mode request the FMU holds (inputs keep their values until set): it changes a few
        # times a run, so an exchange only sends it when it differs. None: send it next time.
        self._mode_sent: int | None = None
        self._out_real = (ctypes.addressof(self._out_vr), ctypes.addressof(self._out_val))
        self._out_count = len(self._out_vr)
        self._contact = (ctypes.addressof(self._contact_vr), ctypes.addressof(self._contact_val))
        self._fsm = (ctypes.addressof(self._fsm_vr), ctypes.addressof(self._fsm_val))
        self._initialized = False
        self._terminated = False
        self._estimation: tuple[Any, ...] | None = None
        self._estimation_at: tuple[int, ...] = ()
        self.estimation: EstimationIo | None = None

    def _check(self, status: int, what: str) -> None:
        if not _fmi_status_ok(status):
            raise SimulationError(f"FMU call {what} failed with status {status}")

    def _failed(self, status: int, what: str) -> SimulationError:
        return SimulationError(f"FMU call {what} failed with status {status}")

    def set_parameters(self, values: dict[str, float]) -> None:
        """Sets parameters by name before initialisation (e.g. gait period)."""
        if self._initialized:
            raise SimulationError("FMU parameters must be set before initialisation")
        for name, value in values.items():
            v = self.contract.parameters.get(name)
            if v is None:
                raise SimulationError(f"the FMU has no parameter '{name}'")
            if v.type == "Real":
                self._fmu.setReal([v.valueReference], [float(value)])
            elif v.type in ("Integer", "Enumeration"):
                self._fmu.setInteger([v.valueReference], [int(value)])
            else:
                raise SimulationError(f"parameter '{name}' has unsupported type {v.type}")

    def enable_estimation(self, mode: str) -> EstimationIo:
        """Sets the `estimator` parameter to `mode` and exchanges the estimator's variables from now on.

        Before initialisation; refuses an FMU without the estimator with a clear error.
        """
        if mode not in ESTIMATOR_MODES:
            raise SimulationError(f"unknown estimator mode '{mode}' (choose from {', '.join(ESTIMATOR_MODES)})")
        self.contract.require_estimation()
        self.set_parameters({ESTIMATOR_PARAMETER: self.contract.estimator_codes[mode]})
        vrs = self.contract.vrs
        in_vr = (ctypes.c_uint * len(ESTIMATION_REAL_INPUTS))(*vrs(ESTIMATION_REAL_INPUTS))
        in_val = (ctypes.c_double * len(ESTIMATION_REAL_INPUTS))()
        valid_vr = (ctypes.c_uint * 1)(*vrs([FIX_VALID]))
        valid_val = (ctypes.c_int * 1)()
        contact_vr = (ctypes.c_uint * len(CONTACT_INPUTS))(*vrs(CONTACT_INPUTS))
        contact_val = (ctypes.c_int * len(CONTACT_INPUTS))(*([CONTACT_UNKNOWN] * len(CONTACT_INPUTS)))
        out_vr = (ctypes.c_uint * len(ESTIMATION_REAL_OUTPUTS))(*vrs(ESTIMATION_REAL_OUTPUTS))
        out_val = (ctypes.c_double * len(ESTIMATION_REAL_OUTPUTS))()
        status_vr = (ctypes.c_uint * 1)(*vrs([EST_STATUS]))
        status_val = (ctypes.c_int * 1)()
        self._estimation = (in_vr, in_val, valid_vr, valid_val, contact_vr, contact_val, out_vr, out_val, status_vr, status_val)
        self._estimation_at = tuple(ctypes.addressof(buffer) for buffer in self._estimation)
        inputs = NamedVector(ESTIMATION_REAL_INPUTS, np.ctypeslib.as_array(in_val))
        outputs = NamedVector(ESTIMATION_REAL_OUTPUTS, np.ctypeslib.as_array(out_val))
        self.estimation = EstimationIo(
            gyro=inputs.view(IMU_GYRO),
            acc=inputs.view(IMU_ACC),
            fix_pos=inputs.view(FIX_POS),
            fix_valid=np.ctypeslib.as_array(valid_val),
            contact=np.ctypeslib.as_array(contact_val),
            est_pos=outputs.view(EST_POS),
            est_vel=outputs.view(EST_VEL),
            est_rpy=outputs.view(EST_RPY),
            est_pos_var=outputs.view(EST_POS_VAR),
            est_att_var=outputs.view(EST_ATT_VAR),
            est_status=np.ctypeslib.as_array(status_val),
            sensor_block=inputs.values,
            estimate_block=outputs.values[0:9],
        )
        return self.estimation

    def initialize(self, start_time: float = 0.0) -> None:
        if self.estimation is None and self.contract.has_estimation:
            # Said explicitly, so a run without sensors never depends on the FMU's default mode.
            self.set_parameters({ESTIMATOR_PARAMETER: self.contract.estimator_codes["groundTruth"]})
        try:
            self._fmu.setupExperiment(startTime=start_time)
            self.exchange_inputs(self.contract.mode.Passive)
            self._fmu.enterInitializationMode()
            self._fmu.exitInitializationMode()
        except Exception as err:
            raise SimulationError(f"FMU initialisation failed: {err}") from err
        self._initialized = True

    def exchange_inputs(self, mode: int, height_map: bool = True) -> None:
        """Writes `inputs` (state, reference, terrain) and the mode request into the FMU.

        `height_map=False`: the height-map inputs are as at the last exchange, so they are not
        sent again (inputs keep their values in the FMU until set).
        """
        c = self._component
        vr, values = self._in_real
        status = self._set_real(c, vr, self._in_count if height_map else self._in_count_without_map, values)
        if status > _FMI2_WARNING:
            raise self._failed(status, "fmi2SetReal")
        if mode != self._mode_sent:
            self._mode_val[0] = mode
            status = self._set_integer(c, self._mode[0], 1, self._mode[1])
            if status > _FMI2_WARNING:
                raise self._failed(status, "fmi2SetInteger")
            self._mode_sent = mode
        if self._estimation is not None:
            in_vr, in_val, valid_vr, valid_val, contact_vr, contact_val = self._estimation_at[:6]
            self._check(self._set_real(c, in_vr, len(ESTIMATION_REAL_INPUTS), in_val), "fmi2SetReal (estimator inputs)")
            self._check(self._set_boolean(c, valid_vr, 1, valid_val), "fmi2SetBoolean (fix.valid)")
            self._check(self._set_integer(c, contact_vr, len(CONTACT_INPUTS), contact_val), "fmi2SetInteger (contact)")

    def do_step(self, time: float, step: float) -> None:
        status = self._do_step(self._component, time, step, 1)
        if status > _FMI2_WARNING:
            raise self._failed(status, f"fmi2DoStep(t={time:.4f}, h={step})")

    def read_outputs(self) -> None:
        """Fills `outputs` (torques, forces, solve time), `contacts` and `fsm_state`."""
        c = self._component
        status = self._get_real(c, self._out_real[0], self._out_count, self._out_real[1])
        if status > _FMI2_WARNING:
            raise self._failed(status, "fmi2GetReal")
        status = self._get_boolean(c, self._contact[0], len(self._contact_vr), self._contact[1])
        if status > _FMI2_WARNING:
            raise self._failed(status, "fmi2GetBoolean")
        status = self._get_integer(c, self._fsm[0], 1, self._fsm[1])
        if status > _FMI2_WARNING:
            raise self._failed(status, "fmi2GetInteger")
        if self._estimation is not None:
            out_vr, out_val, status_vr, status_val = self._estimation_at[6:]
            self._check(self._get_real(c, out_vr, len(ESTIMATION_REAL_OUTPUTS), out_val), "fmi2GetReal (estimate)")
            self._check(self._get_integer(c, status_vr, 1, status_val), "fmi2GetInteger (est.status)")

    def _require_state_support(self, what: str) -> None:
        if not self.can_save_state:
            raise SimulationError(
                f"{self.path} cannot {what} its state (modelDescription: canGetAndSetFMUstate and canSerializeFMUstate must both be true): "
                "rebuild the FMU with FMU state support, or run without forks (`fork = false` in a sweep spec)"
            )
        if not self._initialized or self._terminated:
            raise SimulationError(f"the FMU state can only be {what}d between initialisation and close")

    def save_state(self) -> bytes:
        """The FMU's complete internal state, serialized (fmi2GetFMUstate + fmi2SerializeFMUstate)."""
        from fmpy.fmi1 import FMICallException

        self._require_state_support("save")
        try:
            state = self._fmu.getFMUstate()
        except FMICallException as err:
            raise SimulationError(f"fmi2GetFMUstate failed: {err}") from err
        try:
            return bytes(self._fmu.serializeFMUstate(state))
        except FMICallException as err:
            raise SimulationError(f"fmi2SerializeFMUstate failed: {err}") from err
        finally:
            self._free_state(state)

    def restore_state(self, blob: bytes) -> None:
        """Puts the FMU back into a state from `save_state` (this instance or another of the same FMU).

        A blob the FMU refuses (truncated, another FMU's, another version's) raises SimulationError.
        """
        from fmpy.fmi1 import FMICallException

        self._require_state_support("restore")
        if not isinstance(blob, bytes | bytearray):
            raise SimulationError(f"an FMU state is a byte string, got {type(blob).__name__}")
        if not blob:
            raise SimulationError("an FMU state cannot be empty")
        try:
            state = self._fmu.deSerializeFMUstate(bytes(blob))
        except FMICallException as err:
            raise SimulationError(f"the FMU refused the serialized state ({len(blob)} bytes): {err}") from err
        # The restored instance holds the saved instance's inputs: the next exchange sends the mode again.
        self._mode_sent = None
        try:
            self._fmu.setFMUstate(state)
        except FMICallException as err:
            raise SimulationError(f"fmi2SetFMUstate failed: {err}") from err
        finally:
            self._free_state(state)

    def _free_state(self, state: Any) -> None:
        from fmpy.fmi1 import FMICallException

        try:
            self._fmu.freeFMUstate(state)
        except FMICallException as err:
            raise SimulationError(f"fmi2FreeFMUstate failed: {err}") from err

    def io_snapshot(self) -> FmuIoSnapshot:
        """Copies of the value buffers last written to and read from the FMU."""
        return FmuIoSnapshot(
            inputs=self.inputs.values.copy(),
            outputs=self.outputs.values.copy(),
            mode=int(self._mode_val[0]),
            contacts=self._contact_np.copy(),
            fsm=int(self._fsm_val[0]),
            estimation=None if self._estimation is None else tuple(np.ctypeslib.as_array(buffer).copy() for buffer in self._estimation[1::2]),
        )

    def restore_io(self, io: FmuIoSnapshot) -> None:
        """Refills the value buffers from `io` (the live views stay the same objects)."""
        if io.inputs.shape != self.inputs.values.shape or io.outputs.shape != self.outputs.values.shape:
            raise SimulationError("the saved FMU inputs/outputs do not match this FMU's")
        if (io.estimation is None) != (self._estimation is None):
            raise SimulationError("the saved FMU values and this instance differ in whether the estimator is in use")
        self.inputs.values[:] = io.inputs
        self.outputs.values[:] = io.outputs
        self._mode_val[0] = io.mode
        self._mode_sent = None
        self._contact_np[:] = io.contacts
        self._fsm_val[0] = io.fsm
        if io.estimation is not None and self._estimation is not None:
            for buffer, saved in zip(self._estimation[1::2], io.estimation, strict=True):
                np.ctypeslib.as_array(buffer)[:] = saved

    @property
    def torques(self) -> NDArray[np.float64]:
        return self.outputs.values[self._torques]

    @property
    def forces(self) -> NDArray[np.float64]:
        return self.outputs.values[self._forces]

    @property
    def solve_time(self) -> float:
        return float(self.outputs.values[self._solve_time])

    @property
    def contacts(self) -> list[int]:
        return list(self._contact_val)

    @property
    def contacts_array(self) -> NDArray[np.int32]:
        """Live numpy view of the contact flags (updated by every `read_outputs`)."""
        return self._contact_np

    @property
    def fsm_state(self) -> int:
        return int(self._fsm_val[0])

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
