#!/usr/bin/env bash
# Install what insnav needs on a fresh Debian machine, then the package itself
# with its test extras.  Idempotent: skips what is already there.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}

if [ ! -f /usr/include/eigen3/Eigen/Core ]; then
  echo "[insnav] installing Eigen (libeigen3-dev)"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq || true
  $SUDO apt-get install -y -qq libeigen3-dev cmake g++ >/dev/null
fi
# build backend for the no-isolation build (incremental rebuilds in build/)
"$PY" -m pip install -q "scikit-build-core>=0.10" "pybind11>=3" ninja cmake
echo "[insnav] building and installing insnav"
flock /tmp/insnav-build.lock "$PY" -m pip install -q --no-build-isolation ".[test]"
