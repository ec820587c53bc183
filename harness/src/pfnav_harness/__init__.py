"""pfnav co-simulation harness: P-F plans over LCM, the controller FMU (fmpy) on a DART body model.

Modules follow the data flow: `scenario` (map files, terrain surface) → `planner_client` (LCM) →
`reference` (plan as a time-indexed reference) → `world` (DART) + `fmu_runner` (fmpy) → `cosim`
(master loop, logs) → `metrics` → `report`. `cli` is the `pfnav-demo` command.
"""

__version__ = "0.1.0"
