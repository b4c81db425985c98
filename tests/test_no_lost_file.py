"""No input may cost the user a file.

``insnav run`` (and ``report``, ``evaluate --out``) refuses an output that is
one of its inputs (symbolic and hard links followed) or an existing file
insnav did not write (unless ``--overwrite``), before the run; it writes every
output to a temporary file and renames them all at the end, so a failed run
(a full disk, Ctrl-C) leaves every earlier file exactly as it was."""
import errno
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import insnav
from insnav.cli import main


@pytest.fixture(scope="module")
def ds_dir(tmp_path_factory):
    from insnav.sim.scenario import resolve_raw

    raw, _ = resolve_raw("seed000-sim")
    raw["motion"]["segments"] = [{"duration_s": 20.0}]
    raw["motion"].pop("oscillations", None)
    raw["gnss"]["outages"] = []
    return insnav.simulate(raw, seed=1).save(tmp_path_factory.mktemp("nlf") / "ds")


def _run(capsys, *argv):
    rc = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return rc, out, err


def _snapshot(folder):
    """name -> bytes of every file in ``folder``."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize("target", ["imu.csv", "gnss.csv", "truth.csv", "link", "hardlink"])
def test_run_refuses_an_output_that_is_an_input(tmp_path, ds_dir, capsys, target):
    before = _snapshot(ds_dir)
    if target == "link":
        out = tmp_path / "sol.csv"
        out.symlink_to(ds_dir / "imu.csv")
    elif target == "hardlink":
        out = tmp_path / "sol.csv"
        os.link(ds_dir / "gnss.csv", out)
    else:
        out = ds_dir / target
    rc, _, err = _run(capsys, "run", ds_dir, "--out", out, "--overwrite")
    assert rc == 2 and "is an input of this run" in err and len(err.strip().splitlines()) == 1, err
    assert _snapshot(ds_dir) == before


def test_run_refuses_to_replace_a_users_file_unless_overwrite(tmp_path, ds_dir, capsys):
    notes = tmp_path / "notes.csv"
    notes.write_text("my,notes\n1,2\n")
    rc, _, err = _run(capsys, "run", ds_dir, "--out", notes)
    assert rc == 2 and f"{notes} exists and is not a file insnav wrote" in err and "--overwrite" in err, err
    assert notes.read_text() == "my,notes\n1,2\n"
    # a sidecar name taken by a user's file counts too
    sol = tmp_path / "sol.csv"
    side = tmp_path / "sol.csv.config.toml"
    side.write_text("[my]\nkey = 1\n")
    rc, _, err = _run(capsys, "run", ds_dir, "--out", sol)
    assert rc == 2 and f"{side} exists" in err and not sol.exists(), err
    side.unlink()
    # an insnav solution (and its sidecars) is replaced without --overwrite; a user's file with it
    rc, _, err = _run(capsys, "run", ds_dir, "--out", sol)
    assert rc == 0, err
    rc, _, err = _run(capsys, "run", ds_dir, "--out", sol, "--seed", "3")
    assert rc == 0, err
    rc, _, err = _run(capsys, "run", ds_dir, "--out", notes, "--overwrite")
    assert rc == 0 and notes.read_text().startswith("t_s,lat_deg,"), err


@pytest.mark.parametrize("side", [".rtk.pos", ".rtk.csv"])
def test_rtk_ins_refuses_to_replace_a_users_file_under_its_sidecars_name(tmp_path, ds_dir, capsys, monkeypatch,
                                                                        side):
    """``--coupling rtk`` also writes ``<out>.rtk.pos`` and ``<out>.rtk.csv``: a user's file (or
    RTKLIB's own .pos) under either name is refused before the run, its bytes unchanged."""
    ran = []
    monkeypatch.setattr(insnav, "run", lambda *a, **kw: ran.append(1))
    theirs = tmp_path / f"sol.csv{side}"
    theirs.write_bytes(b"% program   : RTKPOST ver.2.4.3 b34\n" if side == ".rtk.pos" else b"my,notes\n")
    before = _snapshot(tmp_path)
    obs = tmp_path / "rover.obs"  # not read: the outputs are checked first
    rc, _, err = _run(capsys, "run", ds_dir, "--coupling", "rtk", "--obs", obs, "--base", obs, "--nav", obs,
                      "--out", tmp_path / "sol.csv")
    assert rc == 2 and err == (f"insnav run: error: {theirs} exists and is not a file insnav wrote: not replaced "
                               "(choose another --out, or --overwrite to replace it)\n"), err
    assert _snapshot(tmp_path) == before and not ran


def test_unwritable_folder_fails_before_the_run(tmp_path, ds_dir, capsys, monkeypatch):
    import insnav.filters as filters_pkg

    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    if os.access(ro, os.W_OK) and os.geteuid() == 0:  # root writes anyway: make the probe fail instead
        import tempfile

        def no_space(*a, **kw):
            raise OSError(errno.EROFS, "Read-only file system")

        monkeypatch.setattr(tempfile, "mkstemp", no_space)
    ran = []
    monkeypatch.setattr(insnav, "run", lambda *a, **kw: ran.append(1))
    rc, _, err = _run(capsys, "run", ds_dir, "--out", ro / "sol.csv")
    assert rc == 2 and f"cannot write into {ro}" in err and not ran, err
    del filters_pkg


