#!/bin/sh
# The linker of x86_64 Linux builds in this workspace (.cargo/config.toml): the FMU's shared
# library (libquad_controller_fmu_binary.so) is linked by zig against glibc 2.17 symbol versions
# (through cargo-zigbuild's `zig cc`, which adapts rustc's arguments), so it loads on any x86_64
# Linux with glibc >= 2.17, and stripped, as an FMU ships no debug info. Every other link goes to
# cc unchanged. The zig tools are pinned in harness/pyproject.toml (extra `build`) and installed
# into .venv by scripts/setup.sh.
set -eu
fmu_library=0
previous=""
for arg in "$@"; do
    case "$arg" in
        @*)
            # rustc moves long argument lists into a response file, one argument per line.
            if grep -q 'libquad_controller_fmu_binary[^/]*\.so$' "${arg#@}" 2>/dev/null; then fmu_library=1; fi ;;
        *)
            if [ "$previous" = "-o" ]; then
                case "$(basename "$arg")" in libquad_controller_fmu_binary*.so) fmu_library=1 ;; esac
            fi ;;
    esac
    previous="$arg"
done
if [ "$fmu_library" = 0 ]; then
    exec "${PFNAV_HOST_LINKER:-cc}" "$@"
fi
root="$(cd "$(dirname "$0")/../.." && pwd)"
zigbuild="$root/.venv/bin/cargo-zigbuild"
if [ ! -x "$zigbuild" ]; then
    echo "fmu/binary/link-gcc.sh: the FMU's shared library is linked by zig for glibc 2.17, and $zigbuild is missing: run scripts/setup.sh first" >&2
    exit 1
fi
# cargo-zigbuild runs zig as `python3 -m ziglang` when no `zig` is on PATH: the venv's python.
PATH="$root/.venv/bin:$PATH" exec "$zigbuild" zig cc -- -g -fno-sanitize=all -target x86_64-linux-gnu.2.17 -s "$@"
