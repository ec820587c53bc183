"""The FMU's binaries for each FMI 2.0 platform it carries: linux64 always, win64 and darwin64
when bundled by `scripts/build_fmu_portable.sh --all-platforms` (or PFNAV_FMU_ALL_PLATFORMS=1).

Each binary must export every fmi2 function its modelDescription's interface type needs and link
only libraries every system of its platform has. The ELF dynamic section, the PE export and
import tables and the Mach-O load commands and export trie are read here in Python, so no binutils
or macOS tools are needed. Loading is only tried for linux64 (test_fmu_portable.py): the Windows
and macOS binaries have never been loaded on those systems by these tests.

Set PFNAV_FMU_ALL_PLATFORMS=1 to make a missing win64 or darwin64 binary a failure, not a skip.
"""

from __future__ import annotations

import os
import struct
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

import pytest

MODEL_IDENTIFIER = "QuadController"
MEMBERS = {
    "linux64": f"binaries/linux64/{MODEL_IDENTIFIER}.so",
    "win64": f"binaries/win64/{MODEL_IDENTIFIER}.dll",
    "darwin64": f"binaries/darwin64/{MODEL_IDENTIFIER}.dylib",
}

# FMI 2.0.x standard, section 2.1 (common), 3.2 (Model Exchange), 4.2 (Co-Simulation).
COMMON_FUNCTIONS = frozenset(
    (
        "fmi2GetTypesPlatform",
        "fmi2GetVersion",
        "fmi2SetDebugLogging",
        "fmi2Instantiate",
        "fmi2FreeInstance",
        "fmi2SetupExperiment",
        "fmi2EnterInitializationMode",
        "fmi2ExitInitializationMode",
        "fmi2Terminate",
        "fmi2Reset",
        "fmi2GetReal",
        "fmi2GetInteger",
        "fmi2GetBoolean",
        "fmi2GetString",
        "fmi2SetReal",
        "fmi2SetInteger",
        "fmi2SetBoolean",
        "fmi2SetString",
        "fmi2GetFMUstate",
        "fmi2SetFMUstate",
        "fmi2FreeFMUstate",
        "fmi2SerializedFMUstateSize",
        "fmi2SerializeFMUstate",
        "fmi2DeSerializeFMUstate",
        "fmi2GetDirectionalDerivative",
    )
)
CO_SIMULATION_FUNCTIONS = frozenset(
    (
        "fmi2SetRealInputDerivatives",
        "fmi2GetRealOutputDerivatives",
        "fmi2DoStep",
        "fmi2CancelStep",
        "fmi2GetStatus",
        "fmi2GetRealStatus",
        "fmi2GetIntegerStatus",
        "fmi2GetBooleanStatus",
        "fmi2GetStringStatus",
    )
)
MODEL_EXCHANGE_FUNCTIONS = frozenset(
    (
        "fmi2EnterEventMode",
        "fmi2NewDiscreteStates",
        "fmi2EnterContinuousTimeMode",
        "fmi2CompletedIntegratorStep",
        "fmi2SetTime",
        "fmi2SetContinuousStates",
        "fmi2GetDerivatives",
        "fmi2GetEventIndicators",
        "fmi2GetContinuousStates",
        "fmi2GetNominalsOfContinuousStates",
    )
)

# What the binaries may link (case-insensitive for Windows). Found: linux64 needs libc, libm,
# libpthread, libdl and the loader; win64 KERNEL32, ntdll, USERENV, WS2_32, bcryptprimitives and
# the Universal CRT's api-ms-win-crt-* / api-ms-win-core-* API sets (Windows 10 has them all);
# darwin64 only libSystem.
LINUX_ALLOWED = frozenset(
    {
        "libc.so.6",
        "libm.so.6",
        "libpthread.so.0",
        "libdl.so.2",
        "librt.so.1",
        "ld-linux-x86-64.so.2",
        "libgcc_s.so.1",
    }
)
WINDOWS_ALLOWED = frozenset(
    {
        "kernel32.dll",
        "ntdll.dll",
        "userenv.dll",
        "ws2_32.dll",
        "bcrypt.dll",
        "bcryptprimitives.dll",
        "advapi32.dll",
        "msvcrt.dll",
        "ucrtbase.dll",
    }
)
WINDOWS_API_SET_PREFIXES = ("api-ms-win-crt-", "api-ms-win-core-")
DARWIN_ALLOWED = frozenset({"/usr/lib/libSystem.B.dylib"})
# Rust's oldest supported macOS for x86_64-apple-darwin (scripts/build_fmu_portable.sh).
MACOS_MINIMUM = (10, 12, 0)


@dataclass
class BinaryInfo:
    """What a platform's loader sees of one binary."""

    exports: set[str] = field(default_factory=set)
    needed: list[str] = field(default_factory=list)
    sections: list[str] = field(default_factory=list)
    notes: dict[str, str] = field(default_factory=dict)