def _fail_on(monkeypatch, name):
    """Make the write of the output file ``name`` (or ``*name`` for a sidecar)
    fail with ENOSPC once its data are written, as a full disk does at close:
    the hook is the mode fix-up every atomic write makes of its finished
    temporary file ``.NAME.XXXXXXXX.part*``."""
    import re

    from insnav import _atomic

    real = _atomic.chmod_like_new
    pat = re.compile(rf"\.(.*{re.escape(name[1:])}|{re.escape(name)})\.[a-z0-9_]{{8}}\.part.*" if name.startswith(".")
                     else rf"\.{re.escape(name)}\.[a-z0-9_]{{8}}\.part.*")

    def chmod(path, directory=False):
        if pat.fullmatch(Path(path).name):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, directory)

    monkeypatch.setattr(_atomic, "chmod_like_new", chmod)


@pytest.mark.parametrize("fmt", ["csv", "npz", "kfgins"])
@pytest.mark.parametrize("failing", ["solution", ".innovations.csv", ".config.toml"])
def test_a_failed_write_leaves_every_earlier_file_as_it_was(tmp_path, ds_dir, capsys, monkeypatch, fmt, failing):
    if fmt == "kfgins":
        out, args = tmp_path / "kf", ("--out-format", "kfgins")
        sol_name = "KF_GINS_IMU_ERR.txt"  # the second of its three files
    else:
        out, args = tmp_path / f"sol.{fmt}", ()
        sol_name = f"sol.{fmt}"
    rc, _, err = _run(capsys, "run", ds_dir, "--out", out, *args)
    assert rc == 0, err
    folder = out if fmt == "kfgins" else tmp_path
    before = _snapshot(folder)
    assert len(before) >= 3
    _fail_on(monkeypatch, sol_name if failing == "solution" else failing)
    rc, _, err = _run(capsys, "run", ds_dir, "--out", out, "--seed", "5", *args)
    assert rc == 2 and "No space left on device" in err, err
    assert _snapshot(folder) == before  # every old file, byte for byte; no temporary file left
    monkeypatch.undo()
    rc, _, err = _run(capsys, "run", ds_dir, "--out", out, "--seed", "5", *args)
    assert rc == 0 and _snapshot(folder).keys() == before.keys() and _snapshot(folder) != before


def test_a_failed_first_run_leaves_nothing(tmp_path, ds_dir, capsys, monkeypatch):
    _fail_on(monkeypatch, ".config.toml")
    rc, _, err = _run(capsys, "run", ds_dir, "--out", tmp_path / "new" / "kf", "--out-format", "kfgins")
    assert rc == 2, err
    assert list(tmp_path.iterdir()) == []  # not even the folders it made
    rc, _, err = _run(capsys, "run", ds_dir, "--out", tmp_path / "sol.csv")
    assert rc == 2 and list(tmp_path.iterdir()) == [], err
    rc, _, err = _run(capsys, "run", ds_dir, "--out", tmp_path / "a" / "b" / "sol.npz")
    assert rc == 2 and list(tmp_path.iterdir()) == [], err


_LEVELS = textwrap.dedent("""
    import json, os, resource, signal, sys
    from pathlib import Path
    from insnav.cli import main

    ds, out, argv = sys.argv[1], Path(sys.argv[2]), json.loads(sys.argv[4])
    folder = out.parent
    original = {p.name: p.read_bytes() for p in folder.iterdir()}
    res = []
    for limit in json.loads(sys.argv[3]):
        for p in folder.iterdir():
            p.unlink()
        for name, b in original.items():
            (folder / name).write_bytes(b)
        pid = os.fork()
        if pid == 0:  # every file this process writes is cut at `limit` bytes: EFBIG, as ENOSPC on a full disk
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
            sys.stdout = sys.stderr = open(os.devnull, "w")
            os._exit(main(["run", ds, "--out", str(out), "--seed", "9"] + argv))
        _, st = os.waitpid(pid, 0)
        now = {p.name: p.read_bytes() for p in folder.iterdir()}
        res.append(dict(limit=limit, rc=os.waitstatus_to_exitcode(st), unchanged=now == original,
                        names=sorted(now), new=sorted(k for k in now if now[k] != original.get(k))))
    print(json.dumps(res))
""")


