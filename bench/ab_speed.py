"""Speed of two builds side by side (A/B), e.g. before and after a refactor.

Each build is a Python interpreter with insnav installed (a venv).  The two
are run alternately, ROUNDS times, each run timing in one process: the C++
loop of the loose EKF-21 and RB-UKF-21 on the KF-GINS track
(../shared/data/kfgins/sim, 56 min of 200 Hz; the inputs are read once per
process), the tight EKF and RB-UKF on the simulated urban multi-GNSS drive
(the whole insnav.run call) and free-inertial mechanization of the KF-GINS IMU data.  Reported:
the median per build and the ratio B / A (1.00 = same speed).  The machine is
shared and noisy: only the ratio of medians measured in one run means much.

    python3 bench/ab_speed.py /path/to/venvA/bin/python /path/to/venvB/bin/python [--rounds 5]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

CHILD = r"""
import json, os, sys, time
from pathlib import Path
import numpy as np
import insnav
from insnav.io.kfgins_dataset import load_kfgins
D = Path(os.environ.get("INSNAV_SHARED_DATA", "../shared/data")) / "kfgins" / "sim"
ds, cfg = load_kfgins(D / "kf-gins-sim.yaml", D / "Leador-A15-sim.txt.xz", D / "GNSS-RTK-sim.txt", layout=21)
import insnav.filters.loose as loose_mod
core = loose_mod._core
calls = {}
def timed(*a, **k):
    t0 = time.perf_counter()
    out = core.run_loose(*a, **k)
    calls["last"] = time.perf_counter() - t0
    return out
class Wrap:
    def __getattr__(self, n):
        return timed if n == "run_loose" else getattr(core, n)
loose_mod._core = Wrap()
res = {}
for f in ("ekf", "rbukf"):
    insnav.run(ds, config=cfg, filter=f)
    res[f] = calls["last"]
# the tight family (its own unity group in the build): seed 003's 4-satellite drive,
# the whole insnav.run call (sanitising and output arrays included)
import insnav.sim as sim
ds_t = sim.simulate("urban-multignss", seed=0)
for f in ("ekf", "rbukf"):
    t0 = time.perf_counter()
    insnav.run(ds_t, filter=f, coupling="tight")
    res[f"tight_{f}"] = time.perf_counter() - t0
t0 = time.perf_counter()
insnav.mechanize(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b, ds.initial, ds.t0)
res["mechanize"] = time.perf_counter() - t0
print(json.dumps(res))
"""


def run_child(python: str) -> dict:
    r = subprocess.run([python, "-c", CHILD], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{python}: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else 'failed'}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("python_a")
    ap.add_argument("python_b")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    samples = {"A": [], "B": []}
    for _ in range(args.rounds):
        for tag, py in (("A", args.python_a), ("B", args.python_b)):
            samples[tag].append(run_child(py))
    print(f"A = {args.python_a}\nB = {args.python_b}\nmedians over {args.rounds} alternating rounds [s]:\n")
    print("| step | A | B | B / A |")
    print("|---|---|---|---|")
    for k in samples["A"][0]:
        a = statistics.median(s[k] for s in samples["A"])
        b = statistics.median(s[k] for s in samples["B"])
        print(f"| {k} | {a:.3f} | {b:.3f} | {b / a:.2f} |")
    print(f"\ncommand: python3 bench/ab_speed.py {args.python_a} {args.python_b} --rounds {args.rounds}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
