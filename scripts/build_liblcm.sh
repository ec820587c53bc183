#!/usr/bin/env bash
# Builds LCM 1.3.1 (Debian's source, sha256-pinned) with third_party/lcm/fix-receive-bounds.patch:
# the receive-path bounds checks of the UDP multicast providers (see docs/liblcm-fix.md).
# Produces, under build/lcm/ (idempotent, keyed on the patch and this script):
#   lib/liblcm.a                   linked statically by the Rust transport (lcm_types/transport/build.rs)
#   lib/liblcm.so.1 (+ liblcm.so)  for lcm-logger and lcm-logplayer below
#   include/lcm/*.h
#   bin/lcm-logger, bin/lcm-logplayer  linked to lib/liblcm.so.1 (rpath)
#   python/lcm/                    the Python `lcm` module, installed into .venv by setup.sh
# Usage: scripts/build_liblcm.sh PYTHON
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PYTHON="${1:?usage: build_liblcm.sh PYTHON}"
OUT="$ROOT/build/lcm"
PATCH="$ROOT/third_party/lcm/fix-receive-bounds.patch"
# Py_TYPE() is no longer an lvalue since Python 3.10: Py_SET_TYPE in the module init.
PY_PATCH="$ROOT/third_party/lcm/python3-compat.patch"
# Debian's source package, fetched with apt from bookworm's deb-src index (private source list and
# index directory under build/, so the system's apt configuration is not touched). apt checks the
# tarball against the signed index; the pin below is the value of Debian's .dsc as well.
SOURCE_PACKAGE="lcm=1.3.1+repack1-3"
TARBALL_NAME="lcm_1.3.1+repack1.orig.tar.gz"
SHA256="abf293e54aff3d073cb4f9d4d5a261eab0e5ffea02e13fd601715c11612b85e8"
stamp="$OUT/.stamp"
want="$(cat "$PATCH" "$PY_PATCH" "${BASH_SOURCE[0]}" | sha256sum | cut -d' ' -f1) $("$PYTHON" -c 'import sys; print(sys.version_info[:2])')"
if [[ "$(cat "$stamp" 2>/dev/null)" == "$want" && -f "$OUT/lib/liblcm.a" ]]; then
    exit 0
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
tarball="$ROOT/build/lcm-src/$TARBALL_NAME"
if [[ ! -f "$tarball" ]] || ! echo "$SHA256  $tarball" | sha256sum -c --quiet - 2>/dev/null; then
    apt_dir="$ROOT/build/lcm-src/apt"
    mkdir -p "$apt_dir/lists/partial"
    echo "deb-src [signed-by=/usr/share/keyrings/debian-archive-keyring.gpg] http://deb.debian.org/debian bookworm main" \
        > "$apt_dir/sources.list"
    apt_opts=(-q -o Dir::Etc::SourceList="$apt_dir/sources.list" -o Dir::Etc::SourceParts=/nonexistent
              -o Dir::State::Lists="$apt_dir/lists" -o APT::Sandbox::User=root)
    apt-get "${apt_opts[@]}" update >/dev/null
    # The Debian packaging tarball of this revision is gone from the archive (404): apt then
    # reports an error after fetching the .dsc and the upstream tarball, which is all we use.
    (cd "$ROOT/build/lcm-src" && apt-get "${apt_opts[@]}" source --download-only "$SOURCE_PACKAGE" \
        >/dev/null 2>&1) || true
fi
echo "$SHA256  $tarball" | sha256sum -c --quiet - || {
    echo "build_liblcm.sh: $tarball is missing or its SHA-256 is not $SHA256" >&2
    rm -f "$tarball"
    exit 1
}
tar -xzf "$tarball" -C "$work"
src="$work/lcm-1.3.1"
patch -d "$src" -p1 --quiet < "$PATCH"
patch -d "$src" -p1 --quiet < "$PY_PATCH"

# Built beside the old output and swapped in at the end: a build running meanwhile never sees
# a half-written build/lcm.
FINAL="$OUT"
OUT="$ROOT/build/lcm.new"
rm -rf "$OUT"
mkdir -p "$OUT/lib" "$OUT/bin" "$OUT/include/lcm" "$OUT/python/lcm"
LCM_SOURCES=(lcm.c lcm_udpm.c lcm_file.c lcm_memq.c lcm_mpudpm.c lcm_tcpq.c ringbuffer.c
             udpm_util.c eventlog.c lcmtypes/channel_to_port_t.c
             lcmtypes/channel_port_map_update_t.c)
read -r -a GLIB <<< "$(pkg-config --cflags --libs glib-2.0 gthread-2.0)"
CFLAGS=(-O2 -g0 -fPIC -fstack-protector-strong -D_FORTIFY_SOURCE=2 -std=gnu99 -w -I"$src")
(
    cd "$src/lcm"
    gcc "${CFLAGS[@]}" -shared -Wl,-soname,liblcm.so.1 -o "$OUT/lib/liblcm.so.1" \
        "${LCM_SOURCES[@]}" "${GLIB[@]}"
)
ln -s liblcm.so.1 "$OUT/lib/liblcm.so"
# The static archive is what the Rust transport links: no loader search path can swap it for
# the system's unpatched library.
(
    mkdir -p "$work/obj"
    cd "$src/lcm"
    for source in "${LCM_SOURCES[@]}"; do
        gcc "${CFLAGS[@]}" $(pkg-config --cflags glib-2.0) -c "$source" \
            -o "$work/obj/$(basename "${source%.c}").o"
    done
    ar rcs "$OUT/lib/liblcm.a" "$work"/obj/*.o
)
cp "$src"/lcm/{lcm.h,eventlog.h,lcm_coretypes.h} "$OUT/include/lcm/"
(
    cd "$src/lcm-logger"
    link=(-L"$OUT/lib" -llcm -Wl,-rpath,'$ORIGIN/../lib' "${GLIB[@]}")
    gcc "${CFLAGS[@]}" -o "$OUT/bin/lcm-logger" lcm_logger.c glib_util.c "${link[@]}"
    gcc "${CFLAGS[@]}" -o "$OUT/bin/lcm-logplayer" lcm_logplayer.c "${link[@]}"
)

# The Python module: the same patched sources compiled into the extension (as upstream's
# setup.py does), so no Python process uses an unpatched receive path either.
py_include="$("$PYTHON" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
ext_suffix="$("$PYTHON" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')"
(
    cd "$src/lcm-python"
    gcc "${CFLAGS[@]}" -shared -I"$py_include" -o "$OUT/python/lcm/_lcm$ext_suffix" \
        module.c pyeventlog.c pylcm.c pylcm_subscription.c \
        "${LCM_SOURCES[@]/#/../lcm/}" "${GLIB[@]}"
)
cp "$src/lcm-python/lcm/__init__.py" "$OUT/python/lcm/"
echo "$want" > "$OUT/.stamp"
rm -rf "$FINAL.old"
if [[ -d "$FINAL" ]]; then mv "$FINAL" "$FINAL.old"; fi
mv "$OUT" "$FINAL"
rm -rf "$FINAL.old"
