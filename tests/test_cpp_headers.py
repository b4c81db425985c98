"""The public C++ headers as an embedding user includes them: through the plain include path (no
CMake target, no -D flags), with -Wall -Wextra -Werror.

* gnss/spp_solver.hpp and gnss/double_difference.hpp both defined ``insnav::gnss::kNumSystems`` (an
  ``int`` of 4 and an enumerator of 5): no program could use single point positioning beside RTK.
* engine/rtk_ins_engine.hpp, gnss/rtk_rinex.hpp and meas/dd_phase.hpp included Eigen before
  gnss/rtk.hpp raised ``EIGEN_STACK_ALLOCATION_LIMIT`` for its fixed-capacity matrices, so each
  failed its static_assert on its own.

Syntax only (no code generated): about 15 s per translation unit."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

import _cpp_build

REPO = Path(__file__).resolve().parents[1]
EIGEN = Path("/usr/include/eigen3")

pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    not (REPO / "cpp" / "include" / "insnav").is_dir() or _cpp_build.compiler() is None or not EIGEN.is_dir(),
    reason="needs the source tree, a C++ compiler and Eigen (libeigen3-dev)")]


def _syntax_check(tmp_path, includes, body="return 0;"):
    src = tmp_path / "tu.cpp"
    src.write_text("".join(f'#include "insnav/{h}"\n' for h in includes) + f"int main() {{ {body} }}\n")
    return subprocess.run([_cpp_build.compiler(), "-std=c++17", "-Wall", "-Wextra", "-Werror", "-fsyntax-only",
                           f"-I{REPO / 'cpp' / 'include'}", f"-I{EIGEN}", str(src)], capture_output=True, text=True)


@pytest.mark.parametrize("header", ["engine/rtk_ins_engine.hpp", "gnss/rtk_rinex.hpp", "meas/dd_phase.hpp"])
def test_a_carrier_phase_header_compiles_on_its_own(tmp_path, header):
    r = _syntax_check(tmp_path, [header])
    assert r.returncode == 0, r.stderr[-3000:]


def test_single_point_and_double_difference_headers_in_one_program(tmp_path):
    r = _syntax_check(tmp_path, ["gnss/spp_solver.hpp", "gnss/double_difference.hpp"],
                      "static_assert(insnav::gnss::kNumSystems == 5 && insnav::gnss::kSppNumSystems == 4); return 0;")
    assert r.returncode == 0, r.stderr[-3000:]
