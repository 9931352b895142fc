#!/usr/bin/env bash
# Regenerate or check photomat's golden references against a live Mitsuba 3 / Dr.Jit.
#
#   golden/run.sh check      recompute every reference from the committed inputs, compare with
#                            tolerances; exit 1 on drift (what CI runs)
#   golden/run.sh generate   rewrite golden/*.json from the fixed seed (review the diff!)
#
# Installs what it needs: a virtual environment in golden/.venv with the pinned wheels of
# golden/requirements.txt, and Debian's libllvm19 for Dr.Jit's LLVM backend (the LLVM 15 that
# Debian installs by default aborts Dr.Jit). Nothing is written outside golden/ except by apt.
#
# Exit codes: 0 ok; 1 golden drift (check) or generator assertion; 2 usage;
#             3 the golden check could not run (installation failed: registry down, no network,
#               no python3/venv, no apt/root) — never a silent pass.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$HERE/.venv"
MODE="${1:-}"

if [[ "$MODE" != "check" && "$MODE" != "generate" ]]; then
    echo "usage: golden/run.sh check|generate" >&2
    exit 2
fi

cannot_run() {
    {
        echo
        echo "##########################################################################"
        echo "##  GOLDEN CHECK COULD NOT RUN"
        echo "##  $1"
        echo "##  This is an installation failure outside the project (package registry"
        echo "##  or network down, missing system tool), not a golden drift. The goldens"
        echo "##  were NOT checked against Mitsuba. Fix the cause and rerun:"
        echo "##      golden/run.sh $MODE"
        echo "##########################################################################"
        echo
    } >&2
    exit 3
}

as_root() {
    if [[ "$(id -u)" == 0 ]]; then
        "$@"
    elif command -v sudo >/dev/null 2>&1; then
        sudo "$@"
    else
        return 1
    fi
}

find_libllvm19() {
    local candidate
    for candidate in /usr/lib/*/libLLVM.so.19.1 /usr/lib/*/libLLVM-19.so /usr/lib/llvm-19/lib/libLLVM.so.19.1; do
        if [[ -e "$candidate" ]]; then
            echo "$candidate"
            return 0
        fi
    done
    return 1
}

# --- libLLVM 19 for llvm_ad_rgb ------------------------------------------------------------------
if [[ -z "${DRJIT_LIBLLVM_PATH:-}" ]]; then
    if ! DRJIT_LIBLLVM_PATH="$(find_libllvm19)"; then
        echo "golden: installing libllvm19 (Dr.Jit's LLVM backend)"
        command -v apt-get >/dev/null 2>&1 || cannot_run "libLLVM 19 is missing and apt-get is not available (set DRJIT_LIBLLVM_PATH)."
        export DEBIAN_FRONTEND=noninteractive
        if ! as_root apt-get install -y -q libllvm19; then
            as_root apt-get update -q || cannot_run "apt-get update failed (Debian mirror unreachable?)."
            as_root apt-get install -y -q libllvm19 || cannot_run "apt-get install libllvm19 failed."
        fi
        DRJIT_LIBLLVM_PATH="$(find_libllvm19)" || cannot_run "libllvm19 installed but libLLVM.so.19 not found."
    fi
fi
export DRJIT_LIBLLVM_PATH
export DRJIT_CACHE_DIR="$HERE/.cache"
mkdir -p "$DRJIT_CACHE_DIR"

# --- Python environment ------------------------------------------------------------------------
PYTHON="${PYTHON:-python3}"
command -v "$PYTHON" >/dev/null 2>&1 || cannot_run "$PYTHON not found (Python ≥ 3.8 with venv is needed)."
STAMP="$VENV/.requirements.sha256"
WANT="$(sha256sum "$HERE/requirements.txt" | cut -d' ' -f1)"
if [[ ! -x "$VENV/bin/python" || ! -f "$STAMP" || "$(cat "$STAMP")" != "$WANT" ]] \
    || ! "$VENV/bin/python" -c "import mitsuba, drjit" >/dev/null 2>&1; then
    echo "golden: creating $VENV and installing $(grep -v '^#' "$HERE/requirements.txt" | xargs)"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV" || cannot_run "'$PYTHON -m venv' failed (install python3-venv)."
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -r "$HERE/requirements.txt" \
        || cannot_run "pip could not install golden/requirements.txt (PyPI unreachable?)."
    echo "$WANT" >"$STAMP"
fi

cd "$HERE"
exec "$VENV/bin/python" generate.py "$MODE"
