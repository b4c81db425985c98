#!/usr/bin/env bash
# Install what insnav needs on a fresh Debian machine, then the package itself
# with its test extras.  Idempotent: skips what is already there.
#   scripts/install.sh [--deps-only]   (--deps-only: the system packages and the
#                                       build backend, not the package)
#
# Compiler: clang++ when present (installed here on Debian), else the default
# c++.  The core is header-only Eigen templates; clang 14 compiles them about
# 2.5x faster than g++ 12 (the extension: 6 vs 14 min of CPU, measured) with the
# same run-time speed (docs/results/benchmarks.md).  CXX=g++ scripts/install.sh
# builds with g++ instead.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}

missing=()
[ -f /usr/include/eigen3/Eigen/Core ] || missing+=(libeigen3-dev)
command -v c++ >/dev/null || missing+=(g++)
[ -n "${CXX:-}" ] || command -v clang++ >/dev/null || missing+=(clang)
if [ ${#missing[@]} -gt 0 ]; then
  echo "[insnav] installing ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  if command -v apt-get >/dev/null; then
    $SUDO apt-get update -qq || true
    # clang is optional: a failure to get it leaves the default compiler
    $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null ||
      $SUDO apt-get install -y -qq $(printf '%s\n' "${missing[@]}" | grep -vx clang) >/dev/null
  fi
fi
[ -f /usr/include/eigen3/Eigen/Core ] || { echo "[insnav] Eigen 3.4 headers not found (apt-get install libeigen3-dev)" >&2; exit 1; }
if [ -z "${CXX:-}" ] && command -v clang++ >/dev/null; then export CXX=clang++; fi
cxx_define=()  # the same compiler also when build/ already holds a configured tree
[ -n "${CXX:-}" ] && cxx_define=(-Ccmake.define.CMAKE_CXX_COMPILER="$(command -v "$CXX")")
# build backend for the no-isolation build (incremental rebuilds in build/)
"$PY" -m pip install -q "scikit-build-core>=0.10" "pybind11>=3" ninja cmake
[ "${1:-}" = "--deps-only" ] && exit 0  # scripts/test.sh: the C++ tests start building before the package
echo "[insnav] building and installing insnav (CXX=${CXX:-default})"
flock /tmp/insnav-build.lock "$PY" -m pip install -q --no-build-isolation "${cxx_define[@]}" ".[test]"
