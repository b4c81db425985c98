#!/usr/bin/env bash
# The whole test suite (Python + every C++ test and the example built without
# Python under ASan/UBSan, which tests/test_cpp.py runs): installs what is
# missing first.  Arguments go to pytest; with none, the C++ sanitizer build
# starts in the background first (tests/_cpp_build.py) so that it compiles
# while the extension builds and the Python tests run, and pytest uses 2
# workers (pytest-xdist).  scripts/test.sh --quick: the tests not marked slow (about 2 min).
set -euo pipefail
cd "$(dirname "$0")/.."
args=("$@")
if [ "${1:-}" = "--quick" ]; then
  # the quick subset: everything not marked slow (tests/conftest.py SLOW_TESTS), on 2 workers,
  # without the C++ sanitizer build (tests/test_cpp.py is slow)
  shift
  args=(-n 2 -p no:benchmark -m "not slow" "$@")
elif [ ${#args[@]} -eq 0 ]; then
  # Two builds share the 2 cores: the C++ tests (no Python needed) compile in
  # the background from here on, beside the extension and then the Python tests.
  scripts/install.sh --deps-only
  python3 tests/_cpp_build.py --background
  args=(-n 2 -p no:benchmark)  # pytest-benchmark, if installed, refuses xdist with a warning (an error here)
fi
scripts/install.sh
set +e
python3 -m pytest -q "${args[@]}"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then  # pytest: no tests collected
  echo "[insnav] no tests collected"
  exit 0
fi
exit "$rc"
