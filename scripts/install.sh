#!/usr/bin/env bash
# Install what insnav needs on a fresh Debian machine, then the package itself
# with its test extras.  Idempotent: skips what is already there.
#   scripts/install.sh [--deps-only]   (--deps-only: the system packages and the
#                                       build backend, not the package)
# INSNAV_EXTRAS: the extras installed with it (default: test; scripts/test.sh
# adds plot,pandas,parquet,dask,docs).
#
# Compiler: clang++ when present (installed here on Debian), else the default
# c++.  The core is header-only Eigen templates; clang 14 compiles them about
# 2.5x faster than g++ 12 (the extension: 6 vs 14 min of CPU, measured) with the
# same run-time speed (docs/logs/benchmarks.md).  CXX=g++ scripts/install.sh
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
# A build tree configured with another compiler is removed: CMake ignores $CXX
# for an existing cache, and re-configuring it with a new CMAKE_CXX_COMPILER
# drops scikit-build-core's initial cache (an install without insnav._core).
want=$(readlink -f "$(command -v "${CXX:-c++}")" 2>/dev/null || true)
for cache in build/cp*/CMakeCache.txt; do
  [ -f "$cache" ] || continue
  have=$(sed -n 's/^CMAKE_CXX_COMPILER:[A-Z]*=//p' "$cache")
  if [ -n "$want" ] && [ "$(readlink -f "$have" 2>/dev/null)" != "$want" ]; then
    echo "[insnav] $(dirname "$cache") was configured with $have: removing it (now $want)"
    rm -rf "$(dirname "$cache")"
  fi
done
# build backend for the no-isolation build (incremental rebuilds in build/)
"$PY" -m pip install -q "scikit-build-core>=0.10" "pybind11>=3" ninja cmake
[ "${1:-}" = "--deps-only" ] && exit 0  # scripts/test.sh: the C++ tests start building before the package
echo "[insnav] building and installing insnav (CXX=${CXX:-default})"
flock /tmp/insnav-build.lock "$PY" -m pip install -q --no-build-isolation ".[${INSNAV_EXTRAS:-test}]"
# never leave an install that looks complete without its compiled core
(cd / && "$PY" -c "import insnav._core") ||
  { echo "[insnav] the installed package has no working insnav._core (see the build output above)" >&2; exit 1; }
