"""The plain C++ example and tests, built without Python, and the same under
ASan + UBSan (issue 2).  Skips only if cmake or a compiler is missing."""
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


def _build_and_ctest(build_dir: str, *extra: str) -> str:
    b = REPO / "build" / build_dir
    subprocess.run(["cmake", "-S", str(REPO), "-B", str(b), "-DINSNAV_BUILD_EXAMPLES=ON", *extra],
                   check=True, capture_output=True, text=True)
    subprocess.run(["cmake", "--build", str(b), "-j2"], check=True, capture_output=True, text=True)
    res = subprocess.run(["ctest", "--test-dir", str(b), "--output-on-failure"], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    return res.stdout


def test_cpp_example_and_tests():
    out = _build_and_ctest("cpp-test", "-DCMAKE_BUILD_TYPE=Release")
    assert "100% tests passed" in out


def test_cpp_under_asan_ubsan():
    out = _build_and_ctest("cpp-asan", "-DINSNAV_SANITIZE=ON", "-DCMAKE_BUILD_TYPE=RelWithDebInfo")
    assert "100% tests passed" in out


def test_free_inertial_example_prints_drift():
    _build_and_ctest("cpp-test", "-DCMAKE_BUILD_TYPE=Release")
    exe = REPO / "build" / "cpp-test" / "cpp" / "examples" / "free_inertial"
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    drift = float(out.split("position drift")[1].split("m")[0])
    assert drift < 1e-3
