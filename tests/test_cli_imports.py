"""What the single point positioning and RTK commands load: only the modules they run.

``insnav run --filter spp`` and ``--filter rtk`` are compared with RTKLIB's ``rnx2rtkp``
as whole processes (bench/gnss_speed.py, bench/rtk_compare.py), so their start-up
counts: every module imported on the way is paid on every run.  The command is run
in a fresh interpreter and its ``sys.modules`` inspected afterwards (no timing: the timings are in
bench/).
"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

SMARTLOC = "smartloc_berlin_potsdamer_platz"

#: third-party packages the GNSS-only path never needs (plots, data frames, optimisation)
HEAVY_PACKAGES = ("scipy", "matplotlib", "pandas", "pyarrow", "yaml", "numba")
#: insnav modules of other commands or file formats
OTHER_INSNAV = ("insnav.analysis", "insnav.sim", "insnav.io.kfgins", "insnav.io.csv_dataset", "insnav.filters.tight",
                "insnav.filters.loose", "insnav.filters.rtk", "insnav.cli.report", "insnav.cli.tune", "insnav.ins")

_PROBE = """
import json, os, sys
from insnav.cli import main
rc = main(sys.argv[2:])
with open(sys.argv[1], "w") as f:
    json.dump(dict(rc=rc, modules=sorted(sys.modules), blas=os.environ.get("OPENBLAS_NUM_THREADS")), f)
