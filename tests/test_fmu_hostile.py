"""Hostile input to the controller FMU (target/fmu/QuadController.fmu) through fmpy.

Every FMI call must return within 1 s, whatever the parameters and the step size, and a refused
call must be a clean fmi2Error (fmpy raises FMICallException) with a reason in the log, after
which the instance can still be freed and a fresh instance works. Covered here:

- every parameter of modelDescription.xml carries min/max; values just outside them, 0, negative,
  NaN, ±inf, ±1e300, 1e-300 and subnormal values are refused or accepted exactly as the range says;
- extreme communication step sizes and communication points (1e300, NaN, negative, subnormal,
  the former hangs h = 1e12…1e15 and h = 1000) and the tick cap of the most expensive
  configuration, timed;
- named regression tests for each hang of the issue (control.dt = 1e-12, 1e-9, 10, 1e300);
- a seeded random FMI call sequence (2 000 calls) with hostile arguments.

PFNAV_FMU overrides the FMU path; scripts/setup.sh builds it.
"""

from __future__ import annotations

import math
import random
import re
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions
from fmu_support import STATUS_ERROR, logging_callbacks, new_slave
from pfnav_harness.fmu_runner import FmuContract, enumeration

CALL_LIMIT_S = 1.0
FUZZ_SEED = 20261125
FUZZ_CALLS = 5000
# Joint angles of a crouched standing pose (abduction, hip, knee) inside the URDF limits.
STAND_JOINTS = [0.0, 0.87, -1.73] * 4
# Slowest call seen per test, for the report (printed with -s).
WORST: dict[str, tuple[float, str]] = {}


# ---------------------------------------------------------------------------------------------
# Fixtures


@pytest.fixture(scope="module")
def variables(fmu_model_description: Any) -> dict[str, Any]:
    return {v.name: v for v in fmu_model_description.modelVariables}


@pytest.fixture(scope="module")
def parameters(fmu_model_description: Any) -> list[Any]:
    return [v for v in fmu_model_description.modelVariables if v.causality == "parameter"]


# ---------------------------------------------------------------------------------------------
# A slave whose calls are timed and whose log messages are captured.


@dataclass
class Clock:
    """Slowest call of a test."""

    test: str
    worst_s: float = 0.0
    worst_call: str = ""

    def record(self, label: str, elapsed: float) -> None:
        if elapsed > self.worst_s:
            self.worst_s, self.worst_call = elapsed, label
            WORST[self.test] = (elapsed, label)


@dataclass
class Session:
    """One FMU2Slave; every call goes through `call`, which times it."""

    slave: FMU2Slave
    clock: Clock
    messages: list[tuple[int, str]] = field(default_factory=list)
    callbacks: fmi2CallbackFunctions | None = None
    freed: bool = False

    def call(self, label: str, function: Callable[..., Any], *args: Any) -> tuple[bool, Any]:
        """Runs one FMI call: (True, result) or (False, None) on fmi2Error; asserts its time."""
        start = time.perf_counter()
        try:
            result = function(*args)
            ok = True
        except FMICallException as err:
            assert err.status == STATUS_ERROR, f"{label}: {err}"
            result, ok = None, False
        elapsed = time.perf_counter() - start
        self.clock.record(label, elapsed)
        assert elapsed < CALL_LIMIT_S, f"{label} took {elapsed:.3f} s"
        return ok, result

    def ok(self, label: str, function: Callable[..., Any], *args: Any) -> Any:
        mark = len(self.messages)
        ok, result = self.call(label, function, *args)
        assert ok, f"{label} failed: {self.errors_since(mark)}"
        return result

    def refused(self, label: str, function: Callable[..., Any], *args: Any, reason: str) -> str:
        """Expects fmi2Error with exactly one logged error containing `reason`; returns it."""
        mark = len(self.messages)
        ok, _ = self.call(label, function, *args)
        assert not ok, f"{label} was accepted"
        errors = self.errors_since(mark)
        assert len(errors) == 1 and reason in errors[0], f"{label}: {errors}"
        return errors[0]

    def errors_since(self, mark: int) -> list[str]:
        return [m for status, m in self.messages[mark:] if status == STATUS_ERROR]

    def free(self) -> None:
        if not self.freed:
            self.call("fmi2FreeInstance", self.slave.freeInstance)
            self.freed = True


