#!/usr/bin/env bash
# Create a Python venv with pysoem (Cython wrapper around SOEM, an independent EtherCAT master) for the
# interop test `tests/system/pysoem_interop.rs`.
#
#   scripts/pysoem-venv.sh [VENV_DIR]        # default: $PYSOEM_VENV or target/pysoem-venv
#
# Idempotent: if VENV_DIR/bin/python already imports pysoem at the pinned version, it does nothing.
# pysoem is pinned to 1.1.13 (the version the emulator was first cross-checked with, shared notes
# ethercat.md §0). pip uses a binary wheel where PyPI has one for this Python; otherwise it compiles SOEM
# from the sdist, which needs a C compiler, the Python headers and (for some versions) cmake. Missing Debian
# packages (python3-venv, python3-dev, build-essential, cmake) are installed with apt-get only when running as
# root (build tools only after a failed build); otherwise the script says what is missing and fails.
# PyPI unreachable = failure (no silent skip).
#
# Environment: PYTHON (interpreter to base the venv on, default python3), PYSOEM_VERSION (default 1.1.13).
set -euo pipefail

cd "$(dirname "$0")/.."
VENV="${1:-${PYSOEM_VENV:-target/pysoem-venv}}"
PYTHON="${PYTHON:-python3}"
PYSOEM_VERSION="${PYSOEM_VERSION:-1.1.13}"

say() { echo "pysoem-venv: $*" >&2; }

have_pysoem() {
    [ -x "$VENV/bin/python" ] &&
        "$VENV/bin/python" -c "import pysoem, sys; sys.exit(0 if pysoem.__version__ == '$PYSOEM_VERSION' else 1)" \
            >/dev/null 2>&1
}

APT_UPDATED=0
apt_install() {
    # Install Debian packages (only the ones not installed yet), as root only.
    local missing=()
    for p in "$@"; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
        say "missing Debian packages: ${missing[*]} (not root or no apt-get: install them yourself)"
        return 1
    fi
    if [ "$APT_UPDATED" = 0 ]; then
        say "apt-get update"
        DEBIAN_FRONTEND=noninteractive apt-get update -qq
        APT_UPDATED=1
    fi
    say "apt-get install ${missing[*]}"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

if have_pysoem; then
    say "$VENV already has pysoem $PYSOEM_VERSION, nothing to do"
    exit 0
fi

command -v "$PYTHON" >/dev/null || { say "installing python3"; apt_install python3; }

if ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
    say "$PYTHON lacks venv/ensurepip"
    apt_install python3-venv
fi

if [ ! -x "$VENV/bin/python" ]; then
    say "creating venv $VENV with $("$PYTHON" --version 2>&1)"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
fi

PIP_LOG="$(mktemp)"
trap 'rm -f "$PIP_LOG"' EXIT
pip_install() {
    "$VENV/bin/python" -m pip install --disable-pip-version-check --no-input -q "pysoem==$PYSOEM_VERSION" \
        2>&1 | tee "$PIP_LOG" >&2
    return "${PIPESTATUS[0]}"
}

say "pip install pysoem==$PYSOEM_VERSION"
if ! pip_install; then
    if grep -q 'from versions: none\|No matching distribution\|Failed to establish\|NewConnectionError\|ConnectTimeout' "$PIP_LOG"; then
        say "FAILED: PyPI did not offer pysoem==$PYSOEM_VERSION (registry unreachable?)"
        exit 1
    fi
    # No wheel for this Python and the SOEM build from the sdist failed: make sure the build
    # tools are there, then try once more.
    say "pip install failed; checking the build dependencies for compiling SOEM from the sdist"
    include="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
    need=()
    command -v cc >/dev/null || need+=(build-essential)
    command -v cmake >/dev/null || need+=(cmake)
    [ -f "$include/Python.h" ] || need+=(python3-dev)
    if [ ${#need[@]} -gt 0 ]; then
        apt_install "${need[@]}"
    fi
    say "pip install pysoem==$PYSOEM_VERSION (second try)"
    pip_install || { say "FAILED: pip could not build/install pysoem==$PYSOEM_VERSION"; exit 1; }
fi

have_pysoem || { say "FAILED: pysoem installed but not importable from $VENV"; exit 1; }
say "ok: $("$VENV/bin/python" -c 'import pysoem; print("pysoem", pysoem.__version__, pysoem.__file__)')"
