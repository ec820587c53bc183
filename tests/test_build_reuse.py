"""The one-build promise (scripts/setup.sh builds once for the demo, the Python tests and the Rust
tests): the test build may add dev-dependencies but must not change the features of any crate the
release build compiled, or cargo compiles that crate and everything above it a second time."""

from __future__ import annotations

import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def features(edges: str) -> dict[str, set[str]]:
    """Every package of the workspace's graph with the given edge kinds, and its features."""
    listed = subprocess.run(
        ["cargo", "tree", "--workspace", "--offline", "-e", edges, "-f", "{p}|{f}", "--prefix", "none"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    found: dict[str, set[str]] = {}
    for line in listed.splitlines():
        package, _, flags = line.replace(" (*)", "").partition("|")
        found.setdefault(package.strip(), set()).update(f for f in flags.split(",") if f)
    return found


def feature_changes(release: dict[str, set[str]], tests: dict[str, set[str]]) -> list[str]:
    return [f"{p}: +{sorted(tests[p] - f)} -{sorted(f - tests[p])}" for p, f in sorted(release.items()) if p in tests and tests[p] != f]


def test_the_test_build_keeps_the_release_builds_features() -> None:
    release, tests = features("normal,build"), features("normal,build,dev")
    assert "faer v0.21.9" in release or any(p.startswith("faer ") for p in release), "the graph was not read"
    changed = feature_changes(release, tests)
    assert not changed, "dev-dependencies change features of release-built crates (turn them on in a normal dependency):\n" + "\n".join(changed)


def test_a_changed_feature_is_reported() -> None:
    assert feature_changes({"bitflags v2": {"default"}}, {"bitflags v2": {"default", "std"}}) == ["bitflags v2: +['std'] -[]"]