def new_session(fmu_unzipped: Path, fmu_model_description: Any, clock: Clock, name: str = "hostile") -> Session:
    session = Session(new_slave(fmu_unzipped, fmu_model_description, name), clock)
    callbacks = logging_callbacks(lambda status, _category, message: session.messages.append((status, message)))
    session.callbacks = callbacks
    session.ok(
        "fmi2Instantiate",
        lambda: session.slave.instantiate(callbacks=callbacks, loggingOn=True),
    )
    return session


@pytest.fixture
def clock(request: pytest.FixtureRequest) -> Iterator[Clock]:
    c = Clock(request.node.name)
    yield c
    print(f"\n{c.test}: slowest call {c.worst_s * 1e3:.1f} ms ({c.worst_call})")


def initialise(s: Session, start: float = 0.0) -> None:
    s.ok("fmi2SetupExperiment", s.slave.setupExperiment, None, start)
    s.ok("fmi2EnterInitializationMode", s.slave.enterInitializationMode)
    s.ok("fmi2ExitInitializationMode", s.slave.exitInitializationMode)


def max_ticks_logged(s: Session) -> int:
    for _, message in reversed(s.messages):
        found = re.search(r"at most (\d+) control ticks per doStep", message)
        if found:
            return int(found.group(1))
    raise AssertionError(f"no tick cap in the log: {s.messages}")


def assert_fresh_instance_works(fmu_unzipped: Path, fmu_model_description: Any, clock: Clock) -> None:
    s = new_session(fmu_unzipped, fmu_model_description, clock, "fresh")
    initialise(s)
    for k in range(10):
        s.ok("fmi2DoStep", s.slave.doStep, k * 0.01, 0.01)
    s.ok("fmi2Terminate", s.slave.terminate)
    s.free()


def bounds(v: Any) -> tuple[float, float]:
    assert v.min is not None and v.max is not None, f"{v.name} has no min/max"
    return float(v.min), float(v.max)


def real_probes(lo: float, hi: float) -> list[float]:
    return [
        math.nextafter(lo, -math.inf),
        math.nextafter(hi, math.inf),
        0.0,
        -0.0,
        -1.0,
        -hi,
        math.nan,
        math.inf,
        -math.inf,
        1e300,
        -1e300,
        1e-300,
        5e-324,
        lo,
        hi,
    ]


def integer_probes(lo: int, hi: int) -> list[int]:
    return [lo - 1, hi + 1, 0, -1, 2**31 - 1, -(2**31), lo, hi]


# ---------------------------------------------------------------------------------------------
# Parameters


def test_every_parameter_declares_a_range_holding_its_start(parameters: list[Any]) -> None:
    assert len(parameters) == 59
    for v in parameters:
        assert v.type in ("Real", "Integer", "Enumeration"), v.name
        lo, hi = bounds(v)
        assert math.isfinite(lo) and math.isfinite(hi) and lo < hi, v.name
        assert lo <= float(v.start) <= hi, v.name
    by_name = {v.name: v for v in parameters}
    assert bounds(by_name["control.dt"]) == (1e-4, 0.05)
    assert bounds(by_name["mpc.horizon"]) == (10, 40)


