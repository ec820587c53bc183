#!/usr/bin/env bash
# Generates the Python LCM types (package `pfnav`) from lcm_types/*.lcm into build/lcm_python.
# The generated code is never committed (build/ is gitignored) and never edited by hand.
# lcm-gen: $LCM_GEN if set (setup.sh passes lcm-gen 1.5.3 from the PyPI wheel, whose Python
# classes carry the __typenames__/__dimensions__ metadata the tests use), else the venv's, else
# the one on PATH.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
if [[ -z "${LCM_GEN:-}" ]]; then
    if [[ -x "$ROOT/.venv/bin/lcm-gen" ]]; then
        LCM_GEN="$ROOT/.venv/bin/lcm-gen"
    else
        LCM_GEN="$(command -v lcm-gen || true)"
    fi
fi
if [[ -z "$LCM_GEN" ]]; then
    echo "gen_python.sh: lcm-gen not found (install the venv or liblcm-bin)" >&2
    exit 1
fi
# A stale module of a removed type must not survive: regenerate from scratch.
rm -rf build/lcm_python/pfnav
mkdir -p build/lcm_python
"$LCM_GEN" --python --ppath build/lcm_python lcm_types/*.lcm
echo "gen_python.sh: generated $(ls build/lcm_python/pfnav/*_t.py | wc -l) types into build/lcm_python/pfnav"
