"""The C++ example and tests, built without Python under ASan + UBSan, run by
ctest (issue 2).  Skips only if cmake or a compiler is missing.  `make
cpp-test` builds the same without sanitizers at -O3."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(
    not (REPO / "cpp" / "include" / "insnav").is_dir() or shutil.which("cmake") is None,
    reason="needs the source tree and cmake (not available from an installed wheel)",
)


#: One build serves both: every C++ test and the example, without Python, under
#: ASan + UBSan.  The Eigen-heavy tests dominate the suite's time by their
#: compile time (template instantiation: minutes per file on 2 cores), so they
#: are compiled once, at -O1 without debug info, and without the fixed-size
#: update kernels of RbUkf/Ukf (INSNAV_NO_FIXED_UPDATE_KERNELS: the same
#: template code at bounded dynamic sizes; measured on test_rbukf.cpp: 466 s
#: of compiler CPU time without them, > 586 s with them).  The kernels run in
#: the extension, i.e. in every Python filter test; bench/ builds at -O3.
SANITIZED_O1 = ("-DINSNAV_SANITIZE=ON", "-DCMAKE_BUILD_TYPE=Release",
                "-DCMAKE_CXX_FLAGS_RELEASE=-O1 -DNDEBUG -DINSNAV_NO_FIXED_UPDATE_KERNELS")
BUILD = REPO / "build" / "cpp-asan"


@pytest.fixture(scope="module")
def ctest_output() -> str:
    """Configure, build and run ctest once for this module."""
    subprocess.run(["cmake", "-S", str(REPO), "-B", str(BUILD), "-DINSNAV_BUILD_EXAMPLES=ON", *SANITIZED_O1],
                   check=True, capture_output=True, text=True)
    r = subprocess.run(["cmake", "--build", str(BUILD), "-j2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
    res = subprocess.run(["ctest", "--test-dir", str(BUILD), "--output-on-failure"], capture_output=True, text=True)
    return res.stdout + res.stderr


def test_cpp_tests_under_asan_ubsan(ctest_output):
    n_tests = len(list((REPO / "cpp" / "tests").glob("test_*.cpp"))) + 1  # + the example
    assert "100% tests passed" in ctest_output, ctest_output[-6000:]
    assert f"out of {n_tests}" in ctest_output, ctest_output[-2000:]
    assert "runtime error" not in ctest_output  # UBSan reports even where a test would not fail


def test_free_inertial_example_prints_drift(ctest_output):
    exe = BUILD / "cpp" / "examples" / "free_inertial"
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    drift = float(out.split("position drift")[1].split("m")[0])
    assert drift < 1e-3