def test_extreme_values_of_every_parameter_are_refused_cleanly(fmu_unzipped: Path, fmu_model_description: Any, parameters: list[Any], clock: Clock) -> None:
    for v in parameters:
        s = new_session(fmu_unzipped, fmu_model_description, clock, f"param-{v.name}")
        lo, hi = bounds(v)
        vr = [v.valueReference]
        if v.type == "Real":
            for value in real_probes(lo, hi):
                label = f"fmi2SetReal({v.name} = {value!r})"
                if lo <= value <= hi:
                    s.ok(label, s.slave.setReal, vr, [value])
                else:
                    s.refused(label, s.slave.setReal, vr, [value], reason=f"invalid value for {v.name}")
        else:
            for ivalue in integer_probes(int(lo), int(hi)):
                label = f"fmi2SetInteger({v.name} = {ivalue})"
                if lo <= ivalue <= hi:
                    s.ok(label, s.slave.setInteger, vr, [ivalue])
                else:
                    s.refused(label, s.slave.setInteger, vr, [ivalue], reason=f"invalid value for {v.name}")
            s.refused(
                f"fmi2SetReal({v.name} = nan)",
                s.slave.setReal,
                vr,
                [math.nan],
                reason="does not refer to a Real variable",
            )
        # The last accepted value is the range's upper end.
        s.ok("fmi2SetupExperiment", s.slave.setupExperiment, None, 0.0)
        s.ok("fmi2EnterInitializationMode", s.slave.enterInitializationMode)
        getter = s.slave.getReal if v.type == "Real" else s.slave.getInteger
        assert s.ok(f"get {v.name}", getter, vr) == [hi], v.name
        # Values that are each in range may still conflict with others (checked here).
        ok, _ = s.call("fmi2ExitInitializationMode", s.slave.exitInitializationMode)
        if not ok:
            assert v.name in ("mpc.fMin", "stand.bodyHeight"), v.name
            assert any("controller rejected the parameters" in m for m in s.errors_since(0))
            setter = s.slave.setReal if v.type == "Real" else s.slave.setInteger
            start = float(v.start) if v.type == "Real" else int(v.start)
            s.ok(f"reset {v.name}", setter, vr, [start])
            s.ok("fmi2ExitInitializationMode", s.slave.exitInitializationMode)
        s.ok("fmi2DoStep", s.slave.doStep, 0.0, 0.001)
        s.ok("fmi2Terminate", s.slave.terminate)
        s.free()
    assert_fresh_instance_works(fmu_unzipped, fmu_model_description, clock)


def test_parameters_cannot_change_after_initialisation(fmu_unzipped: Path, fmu_model_description: Any, variables: dict[str, Any], clock: Clock) -> None:
    s = new_session(fmu_unzipped, fmu_model_description, clock)
    initialise(s)
    s.refused(
        "set control.dt while running",
        s.slave.setReal,
        [variables["control.dt"].valueReference],
        [1e-12],
        reason="fixed parameter",
    )
    s.ok("fmi2DoStep", s.slave.doStep, 0.0, 0.01)
    s.free()


# Named regressions: each value hung or froze the controller before parameters had ranges.
@pytest.mark.parametrize(
    ("dt", "symptom"),
    [
        (1e-12, "first doStep(1 ms) never returned"),
        (1e-9, "3.6 s per doStep"),
        (10.0, "no control tick ever ran"),
        (1e300, "no control tick ever ran"),
    ],
    ids=["dt_1e-12_hang", "dt_1e-9_slow", "dt_10_no_tick", "dt_1e300_no_tick"],
)
def test_regression_control_dt(dt: float, symptom: str, fmu_unzipped: Path, fmu_model_description: Any, variables: dict[str, Any], clock: Clock) -> None:
    s = new_session(fmu_unzipped, fmu_model_description, clock)
    message = s.refused(
        f"control.dt = {dt} ({symptom})",
        s.slave.setReal,
        [variables["control.dt"].valueReference],
        [dt],
        reason="invalid value for control.dt",
    )
    assert "maximum 0.05" in message or "minimum 0.0001" in message, message
    # Nothing was stored: the instance runs at the default tick.
    initialise(s)
    s.ok("fmi2DoStep", s.slave.doStep, 0.0, 0.001)
    s.free()
    assert_fresh_instance_works(fmu_unzipped, fmu_model_description, clock)