def test_no_file_is_lost_at_any_free_space_level(tmp_path, ds_dir, capsys):
    """13 file-size limits (RLIMIT_FSIZE: a write past it fails, as on a full
    disk) from a few bytes to above the largest output, each a forked run over
    an earlier solution whose sidecars are larger than the solution (written at
    0.5 Hz against 1 Hz fixes, so a limit between their sizes fails the
    innovations file after the solution was written): each failed run leaves
    the old files byte for byte, each successful one replaces all of them."""
    out = tmp_path / "run" / "sol.csv"
    argv = ["--output-rate", "0.5", "--columns", "nav"]
    rc, _, err = _run(capsys, "run", ds_dir, "--out", out, *argv)
    assert rc == 0, err
    sizes = sorted(p.stat().st_size for p in out.parent.iterdir())
    assert sizes[-1] == (out.parent / "sol.csv.innovations.csv").stat().st_size > out.stat().st_size
    levels = sorted({10, 4 * sizes[-1], 8 * sizes[-1]} | {s + d for s in sizes for d in (-50, -1, 1, 50)})[:13]
    levels[-1] = 8 * sizes[-1]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join(sys.path))
    r = subprocess.run([sys.executable, "-c", _LEVELS, str(ds_dir), str(out), json.dumps(levels), json.dumps(argv)],
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout)
    assert len(res) == 13
    names = sorted(p.name for p in out.parent.iterdir())
    for x in res:
        assert x["rc"] in (0, 2), x
        if x["rc"] == 2:
            assert x["unchanged"], x  # not one byte of the earlier files lost or changed, no temporary file left
        else:
            assert x["names"] == names and x["new"] == names, x  # every file the new one
    assert res[0]["rc"] == 2 and res[-1]["rc"] == 0
    between = [x for x in res if out.stat().st_size < x["limit"] < sizes[-1]]
    assert between and all(x["rc"] == 2 for x in between)  # the solution fitted, the innovations did not


def test_parquet_without_pyarrow_fails_before_the_run(tmp_path, ds_dir, capsys, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_pyarrow(name, *a, **kw):
        if name == "pyarrow" or name.startswith("pyarrow."):
            raise ImportError("No module named 'pyarrow'")
        return real_import(name, *a, **kw)

    monkeypatch.setattr(builtins, "__import__", no_pyarrow)
    ran = []
    monkeypatch.setattr(insnav, "run", lambda *a, **kw: ran.append(1))
    rc, _, err = _run(capsys, "run", ds_dir, "--out", tmp_path / "sol.parquet")
    assert rc == 2 and "pyarrow" in err and not ran and not list(tmp_path.iterdir()), err


def test_what_counts_as_insnavs_own_file(tmp_path, ds_dir, capsys):
    """A solution of any --columns groups is insnav's; KF-GINS result files are
    insnav's only beside the configuration insnav writes with them (without it
    they are KF-GINS's own results, not replaced without --overwrite)."""
    sol = tmp_path / "bias.csv"
    rc, _, err = _run(capsys, "run", ds_dir, "--out", sol, "--columns", "bias")
    assert rc == 0, err
    rc, _, err = _run(capsys, "run", ds_dir, "--out", sol, "--columns", "sigma")
    assert rc == 0, err
    kf = tmp_path / "kf"
    rc, _, err = _run(capsys, "run", ds_dir, "--out", kf, "--out-format", "kfgins")
    assert rc == 0, err
    rc, _, err = _run(capsys, "run", ds_dir, "--out", kf, "--out-format", "kfgins", "--seed", "2")
    assert rc == 0, err
    (kf / "KF_GINS_Navresult.nav.config.toml").unlink()  # now it looks like KF-GINS's own output folder
    before = _snapshot(kf)
    rc, _, err = _run(capsys, "run", ds_dir, "--out", kf, "--out-format", "kfgins")
    assert rc == 2 and "KF_GINS_Navresult.nav exists and is not a file insnav wrote" in err, err
    assert _snapshot(kf) == before
    rc, _, err = _run(capsys, "run", ds_dir, "--out", kf, "--out-format", "kfgins", "--overwrite")
    assert rc == 0 and (kf / "KF_GINS_Navresult.nav.config.toml").is_file(), err


@pytest.mark.parametrize("fmt", ["csv", "kfgins"])
def test_format_csv_and_kfgins_refuse_their_own_inputs(tmp_path, capsys, fmt):
    """`--out my_imu.csv` with `--imu my_imu.csv` (and the GNSS file): refused
    before anything is read, even with --overwrite."""
    imu, gnss, cfg = tmp_path / "my_imu.csv", tmp_path / "fixes.csv", tmp_path / "run.toml"
    for p in (imu, gnss, cfg):
        p.write_text("anything\n")
    if fmt == "kfgins":  # the YAML's data files are inputs too, and the solution's sidecars count
        cfg = tmp_path / "kf.yaml"
        cfg.write_text('imupath: "./my_imu.csv"\ngnsspath: "./fixes.csv"\n')
        argv = ["--format", "kfgins", "--config", cfg]
        targets = [imu, gnss]
        os.link(imu, tmp_path / "sol.csv.innovations.csv")
        targets.append(tmp_path / "sol.csv")
    else:
        argv = ["--format", "csv", "--imu", imu, "--gnss", gnss, "--config", cfg]
        targets = [imu, gnss]
    for out in targets:
        rc, _, err = _run(capsys, "run", *argv, "--out", out, "--overwrite")
        assert rc == 2 and "is an input of this run" in err, err
    assert imu.read_text() == gnss.read_text() == "anything\n"
