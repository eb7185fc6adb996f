#!/usr/bin/env bash
# Install skyfit-mi into ./.venv, with libLLVM >= 17 for Mitsuba's CPU variant.
#   bash scripts/install.sh          # the package
#   bash scripts/install.sh --test   # the package and the test dependencies (pytest, pyradiance,
#                                    # hypothesis, colour-checker-detection)
set -euo pipefail
cd "$(dirname "$0")/.."

have_llvm() {
  ls /usr/lib/*/libLLVM*.so* /usr/lib/llvm-*/lib/libLLVM*.so* 2>/dev/null \
    | grep -Eq 'libLLVM(-|\.so\.)(1[7-9]|[2-9][0-9])'
}
if [ -z "${DRJIT_LIBLLVM_PATH:-}" ] && ! have_llvm; then
  echo "install.sh: libLLVM >= 17 not found; installing Debian's libllvm19" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq libllvm19 >/dev/null
fi

PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
extra=""; [ "${1:-}" = "--test" ] && extra="[test]"
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -e ".${extra}"
echo "install.sh: skyfit-mi installed in $(pwd)/.venv"