# ---------------------------------------------------------------------------------------------
# Step sizes and communication points


@pytest.mark.parametrize(
    "h",
    [1e12, 1e13, 1e14, 1e15, 1000.0],
    ids=["h_1e12_hang", "h_1e13_hang", "h_1e14_hang", "h_1e15_hang", "h_1000_27s"],
)
def test_regression_huge_step_is_refused_at_once(h: float, fmu_unzipped: Path, fmu_model_description: Any, clock: Clock) -> None:
    s = new_session(fmu_unzipped, fmu_model_description, clock)
    initialise(s)
    s.refused(f"doStep(h = {h})", s.slave.doStep, 0.0, h, reason="use shorter steps")
    s.ok("fmi2DoStep", s.slave.doStep, 0.0, 0.01)
    s.free()
    assert_fresh_instance_works(fmu_unzipped, fmu_model_description, clock)


def test_extreme_step_sizes_and_communication_points(fmu_unzipped: Path, fmu_model_description: Any, clock: Clock) -> None:
    s = new_session(fmu_unzipped, fmu_model_description, clock)
    initialise(s)
    cap = max_ticks_logged(s)
    # About a third of a second at 1 ms ticks with the default parameters (fmu/src/budget.rs).
    assert 344 <= cap <= 345, cap
    refused_steps = [
        (1e300, "use shorter steps"),
        (1.7976931348623157e308, "use shorter steps"),
        (math.inf, "must be finite and > 0"),
        (-math.inf, "must be finite and > 0"),
        (math.nan, "must be finite and > 0"),
        (-1.0, "must be finite and > 0"),
        (0.0, "must be finite and > 0"),
        (-0.0, "must be finite and > 0"),
        (-5e-324, "must be finite and > 0"),
        ((cap + 1) * 0.001, "use shorter steps"),
    ]
    for h, reason in refused_steps:
        s.refused(f"doStep(h = {h!r})", s.slave.doStep, 0.0, h, reason=reason)
    for t in [math.nan, math.inf, -math.inf, 1e300, -1e300, 0.001, -0.001]:
        s.refused(f"doStep(t = {t!r})", s.slave.doStep, t, 0.001, reason="does not match the FMU time")
    # Subnormal and tiny steps are valid: no tick, the time advances exactly.
    t = 0.0
    for h in [5e-324, 1e-300, 1e-12]:
        s.ok(f"doStep(h = {h!r})", s.slave.doStep, t, h)
        t += h
    # The communication point may drift by rounding (as a master summing steps does).
    s.ok("doStep at drifted t", s.slave.doStep, t * (1 + 1e-12) + 1e-15, cap * 0.001)
    t += cap * 0.001
    s.ok("doStep after the cap", s.slave.doStep, t, 0.01)
    s.ok("fmi2Terminate", s.slave.terminate)
    s.free()
    assert_fresh_instance_works(fmu_unzipped, fmu_model_description, clock)


def test_extreme_experiment_times_return_at_once(fmu_unzipped: Path, fmu_model_description: Any, clock: Clock) -> None:
    for start, stop in [(math.nan, None), (math.inf, None), (0.0, math.nan), (1.0, 0.5), (0.0, -math.inf)]:
        s = new_session(fmu_unzipped, fmu_model_description, clock)
        s.refused(
            f"setupExperiment({start}, {stop})",
            s.slave.setupExperiment,
            None,
            start,
            stop,
            reason="fmi2SetupExperiment",
        )
        s.free()
    for start in [1e15, 1e300, -1e300, 5e-324]:
        s = new_session(fmu_unzipped, fmu_model_description, clock)
        initialise(s, start)
        # The tick grid cannot resolve 1 ms at 1e300: no tick runs, nothing hangs.
        s.call(f"doStep at start {start}", s.slave.doStep, start, 0.5)
        s.free()


