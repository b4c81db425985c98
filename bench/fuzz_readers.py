"""Long coverage-guided fuzz run of the readers (atheris / libFuzzer).

Targets (``--target``): ``imu_csv`` (insnav dataset imu.csv via read_csv +
row checks), ``kfgins_imu``, ``kfgins_gnss``, ``kfgins_yaml``, ``rinex_nav``,
``rinex_obs``, ``run_toml`` (RunConfig TOML), ``scenario_toml``,
``kfgins_run_imu`` / ``_gnss`` / ``_yaml`` (the file loaded with the other two
valid ones and run: ``load_kfgins`` + ``insnav.run``), ``tables_toml`` (the
run TOML with the ``[imu]``, ``[gnss]``, ``[initial]``, ``[align]`` and
``[rinex]`` tables).  The input
bytes become the file; the property is that the reader returns or raises
``ValueError`` (``RinexError``, ``ConfigError``, ``ScenarioError`` are
subclasses) -- any other exception is a finding and stops the run.

    pip install atheris
    python bench/fuzz_readers.py --target kfgins_imu -atheris_runs=200000
    python bench/fuzz_readers.py --all --seconds 60      # each target for 60 s

Without atheris the same targets run under hypothesis (random, not
coverage-guided) for ``--seconds``.  The short fixed-budget version is
tests/test_fuzz_readers.py.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TMP = Path(tempfile.mkdtemp(prefix="insnav-fuzz-"))
REPO = Path(__file__).resolve().parents[1]


def _write(name: str, data: bytes) -> Path:
    p = TMP / name
    p.write_bytes(data)
    return p


def _imu_csv(data):
    from insnav.data.dataset import ImuData, check_finite_rows, read_csv

    a, origin = read_csv(_write("imu.csv", b"t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps\n"
                                + data), ImuData.COLUMNS, return_origin=True)
    check_finite_rows(a, origin, ImuData.COLUMNS)
    from insnav.filters.sanitize import sanitize_imu

    sanitize_imu(ImuData.from_array(a))


def _kfgins(kind):
    def f(data):
        from insnav.io import kfgins

        p = _write({"imu": "imu.txt", "gnss": "gnss.txt", "yaml": "kf-gins.yaml"}[kind], data)
        r = {"imu": kfgins.read_kfgins_imu, "gnss": kfgins.read_kfgins_gnss, "yaml": kfgins.read_kfgins_config}[kind]
        out = r(p)
        if kind == "imu":
            from insnav.filters.sanitize import sanitize_imu

            sanitize_imu(out)
    return f


def _rinex(kind):
    def f(data):
        from insnav.gnss import read_rinex_nav, read_rinex_obs

        (read_rinex_nav if kind == "nav" else read_rinex_obs)(_write(f"f.{kind}", data))
    return f


def _run_toml(data):
    from insnav.config import load_config

    load_config(_write("run.toml", data))


def _scenario_toml(data):
    from insnav.sim.scenario import load_scenario

    load_scenario(_write("scenario.toml", data))


_KF = {}


def _kfgins_files():
    """A valid 3 s KF-GINS set (YAML, IMU, GNSS) from the seed000 simulation, written once."""
    if not _KF:
        import insnav
        from insnav.io import kfgins

        ds = insnav.simulate("seed000-sim", seed=1)
        n = 600
        ds.imu = type(ds.imu)(ds.imu.t[:n], ds.imu.dtheta_b[:n], ds.imu.dv_b[:n])
        ds.gnss = type(ds.gnss).from_array(ds.gnss.to_array()[:3])
        kfgins.write_kfgins_imu(TMP / "base_imu.txt", ds.imu)
        kfgins.write_kfgins_gnss(TMP / "base_gnss.txt", ds.gnss)
        i = ds.initial
        _KF["yaml"] = (f"imupath: imu.txt\ngnsspath: gnss.txt\noutputpath: out\nimudatalen: 7\nimudatarate: 200\n"
                       f"starttime: {ds.t0}\nendtime: -1\ninitpos: [{i.lat_deg}, {i.lon_deg}, {i.h_m}]\n"
                       f"initvel: [0, 0, 0]\ninitatt: [{i.roll_deg}, {i.pitch_deg}, {i.yaw_deg}]\n"
                       "imunoise:\n  arw: [0.2, 0.2, 0.2]\n  vrw: [0.4, 0.4, 0.4]\n  corrtime: 1.0\n"
                       "antlever: [0.1, 0.2, 0.3]\n").encode()
        _KF["imu"] = (TMP / "base_imu.txt").read_bytes()
        _KF["gnss"] = (TMP / "base_gnss.txt").read_bytes()
    return _KF


def _kfgins_run(kind):
    """The input bytes as one of the three KF-GINS files (the others valid), loaded and run:
    an empty IMU file, an endtime before starttime, a lever arm in mm or a GNSS sigma of 1e155
    must end in a ValueError naming the file and key or line, never IndexError / FloatingPointError."""
    def f(data):
        import insnav
        from insnav.io.kfgins_dataset import load_kfgins

        files = dict(_kfgins_files())
        files[kind] = data
        _write("imu.txt", files["imu"])
        _write("gnss.txt", files["gnss"])
        ds, cfg = load_kfgins(_write("kf-gins.yaml", files["yaml"]))
        insnav.run(ds, config=cfg)
    return f


def _tables_toml(data):
    """The input bytes as a run TOML with the --format csv and --format rinex tables."""
    import tomllib

    from insnav.config import config_from_dict
    from insnav.io.csv_dataset import load_csv_run
    from insnav.io.rinex_dataset import RinexOptions

    d = tomllib.loads(data.decode("utf-8", "replace"))
    rin = d.pop("rinex", None)
    if isinstance(rin, dict):
        RinexOptions.from_dict(rin)
    run = {k: v for k, v in d.items() if k not in ("imu", "gnss", "initial", "align")}
    config_from_dict(run, source="run.toml")
    load_csv_run(TMP / "missing-imu.csv", TMP / "missing-gnss.csv", d)  # the tables are checked before the files


TARGETS = {"imu_csv": _imu_csv, "kfgins_imu": _kfgins("imu"), "kfgins_gnss": _kfgins("gnss"),
           "kfgins_yaml": _kfgins("yaml"), "rinex_nav": _rinex("nav"), "rinex_obs": _rinex("obs"),
           "run_toml": _run_toml, "scenario_toml": _scenario_toml, "kfgins_run_imu": _kfgins_run("imu"),
           "kfgins_run_gnss": _kfgins_run("gnss"), "kfgins_run_yaml": _kfgins_run("yaml"),
           "tables_toml": _tables_toml}


def one_input(target):
    fn = TARGETS[target]

    def test(data: bytes):
        try:
            fn(data)
        except (ValueError, FileNotFoundError, RecursionError):
            pass  # the documented errors (RecursionError: tomllib on pathological nesting)
    return test


def _run_atheris(target, argv):
    import atheris

    with atheris.instrument_imports():
        import insnav.config  # noqa: F401
        import insnav.data.dataset  # noqa: F401
        import insnav.gnss.rinex  # noqa: F401
        import insnav.io.kfgins  # noqa: F401
        import insnav.filters.sanitize  # noqa: F401
        import insnav.sim.scenario  # noqa: F401
        import insnav.io.kfgins_dataset  # noqa: F401
        import insnav.io.csv_dataset  # noqa: F401
        import insnav.io.rinex_dataset  # noqa: F401
    atheris.Setup([sys.argv[0], *argv], one_input(target))
    atheris.Fuzz()


def _run_hypothesis(target, seconds):
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    n = 0
    t_end = time.time() + seconds

    @settings(max_examples=10**9, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(st.binary(max_size=4096))
    def run(data):
        nonlocal n
        n += 1
        if time.time() > t_end:
            raise KeyboardInterrupt
        one_input(target)(data)

    try:
        run()
    except KeyboardInterrupt:
        pass
    print(f"{target}: {n} inputs in {seconds} s (hypothesis), no finding")


def main():
    args = sys.argv[1:]
    seconds = 60
    if "--seconds" in args:
        i = args.index("--seconds")
        seconds = int(args[i + 1])
        del args[i:i + 2]
    if "--all" in args:
        args.remove("--all")
        for t in TARGETS:
            r = subprocess.run([sys.executable, __file__, "--target", t, f"-max_total_time={seconds}",
                                "--seconds", str(seconds), *args], capture_output=True, text=True)
            tail = [ln for ln in (r.stdout + r.stderr).splitlines() if "Done" in ln or "no finding" in ln
                    or "Uncaught" in ln or "Error" in ln][-3:]
            print(f"{t}: exit {r.returncode}; " + " | ".join(tail), flush=True)
        return
    i = args.index("--target")
    target = args[i + 1]
    del args[i:i + 2]
    try:
        import atheris  # noqa: F401
    except ImportError:
        _run_hypothesis(target, seconds)
        return
    _run_atheris(target, args)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