"""


def _loaded(tmp_path, argv, env_extra=None) -> dict:
    probe = tmp_path / "modules.json"
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("OPENBLAS_NUM_THREADS",
                                                                          "GOTO_NUM_THREADS", "OMP_NUM_THREADS")}
    env.update(env_extra or {})
    r = subprocess.run([sys.executable, "-c", _PROBE, str(probe), *map(str, argv)], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(probe.read_text())


def test_spp_command_imports_no_heavy_module(shared_data, tmp_path):
    d = shared_data / SMARTLOC
    if not (d / "Berlin_Potsdamer_Platz.obs").is_file():
        pytest.skip(f"{d} not found (the smartLoc data set)")
    out = _loaded(tmp_path, ["run", "--filter", "spp", "--format", "rinex", "--obs", d / "Berlin_Potsdamer_Platz.obs",
                             "--nav", f"{d / 'brdc1580.16n'},{d / 'brdc1580.16g'}", "--out", tmp_path / "spp.csv"])
    assert out["rc"] == 0
    mods = set(out["modules"])
    assert "insnav.filters.spp" in mods and "insnav._core" in mods  # the probe did run the command
    heavy = sorted(m for m in mods if m.split(".")[0] in HEAVY_PACKAGES)
    assert heavy == []
    other = sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in OTHER_INSNAV))
    assert other == []
    assert "tomllib" not in mods  # no --config: no TOML to read
    assert out["blas"] == "1"  # numpy's OpenBLAS without its busy-waiting thread pool


def test_spp_command_with_config_reads_toml(shared_data, tmp_path):
    """The lazy TOML import still serves --config (the same modules otherwise)."""
    d = shared_data / SMARTLOC
    if not (d / "Berlin_Potsdamer_Platz.obs").is_file():
        pytest.skip(f"{d} not found (the smartLoc data set)")
    cfg = tmp_path / "run.toml"
    cfg.write_text('[gnss]\nsystems = "G"\n')
    out = _loaded(tmp_path, ["run", "--filter", "spp", "--format", "rinex", "--obs", d / "Berlin_Potsdamer_Platz.obs",
                             "--nav", d / "brdc1580.16n", "--config", cfg, "--out", tmp_path / "spp.csv"])
    assert out["rc"] == 0 and "tomllib" in out["modules"]
    assert 'systems = "G"' in (tmp_path / "spp.csv.config.toml").read_text()


def _rtk_run_modules(shared_data, tmp_path, interpreter_modules, fastpath):
    """The probe's record and the modules loaded by ``insnav run --filter rtk`` (GPS L1, instantaneous AR) on the MatRTKLIB
    static pair with ``INSNAV_RTK_FASTPATH=fastpath``; the run must succeed."""
    d = shared_data / "matrtklib_static_septentrio"
    if not (d / "rover.obs").is_file():
        pytest.skip(f"{d} not found (the MatRTKLIB static data set)")
    (tmp_path / "rtk.toml").write_text('filter = "rtk"\n\n[rtk]\nar_mode = "instantaneous"\nsystems = "G"\n'
                                       'frequencies = 1\n')
    out = _loaded(tmp_path, ["run", "--filter", "rtk", "--format", "rinex", "--obs", d / "rover.obs", "--base",
                             d / "base.obs", "--nav", d / "base.nav", "--config", tmp_path / "rtk.toml", "--quiet",
                             "--out", tmp_path / "rtk.pos"], {"INSNAV_RTK_FASTPATH": fastpath})
    assert out["rc"] == 0
    return out, set(out["modules"]) - interpreter_modules


def test_rtk_command_loads_only_what_it_runs(shared_data, tmp_path, interpreter_modules):
    """``insnav run --filter rtk`` on its usual path (``INSNAV_RTK_FASTPATH=0``; bench/rtk_compare.py
    times the command as a whole process against rnx2rtkp, and the runs the numpy-free path of
    insnav.cli.rtk_fast does not cover take this one): the RINEX readers, the orbits and the RTK
    engine; not the dataset folder format (insnav.data.dataset: the solution layer imports
    insnav.data.nav only), not the SPP solver (the navigation files are read through gnss.rinex),
    no other filter or command."""
    out, mods = _rtk_run_modules(shared_data, tmp_path, interpreter_modules, fastpath="0")
    assert {"insnav.filters.rtk", "insnav.gnss.rtk", "insnav._core"} <= mods  # the probe did run the command
    assert (tmp_path / "rtk.pos").is_file() and (tmp_path / "rtk.pos.rtk.csv").is_file()
    assert sorted(m for m in mods if m.split(".")[0] in HEAVY_PACKAGES) == []
    free = tuple(p for p in START_UP_FREE if p != "tomllib")  # (--config is a TOML)
    assert sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in free)) == []
    others = tuple(p for p in OTHER_INSNAV if p != "insnav.filters.rtk") + (
        "insnav.data.dataset", "insnav.gnss.spp", "insnav.filters.spp", "insnav.filters.rtk_ins",
        "insnav.io.rinex_dataset", "insnav._imu_scan",  # no IMU: nothing to scan
        "insnav.gnss.constellation")  # the simulator's constellation (insnav.gnss loads its names lazily)
    assert sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in others)) == []
    assert out["blas"] == "1"


def test_rtk_command_without_numpy_loads_neither_numpy_nor_argparse(shared_data, tmp_path, interpreter_modules):
    """The same command on the path of insnav.cli.rtk_fast (GPS, RINEX 3, .pos): one call into the
    compiled core, no numpy, no argparse, none of the Python RTK modules."""
    out, mods = _rtk_run_modules(shared_data, tmp_path, interpreter_modules, fastpath="1")
    assert {"insnav.cli.rtk_fast", "insnav._core", "insnav.gnss._rtk_keys"} <= mods
    assert (tmp_path / "rtk.pos").is_file() and (tmp_path / "rtk.pos.rtk.csv").is_file()
    banned = ("numpy", "argparse", "insnav.gnss.rtk", "insnav.filters", "insnav.config", "insnav.gnss.rinex")
    assert sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in banned)) == []


#: what no run path needs at start-up: numpy.ma (np.median / np.unique import it, ~15 ms;
#: insnav._median replaces them), the thread pool of concurrent.futures and logging
#: (~5 ms) and the TOML reader without a TOML
START_UP_FREE = ("numpy.ma", "concurrent.futures", "logging", "tomllib")


def _modules_after(imports: str) -> set:
    """sys.modules of a fresh interpreter after ``imports`` (Python code)."""
    code = f"import json, sys; {imports}; print(json.dumps(sorted(sys.modules)))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return set(json.loads(r.stdout))


@pytest.fixture(scope="module")
def interpreter_modules() -> set:
    """What the interpreter itself loads at start-up (site hooks may load a decompressor)."""
    return _modules_after("pass")


@pytest.mark.parametrize("module", ["insnav", "insnav.cli", "insnav.cli.run"])
def test_importing_the_package_and_the_run_command_loads_no_heavy_module(module, interpreter_modules):
    mods = _modules_after(f"import {module}") - interpreter_modules
    assert module in mods
    assert sorted(m for m in mods if m.split(".")[0] in HEAVY_PACKAGES) == []
    assert sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in START_UP_FREE)) == []
    assert sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in OTHER_INSNAV)) == []


@pytest.mark.parametrize("out_name", ["sol.csv", "sol.npz"])
def test_kfgins_run_loads_only_what_it_runs(shared_data, tmp_path, out_name, interpreter_modules):
    """``insnav run --format kfgins`` (block by block, for CSV and npz alike):
    the KF-GINS reader and the loose filter, nothing of the other commands."""
    import shutil

    from test_stream import LINES

    sim = shared_data / "kfgins" / "sim"
    if not (sim / "Leador-A15-sim.txt.xz").is_file():
        pytest.skip(f"{sim} not found (the KF-GINS data set)")
    import lzma

    with lzma.open(sim / "Leador-A15-sim.txt.xz", "rb") as f:
        (tmp_path / "imu.txt").write_bytes(b"".join(f.readline() for _ in range(LINES)))
    shutil.copy(sim / "GNSS-RTK-sim.txt", tmp_path / "gnss.txt")
    yaml = "\n".join('imupath: "./imu.txt"' if ln.startswith("imupath:") else
                     'gnsspath: "./gnss.txt"' if ln.startswith("gnsspath:") else ln
                     for ln in (sim / "kf-gins-sim.yaml").read_text().splitlines())
    (tmp_path / "kf.yaml").write_text(yaml + "\n")
    out = _loaded(tmp_path, ["run", "--format", "kfgins", "--config", tmp_path / "kf.yaml", "--quiet",
                             "--out", tmp_path / "out" / out_name])
    assert out["rc"] == 0
    mods = set(out["modules"]) - interpreter_modules
    assert "insnav.io.kfgins" in mods and "insnav._core" in mods  # the probe did run the command
    assert (tmp_path / "out" / out_name).is_file()
    assert sorted(m for m in mods if m.split(".")[0] in HEAVY_PACKAGES) == []
    assert sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in START_UP_FREE)) == []
    others = ("insnav.analysis", "insnav.sim", "insnav.gnss", "insnav.filters.tight", "insnav.filters.rtk",
              "insnav.cli.report", "insnav.cli.tune")
    assert sorted(m for m in mods if any(m == p or m.startswith(p + ".") for p in others)) == []


def test_tight_rinex_run_loads_no_numpy_ma(shared_data, tmp_path, interpreter_modules):
    """The tight GPS + Galileo + BeiDou walk run (bench/gnss_speed.py) without numpy.ma: its medians,
    percentiles and distinct values go through insnav._median."""
    from pathlib import Path

    w = shared_data / "rtklibexplorer_walk_0827"
    if not (w / "rinex_derived" / "gnss_1730.obs").is_file():
        pytest.skip(f"{w} not found (the walk data set)")
    text = (Path(__file__).parent / "data" / "walk_0827.toml").read_text()
    (tmp_path / "gec.toml").write_text(text.replace('systems = "G"\n', 'systems = "GEC"\n'))
    out = _loaded(tmp_path, ["run", "--format", "rinex", "--obs", w / "rinex_derived/gnss_1730.obs", "--nav",
                             w / "rinex_derived/gnss_1730.nav", "--imu", w / "raw/imu_1730.csv", "--coupling", "tight",
                             "--filter", "ekf", "--config", tmp_path / "gec.toml", "--quiet", "--out",
                             tmp_path / "walk.csv"])
    assert out["rc"] == 0
    mods = set(out["modules"]) - interpreter_modules
    assert "insnav.filters.tight" in mods  # the probe did run the command
    assert sorted(m for m in mods if m == "numpy.ma" or m.startswith("numpy.ma.")) == []


def test_percentile_equals_numpy():
    """insnav._median.percentile is np.percentile (method "linear") to the last bit."""
    import numpy as np

    from insnav._median import percentile

    rng = np.random.default_rng(3)
    for trial in range(3000):
        x = rng.normal(size=int(rng.integers(1, 40))) * 10.0 ** rng.uniform(-3, 3)
        if trial % 4 == 0:
            x = np.round(x)  # ties
        for q in (0.0, 5.0, 50.0, 95.0, 100.0, float(rng.uniform(0, 100))):
            assert percentile(x, q) == float(np.percentile(x, q)), (x, q)
    assert np.isnan(percentile([1.0, np.nan, 2.0], 95)) and np.isnan(percentile([], 50))


_VERSION_PROBE = """
import contextlib, io, json, sys
from insnav.cli import main
buf = io.StringIO()
with contextlib.redirect_stdout(buf):
    try:
        rc = main(sys.argv[1:])
    except SystemExit as exc:  # argparse's --version and --help actions
        rc = exc.code
print(json.dumps(dict(rc=rc, out=buf.getvalue(), modules=sorted(sys.modules))))
"""


@pytest.mark.parametrize("argv, areas", [(["--version"], False), (["--debug", "--vers"], False),
                                         (["--help", "--version"], True)])
def test_version_loads_no_command_module(argv, areas, interpreter_modules):
    """``insnav --version`` answers from the top-level parser alone: none of the
    sub-commands' modules, no numpy (``--help`` before it still registers them
    all: argparse prints the help with every command first)."""
    import insnav
    from insnav.cli import _AREAS

    r = subprocess.run([sys.executable, "-c", _VERSION_PROBE, *argv], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["rc"] == 0
    mods = set(out["modules"]) - interpreter_modules
    area_modules = {m for m, _, _ in _AREAS} | {"insnav.cli.run", "insnav.config"}
    if areas:
        assert area_modules <= mods and "numpy" in mods and "run" in out["out"]
    else:
        assert out["out"] == f"insnav {insnav.__version__}\n"
        assert sorted(m for m in mods if m.startswith("insnav")) == ["insnav", "insnav.cli", "insnav.errors"]
        assert sorted(mods & area_modules) == [] and "numpy" not in mods and "argparse" in mods