# Ill-conditioned weights at the ends of their ranges make the MPC take more iterations.
EXTREME_WEIGHTS = {f"mpc.q[{i}]": 1e5 for i in range(1, 14)} | {"mpc.r": 1e-8}


@pytest.mark.parametrize("weights", [{}, EXTREME_WEIGHTS], ids=["default_weights", "extreme_weights"])
def test_tick_cap_of_the_most_expensive_parameters_keeps_calls_under_a_second(
    weights: dict[str, float], fmu_unzipped: Path, fmu_model_description: Any, variables: dict[str, Any], fmu_contract: FmuContract, clock: Clock
) -> None:
    s = new_session(fmu_unzipped, fmu_model_description, clock)
    vr = {name: v.valueReference for name, v in variables.items()}
    reals = {"control.dt": 1e-4, "gait.period": 0.05, "stand.upDuration": 0.01} | weights
    s.ok("set worst reals", s.slave.setReal, [vr[n] for n in reals], list(reals.values()))
    ints = {"mpc.everyTicks": 1, "mpc.horizon": 40, "gait.kind": int(enumeration(fmu_model_description, "GaitKind").Walk)}
    s.ok("set worst integers", s.slave.setInteger, [vr[n] for n in ints], list(ints.values()))
    state = {"base.pos.z": fmu_contract.stand_height, "ref.vx": 0.3, "ref.bodyHeight": fmu_contract.stand_height}
    state |= {f"joint.q[{i + 1}]": q for i, q in enumerate(STAND_JOINTS)}
    s.ok("set state", s.slave.setReal, [vr[n] for n in state], list(state.values()))
    fsm, modes = fmu_contract.fsm, fmu_contract.mode
    s.ok("cmd.mode = locomotion", s.slave.setInteger, [vr["cmd.mode"]], [modes.Locomotion])
    initialise(s)
    cap = max_ticks_logged(s)
    assert cap == 8, "most expensive parameters: see fmu/src/budget.rs"
    h = cap * 1e-4
    t = 0.0
    s.refused("one tick over the cap", s.slave.doStep, t, (cap + 1) * 1e-4, reason="use shorter steps")
    solved = 0
    for _ in range(60):
        s.ok(f"doStep({cap} ticks, MPC every tick, horizon 40)", s.slave.doStep, t, h)
        t += h
        solved += s.ok("get mpc.solved", s.slave.getBoolean, [vr["mpc.solved"]])[0]
    # The MPC really ran (otherwise the timing proves nothing): locomotion with solves.
    assert s.ok("get fsm", s.slave.getInteger, [vr["fsm.state"]]) == [fsm.Locomotion]
    assert solved > 0
    # A rough local height map adds the foothold search on it to every tick and horizon step.
    rng = random.Random(7)
    terrain = {"terrain.map.x0": -0.25, "terrain.map.y0": -0.25, "terrain.map.spacing": 0.05}
    terrain |= {name: rng.uniform(-0.03, 0.03) for name in fmu_contract.height_map_heights}
    s.ok("set height map", s.slave.setReal, [vr[n] for n in terrain], list(terrain.values()))
    for _ in range(60):
        s.ok(f"doStep({cap} ticks, MPC every tick, horizon 40, height map)", s.slave.doStep, t, h)
        t += h
    assert s.ok("get fsm", s.slave.getInteger, [vr["fsm.state"]]) == [fsm.Locomotion]
    assert clock.worst_s < CALL_LIMIT_S
    s.free()


# ---------------------------------------------------------------------------------------------
# Random call sequence


