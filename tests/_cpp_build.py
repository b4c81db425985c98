"""The sanitizer build of the plain C++ example and tests, shared by
tests/test_cpp.py and scripts/test.sh.

One build serves both: every C++ test and the example, without Python, under
ASan + UBSan.  Its cost is compile time (Eigen template instantiation, minutes
of CPU), so:

* it is compiled once, at -O0 (-O1 costs 2-3x the compile time; the three
  tests with long simulated runs are built at -O1, cpp/tests/CMakeLists.txt), without
  the fixed-size update kernels of RbUkf/Ukf (INSNAV_NO_FIXED_UPDATE_KERNELS:
  the same template code at bounded dynamic sizes; the kernels run in the
  extension, i.e. in every Python filter test, in bench/, and here in
  cpp/tests/test_fixed_kernels.cpp, which switches them back on);
* one executable per test by default; INSNAV_TEST_UNITY=1 builds them as 3 unity
  TUs and test_fixed_kernels.cpp alone (the tests of a group share one
  compilation of their common Eigen and engine instantiations: 14 % less CPU,
  but up to 7 GB per compiler process; cpp/tests/CMakeLists.txt has the per-TU
  CPU measured, and what it goes to), still one ctest entry per test_*.cpp;
* with clang++ when present (as scripts/install.sh builds the extension);
* scripts/test.sh starts it in the background (``python3 tests/_cpp_build.py
  --background``) before it builds the extension, so that the two builds and
  then the Python tests share the cores; tests/test_cpp.py waits for it under the same lock
  (build/cpp-asan.lock) and builds whatever is left itself, so running pytest
  alone works too.

    python3 tests/_cpp_build.py [--background]
"""
from __future__ import annotations

import fcntl
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BUILD = REPO / "build" / "cpp-asan"
LOCK = REPO / "build" / "cpp-asan.lock"
LOG = REPO / "build" / "cpp-asan.log"
FLAGS = ("-DINSNAV_BUILD_EXAMPLES=ON", "-DINSNAV_SANITIZE=ON", "-DCMAKE_BUILD_TYPE=Release",
         "-DCMAKE_CXX_FLAGS_RELEASE=-O0 -DNDEBUG -DINSNAV_NO_FIXED_UPDATE_KERNELS",
         # INSNAV_TEST_UNITY=1: the tests as a few unity TUs (cpp/tests/CMakeLists.txt:
         # 922 -> 791 s of compile CPU measured, but up to 7 GB per compiler process,
         # beside the extension's unity TUs of up to 3.7 GB each in scripts/test.sh:
         # opt-in, so that a 24 GB CI machine keeps its margin)
         f"-DINSNAV_TEST_UNITY={'ON' if os.environ.get('INSNAV_TEST_UNITY') == '1' else 'OFF'}")


def compiler() -> str | None:
    """$CXX, else clang++ when installed, else CMake's default (None)."""
    cxx = os.environ.get("CXX") or shutil.which("clang++")
    return shutil.which(cxx) if cxx else None


def build(log=None) -> subprocess.CompletedProcess:
    """Configure and build under the lock; returns the build step's result."""
    LOCK.parent.mkdir(parents=True, exist_ok=True)
    with open(LOCK, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # waits for a build already running (--background)
        cfg = ["cmake", "-S", str(REPO), "-B", str(BUILD), *FLAGS]
        if shutil.which("ninja"):
            cfg += ["-G", "Ninja"] if not (BUILD / "CMakeCache.txt").exists() else []
        cxx = compiler()
        if cxx:
            cfg.append(f"-DCMAKE_CXX_COMPILER={cxx}")
        out = dict(stdout=log, stderr=subprocess.STDOUT) if log else dict(capture_output=True)
        r = subprocess.run(cfg, text=True, **out)
        if r.returncode != 0:
            return r
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.monotonic()
        r = subprocess.run(["cmake", "--build", str(BUILD), "-j2"], text=True, **out)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
        if log:  # the figure in README.md (Testing: where the time goes)
            print(f"[insnav] C++ sanitizer build: {time.monotonic() - t0:.0f} s wall, {cpu:.0f} s CPU",
                  file=log, flush=True)
        return r


def ctest() -> str:
    """Run every C++ test (2 at a time); stdout + stderr."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(["ctest", "--test-dir", str(BUILD), "-j2", "--output-on-failure"],
                       capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return r.stdout + r.stderr + f"[insnav] ctest: {cpu:.0f} s CPU\n"


def main(argv: list[str]) -> int:
    if shutil.which("cmake") is None:
        return 0  # test_cpp skips with its own message
    if "--background" in argv:
        LOG.parent.mkdir(parents=True, exist_ok=True)
        with open(LOG, "w") as log:
            subprocess.Popen([sys.executable, __file__], stdout=log, stderr=subprocess.STDOUT,
                             start_new_session=True)
        print(f"[insnav] C++ sanitizer build started in the background (log: {LOG.relative_to(REPO)})")
        return 0
    r = build(sys.stdout)
    return r.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
