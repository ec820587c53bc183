"""The documentation's shape: a short README for users, a README per package, links that resolve.

Measured figures belong to generated pages under docs/results/ (pfnav_harness.results_page), to
docs/benchmarks.md or CHANGELOG.md, never to the README, where they go stale unseen. Each check is
a function that the tests also run on a bad text, so a check that cannot fail is caught too.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from pfnav_harness.results_page import GENERATED_MARKER, RESULTS_DIR

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
MAX_README_LINES = 300
# Packages that are not Cargo crates but have a README of their own.
OTHER_PACKAGES = ("harness", "robot", "lcm_types")

LINK = re.compile(
    r"!?\[(?P<text>(?:[^\[\]]|\[[^\]]*\])*)\]\((?P<target>[^)\s]+)(?:\s+\"[^\"]*\")?\)"
)
DATE = re.compile(r"20\d\d-\d\d-\d\d")
TIMING = (
    re.compile(r"\b\d[\d.,]*\s*(?:ns|µs|us|ms|s|sec|min|h)\b"),
    re.compile(r"\bs per\b"),
    re.compile(r"per simulated second", re.IGNORECASE),
    re.compile(r"(?:×|x|times) (?:faster than )?real[- ]time", re.IGNORECASE),
    re.compile(r"\bwall[- ](?:time|clock|s\b)", re.IGNORECASE),
)
FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")


def without_links(text: str) -> str:
    """The text with every markdown link (text and target) taken out: a link may name a dated page."""
    return LINK.sub(" ", text)


def dates(text: str) -> list[str]:
    return DATE.findall(without_links(text))


def timing_phrases(text: str) -> list[str]:
    body = without_links(text)
    return [m.group(0) for pattern in TIMING for m in pattern.finditer(body)]


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(markdown: str) -> set[str]:
    found: set[str] = set()
    counts: dict[str, int] = {}
    in_code = False
    for line in markdown.splitlines():
        if FENCE.match(line):
            in_code = not in_code
            continue
        match = HEADING.match(line)
        if in_code or not match:
            continue
        slug = github_slug(match.group(2))
        # Repeated headings get -1, -2, … as on GitHub.
        n = counts.get(slug, 0)
        counts[slug] = n + 1
        found.add(slug if n == 0 else f"{slug}-{n}")
    return found


def links(markdown: str) -> list[str]:
    targets: list[str] = []
    in_code = False
    for line in markdown.splitlines():
        if FENCE.match(line):
            in_code = not in_code
            continue
        if not in_code:
            targets.extend(m.group("target") for m in LINK.finditer(line))
    return targets


def broken_links(page: Path) -> list[str]:
    """Relative links of `page` whose file (or heading anchor, in markdown files) does not exist."""
    broken = []
    for target in links(page.read_text(encoding="utf-8")):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):
            continue  # http(s), mailto: not checked offline
        path_part, _, anchor = target.partition("#")
        resolved = (page.parent / path_part).resolve() if path_part else page
        if not resolved.exists():
            broken.append(
                f"{target} (no {resolved.relative_to(REPO) if resolved.is_relative_to(REPO) else resolved})"
            )
        elif (
            anchor
            and resolved.suffix == ".md"
            and anchor not in anchors(resolved.read_text(encoding="utf-8"))
        ):
            broken.append(f"{target} (no heading with anchor #{anchor})")
    return broken


def package_folders() -> list[Path]:
    members = tomllib.loads((REPO / "Cargo.toml").read_text())["workspace"]["members"]
    return [Path(m) for m in members] + [Path(p) for p in OTHER_PACKAGES]


def readme_covering(folder: Path) -> Path | None:
    """The folder's own README, or its parent's when that has a section for the folder (lcm_types/codegen)."""
    own = REPO / folder / "README.md"
    if own.is_file():
        return own
    parent = REPO / folder.parent / "README.md"
    if folder.parent != Path(".") and parent.is_file():
        headings = [
            m.group(2)
            for line in parent.read_text(encoding="utf-8").splitlines()
            if (m := HEADING.match(line))
        ]
        if any(re.search(rf"\b{re.escape(folder.name)}\b", h) for h in headings):
            return parent
    return None


def package_readmes() -> list[Path]:
    return sorted(
        {
            readme
            for folder in package_folders()
            if (readme := readme_covering(folder)) is not None
        }
    )


def documentation_pages() -> list[Path]:
    """The hand-written pages whose links must resolve: READMEs, the changelog, docs/*.md."""
    return [
        README,
        *package_readmes(),
        REPO / "CHANGELOG.md",
        *sorted((REPO / "docs").glob("*.md")),
    ]


# --- the README -----------------------------------------------------------------------------------


def test_readme_is_short() -> None:
    lines = README.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_README_LINES, (
        f"README.md has {lines} lines; reference content belongs in the package READMEs"
    )


def test_readme_starts_with_the_two_commands() -> None:
    text = README.read_text(encoding="utf-8")
    first_block = text.split("```", 2)[1]
    assert (
        "bash scripts/demo.sh" in first_block and "bash scripts/test.sh" in first_block
    )
    assert text.index("```") < text.index("\n## "), (
        "the commands come before the first section"
    )


def test_readme_has_no_dated_measurement() -> None:
    found = dates(README.read_text(encoding="utf-8"))
    assert not found, (
        f"dates in README.md (measurements go to docs/results/, history to CHANGELOG.md): {found}"
    )


def test_readme_has_no_timing() -> None:
    found = timing_phrases(README.read_text(encoding="utf-8"))
    assert not found, f"timings in README.md (link a results page instead): {found}"


def test_the_checks_catch_a_lab_notebook() -> None:
    notebook = (
        "Measured 2026-11-27: 0.155 wall s per simulated s, 6.4× faster than real time, solve 12.7 ms, "
        "suite 30 min. See [the page of 2026-11-27](docs/results/cosim.md) and [runs](x.md#run-3-s)."
    )
    assert dates(notebook) == ["2026-11-27"]
    assert set(timing_phrases(notebook)) >= {
        "wall s",
        "s per",
        "12.7 ms",
        "30 min",
        "× faster than real time",
    }
    assert not dates("[2026-11-27](docs/results/a.md)") and not timing_phrases(
        "[3 s](docs/x.md)"
    )


# --- package READMEs ------------------------------------------------------------------------------


def test_every_package_folder_has_a_readme() -> None:
    missing = [
        str(folder) for folder in package_folders() if readme_covering(folder) is None
    ]
    assert not missing, (
        f"package folders without a README (or a section in their parent's): {missing}"
    )


def test_a_folder_without_readme_or_section_is_found(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(__import__(__name__), "REPO", tmp_path)
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    (tmp_path / "pkg" / "README.md").write_text("# pkg\n\n## other\n")
    assert readme_covering(Path("pkg/sub")) is None
    (tmp_path / "pkg" / "README.md").write_text("# pkg\n\n## sub (crate `x`)\n")
    assert readme_covering(Path("pkg/sub")) == tmp_path / "pkg" / "README.md"


# --- links ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "page", documentation_pages(), ids=lambda p: str(p.relative_to(REPO))
)
def test_every_relative_link_resolves(page: Path) -> None:
    broken = broken_links(page)
    assert not broken, f"{page.relative_to(REPO)}: broken links {broken}"


def test_a_broken_link_or_anchor_is_found(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(__import__(__name__), "REPO", tmp_path)
    (tmp_path / "a.md").write_text("# Title\n\n## Use it (`x`)\n")
    page = tmp_path / "README.md"
    page.write_text(
        "[ok](a.md#use-it-x) [gone](b.md) [bad anchor](a.md#nothing) [web](https://example.com)\n```\n[in code](c.md)\n```\n"
    )
    assert broken_links(page) == [
        "b.md (no b.md)",
        "a.md#nothing (no heading with anchor #nothing)",
    ]


def test_github_slugs() -> None:
    assert (
        github_slug("Planner (`cargo bench -p pf-planner --bench pf`)")
        == "planner-cargo-bench--p-pf-planner---bench-pf"
    )
    assert (
        github_slug("November 2026, before the dated entries")
        == "november-2026-before-the-dated-entries"
    )
    assert anchors("# A\n## B\n## B\n```\n# not a heading\n```\n") == {"a", "b", "b-1"}


# --- results pages --------------------------------------------------------------------------------


def results_pages() -> list[Path]:
    return sorted((REPO / RESULTS_DIR).glob("*.md"))


@pytest.mark.parametrize("page", results_pages(), ids=lambda p: p.name)
def test_results_pages_are_generated_and_stamped(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    assert text.startswith("# ") and GENERATED_MARKER in text, (
        f"{page.name} was not written by pfnav_harness.results_page"
    )
    assert re.search(r"Generated by `[^`]+`", text), (
        f"{page.name} does not name the command that regenerates it"
    )
    assert "| commit | machine | date (UTC) |" in text and DATE.search(text), (
        f"{page.name} has no stamp"
    )