HOSTILE_REALS = [math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300, 5e-324, -5e-324, 1e15, -1.0, 0.0]
SANE_STEPS = [1e-3, 1e-3, 4e-3, 0.01, 0.05, 0.2]
HOSTILE_STEPS = [1.0, 1000.0, 1e15, 1e300, math.nan, math.inf, -1.0, 0.0, 5e-324, 1e-300]
FUZZ_OPS = {
    "setParameter": 18,
    "setInputs": 18,
    "standingState": 5,
    "setBoolean": 1,
    "get": 6,
    "doStep": 25,
    "setup": 3,
    "enter": 4,
    "exit": 4,
    "initialise": 5,
    "terminate": 2,
    "reset": 4,
    "status": 2,
    "new": 1,
}


# Phases of the FMI 2.0 Co-Simulation state chart, as the FMU implements it (fmu/src/instance.rs).
INSTANTIATED, INIT_MODE, STEP_COMPLETE, STEP_FAILED, TERMINATED = "instantiated", "initializationMode", "stepComplete", "stepFailed", "terminated"
SETTABLE_IN = (INSTANTIATED, INIT_MODE, STEP_COMPLETE)
# A doStep this long needs more control ticks than any parameter set allows in one call.
STEP_OVER_EVERY_CAP = 1e15


