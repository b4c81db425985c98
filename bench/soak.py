"""Soak run: 24 h at 200 Hz with periodic GNSS outages.

Two parts, same scenario (``cpp/tests/test_soak.cpp``): a vehicle parked at
34.25 N, 108.95 E, 400 m turning through a full circle about its vertical
(10 deg/s for 36 s) every 5 min; MEMS errors (ARW 0.2 deg/sqrt(h), VRW
0.1 m/s/sqrt(h), biases 30 deg/h and 5 mg); GNSS 1 Hz (1 m, 0.05 m/s) with a
60 s outage every 10 min.

1. C++: ``test_soak <hours>`` built in Release and under ASan + UBSan; it checks
   after every filter step (propagate, cycle end, update) that P is finite,
   symmetric and positive definite (EKF and RB-UKF), and reports the maximum
   position error and the peak RSS.
2. Python API: the same data generated with numpy (in chunks) and run through
   ``insnav.run`` (EKF and RB-UKF, 1 Hz output) while a thread samples the
   process RSS every 0.5 s (the C++ loop releases the GIL): RSS must stay
   flat during the run; every sigma output finite and positive; no NaN.

    python bench/soak.py [--hours 24] [--skip-asan] [--skip-python]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from _soak import python_soak  # noqa: E402  (the scenario and the Python run: tests/_soak.py)


def build_and_run_cpp(hours: float, sanitize: bool) -> str:
    b = REPO / "build" / ("soak-asan" if sanitize else "soak-release")
    args = ["cmake", "-S", str(REPO), "-B", str(b), "-DINSNAV_BUILD_EXAMPLES=ON"]
    args += ["-DINSNAV_SANITIZE=ON", "-DCMAKE_BUILD_TYPE=RelWithDebInfo"] if sanitize else \
        ["-DCMAKE_BUILD_TYPE=Release"]
    subprocess.run(args, check=True, capture_output=True, text=True)
    subprocess.run(["cmake", "--build", str(b), "-j2", "--target", "test_soak"], check=True, capture_output=True,
                   text=True)
    exe = next(b.rglob("test_soak"))
    t0 = time.time()
    res = subprocess.run([str(exe), str(hours)], capture_output=True, text=True)
    out = res.stdout + res.stderr
    return f"[{'ASan+UBSan' if sanitize else 'Release'}, {time.time() - t0:.0f} s, exit {res.returncode}]\n{out}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--skip-asan", action="store_true")
    ap.add_argument("--skip-cpp", action="store_true")
    ap.add_argument("--skip-python", action="store_true")
    a = ap.parse_args(argv)
    if not a.skip_cpp:
        print(build_and_run_cpp(a.hours, sanitize=False), flush=True)
        if not a.skip_asan:
            print(build_and_run_cpp(a.hours, sanitize=True), flush=True)
    if not a.skip_python:
        for r in python_soak(a.hours):
            print(r, flush=True)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
