#!/usr/bin/env bash
# Create a Python venv with the independent EtherCAT masters of `tests/system/independent_masters.rs`,
# installed from PyPI:
#   * kickcat 2.5 — Python bindings of KickCAT, a C++ EtherCAT master (binary wheels);
#   * ebpfcat 1.0.0 — a pure-Python EtherCAT master whose fast process-data path is an XDP/eBPF
#     program (pure Python; the eBPF part needs the bpf() system call, see the test);
#   * pysoem 1.1.13 — Cython bindings of SOEM (as scripts/pysoem-venv.sh; binary wheels).
#
#   scripts/masters-venv.sh [VENV_DIR]        # default: $MASTERS_VENV or target/masters-venv
#
# Idempotent: if VENV_DIR/bin/python already imports both at the pinned versions, it does nothing.
# PyPI unreachable = failure (no silent skip); python3-venv is installed with apt-get only when
# running as root, as scripts/pysoem-venv.sh does.
#
# Environment: PYTHON (interpreter to base the venv on, default python3), KICKCAT_VERSION (2.5),
# EBPFCAT_VERSION (1.0.0), PYSOEM_VERSION (1.1.13).
set -euo pipefail

cd "$(dirname "$0")/.."
VENV="${1:-${MASTERS_VENV:-target/masters-venv}}"
PYTHON="${PYTHON:-python3}"
KICKCAT_VERSION="${KICKCAT_VERSION:-2.5}"
EBPFCAT_VERSION="${EBPFCAT_VERSION:-1.0.0}"
PYSOEM_VERSION="${PYSOEM_VERSION:-1.1.13}"

say() { echo "masters-venv: $*" >&2; }

have_all() {
    [ -x "$VENV/bin/python" ] &&
        "$VENV/bin/python" - "$KICKCAT_VERSION" "$EBPFCAT_VERSION" "$PYSOEM_VERSION" >/dev/null 2>&1 <<'PY'
import sys
from importlib.metadata import version
import kickcat, ebpfcat.ethercat, pysoem  # noqa: F401  (importable, not only installed)
want = tuple(sys.argv[1:4])
sys.exit(0 if (version("kickcat"), version("ebpfcat"), version("pysoem")) == want else 1)
PY
}

if have_all; then
    say "$VENV already has kickcat $KICKCAT_VERSION, ebpfcat $EBPFCAT_VERSION, pysoem $PYSOEM_VERSION"
    exit 0
fi

if ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
    say "$PYTHON lacks venv/ensurepip"
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        DEBIAN_FRONTEND=noninteractive apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends python3-venv
    else
        say "install python3-venv yourself (not root or no apt-get)"
        exit 1
    fi
fi

if [ ! -x "$VENV/bin/python" ]; then
    say "creating venv $VENV with $("$PYTHON" --version 2>&1)"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
fi

PKGS=("kickcat==$KICKCAT_VERSION" "ebpfcat==$EBPFCAT_VERSION" "pysoem==$PYSOEM_VERSION")
say "pip install ${PKGS[*]}"
"$VENV/bin/python" -m pip install --disable-pip-version-check --no-input -q "${PKGS[@]}" >&2 ||
    { say "FAILED: pip could not install ${PKGS[*]} (PyPI unreachable, or no wheel and no compiler)"; exit 1; }

have_all || { say "FAILED: installed but not importable from $VENV"; exit 1; }
say "ok: $("$VENV/bin/python" -c 'from importlib.metadata import version as v; print(*(f"{p} {v(p)}" for p in ("kickcat", "ebpfcat", "pysoem")))')"
