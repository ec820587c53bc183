"""The shipped FMU binary is portable (issue 21): it needs no glibc newer than 2.28, carries no
debug info, and fmpy loads and steps it.

The binary is the one inside target/fmu/QuadController.fmu (PFNAV_FMU overrides), which
scripts/setup.sh bundles from scripts/build_fmu_portable.sh: linked by zig (cargo-zigbuild)
against glibc 2.17 symbol versions, `fmu-release` profile (stripped). The ELF is read here in
Python (section headers and the GNU version-needs table), so no binutils are required.
"""

from __future__ import annotations

import math
import struct
import zipfile
from pathlib import Path
from typing import NamedTuple

import pytest

MAX_GLIBC = (2, 28)
SO_MEMBER = "binaries/linux64/QuadController.so"
SHT_GNU_VERNEED = 0x6FFFFFFE


class Section(NamedTuple):
    name: str
    type: int
    offset: int
    size: int
    link: int
    info: int


def _sections(elf: bytes) -> list[Section]:
    assert elf[:4] == b"\x7fELF", "not an ELF file"
    assert elf[4] == 2 and elf[5] == 1, "expected a 64-bit little-endian ELF"
    (shoff,) = struct.unpack_from("<Q", elf, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", elf, 0x3A)
    raw = []
    for i in range(shnum):
        name, typ, _flags, _addr, offset, size, link, info = struct.unpack_from(
            "<IIQQQQII", elf, shoff + i * shentsize
        )
        raw.append((name, typ, offset, size, link, info))
    strtab_offset = raw[shstrndx][2]
    return [
        Section(_cstr(elf, strtab_offset + name), typ, offset, size, link, info)
        for name, typ, offset, size, link, info in raw
    ]


def _cstr(data: bytes, at: int) -> str:
    return data[at : data.index(b"\0", at)].decode()


def _needed_versions(elf: bytes) -> dict[str, set[str]]:
    """Symbol versions the binary needs, by library (the .gnu.version_r entries)."""
    sections = _sections(elf)
    needed: dict[str, set[str]] = {}
    for verneed in (s for s in sections if s.type == SHT_GNU_VERNEED):
        strtab = sections[verneed.link].offset
        at = verneed.offset
        for _ in range(verneed.info):
            _version, count, file, aux, next_entry = struct.unpack_from("<HHIII", elf, at)
            names = needed.setdefault(_cstr(elf, strtab + file), set())
            aux_at = at + aux
            for _ in range(count):
                _hash, _flags, _other, name, next_aux = struct.unpack_from("<IHHII", elf, aux_at)
                names.add(_cstr(elf, strtab + name))
                aux_at += next_aux
            at += next_entry
    return needed


def _glibc_version(name: str) -> tuple[int, ...] | None:
    if not name.startswith("GLIBC_") or not name[6:7].isdigit():
        return None  # GLIBC_PRIVATE and other non-numbered versions
    return tuple(int(part) for part in name[6:].split("."))


@pytest.fixture(scope="module")
def shared_library(fmu_file: Path) -> bytes:
    with zipfile.ZipFile(fmu_file) as archive:
        return archive.read(SO_MEMBER)


def test_needs_no_glibc_newer_than_2_28(shared_library: bytes) -> None:
    needed = _needed_versions(shared_library)
    versions = {
        version: name
        for names in needed.values()
        for name in names
        if (version := _glibc_version(name)) is not None
    }
    assert versions, f"no GLIBC symbol versions found (needs: {needed})"
    highest = max(versions)
    print(f"highest GLIBC version needed: {versions[highest]} (by library: {needed})")
    assert highest <= MAX_GLIBC, (
        f"{SO_MEMBER} needs {versions[highest]} > GLIBC_{'.'.join(map(str, MAX_GLIBC))}: "
        "bundle it with scripts/build_fmu_portable.sh"
    )


def test_has_no_debug_info(shared_library: bytes) -> None:
    names = [s.name for s in _sections(shared_library)]
    debug = [n for n in names if n.startswith((".debug", ".zdebug"))]
    print(f"{SO_MEMBER}: {len(shared_library) / 2**20:.2f} MiB, sections {names}")
    assert not debug, f"{SO_MEMBER} carries debug sections {debug}"
    assert ".symtab" not in names, f"{SO_MEMBER} is not stripped (has .symtab)"


def test_fmpy_loads_and_steps_it(fmu_file: Path) -> None:
    from fmpy import simulate_fmu

    result = simulate_fmu(
        str(fmu_file),
        stop_time=0.05,
        step_size=0.001,
        output_interval=0.001,
        output=["fsm.state", *(f"joint.tau[{i}]" for i in range(1, 13))],
    )
    assert len(result) >= 50
    assert result["time"][-1] == pytest.approx(0.05)
    for i in range(1, 13):
        assert all(math.isfinite(v) for v in result[f"joint.tau[{i}]"])
