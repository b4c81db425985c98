"""The C++ example and tests, built without Python under ASan + UBSan, run by
ctest; the build itself is tests/_cpp_build.py.  Skips only if cmake
or the source tree is missing.  `make cpp-test` builds the same without
sanitizers at -O3."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

import _cpp_build  # tests/_cpp_build.py: flags, compiler choice, lock shared with scripts/test.sh

REPO = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(
    not (REPO / "cpp" / "include" / "insnav").is_dir() or shutil.which("cmake") is None,
    reason="needs the source tree and cmake (not available from an installed wheel)",
)


@pytest.fixture(scope="module")
def ctest_output() -> str:
    """Build (or wait for scripts/test.sh's background build), then run ctest once."""
    r = _cpp_build.build()
    assert r.returncode == 0, (r.stdout or "")[-4000:] + (r.stderr or "")[-4000:]
    return _cpp_build.ctest()


def test_cpp_tests_under_asan_ubsan(ctest_output):
    # every test_*.cpp (test_fixed_kernels.cpp with the fixed-size update kernels
    # that the rest of this build leaves out, cpp/tests/CMakeLists.txt) and the example
    n_tests = len(list((REPO / "cpp" / "tests").glob("test_*.cpp"))) + 1
    assert "100% tests passed" in ctest_output, ctest_output[-6000:]
    assert f"out of {n_tests}" in ctest_output, ctest_output[-2000:]
    assert "runtime error" not in ctest_output  # UBSan reports even where a test would not fail


def test_free_inertial_example_prints_drift(ctest_output):
    exe = _cpp_build.BUILD / "cpp" / "examples" / "free_inertial"
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    drift = float(out.split("position drift")[1].split("m")[0])
    assert drift < 1e-3


def test_loose_realtime_example_reproduces_batch(ctest_output, shared_data, tmp_path):
    """cpp/examples/loose_realtime.cpp under ASan: the KF-GINS sim files read
    line by line and pushed (fixes 20 samples late) reproduce the batch engine
    to 1e-9, every row."""
    import lzma

    d = shared_data / "kfgins" / "sim"
    imu = tmp_path / "imu.txt"
    with lzma.open(d / "Leador-A15-sim.txt.xz", "rt") as src, open(imu, "w") as dst:
        for i, line in enumerate(src):  # 456250 .. 456400 s: 100 s after the start time
            if i >= 30000:
                break
            dst.write(line)
    exe = _cpp_build.BUILD / "cpp" / "examples" / "loose_realtime"
    r = subprocess.run([str(exe), str(d / "kf-gins-sim.yaml"), str(imu), str(d / "GNSS-RTK-sim.txt"),
                        "--latency-samples", "20"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    import re

    diff = float(re.search(r"max difference (\S+)", r.stdout).group(1))
    assert diff <= 1e-9
    applied = int(re.search(r"\((\d+) applied", r.stdout).group(1))
    assert applied >= 99  # a fix per second
