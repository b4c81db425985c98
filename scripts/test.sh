#!/usr/bin/env bash
# The whole test suite (Python + the plain C++ tests + the ASan/UBSan build,
# which tests/test_cpp.py drives): installs what is missing first.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install.sh
set +e
python3 -m pytest -q "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then  # pytest: no tests collected
  echo "[insnav] no tests collected"
  exit 0
fi
exit "$rc"