@dataclass
class Fuzzer:
    """Random FMI calls, about a third of them with hostile arguments, on one instance at a time.

    Sane calls (valid lifecycle, in-range parameters, a standing state, millisecond steps) keep
    the instance ticking, so the hostile ones also hit a running controller. Every call is checked
    against a model of the FMU's state chart: a call the model says must fail (wrong phase, a value
    outside its range, a non-finite or absurd step, a wrong communication point) must be refused,
    and one it says must succeed must succeed; calls whose outcome depends on the controller (the
    stand-up accepting the state, the parameters fitting together) update the model from what the
    FMU answered."""

    fmu_unzipped: Path
    fmu_model_description: Any
    clock: Clock
    rng: random.Random
    session: Session | None = None
    phase: str = INSTANTIATED
    time: float = 0.0
    start_time: float = 0.0
    instances: int = 0
    outcomes: Counter[str] = field(default_factory=Counter)
    checked: Counter[str] = field(default_factory=Counter)
    parameters: list[Any] = field(default_factory=list)
    inputs: list[Any] = field(default_factory=list)
    vr: dict[str, int] = field(default_factory=dict)
    stand_height: float = math.nan

    def __post_init__(self) -> None:
        self.stand_height = FmuContract(self.fmu_model_description, "the fuzzed FMU").stand_height
        for v in self.fmu_model_description.modelVariables:
            self.vr[v.name] = v.valueReference
            if v.causality == "parameter":
                self.parameters.append(v)
            elif v.causality == "input":
                self.inputs.append(v)

    def fresh(self) -> Session:
        if self.session is not None:
            self.session.free()
        self.instances += 1
        self.session = new_session(self.fmu_unzipped, self.fmu_model_description, self.clock, f"fuzz{self.instances}")
        self.phase, self.time, self.start_time = INSTANTIATED, 0.0, 0.0
        return self.session

    def hostile(self) -> bool:
        return self.rng.random() < 0.35

    def parameter_value(self, v: Any) -> float:
        lo, hi = bounds(v)
        if self.hostile():
            pool = [*HOSTILE_REALS, lo, hi, math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf)]
            value = self.rng.choice(pool)
        else:
            value = self.rng.uniform(lo, hi)
        if v.type in ("Integer", "Enumeration"):
            return int(min(max(value, -(2**31)), 2**31 - 1)) if math.isfinite(value) else self.rng.choice([0, -(2**31), 2**31 - 1])
        return value

    def input_value(self, v: Any) -> float:
        if self.hostile():
            return self.rng.choice(HOSTILE_REALS)
        return float(v.start) + self.rng.gauss(0.0, 0.05)

    def call(self, op: str, label: str, function: Callable[..., Any], *args: Any, expect: bool | None) -> tuple[bool, list[str]]:
        """Runs one call; `expect` True/False: it must succeed/be refused (None: either). Returns
        whether it succeeded and the errors it logged."""
        assert self.session is not None
        mark = len(self.session.messages)
        ok, _ = self.session.call(label, function, *args)
        errors = self.session.errors_since(mark)
        if expect is not None:
            where = f"{label} in phase {self.phase} (t = {self.time!r})"
            assert ok == expect, f"{where}: expected {'success' if expect else 'refusal'}, got {'success' if ok else errors}"
            self.checked[f"{op} {'ok' if ok else 'refused'}"] += 1
        self.outcomes[f"{op} {'ok' if ok else 'refused'}"] += 1
        return ok, errors

    def settable(self) -> bool:
        return self.phase in SETTABLE_IN

    def parameter_accepted(self, v: Any, value: float) -> bool:
        lo, hi = bounds(v)
        in_range = math.isfinite(value) and lo <= value <= hi
        running_ok = self.phase != STEP_COMPLETE or v.variability == "tunable"
        return self.settable() and running_ok and in_range

    def step_refused_for_sure(self, t: float, h: float) -> bool:
        return (
            self.phase != STEP_COMPLETE
            or not (math.isfinite(t) and abs(t - self.time) < 0.5)
            or not (math.isfinite(h) and h > 0.0)
            or h >= STEP_OVER_EVERY_CAP
        )

    def lifecycle(self, op: str, function: Callable[..., Any], allowed_in: tuple[str, ...]) -> bool:
        ok, _ = self.call(op, op, function, expect=False if self.phase not in allowed_in else None)
        return ok

    def step(self) -> None:
        s = self.session or self.fresh()
        rng = self.rng
        op = rng.choices(list(FUZZ_OPS), weights=list(FUZZ_OPS.values()))[0]
        slave = s.slave
        if op == "setParameter":
            v = rng.choice(self.parameters)
            value = self.parameter_value(v)
            setter = slave.setReal if v.type == "Real" else slave.setInteger
            self.call(op, f"set {v.name} = {value!r}", setter, [v.valueReference], [value], expect=self.parameter_accepted(v, value))
        elif op == "setInputs":
            chosen = rng.sample(self.inputs, rng.randint(1, 4))
            reals = [v for v in chosen if v.type == "Real"]
            values = [self.input_value(v) for v in reals]
            phase_refuses = False if not self.settable() else None
            self.call(op, f"setReal {[v.name for v in reals]} = {values}", slave.setReal, [v.valueReference for v in reals], values, expect=phase_refuses)
            if len(reals) < len(chosen):
                mode = rng.choice([0, 1, 2, 2, 3, -1, 2**31 - 1])
                self.call(op, f"cmd.mode = {mode}", slave.setInteger, [self.vr["cmd.mode"]], [mode], expect=phase_refuses)
        elif op == "standingState":
            state = {"base.pos.z": self.stand_height, "base.quat.w": 1.0, "ref.vx": rng.uniform(-0.5, 0.5), "ref.bodyHeight": self.stand_height}
            state |= {f"joint.q[{i + 1}]": q for i, q in enumerate(STAND_JOINTS)}
            state |= {f"joint.dq[{i + 1}]": 0.0 for i in range(12)}
            self.call(op, "standing state", slave.setReal, [self.vr[n] for n in state], list(state.values()), expect=self.settable())
            modes = enumeration(self.fmu_model_description, "ModeRequest")
            mode = rng.choice([modes.Stand, modes.Locomotion])
            self.call(op, "cmd.mode", slave.setInteger, [self.vr["cmd.mode"]], [mode], expect=self.settable())
        elif op == "setBoolean":
            # An output: never settable.
            self.call(op, "setBoolean stance[1]", slave.setBoolean, [self.vr["stance[1]"]], [True], expect=False)
        elif op == "get":
            getter = rng.choice([slave.getReal, slave.getInteger, slave.getBoolean])
            vrs = [rng.choice([0, 5, 100, 250, 10**6, 2**32 - 1]) for _ in range(rng.randint(1, 3))]
            # Whether the value references name variables of the getter's type depends on the table.
            self.call(op, f"get {vrs}", getter, vrs, expect=False if self.phase == INSTANTIATED else None)
        elif op == "doStep":
            h = rng.choice(HOSTILE_STEPS if self.hostile() else SANE_STEPS)
            t = self.time if rng.random() < 0.9 else rng.choice([math.nan, -1.0, self.time + 1.0, 1e300])
            ok, errors = self.call(op, f"doStep({t!r}, {h!r})", slave.doStep, t, h, expect=False if self.step_refused_for_sure(t, h) else None)
            if ok:
                self.time = t + h
            elif any("controller step at t" in e for e in errors):
                self.phase = STEP_FAILED
        elif op == "setup":
            start = rng.choice([0.0, 0.0, 1.0, -5.0, 1e15, math.nan, math.inf])
            stop = rng.choice([None, 1e9, start - 1.0, math.nan])
            valid = math.isfinite(start) and (stop is None or (math.isfinite(stop) and stop >= start))
            ok, _ = self.call(op, f"setupExperiment({start}, {stop})", slave.setupExperiment, None, start, stop, expect=self.phase == INSTANTIATED and valid)
            if ok:
                self.time = self.start_time = start
        elif op == "initialise":
            ok, _ = self.call(op, "setupExperiment(0)", slave.setupExperiment, None, 0.0, expect=self.phase == INSTANTIATED)
            if ok:
                self.time = self.start_time = 0.0
            self.enter()
            self.exit()
        elif op == "enter":
            self.enter()
        elif op == "exit":
            self.exit()
        elif op == "terminate":
            if self.lifecycle(op, slave.terminate, (STEP_COMPLETE, STEP_FAILED)):
                self.phase = TERMINATED
        elif op == "reset":
            self.call(op, "reset", slave.reset, expect=True)
            self.phase, self.time, self.start_time = INSTANTIATED, 0.0, 0.0
        elif op == "status":
            kind = rng.choice([0, 1, 2, 3, 99])
            self.call(op, "getRealStatus", slave.getRealStatus, kind, expect=False if self.phase in (INSTANTIATED, INIT_MODE) else None)
        else:
            self.fresh()

    def enter(self) -> None:
        assert self.session is not None
        if self.lifecycle("enter", self.session.slave.enterInitializationMode, (INSTANTIATED,)):
            self.phase = INIT_MODE

    def exit(self) -> None:
        assert self.session is not None
        # Parameters each in range may still conflict with one another: then it stays in initialization mode.
        if self.lifecycle("exit", self.session.slave.exitInitializationMode, (INIT_MODE,)):
            self.phase, self.time = STEP_COMPLETE, self.start_time


def test_random_call_sequence_never_crashes_or_hangs(fmu_unzipped: Path, fmu_model_description: Any, clock: Clock) -> None:
    fuzzer = Fuzzer(fmu_unzipped, fmu_model_description, clock, random.Random(FUZZ_SEED))
    for _ in range(FUZZ_CALLS):
        fuzzer.step()
    if fuzzer.session is not None:
        fuzzer.session.free()
    print(f"\nfuzz: {FUZZ_CALLS} steps, {fuzzer.instances} instances: {sorted(fuzzer.outcomes.items())}; checked against the model: {sorted(fuzzer.checked.items())}")
    # The sequence reached a running controller and exercised both outcomes of the key calls.
    for key in ("doStep ok", "doStep refused", "setParameter ok", "setParameter refused", "initialise ok", "setInputs refused"):
        assert fuzzer.outcomes[key] >= 20, (key, fuzzer.outcomes)
    # Most calls had an outcome the model of the state chart fixed in advance.
    for key in ("doStep refused", "setParameter ok", "setParameter refused", "exit refused", "terminate refused"):
        assert fuzzer.checked[key] >= 10, (key, fuzzer.checked)
    assert_fresh_instance_works(fmu_unzipped, fmu_model_description, clock)
