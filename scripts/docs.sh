#!/usr/bin/env bash
# Build the documentation site into build/docs (HTML), warnings as errors.
#
#   scripts/docs.sh [OUTDIR]          (default build/docs)
#
# Sphinx + MyST-NB + numpydoc (the `docs` extra: pip install '.[docs]', which
# this script installs when Sphinx is missing).  Every tutorial in
# docs/tutorials/ is executed at every build (an error in any cell fails it);
# the API, CLI and configuration references are generated from the code.  The
# tutorials read the third-party data from ../shared/data beside the
# repository (or $INSNAV_SHARED_DATA).
#
# The package documented is the one `python3 -c "import insnav"` imports
# (the installed one, or PYTHONPATH=python with a built insnav/_core*.so);
# the `insnav` command the tutorials run is that same package
# (`python3 -m insnav`, through a shim first on PATH).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PY=${PYTHON:-python3}
OUT=${1:-build/docs}
if ! "$PY" -c "import sphinx, myst_nb, numpydoc, furo" 2>/dev/null; then
  echo "[insnav] installing the docs extra (Sphinx, MyST-NB, numpydoc, furo)"
  "$PY" -m pip install -q "sphinx>=7.2" "myst-nb>=1.1" "numpydoc>=1.6" "furo>=2024.1" "matplotlib>=3.6" \
    "pandas>=1.5" "distributed>=2023.1"
fi
"$PY" -c "import insnav._core" || { echo "[insnav] insnav._core is not importable: scripts/install.sh first" >&2; exit 1; }
shim=$ROOT/build/docs-bin
mkdir -p "$shim"
printf '#!/bin/sh\nexec %q -m insnav "$@"\n' "$(command -v "$PY")" > "$shim/insnav"
chmod +x "$shim/insnav"
export PATH=$shim:$PATH
export INSNAV_SHARED_DATA=${INSNAV_SHARED_DATA:-$(cd "$ROOT/.." && pwd)/shared/data}
t0=$(date +%s)
# -W --keep-going: every warning is an error (all of them listed); -n: nitpicky references;
# -E: a fresh environment, so every tutorial runs again
"$PY" -m sphinx -b html -W --keep-going -E -q -d "$OUT/.doctrees" docs "$OUT"
echo "[insnav] documentation built in $(( $(date +%s) - t0 )) s: $OUT/index.html"
