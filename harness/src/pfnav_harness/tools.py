"""The repository's command-line tools (`pf-plan`, `bundle-fmu`) as the harness runs them: one
place for how they are started (no Rust backtraces: their errors name the item and the file),
bounded in time, and how their failures read."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

from .errors import HarnessError, MissingArtifactError


def failure_detail(proc: subprocess.CompletedProcess[str]) -> str:
    """A failed run's error report on one line (anyhow's "Error: …", "Caused by:" lines joined)."""
    lines = [line.strip() for line in (proc.stderr or proc.stdout or "").splitlines()]
    kept = [line.removeprefix("Error: ") for line in lines if line and line != "Caused by:"]
    return " / ".join(kept) or f"exit code {proc.returncode}"


def run_tool(
    binary: Path,
    args: Sequence[str],
    *,
    what: str,
    failure: type[HarnessError],
    timeout: float,
    stdin: str | None = None,
    env: Mapping[str, str] | None = None,
) -> str:
    """Runs `binary args…` and returns its standard output.

    `what` names the job in errors ("scenario 'pits' could not be exported"). A binary that cannot
    be started raises MissingArtifactError; a run over `timeout` seconds or a non-zero exit raises
    `failure` with the tool's own error text.
    """
    command = [str(binary), *args]
    try:
        proc = subprocess.run(
            command,
            input=stdin,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
            env={**os.environ, "RUST_BACKTRACE": "0", "RUST_LIB_BACKTRACE": "0", **(env or {})},
        )
    except OSError as err:
        raise MissingArtifactError(f"cannot run {binary}: {err}") from err
    except subprocess.TimeoutExpired as err:
        raise failure(f"{what}: `{binary.name} {' '.join(args[:2])}` did not finish within {timeout:.0f} s") from err
    if proc.returncode != 0:
        raise failure(f"{what} (exit {proc.returncode}): {failure_detail(proc)}")
    return proc.stdout
