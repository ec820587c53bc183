"""Errors the command line turns into a one-line message and a non-zero exit code."""

from __future__ import annotations


class HarnessError(Exception):
    """A failure with a message meant for the user (no traceback needed)."""

    exit_code: int = 1


class ScenarioError(HarnessError):
    """The scenario does not exist or its files are malformed."""

    exit_code = 2


class MissingArtifactError(HarnessError):
    """A binary or the FMU that the harness needs has not been built."""

    exit_code = 3


class PlannerError(HarnessError):
    """The planner did not answer, or answered with an error status."""

    exit_code = 4


class SimulationError(HarnessError):
    """The co-simulation could not run (FMU rejected a call, physics blew up)."""

    exit_code = 5
