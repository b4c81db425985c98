#!/usr/bin/env bash
# The main job on its built-in default: installs what is missing, then runs
# `insnav demo` (simulate seed000-sim, run EKF and RB-UKF, print the table,
# write a report folder).  Extra arguments go to `insnav demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install.sh
exec python3 -m insnav demo "$@"