def _cstr(data: bytes, at: int) -> str:
    return data[at : data.index(b"\0", at)].decode()


# --- ELF (linux64) -------------------------------------------------------------------------------

SHT_DYNSYM = 11
SHT_DYNAMIC = 6
DT_NEEDED = 1


def read_elf(elf: bytes) -> BinaryInfo:
    assert elf[:4] == b"\x7fELF" and elf[4] == 2 and elf[5] == 1, "not a 64-bit LE ELF"
    (shoff,) = struct.unpack_from("<Q", elf, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", elf, 0x3A)
    headers = [
        struct.unpack_from("<IIQQQQIIQQ", elf, shoff + i * shentsize)
        for i in range(shnum)
    ]
    names_at = headers[shstrndx][4]
    info = BinaryInfo(sections=[_cstr(elf, names_at + h[0]) for h in headers])
    for (
        _name,
        typ,
        _flags,
        _addr,
        offset,
        size,
        link,
        _info,
        _align,
        entsize,
    ) in headers:
        strtab = headers[link][4]
        if typ == SHT_DYNSYM:
            for at in range(offset, offset + size, entsize):
                name, st_info, _other, shndx = struct.unpack_from("<IBBH", elf, at)
                binding, kind = st_info >> 4, st_info & 0xF
                if (
                    shndx != 0 and binding in (1, 2) and kind == 2
                ):  # defined GLOBAL/WEAK FUNC
                    info.exports.add(_cstr(elf, strtab + name))
        elif typ == SHT_DYNAMIC:
            for at in range(offset, offset + size, entsize):
                tag, value = struct.unpack_from("<qQ", elf, at)
                if tag == DT_NEEDED:
                    info.needed.append(_cstr(elf, strtab + value))
    return info


# --- PE (win64) ----------------------------------------------------------------------------------


def read_pe(pe: bytes) -> BinaryInfo:
    assert pe[:2] == b"MZ", "not a PE file"
    (header,) = struct.unpack_from("<I", pe, 0x3C)
    assert pe[header : header + 4] == b"PE\0\0", "no PE signature"
    machine, nsections, _time, _symtab, _nsyms, optional_size, characteristics = (
        struct.unpack_from("<HHIIIHH", pe, header + 4)
    )
    assert machine == 0x8664, f"machine {machine:#x} is not x86-64"
    assert characteristics & 0x2000, "not a DLL"
    optional = header + 24
    (magic,) = struct.unpack_from("<H", pe, optional)
    assert magic == 0x20B, "not PE32+"
    major_os, minor_os = struct.unpack_from("<HH", pe, optional + 40)
    major_sub, minor_sub = struct.unpack_from("<HH", pe, optional + 48)
    (ndirs,) = struct.unpack_from("<I", pe, optional + 108)
    dirs = [struct.unpack_from("<II", pe, optional + 112 + 8 * i) for i in range(ndirs)]
    sections = []
    at = optional + optional_size
    for i in range(nsections):
        name, vsize, vaddr, raw_size, raw_at = struct.unpack_from(
            "<8sIIII", pe, at + 40 * i
        )
        sections.append(
            (name.rstrip(b"\0").decode(), vaddr, max(vsize, raw_size), raw_at)
        )

    def offset(rva: int) -> int:
        for _name, vaddr, size, raw_at in sections:
            if vaddr <= rva < vaddr + size:
                return rva - vaddr + raw_at
        raise AssertionError(f"RVA {rva:#x} is in no section")

    info = BinaryInfo(
        sections=[s[0] for s in sections],
        notes={
            "OS version": f"{major_os}.{minor_os}",
            "subsystem": f"{major_sub}.{minor_sub}",
        },
    )
    export_rva, export_size = dirs[0]
    if export_size:
        nnames, _functions_rva, names_rva = struct.unpack_from(
            "<III", pe, offset(export_rva) + 24
        )
        names_at = offset(names_rva)
        for i in range(nnames):
            (name_rva,) = struct.unpack_from("<I", pe, names_at + 4 * i)
            info.exports.add(_cstr(pe, offset(name_rva)))
    # Import (1) and delay-load import (13) descriptors: 20 and 32 bytes, the DLL name's RVA at
    # offset 12 and 4, a zero entry ends each table.
    for index, entry_size, name_field in ((1, 20, 12), (13, 32, 4)):
        if index >= ndirs or not dirs[index][1]:
            continue
        at = offset(dirs[index][0])
        while any(pe[at : at + entry_size]):
            (name_rva,) = struct.unpack_from("<I", pe, at + name_field)
            info.needed.append(_cstr(pe, offset(name_rva)))
            at += entry_size
    return info


# --- Mach-O (darwin64) ---------------------------------------------------------------------------

LC_SYMTAB = 0x2
LC_LOAD_DYLIB = 0xC
LC_ID_DYLIB = 0xD
LC_LOAD_WEAK_DYLIB = 0x80000018
LC_REEXPORT_DYLIB = 0x8000001F
LC_LAZY_LOAD_DYLIB = 0x20
LC_LOAD_UPWARD_DYLIB = 0x80000023
LC_DYLD_INFO = 0x22
LC_DYLD_INFO_ONLY = 0x80000022
LC_DYLD_EXPORTS_TRIE = 0x80000033
LC_BUILD_VERSION = 0x32
LC_VERSION_MIN_MACOSX = 0x24
DYLIB_COMMANDS = {
    LC_LOAD_DYLIB,
    LC_LOAD_WEAK_DYLIB,
    LC_REEXPORT_DYLIB,
    LC_LAZY_LOAD_DYLIB,
    LC_LOAD_UPWARD_DYLIB,
}


def _uleb128(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[at]
        at += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, at


def _export_trie(data: bytes, start: int, size: int) -> set[str]:
    """The names in a dyld export trie (terminal nodes), iteratively with a visited set."""
    names: set[str] = set()
    stack = [(0, b"")]
    seen: set[int] = set()
    while stack:
        node, prefix = stack.pop()
        assert node < size and node not in seen, "malformed export trie"
        seen.add(node)
        terminal_size, at = _uleb128(data, start + node)
        if terminal_size:
            names.add(prefix.decode())
        at += terminal_size
        children = data[at]
        at += 1
        for _ in range(children):
            end = data.index(b"\0", at)
            label = data[at:end]
            child, at = _uleb128(data, end + 1)
            stack.append((child, prefix + label))
    return names


def _version(packed: int) -> str:
    return f"{packed >> 16}.{(packed >> 8) & 0xFF}.{packed & 0xFF}"


def read_macho(macho: bytes) -> BinaryInfo:
    magic, cputype, _sub, filetype, ncmds, _sizeofcmds, _flags = struct.unpack_from(
        "<IiIIIII", macho, 0
    )
    assert magic == 0xFEEDFACF, "not a 64-bit little-endian Mach-O"
    assert cputype == 0x01000007, f"cpu type {cputype:#x} is not x86-64"
    assert filetype == 6, f"file type {filetype} is not MH_DYLIB"
    info = BinaryInfo()
    symtab_exports: set[str] = set()
    at = 32
    for _ in range(ncmds):
        cmd, cmdsize = struct.unpack_from("<II", macho, at)
        if cmd in DYLIB_COMMANDS or cmd == LC_ID_DYLIB:
            (name_at,) = struct.unpack_from("<I", macho, at + 8)
            name = _cstr(macho, at + name_at)
            if cmd == LC_ID_DYLIB:
                info.notes["install name"] = name
            else:
                info.needed.append(name)
        elif cmd in (LC_DYLD_INFO, LC_DYLD_INFO_ONLY):
            export_off, export_size = struct.unpack_from("<II", macho, at + 40)
            if export_size:
                info.exports |= _export_trie(macho, export_off, export_size)
        elif cmd == LC_DYLD_EXPORTS_TRIE:
            export_off, export_size = struct.unpack_from("<II", macho, at + 8)
            info.exports |= _export_trie(macho, export_off, export_size)
        elif cmd == LC_SYMTAB:
            symoff, nsyms, stroff, _strsize = struct.unpack_from("<IIII", macho, at + 8)
            for i in range(nsyms):
                strx, n_type, _sect, _desc, _value = struct.unpack_from(
                    "<IBBHQ", macho, symoff + 16 * i
                )
                if (
                    n_type & 0x01 and n_type & 0x0E == 0x0E
                ):  # N_EXT, defined in a section
                    symtab_exports.add(_cstr(macho, stroff + strx))
        elif cmd == LC_BUILD_VERSION:
            _platform, minos, sdk = struct.unpack_from("<III", macho, at + 8)
            info.notes["minimum macOS"] = _version(minos)
            info.notes["SDK"] = _version(sdk)
        elif cmd == LC_VERSION_MIN_MACOSX:
            minos, sdk = struct.unpack_from("<II", macho, at + 8)
            info.notes["minimum macOS"] = _version(minos)
            info.notes["SDK"] = _version(sdk)
        at += cmdsize
    info.notes["symtab externals"] = str(len(symtab_exports))
    # C names carry a leading underscore in Mach-O.
    info.exports = {name.removeprefix("_") for name in info.exports}
    return info


READERS = {"linux64": read_elf, "win64": read_pe, "darwin64": read_macho}


# --- tests ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def archive(fmu_file: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(fmu_file) as fmu:
        names = set(fmu.namelist())
        contents = {
            name: fmu.read(name) for name in names if name.startswith("binaries/")
        }
        contents["modelDescription.xml"] = fmu.read("modelDescription.xml")
    return contents


@pytest.fixture(scope="module")
def required_functions(archive: dict[str, bytes]) -> frozenset[str]:
    root = ElementTree.fromstring(archive["modelDescription.xml"])
    required: frozenset[str] = frozenset()
    for element, functions in (
        ("CoSimulation", CO_SIMULATION_FUNCTIONS),
        ("ModelExchange", MODEL_EXCHANGE_FUNCTIONS),
    ):
        interface = root.find(element)
        if interface is not None:
            assert interface.get("modelIdentifier") == MODEL_IDENTIFIER
            required |= COMMON_FUNCTIONS | functions
    assert required, (
        "modelDescription.xml declares neither CoSimulation nor ModelExchange"
    )
    return required


def binary_info(archive: dict[str, bytes], platform: str) -> BinaryInfo:
    member = MEMBERS[platform]
    if member not in archive:
        message = (
            f"{member} is not in the FMU: bundle it with "
            "`bash scripts/build_fmu_portable.sh --all-platforms`"
        )
        if os.environ.get("PFNAV_FMU_ALL_PLATFORMS") == "1":
            pytest.fail(message)
        pytest.skip(message)
    return READERS[platform](archive[member])


def test_only_known_platforms_with_fmi_file_names(archive: dict[str, bytes]) -> None:
    binaries = sorted(name for name in archive if name.startswith("binaries/"))
    print(f"binaries in the FMU: {binaries}")
    assert MEMBERS["linux64"] in binaries
    assert set(binaries) <= set(MEMBERS.values()), binaries


@pytest.mark.parametrize("platform", list(MEMBERS))
def test_exports_every_fmi2_function(
    archive: dict[str, bytes], required_functions: frozenset[str], platform: str
) -> None:
    info = binary_info(archive, platform)
    fmi2 = {name for name in info.exports if name.startswith("fmi2")}
    print(
        f"{platform}: {len(info.exports)} exported names, {len(fmi2)} fmi2 functions; {info.notes}"
    )
    missing = required_functions - info.exports
    assert not missing, f"{platform} lacks {sorted(missing)}"
    assert (
        fmi2 <= COMMON_FUNCTIONS | CO_SIMULATION_FUNCTIONS | MODEL_EXCHANGE_FUNCTIONS
    ), sorted(
        fmi2 - COMMON_FUNCTIONS - CO_SIMULATION_FUNCTIONS - MODEL_EXCHANGE_FUNCTIONS
    )


def _unexpected_libraries(platform: str, needed: list[str]) -> list[str]:
    if platform == "linux64":
        return [lib for lib in needed if lib not in LINUX_ALLOWED]
    if platform == "win64":
        return [
            lib
            for lib in needed
            if lib.lower() not in WINDOWS_ALLOWED
            and not lib.lower().startswith(WINDOWS_API_SET_PREFIXES)
        ]
    return [lib for lib in needed if lib not in DARWIN_ALLOWED]


@pytest.mark.parametrize("platform", list(MEMBERS))
def test_links_only_system_libraries(archive: dict[str, bytes], platform: str) -> None:
    info = binary_info(archive, platform)
    print(f"{platform} links {info.needed}")
    assert info.needed, f"{platform}: no libraries found (reader broken?)"
    unexpected = _unexpected_libraries(platform, info.needed)
    assert not unexpected, (
        f"{platform} links libraries outside the allowlist: {unexpected}"
    )


def test_the_windows_dll_is_stripped(archive: dict[str, bytes]) -> None:
    info = binary_info(archive, "win64")
    print(f"win64 sections {info.sections}; {info.notes}")
    # GNU linkers name DWARF sections `.debug_*`, or `/N` (a string-table offset) when longer.
    debug = [s for s in info.sections if s.startswith((".debug", "/"))]
    assert not debug, f"the DLL carries debug sections {debug}"


def test_the_macos_dylib_loads_on_old_macos_and_is_relocatable(
    archive: dict[str, bytes],
) -> None:
    info = binary_info(archive, "darwin64")
    print(f"darwin64: {info.notes}")
    # dyld refuses a library whose minimum is newer than the running macOS; zig's default is the
    # newest it knows (15.0 with ziglang 0.17), so the build sets MACOSX_DEPLOYMENT_TARGET.
    minimum = tuple(int(part) for part in info.notes["minimum macOS"].split("."))
    assert minimum <= MACOS_MINIMUM, f"needs macOS {info.notes['minimum macOS']}"
    # An absolute build-machine path as install name would leak into importers linking it.
    assert info.notes.get("install name", "").startswith("@rpath/"), info.notes
