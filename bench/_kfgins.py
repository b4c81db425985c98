"""KF-GINS built in Release on this machine, for side-by-side timing (not part of the package).

KF-GINS (i2Nav-WHU, GPL-3.0) is the reference EKF GNSS/INS program for the KF-GINS track.  It is not
vendored: ``python bench/_kfgins.py`` clones it at a pinned commit into ``build/kfgins-src`` (or takes
``--src DIR``, an existing checkout) and builds it with its own CMake project in Release
(``-O3 -DNDEBUG``, the compiler CMake finds: g++, as KF-GINS's README recommends).  The bench scripts
then find the binary with :func:`find_kfgins`; ``INSNAV_KFGINS_BIN`` points them at another build.

    python bench/_kfgins.py [--src DIR]
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

from _common import ROOT

KFGINS_URL = "https://github.com/i2Nav-WHU/KF-GINS"
KFGINS_COMMIT = "f39bc2e7be8a47eb3bf8ba1dbcb0bf4e7a3edd6a"
BUILD = ROOT / "build" / "kfgins"
BINARY = BUILD / "KF-GINS"


def find_kfgins() -> Path | None:
    """The KF-GINS binary to time: ``$INSNAV_KFGINS_BIN``, else the one :func:`build_kfgins` made."""
    env = os.environ.get("INSNAV_KFGINS_BIN")
    if env:
        p = Path(env)
        if not (p.is_file() and os.access(p, os.X_OK)):
            raise SystemExit(f"INSNAV_KFGINS_BIN={env}: not an executable file")
        return p
    return BINARY if BINARY.is_file() else None


def kfgins_commit(src: Path) -> str:
    r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=src, capture_output=True, text=True)
    return r.stdout.strip() if r.returncode == 0 else "unknown"


def build_kfgins(src: Path | None = None) -> Path:
    """Build KF-GINS in Release and copy the binary to ``build/kfgins/KF-GINS``; returns its path."""
    if src is None:
        src = ROOT / "build" / "kfgins-src"
        if not (src / "CMakeLists.txt").is_file():
            subprocess.run(["git", "clone", "--quiet", KFGINS_URL, str(src)], check=True)
            subprocess.run(["git", "checkout", "--quiet", KFGINS_COMMIT], cwd=src, check=True)
    src = src.resolve()
    if not (src / "src" / "kf_gins.cpp").is_file():
        raise SystemExit(f"{src}: not a KF-GINS checkout (src/kf_gins.cpp missing)")
    cmake_dir = BUILD / "cmake"
    cmake_dir.mkdir(parents=True, exist_ok=True)
    # KF-GINS's bundled yaml-cpp 0.7.0 asks for CMake < 3.5, which CMake 4 refuses without this
    subprocess.run(["cmake", "-S", str(src), "-B", str(cmake_dir), "-DCMAKE_BUILD_TYPE=Release",
                    "-DCMAKE_POLICY_VERSION_MINIMUM=3.5"], check=True, stdout=subprocess.DEVNULL)
    subprocess.run(["cmake", "--build", str(cmake_dir), "--target", "KF-GINS", "-j2"], check=True,
                   stdout=subprocess.DEVNULL)
    built = src / "bin" / "KF-GINS"  # KF-GINS's CMakeLists sets EXECUTABLE_OUTPUT_PATH to its bin/
    shutil.copy2(built, BINARY)
    (BUILD / "COMMIT").write_text(kfgins_commit(src) + "\n")
    return BINARY


def built_commit() -> str:
    f = BUILD / "COMMIT"
    return f.read_text().strip() if f.is_file() else "unknown"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--src", type=Path, help="an existing KF-GINS checkout (default: clone it)")
    a = ap.parse_args()
    print(build_kfgins(a.src))
    return 0


if __name__ == "__main__":
    sys.exit(main())
