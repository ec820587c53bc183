"""Helpers shared by the FMU tests (test_fmu_quad_controller.py, test_fmu_hostile.py).

The fixtures `fmu_file`, `fmu_unzipped` and `fmu_model_description` are in conftest.py.
"""

from __future__ import annotations

from collections.abc import Callable
from ctypes import byref
from pathlib import Path
from typing import Any

from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.fmi2 import calloc as fmi_calloc
from fmpy.fmi2 import free as fmi_free
from fmpy.logging import addLoggerProxy

# fmi2Error.
STATUS_ERROR = 3


def new_slave(unzipped: Path, md: Any, name: str, guid: str | None = None) -> FMU2Slave:
    """An FMU2Slave of the unzipped FMU (not yet instantiated); `guid` overrides the FMU's own."""
    return FMU2Slave(
        guid=guid or md.guid,
        unzipDirectory=str(unzipped),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName=name,
    )


# fmpy's logger proxy (`addLoggerProxy`) keeps the Python logger it was last given in a global of
# its native library and forwards every proxied message to it, also those of instances made with
# fmpy's default callbacks later on. A test's callbacks must therefore live as long as the process:
# freed, the next FMU message of any instance would call into freed memory.
_PROXIED_CALLBACKS: list[fmi2CallbackFunctions] = []


def logging_callbacks(sink: Callable[[int, str, str], None]) -> fmi2CallbackFunctions:
    """Callbacks whose logger passes (status, category, formatted message) of every message to `sink`.

    They are kept alive for the rest of the process (see `_PROXIED_CALLBACKS`).
    """

    def log(_env: Any, _instance: bytes, status: int, category: bytes, message: bytes) -> None:
        sink(status, category.decode(errors="replace"), message.decode(errors="replace"))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmi_calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmi_free)
    # The proxy formats the printf-style message before it reaches Python.
    addLoggerProxy(byref(callbacks))
    _PROXIED_CALLBACKS.append(callbacks)
    return callbacks
