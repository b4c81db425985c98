#!/usr/bin/env bash
# The whole test suite (Python + every C++ test and the example built without
# Python under ASan/UBSan, which tests/test_cpp.py runs): installs what is
# missing first.  Arguments go to pytest; with none, the C++ sanitizer build
# starts in the background first (tests/_cpp_build.py) so that it compiles
# while the extension builds and the Python tests run, and pytest uses 2
# workers (pytest-xdist).  scripts/test.sh --quick: the tests not marked slow
# (tests/conftest.py SLOW_TESTS; about 2 min), without the C++ sanitizer build.
#
# Everything the package promises is tested, so everything is installed first:
# Debian's chromium (the HTML report's headless-browser check) and the optional
# extras plot, pandas, parquet, dask and docs (the documentation build is a
# test).  A test whose capability is missing FAILS (tests/conftest.py); the
# only skips are explicit opt-outs, e.g. INSNAV_SKIP_BROWSER=1 (no Chromium
# install either), and .ci/run allows none (INSNAV_NO_SKIP=1).
set -euo pipefail
cd "$(dirname "$0")/.."
args=("$@")
# Bytecode caches on (__pycache__/, ignored by git) even where the environment
# switches them off: each pytest worker then compiles and assertion-rewrites a
# test module once, and each `python -m insnav` child process reuses the
# package's compiled modules.  Measured on 2 cores: collection 9.5 -> 2.7 s per
# worker, the quick subset 123 -> 116 s.
unset PYTHONDONTWRITEBYTECODE
export INSNAV_EXTRAS=${INSNAV_EXTRAS:-test,plot,pandas,parquet,dask,docs}
# the compiler, Eigen and the build backend (its own apt-get, before the one below)
scripts/install.sh --deps-only
if [ "${1:-}" = "--quick" ]; then
  shift
  args=(-n 2 --dist loadfile --no-loadscope-reorder --max-worker-restart 0 -p no:benchmark -m "not slow" "$@")
elif [ ${#args[@]} -eq 0 ]; then
  # Two builds share the 2 cores: the C++ tests (no Python needed) compile in
  # the background from here on, beside the extension and then the Python tests.
  python3 tests/_cpp_build.py --background
  # (--dist loadfile: the order of tests/conftest.py; a file on one worker, so its module fixtures run once;
  # --max-worker-restart 0: a worker that crashes ends the run with the test named, where xdist's
  # loadfile scheduler can wait forever for a replacement worker, pytest-dev/pytest-xdist#784)
  args=(-n 2 --dist loadfile --no-loadscope-reorder --max-worker-restart 0 -p no:benchmark)  # pytest-benchmark, if installed, refuses xdist with a warning (an error here)
fi
# The system packages only the tests need, installed (one apt-get update, one
# install) in the background while the compilers run: their download and
# unpacking cost a minute of wall time on a fresh CI machine, little CPU.
apt_pkgs=()
if [ "${INSNAV_SKIP_BROWSER:-}" != 1 ] || [ "${INSNAV_NO_SKIP:-}" = 1 ]; then
  if ! command -v chromium >/dev/null && ! command -v chromium-browser >/dev/null &&
     ! command -v google-chrome >/dev/null; then
    echo "[insnav] installing chromium (the report's browser test; INSNAV_SKIP_BROWSER=1 opts out)"
    apt_pkgs+=(chromium)
  fi
fi
# RTKLIB's rnx2rtkp: the RTK tests run it beside insnav on the same files (the GNSS anchor)
if ! command -v rnx2rtkp >/dev/null; then
  echo "[insnav] installing rtklib (rnx2rtkp: the RTK tests compare with it)"
  apt_pkgs+=(rtklib)
fi
apt_pid=""
if [ ${#apt_pkgs[@]} -gt 0 ] && command -v apt-get >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  mkdir -p build
  ( $SUDO apt-get update -qq || true
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${apt_pkgs[@]}" ) >build/apt.log 2>&1 &
  apt_pid=$!
fi
scripts/install.sh
if [ -n "$apt_pid" ] && ! wait "$apt_pid"; then
  echo "[insnav] apt-get install ${apt_pkgs[*]} failed:" >&2
  tail -20 build/apt.log >&2
  exit 1
fi
set +e
python3 -m pytest -q "${args[@]}"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then  # pytest: no tests collected
  echo "[insnav] no tests collected"
  exit 0
fi
exit "$rc"
