"""Shared fixtures of the cross-component tests (owned by the harness helper).

The build products come from `scripts/setup.sh` (release binaries in target/release, the FMU in
target/fmu); each can be overridden by env (PFNAV_PF_PLAN, PFNAV_PLANNER_SERVICE, PFNAV_FMU).
A missing product is a test error with the build command, never a skip: `scripts/test.sh` builds
everything first. Tests that use LCM over udpm:// must run inside a private network namespace
(`scripts/netns.sh`, as `scripts/test.sh` does); the `lcm_url` fixture refuses otherwise.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
_generated = REPO_ROOT / "build" / "lcm_python"
if _generated.is_dir() and str(_generated) not in sys.path:
    # setup.sh installs a .pth for this; keep tests working from a tree where it is not yet there.
    sys.path.insert(0, str(_generated))

from pfnav_harness import paths
from pfnav_harness import scenario as harness_scenario
from pfnav_harness.cli import in_private_network_namespace
from pfnav_harness.errors import MissingArtifactError
from pfnav_harness.fmu_runner import FmuContract, read_contract
from pfnav_harness.lcm_channels import udpm_url
from pfnav_harness.pipeline import export_scenario
from pfnav_harness.planner_client import Plan, PlannerClient
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario


def _artifact(getter: object) -> Path:
    try:
        return getter()  # type: ignore[operator]
    except MissingArtifactError as err:
        pytest.fail(str(err), pytrace=False)


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


@pytest.fixture(scope="session")
def pf_plan_bin() -> Path:
    return _artifact(paths.pf_plan_path)


@pytest.fixture(scope="session")
def planner_service_bin() -> Path:
    return _artifact(paths.planner_service_path)


@pytest.fixture(scope="session")
def fmu_file() -> Path:
    return _artifact(paths.fmu_path)


@pytest.fixture(scope="session")
def fmu_unzipped(fmu_file: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The FMU archive extracted once per session (FMU2Slave instances load from it)."""
    from fmpy import extract

    return Path(extract(str(fmu_file), unzipdir=str(tmp_path_factory.mktemp("fmu"))))


@pytest.fixture(scope="session")
def fmu_model_description(fmu_file: Path) -> Any:
    """fmpy's reading of the FMU's modelDescription.xml."""
    from fmpy import read_model_description

    return read_model_description(str(fmu_file))


@pytest.fixture(scope="session")
def fmu_contract(fmu_file: Path) -> FmuContract:
    """The FMU variables, value references and enumeration codes the harness uses, checked."""
    return read_contract(fmu_file)


@pytest.fixture(scope="session")
def robot() -> RobotDescription:
    """Our robot (robot/quadruped.toml, the robot of the default FMU), whatever $PFNAV_ROBOT says."""
    return RobotDescription.load(paths.default_robot_config_path())


@pytest.fixture(scope="session")
def lcm_url() -> str:
    """A udpm:// URL on loopback only; fails outside a private network namespace (network rule)."""
    if not in_private_network_namespace():
        pytest.fail(
            "LCM udpm:// tests must run inside a private network namespace: bash scripts/netns.sh .venv/bin/pytest ...",
            pytrace=False,
        )
    # A port of its own keeps this session's traffic apart from other tests on the same namespace.
    return udpm_url(7600 + os.getpid() % 100)


@pytest.fixture(scope="session")
def paper_scenarios(
    pf_plan_bin: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Scenario]:
    """The paper's three scenarios as exported by `pf-plan scenario export`."""
    folder = tmp_path_factory.mktemp("scenarios")
    return {
        name: export_scenario(pf_plan_bin, name, folder) for name in harness_scenario.paper_scenario_names()
    }


@pytest.fixture(scope="session")
def planner(
    lcm_url: str, planner_service_bin: Path, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[PlannerClient]:
    """A pf-planner-service started for this test session, and an LCM client talking to it."""
    log = tmp_path_factory.mktemp("service") / "pf-planner-service.log"
    with PlannerClient(
        lcm_url,
        "PFNAV_TEST_",
        planner_service_bin,
        service_log=log,
        startup_timeout=20.0,
    ) as client:
        yield client


@pytest.fixture(scope="session")
def plan_for(
    planner: PlannerClient, paper_scenarios: dict[str, Scenario]
) -> Callable[[str, str], Plan]:
    """`plan_for(scenario, method)`: the service's plan, requested once per session (P-F solves take a while)."""
    cache: dict[tuple[str, str], Plan] = {}

    def get(name: str, method: str) -> Plan:
        if (name, method) not in cache:
            scenario = paper_scenarios[name]
            # Published afresh for every request: the service keeps only its most recent maps and
            # refuses an older sequence number, and other tests (online runs) publish many maps.
            map_seq = planner.publish_map(scenario.terrain)
            cache[(name, method)] = planner.request_plan(
                scenario,
                method,
                map_seq,
                timeout=300.0,
                retries=2,
                max_solve_time=240.0,
            )
        return cache[(name, method)]

    return get
