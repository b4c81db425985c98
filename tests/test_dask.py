"""The Dask distributed Monte Carlo backend against a real local cluster
(a scheduler and two worker processes): the same numbers, run for run, as
the local process backend, from Python and from ``insnav compare``; clear
errors for an unreachable scheduler, a version mismatch and a missing extra."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from conftest import require_module  # noqa: E402

distributed = require_module("distributed", "dask")

import insnav  # noqa: E402
from insnav.cli import main  # noqa: E402

insnav.montecarlo  # noqa: B018  (loads the module behind the lazy attribute)
mc = sys.modules["insnav.analysis.montecarlo"]

FILTERS = ("kf", "rdkf", "ekf")

# 40 s of the seed 001 route (100 Hz IMU, 10 Hz GNSS delayed by 0/1 epoch): a file,
# so the backend has to ship the resolved scenario to the workers.
SHORT_SCENARIO = """\
extends = "seed001-low"
name = "mc-short"
description = "40 s of seed001-low: cruise, accelerate, 90 deg turn"

[[motion.segments]]
duration_s = 10.0
[[motion.segments]]
duration_s = 10.0
target_speed_mps = 20.0
[[motion.segments]]
duration_s = 20.0
heading_change_deg = 90.0
"""


@pytest.fixture(scope="module")
def cluster():
    """Scheduler + 2 single-threaded worker processes, closed at teardown."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address="127.0.0.1:0") as c:  # no fixed port 8787
        yield c


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    p = tmp_path_factory.mktemp("dask") / "short.toml"
    p.write_text(SHORT_SCENARIO, encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def reference(scenario):
    """The same campaign on the local backend (one process: the reference)."""
    return insnav.montecarlo(str(scenario), FILTERS, runs=4, seed=11, workers=1, progress=False)


def _same_runs(a, b):
    assert [(r["index"], r["sim_seed"], r["init_seed"]) for r in a.per_run] == \
           [(r["index"], r["sim_seed"], r["init_seed"]) for r in b.per_run]
    for ra, rb in zip(a.per_run, b.per_run):
        assert ra["metrics"] == rb["metrics"]  # bit for bit, not approximately


def test_dask_matches_local_run_for_run(cluster, scenario, reference):
    res = insnav.montecarlo(str(scenario), FILTERS, runs=4, seed=11, backend="dask",
                            scheduler=cluster.scheduler_address, progress=False)
    _same_runs(res, reference)
    assert res.backend == "dask" and res.scheduler == cluster.scheduler_address
    assert res.workers == 2  # counted on the cluster, not the local CPUs
    assert res.summary == reference.summary
    # the runs are real, different realisations and the physics holds: time-tagged
    # GNSS (ekf) beats the random-delay KF, which beats fixes used as if current (kf)
    v = res.values("kf", "pos_n_rmse_m")
    assert len(set(v.tolist())) == 4
    m = {f: res.summary[f]["pos_n_rmse_m"]["mean"] for f in FILTERS}
    assert m["ekf"] < m["rdkf"] < m["kf"]
    assert 0.05 < m["kf"] < 2.0  # 20 m/s x 0.1 s late fixes: decimetres, not metres


def test_dask_accepts_a_client_and_leaves_it_open(cluster, scenario, reference):
    with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
        res = insnav.montecarlo(str(scenario), FILTERS, runs=2, seed=11, backend="dask", scheduler=client,
                                progress=False)
        assert client.status == "running"
        assert client.submit(sum, [1, 2], pure=False).result() == 3
    assert [r["metrics"] for r in res.per_run] == [r["metrics"] for r in reference.per_run[:2]]


def test_compare_cli_dask(cluster, scenario, reference, capsys):
    rc = main(["compare", str(scenario), "--filters", ",".join(FILTERS), "--runs", "4", "--seed", "11",
               "--backend", "dask", "--scheduler", cluster.scheduler_address, "--json", "--compact"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["backend"] == "dask" and out["scheduler"] == cluster.scheduler_address
    assert [r["metrics"] for r in out["per_run"]] == [r["metrics"] for r in reference.per_run]


def test_worker_errors_come_back(cluster, scenario):
    with pytest.raises(ValueError, match="nope"):
        insnav.montecarlo(str(scenario), ("nope",), runs=2, seed=1, backend="dask",
                          scheduler=cluster.scheduler_address, progress=False)


def test_version_mismatch_refused(cluster, scenario, monkeypatch):
    monkeypatch.setattr(insnav, "__version__", "0.0.0-not-the-workers")
    with pytest.raises(mc.BackendError, match="another insnav version"):
        insnav.montecarlo(str(scenario), ("kf",), runs=1, backend="dask", scheduler=cluster.scheduler_address,
                          progress=False)


def test_unreachable_scheduler_is_one_line(scenario, capsys):
    import socket

    with socket.socket() as s:  # a free port that nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    addr = f"tcp://127.0.0.1:{port}"
    rc = main(["compare", str(scenario), "--runs", "1", "--filters", "kf", "--scheduler", addr])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and addr in err and "no Dask scheduler" in err
    rc = main(["compare", str(scenario), "--runs", "1", "--filters", "kf", "--backend", "dask",
               "--scheduler", "no-port-here"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "no-port-here" in err and "\n" not in err
    rc = main(["compare", str(scenario), "--runs", "1", "--backend", "local", "--scheduler", addr])
    assert rc == 2 and "--backend dask" in capsys.readouterr().err
    with pytest.raises(ValueError, match="takes no scheduler"):
        insnav.montecarlo(str(scenario), ("kf",), runs=1, backend="serial", scheduler=addr)


def test_missing_distributed_names_the_extra(scenario, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(ImportError, match=r"pip install 'insnav\[dask\]'"):
        insnav.montecarlo(str(scenario), ("kf",), runs=1, backend="dask")
    rc = main(["compare", str(scenario), "--runs", "1", "--filters", "kf", "--backend", "dask"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "insnav[dask]" in err and "\n" not in err


def test_dask_without_scheduler_starts_a_local_cluster(scenario, reference, monkeypatch):
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    import dask

    with dask.config.set({"scheduler-address": None}):
        res = insnav.montecarlo(str(scenario), FILTERS, runs=2, seed=11, workers=1, backend="dask",
                                progress=False)
    assert res.scheduler.startswith("tcp://127.0.0.1:") and res.workers == 1
    assert [r["metrics"] for r in res.per_run] == [r["metrics"] for r in reference.per_run[:2]]


@pytest.fixture(scope="module")
def separate_cluster(tmp_path_factory):
    """The recipe of a real cluster, on loopback: ``dask scheduler`` and two
    ``dask worker`` processes started as separate programs (no nanny, one
    thread each), the workers in a directory of their own.  Yields the
    scheduler address; the processes are stopped at teardown."""
    import os
    import subprocess
    import time

    work = tmp_path_factory.mktemp("dask-cluster")
    sched_file = work / "scheduler.json"
    logs = [open(work / f"{name}.log", "wb") for name in ("scheduler", "worker0", "worker1")]
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(sched_file)], cwd=work,
                              stdout=subprocess.DEVNULL, stderr=logs[0])]
    try:
        t_end = time.monotonic() + 60
        while not (sched_file.exists() and sched_file.stat().st_size) and time.monotonic() < t_end:
            assert procs[0].poll() is None, (work / "scheduler.log").read_text()[-2000:]
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        for i in range(2):
            wdir = work / f"worker{i}"
            wdir.mkdir()
            procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--no-nanny",
                                           "--nthreads", "1", "--no-dashboard", "--name", f"w{i}",
                                           "--local-directory", str(wdir)], cwd=wdir,
                                          stdout=subprocess.DEVNULL, stderr=logs[1 + i]))
        with distributed.Client(address, set_as_default=False) as client:
            client.wait_for_workers(2, timeout=60)
        yield address, procs
    finally:
        # the workers first, while their scheduler still answers: a worker whose
        # scheduler is gone retries it and outlives SIGTERM (the 30 s timeout below)
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for f in logs:
            f.close()


def test_separate_processes_cluster_matches_local(separate_cluster, scenario, reference, monkeypatch, capsys):
    """insnav compare --backend dask --scheduler tcp://... against a scheduler and two
    workers that are separate programs: the scenario is a path RELATIVE to the
    client's directory, which the workers (in directories of their own) cannot
    resolve, so the numbers can only come from the scenario the client shipped;
    they equal the local backend's run for run."""
    import os

    address, procs = separate_cluster
    monkeypatch.chdir(scenario.parent)
    rel = scenario.name
    with distributed.Client(address, set_as_default=False) as client:
        pids = client.run(os.getpid)
        cwds = client.run(os.getcwd)
    assert len(set(pids.values())) == 2 and os.getpid() not in pids.values()
    assert {p.pid for p in procs[1:]} == set(pids.values())  # the workers are the processes started here
    assert all(not (Path(c) / rel).exists() for c in cwds.values())  # the file is not where they run
    rc = main(["compare", rel, "--filters", ",".join(FILTERS), "--runs", "4", "--seed", "11",
               "--backend", "dask", "--scheduler", address, "--json", "--compact"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["backend"] == "dask" and out["scheduler"] == address and out["workers"] == 2
    assert [r["metrics"] for r in out["per_run"]] == [r["metrics"] for r in reference.per_run]
    assert out["summary"] == json.loads(json.dumps(reference.summary))
