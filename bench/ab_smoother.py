"""Cost of the RTS smoother, two builds side by side (A/B).

Each build is a Python interpreter with insnav installed.  Each child
process loads the KF-GINS track with its four 60 s outages
(../shared/data/kfgins/sim, GNSS-RTK-sim-outage4, loose EKF-21) once and times
ROUNDS alternating forward and smoothed ``insnav.run`` calls, split into the
C++ run (``_core.run_loose``, forward pass, record and backward pass),
``smoothed_rows`` (``_core.smooth_rows`` and its copies) and the rest
(Python).  The children of A and B run alternately; reported: the medians
per build and the smoothed / forward ratio of the whole call.

    python3 bench/ab_smoother.py /path/to/pythonA /path/to/pythonB [--rounds 5]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

CHILD = r"""
import json, os, statistics, sys, time
from pathlib import Path
import numpy as np
import insnav
import insnav.filters.loose as loose_mod
import insnav.filters.smoothing as sm_mod
from insnav.config import RunConfig
from insnav.io.kfgins_dataset import load_kfgins
D = Path(os.environ.get("INSNAV_SHARED_DATA", "/work/shared/data")) / "kfgins" / "sim"
ds, cfg = load_kfgins(D / "kf-gins-sim.yaml", D / "Leador-A15-sim.txt.xz", D / "GNSS-RTK-sim-outage4.txt", layout=21)
core = loose_mod._core
last = {}
def run_loose(*a, **k):
    t0 = time.perf_counter()
    out = core.run_loose(*a, **k)
    last["core"] = time.perf_counter() - t0
    return out
class Wrap:
    def __getattr__(self, n):
        return run_loose if n == "run_loose" else getattr(core, n)
loose_mod._core = Wrap()
rows0 = sm_mod.smoothed_rows
def smoothed_rows(*a, **k):
    t0 = time.perf_counter()
    rows0(*a, **k)
    last["rows"] = time.perf_counter() - t0
sm_mod.smoothed_rows = smoothed_rows
res = {k: [] for k in ("fwd", "fwd_core", "sm", "sm_core", "sm_rows")}
for r in range(int(sys.argv[1])):
    for smooth in (False, True):
        c = RunConfig(**{**cfg.__dict__, "filter": "ekf", "smooth": smooth})
        last.clear()
        t0 = time.perf_counter()
        insnav.run(ds, config=c)
        wall = time.perf_counter() - t0
        key = "sm" if smooth else "fwd"
        res[key].append(wall)
        res[key + "_core"].append(last["core"])
        if smooth:
            res["sm_rows"].append(last["rows"])
print(json.dumps({k: statistics.median(v) for k, v in res.items()}))
"""


def run_child(python: str, rounds: int) -> dict:
    r = subprocess.run([python, "-c", CHILD, str(rounds)], capture_output=True, text=True, cwd="/")
    if r.returncode != 0:
        sys.exit(f"{python}: {r.stderr.strip()[-2000:] if r.stderr.strip() else 'failed'}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("python_a")
    ap.add_argument("python_b")
    ap.add_argument("--rounds", type=int, default=5, help="forward + smoothed pairs per child")
    ap.add_argument("--children", type=int, default=2, help="alternating children per build")
    args = ap.parse_args(argv)
    runs = {"A": [], "B": []}
    for _ in range(args.children):
        for name, py in (("A", args.python_a), ("B", args.python_b)):
            runs[name].append(run_child(py, args.rounds))
    print("| build | forward [s] | smoothed [s] | ratio | C++ run fwd / smoothed [s] | smoothed_rows [s] | rest [s] |")
    print("|---|---|---|---|---|---|---|")
    for name in ("A", "B"):
        m = {k: statistics.median(r[k] for r in runs[name]) for k in runs[name][0]}
        rest = m["sm"] - m["sm_core"] - m["sm_rows"] - (m["fwd"] - m["fwd_core"])
        print(f"| {name} | {m['fwd']:.3f} | {m['sm']:.3f} | {m['sm'] / m['fwd']:.2f}x | "
              f"{m['fwd_core']:.3f} / {m['sm_core']:.3f} | {m['sm_rows']:.3f} | {rest:+.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
