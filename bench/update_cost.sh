#!/usr/bin/env bash
# Instructions per measurement update: UKF (augmented UT, seed 000 eqs. (14)-(21))
# against the RB-UKF linear update (eqs. (22)-(24)) in its dense and block-sparse
# forms, on the same P, H, R.  Counted with valgrind --tool=callgrind (instruction
# counts are reproducible, unlike wall time on a shared machine): each kind runs
# N updates, and a baseline run of the same program with the update skipped is
# subtracted, so  instr/update = (I(kind, N) - I(none, N)) / N.
#
# usage: bench/update_cost.sh [N=200]      (writes the markdown table to stdout)
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-200}
BUILD=build/bench
flock /tmp/insnav-build.lock sh -c "cmake -S . -B $BUILD -DINSNAV_BUILD_BENCH=ON -DCMAKE_BUILD_TYPE=Release >/dev/null && cmake --build $BUILD --target update_cost -j2 >/dev/null"
EXE=$BUILD/bench/cpp/update_cost
command -v valgrind >/dev/null || { echo "valgrind not found (apt-get install valgrind)" >&2; exit 1; }

count() {  # instructions executed by one run
  valgrind --tool=callgrind --callgrind-out-file=/dev/null "$EXE" "$@" 2>&1 | awk '/Collected/ {print $NF}'
}

KINDS="ukf dense_paper dense_joseph sparse_joseph sparse_factored"
echo "Command: bench/update_cost.sh $N   (valgrind --tool=callgrind, $N updates per kind minus a baseline run with the update skipped; $(g++ --version | head -1), CMAKE_BUILD_TYPE=Release)"
echo
echo "| states m | rows n | H cols c | update | instr/update | saving vs UKF (instr) | analytic flops | saving vs UKF (flops) |"
echo "|---|---|---|---|---|---|---|---|"
for cfg in "15 6 6" "21 6 6" "15 6 15"; do
  set -- $cfg
  m=$1; r=$2; c=$3
  base=$(count none "$N" "$m" "$r" "$c")
  fl=$("$EXE" flops 0 "$m" "$r" "$c")
  ukf_i=""; ukf_f=""
  for k in $KINDS; do
    tot=$(count "$k" "$N" "$m" "$r" "$c")
    per=$(( (tot - base) / N ))
    f=$(echo "$fl" | awk -v k="$k" '{for (i = 1; i < NF; i += 2) if ($i == k) print $(i + 1)}')
    if [ "$k" = ukf ]; then ukf_i=$per; ukf_f=$f; fi
    si=$(awk -v a="$ukf_i" -v b="$per" 'BEGIN {printf "%.1f %%", 100 * (1 - b / a)}')
    sf=$(awk -v a="$ukf_f" -v b="$f" 'BEGIN {printf "%.1f %%", 100 * (1 - b / a)}')
    [ "$k" = ukf ] && si="-" && sf="-"
    echo "| $m | $r | $c | $k | $per | $si | $f | $sf |"
  done
done
echo
pf=$("$EXE" flops 0 15 6 6 | awk '{for (i = 1; i < NF; i += 2) if ($i == "paper_ukf" || $i == "paper_rbukf") printf "%s %s ", $i, $(i + 1)}')
echo "seed 000 analytic counts (m = 15, n = 6): $pf(41.7 % less)"
