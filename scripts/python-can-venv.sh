#!/usr/bin/env bash
# Create a Python venv with python-can, msgpack, python-canopen and durand, the independent peers
# of the CAN-over-UDP interop tests (tests/system/can_udp_interop.rs, the CANopen interop tests, and
# tests/system/canopen_independent_node.rs with a CiA 402 node on durand):
#
#   scripts/python-can-venv.sh [VENV_DIR]     # default: $PYTHON_CAN_VENV or target/can-venv
#
# Pinned: python-can==4.6.1 and canopen==2.4.1 (the versions in shared notes canopen.md §3/§4),
# msgpack==1.2.4 (what python-can 4.6.1 resolved to there; python-can's udp_multicast needs it),
# durand==0.5.0 (pure-Python CiA 301 node stack; the version tests/python/durand_cia402_node.py
# was written and run against, notes peers.md).
# Idempotent: if VENV_DIR/bin/python already imports all three at these versions, it does
# nothing. All three are pure Python or have wheels, so no compiler is needed. python3-venv is
# installed with apt-get only when running as root; otherwise the script says what is missing.
# PyPI unreachable = failure (no silent skip).
#
# Environment: PYTHON (interpreter to base the venv on, default python3), PYTHON_CAN_VERSION,
# CANOPEN_VERSION, MSGPACK_VERSION, DURAND_VERSION (override the pins).
set -euo pipefail

cd "$(dirname "$0")/.."
VENV="${1:-${PYTHON_CAN_VENV:-target/can-venv}}"
PYTHON="${PYTHON:-python3}"
PYTHON_CAN_VERSION="${PYTHON_CAN_VERSION:-4.6.1}"
CANOPEN_VERSION="${CANOPEN_VERSION:-2.4.1}"
MSGPACK_VERSION="${MSGPACK_VERSION:-1.2.4}"
DURAND_VERSION="${DURAND_VERSION:-0.5.0}"

say() { echo "python-can-venv: $*" >&2; }

check_py='
import sys
from importlib.metadata import version
want = {"python-can": sys.argv[1], "canopen": sys.argv[2], "msgpack": sys.argv[3],
        "durand": sys.argv[4]}
import can, canopen, msgpack, durand  # noqa: F401  (importable, not only installed)
bad = {k: version(k) for k, v in want.items() if version(k) != v}
sys.exit(1 if bad else 0)
'
have_all() {
    [ -x "$VENV/bin/python" ] &&
        "$VENV/bin/python" -c "$check_py" "$PYTHON_CAN_VERSION" "$CANOPEN_VERSION" "$MSGPACK_VERSION" \
            "$DURAND_VERSION" >/dev/null 2>&1
}

# Several test binaries may call this at once: one installer at a time per venv.
mkdir -p "$(dirname "$VENV")"
if command -v flock >/dev/null; then
    exec 9>"$VENV.lock"
    flock -w 600 9 || { say "FAILED: another install into $VENV did not finish within 600 s"; exit 1; }
fi

if have_all; then
    say "$VENV already has python-can $PYTHON_CAN_VERSION, canopen $CANOPEN_VERSION, msgpack $MSGPACK_VERSION, durand $DURAND_VERSION"
    exit 0
fi

command -v "$PYTHON" >/dev/null || { say "FAILED: no $PYTHON (install python3)"; exit 1; }

if ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        say "apt-get install python3-venv"
        DEBIAN_FRONTEND=noninteractive apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends python3-venv
    else
        say "FAILED: $PYTHON lacks venv/ensurepip (install python3-venv)"
        exit 1
    fi
fi

if [ ! -x "$VENV/bin/python" ]; then
    say "creating venv $VENV with $("$PYTHON" --version 2>&1)"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
fi

PIP_LOG="$(mktemp)"
trap 'rm -f "$PIP_LOG"' EXIT
say "pip install python-can==$PYTHON_CAN_VERSION canopen==$CANOPEN_VERSION msgpack==$MSGPACK_VERSION durand==$DURAND_VERSION"
if ! "$VENV/bin/python" -m pip install --disable-pip-version-check --no-input -q \
    "python-can==$PYTHON_CAN_VERSION" "canopen==$CANOPEN_VERSION" "msgpack==$MSGPACK_VERSION" \
    "durand==$DURAND_VERSION" 2>&1 | tee "$PIP_LOG" >&2; then
    if grep -q 'from versions: none\|No matching distribution\|Failed to establish\|NewConnectionError\|ConnectTimeout\|Temporary failure in name resolution' "$PIP_LOG"; then
        say "FAILED: PyPI did not offer the pinned packages (registry unreachable?)"
    else
        say "FAILED: pip install failed"
    fi
    exit 1
fi

have_all || { say "FAILED: packages installed but not importable at the pinned versions from $VENV"; exit 1; }
say "ok: $("$VENV/bin/python" -c 'import can, canopen, msgpack; from importlib.metadata import version; print("python-can", can.__version__, "canopen", canopen.__version__, "msgpack", msgpack.version, "durand", version("durand"))')"
