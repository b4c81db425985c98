"""Mechanization throughput: plain C++ loop vs the Python batch call, side by side.

    cd insnav && python3 bench/bench_mechanization.py [--repeats 15]

Both integrate the same 1 h of 200 Hz IMU increments (720 000 samples, a turning,
pitching motion).  Each round runs the C++ program once (bench/mechanization_bench.cpp,
compiled here with the extension's compiler (``$CXX``, else clang++ when installed, else
g++, as scripts/install.sh chooses) and its Release flags -O3 -DNDEBUG)
and times one Python batch call ``insnav.mechanize`` and one call of the binding
alone; the order alternates between rounds.  Reported: medians over the rounds and
the median of the per-round ratios, by wall clock and by thread CPU time (CPU time
does not advance while the thread waits for a core, so it is the steadier figure on
a shared machine).  All loops are single-threaded: the figures are per core.

* ``plain``:        Strapdown::update only;
* ``output``:       the loop of the Python binding (update + lat/lon/h, v_n,
                    roll/pitch/yaw written for every sample) into buffers allocated
                    and zeroed beforehand;
* ``output_fresh``: the same into buffers malloc'ed inside the timed region (first-touch
                    page faults, as the binding's new numpy arrays);
* batch:            insnav.mechanize: dtype/shape conversion, then the binding (the same
                    C++ loop with the GIL released, checking each sample (finite,
                    increasing time) as it goes and writing degrees directly into new
                    numpy arrays), then the Trajectory;
* binding alone:    insnav._core.mechanize without the Python wrapper.

Targets: >= 3 M samples/s per core in C++; the batch call within 10 % of C++.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import insnav
from insnav import _core

REPO = Path(__file__).resolve().parents[1]
N = 720_000  # 1 h at 200 Hz
ROWS = (("plain", "C++ `Strapdown::update` only"),
        ("output", "C++ update + output arrays (the binding's loop), buffers ready"),
        ("output_fresh", "C++ update + output arrays, buffers allocated in the timed region"),
        ("batch", "Python batch `insnav.mechanize`"),
        ("core", "binding alone, `insnav._core.mechanize`"))


def compiler() -> str:
    """The compiler scripts/install.sh builds insnav._core with."""
    import shutil

    return os.environ.get("CXX") or shutil.which("clang++") or "g++"


def build(exe: Path) -> None:
    subprocess.run([compiler(), "-O3", "-DNDEBUG", "-std=c++17", f"-I{REPO / 'cpp' / 'include'}",
                    "-I/usr/include/eigen3", str(REPO / "bench" / "mechanization_bench.cpp"), "-o", str(exe)],
                   check=True)


def run_cpp(exe: Path, n: int) -> dict:
    out = subprocess.run([str(exe), str(n), "1"], check=True, capture_output=True, text=True).stdout
    res = {}
    for line in out.splitlines():
        k, wall, cpu = line.split()
        res[k] = (float(wall), float(cpu))
    return res


def timed(f, n):
    w0, c0 = time.perf_counter(), time.thread_time()
    f()
    return n / (time.perf_counter() - w0), n / (time.thread_time() - c0)


def breakdown(t, dth, dv, init, repeats):
    """Thread CPU time of the phases of insnav.mechanize (the same steps as python/insnav/ins/mechanize.py)."""
    from insnav._validate import as_float_array
    from insnav.data.nav import Trajectory

    ph = {k: [] for k in ("as_float_array", "_core.mechanize (checks + degrees inside)", "Trajectory", "total")}
    for _ in range(repeats):
        c0 = time.thread_time()
        a = as_float_array(t, "t")
        b = as_float_array(dth, "dtheta_b", (3,))
        c = as_float_array(dv, "dv_b", (3,))
        c1 = time.thread_time()
        out = _core.mechanize(a, b, c, 0.0, init.pos_llh, init.v_n, init.rpy, True, True)
        c2 = time.thread_time()
        assert out["bad_sample"] < 0
        Trajectory(t=a.copy(), lat_deg=out["lat_deg"], lon_deg=out["lon_deg"], h_m=out["h_m"], v_n=out["v_n"],
                   roll_deg=out["roll_deg"], pitch_deg=out["pitch_deg"], yaw_deg=out["yaw_deg"])
        c3 = time.thread_time()
        for k, v in zip(ph, (c1 - c0, c2 - c1, c3 - c2, c3 - c0)):
            ph[k].append(1e3 * v)
    tot = float(np.median(ph["total"]))
    print(f"phases of the batch call, thread CPU time, median of {repeats} (separate from the rounds above):")
    print("| phase | median [ms] | share of the total |")
    print("|---|---|---|")
    for k, v in ph.items():
        print(f"| {k} | {np.median(v):.2f} | {100 * np.median(v) / tot:.1f} % |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=15, help="rounds (each: one C++ run, one batch call)")
    ap.add_argument("--samples", type=int, default=N)
    a = ap.parse_args(argv)
    n = a.samples
    dt = 0.005
    t = np.arange(1, n + 1) * dt
    dth = np.column_stack([0.01 * np.sin(0.5 * t), 0.02 * np.cos(0.3 * t), np.full(n, 0.05)]) * dt
    dv = np.column_stack([0.3 * np.sin(0.1 * t), np.full(n, 0.2), np.full(n, -9.8)]) * dt
    init = insnav.NavState(0.6 * 180 / np.pi, 2.0 * 180 / np.pi, 100.0, [10.0, 0, 0])
    load0 = os.getloadavg()
    rates = {k: [] for k, _ in ROWS}  # (wall, cpu) per round

    def py_round():
        rates["batch"].append(timed(lambda: insnav.mechanize(t, dth, dv, init, t0=0.0), n))
        rates["core"].append(timed(lambda: _core.mechanize(t, dth, dv, 0.0, init.pos_llh, init.v_n, init.rpy,
                                                           True, True), n))

    with tempfile.TemporaryDirectory() as d:
        exe = Path(d) / "mechanization_bench"
        build(exe)
        insnav.mechanize(t[:1000], dth[:1000], dv[:1000], init, t0=0.0)  # warm-up (imports, first call)
        for r in range(a.repeats):
            if r % 2:
                py_round()
            c = run_cpp(exe, n)
            for k in ("plain", "output", "output_fresh"):
                rates[k].append(c[k])
            if not r % 2:
                py_round()
    load1 = os.getloadavg()
    R = {k: np.asarray(v) for k, v in rates.items()}  # (rounds, 2)
    med = lambda x: float(np.median(x))  # noqa: E731
    print(f"samples per run: {n} ({n * dt / 3600:.2f} h at 200 Hz); rounds: {a.repeats}; "
          f"{os.cpu_count()} cores; load average (1 min) before/after: {load0[0]:.2f}/{load1[0]:.2f}; "
          f"C++ loop compiled with {compiler()} -O3")
    print()
    print("| loop | wall clock: median [M samples/s] | min, max | thread CPU time: median [M samples/s] "
          "| min, max |")
    print("|---|---|---|---|---|")
    for k, label in ROWS:
        w, c = R[k][:, 0], R[k][:, 1]
        print(f"| {label} | {med(w) / 1e6:.2f} | {w.min() / 1e6:.2f}, {w.max() / 1e6:.2f} | "
              f"{med(c) / 1e6:.2f} | {c.min() / 1e6:.2f}, {c.max() / 1e6:.2f} |")
    print()
    print("| ratio (median of the per-round ratios) | wall clock | thread CPU time |")
    print("|---|---|---|")
    for num, den in (("batch", "output"), ("batch", "output_fresh"), ("batch", "plain"), ("core", "output_fresh"),
                     ("batch", "core")):
        q = R[num] / R[den]
        print(f"| {num} / {den} | {med(q[:, 0]):.3f} ({q[:, 0].min():.2f}-{q[:, 0].max():.2f}) | "
              f"{med(q[:, 1]):.3f} ({q[:, 1].min():.2f}-{q[:, 1].max():.2f}) |")
    print()
    print("per round, wall clock [M samples/s] (" + ", ".join(k for k, _ in ROWS) + "): " +
          "; ".join(", ".join(f"{R[k][i, 0] / 1e6:.2f}" for k, _ in ROWS) for i in range(a.repeats)))
    print()
    breakdown(t, dth, dv, init, max(5, a.repeats // 2))
    print()
    print(f"command: cd insnav && python3 bench/bench_mechanization.py --repeats {a.repeats}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
