"""Every FMU variable name the documentation mentions exists in the bundled FMU's modelDescription.xml.

The variable reference is fmu/README.md; the root README and the READMEs of the packages that use
the FMU may name variables too. A mention is a `code` span whose first name part (before the first
`.` or `[`) is the first part of some FMU variable; patterns are expanded: `{a,b}` alternatives,
`[1..121]` both ends, `[i]` index 1, `*` any (at least one variable must match).
"""

from __future__ import annotations

import fnmatch
import re
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]
FILE_NAME = re.compile(r"\.(rs|py|xml|json|toml|md|sh|fmu|so|urdf|html)$")
# The FMU's reference page, and the other pages that may name its variables.
FMU_README = Path("fmu") / "README.md"
PAGES = (FMU_README, Path("README.md"), Path("controller") / "README.md", Path("harness") / "README.md")


def expand(pattern: str) -> list[str]:
    """The concrete names (or `*` globs) a README pattern stands for."""
    brace = re.search(r"\{([^{}]*)\}", pattern)
    if brace:
        head, tail = pattern[: brace.start()], pattern[brace.end() :]
        return [name for alternative in brace.group(1).split(",") for name in expand(head + alternative + tail)]
    span = re.search(r"\[(\d+)\.\.(\d+)\]", pattern)
    if span:
        head, tail = pattern[: span.start()], pattern[span.end() :]
        return [name for end in span.groups() for name in expand(f"{head}[{end}]{tail}")]
    return [pattern.replace("[i]", "[1]")]


def mentions(text: str, heads: set[str]) -> set[str]:
    spans = re.findall(r"`([^`\s]+)`", text)
    return {s for s in spans if re.split(r"[.\[]", s, maxsplit=1)[0] in heads and not FILE_NAME.search(s)}


def missing_names(mentioned: set[str], names: set[str]) -> list[str]:
    return [
        f"{mention} ({name})"
        for mention in sorted(mentioned)
        for name in expand(mention)
        if not (fnmatch.filter(names, name.replace("[", "[[]")) if "*" in name else name in names)
    ]


def test_expand() -> None:
    assert expand("terrain.map.{x0,h[1..121]}") == ["terrain.map.x0", "terrain.map.h[1]", "terrain.map.h[121]"]
    assert expand("joint.q[i]") == ["joint.q[1]"]


def test_a_wrong_name_is_caught() -> None:
    names = {"joint.q[1]", "joint.q[12]", "fsm.state"}
    heads = {"joint", "fsm"}
    found = mentions("`joint.q[1..12]` and `fsm.State` and `joint.tau[1..12]`", heads)
    assert missing_names(found, names) == ["fsm.State (fsm.State)", "joint.tau[1..12] (joint.tau[1])", "joint.tau[1..12] (joint.tau[12])"]


@pytest.mark.parametrize("page", PAGES, ids=str)
def test_every_fmu_variable_the_documentation_names_exists(fmu_model_description: Any, page: Path) -> None:
    names = {v.name for v in fmu_model_description.modelVariables}
    heads = {re.split(r"[.\[]", n, maxsplit=1)[0] for n in names}
    found = mentions((REPO / page).read_text(encoding="utf-8"), heads)
    if page == FMU_README:
        # The reference must keep naming the variables: an emptied table would pass vacuously.
        assert {"joint.dq[i]", "joint.tau[1..12]", "fsm.state", "cmd.mode", "est.status", "estimator"} <= found, found
    missing = missing_names(found, names)
    assert not missing, f"{page} names FMU variables that do not exist: {missing}"
