"""The whole command line on the KF-GINS track against the filter alone.

Each variant is a fresh ``python -m insnav run --format kfgins ... --quiet
--timings`` process (process start, imports, read, filter, write), timed
around the process; its peak RSS comes from ``os.wait4`` (the child's own
rusage).  The filter-only figures are in-process calls of ``insnav.run`` on
the already-read dataset (sanitize, checks, C++ loop, output arrays) and of
the compiled loop alone (``_core.run_loose``, timed through a thin wrapper).
The variants and the filter-only calls are interleaved, round by round, so
they see the same machine load; medians over --repeat rounds.  The
variants with ``--stream off`` read the IMU file whole (the path before the
block-by-block run; the others stream, insnav.filters.stream), for the A/B
of the two.  Then, once each, the bounded-memory rows: a synthesised
recording of ``--day-hours`` (default 24 h at 200 Hz, about 2 GB of text
under the temporary folder, deleted at the end; the 5.5 GB all-columns CSV
too) run block by block at 10 Hz and 200 Hz output.  KF-GINS itself, built
in Release on this machine (``python bench/_kfgins.py``; ``INSNAV_KFGINS_BIN``
for another build), runs in every round beside the variants on the same
files, and the document divides its CPU time by each variant's.  Writes
docs/results/cli_end_to_end.md.

    python bench/cli_end_to_end.py [--repeat 5] [--day-hours 24]
    python bench/cli_end_to_end.py --repeat 1 --day-hours 0.1 --out /tmp/e2e.md   # a quick check
    python bench/cli_end_to_end.py --day-only --out /tmp/day.md   # the bounded-memory rows alone
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import ROOT, compile_package, git_commit
from _kfgins import build_kfgins, built_commit, find_kfgins
from _stamps import with_stamp  # noqa: E402

SIM = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data")) / "kfgins" / "sim"
IMU_XZ = SIM / "Leador-A15-sim.txt.xz"

#: (label, extra arguments, output name); the filter is EKF unless the label says otherwise
VARIANTS = [
    ("EKF, CSV, 200 Hz, all columns", [], "sol.csv"),
    ("EKF, npz, 200 Hz", [], "sol.npz"),
    ("EKF, Parquet, 200 Hz", [], "sol.parquet"),
    ("EKF, CSV, 10 Hz", ["--output-rate", "10"], "sol10.csv"),
    ("EKF, npz, 10 Hz", ["--output-rate", "10"], "sol10.npz"),
    ("EKF, CSV, 200 Hz, nav columns only", ["--columns", "nav"], "nav.csv"),
    ("EKF, KF-GINS layout (.nav + IMU_ERR), 200 Hz", ["--out-format", "kfgins"], "kfgins_out"),
    ("EKF, CSV, 200 Hz, IMU read from the .xz", ["--imu", str(IMU_XZ)], "solxz.csv"),
    ("RB-UKF, CSV, 200 Hz", ["--filter", "rbukf"], "rbukf.csv"),
    ("EKF, CSV, 200 Hz, IMU file read whole (--stream off)", ["--stream", "off"], "whole.csv"),
    ("EKF, npz, 200 Hz, IMU file read whole (--stream off)", ["--stream", "off"], "whole.npz"),
    ("EKF, CSV, 10 Hz, IMU file read whole (--stream off)", ["--output-rate", "10", "--stream", "off"],
     "whole10.csv"),
]
#: the long-recording rows: (label, extra arguments, output name), run once each on a synthesised day
DAY_VARIANTS = [
    ("EKF, CSV, 10 Hz (block by block)", ["--output-rate", "10"], "day10.csv"),
    ("EKF, npz, 10 Hz (block by block)", ["--output-rate", "10"], "day10.npz"),
    ("EKF, Parquet, 10 Hz (block by block)", ["--output-rate", "10"], "day10.parquet"),
    ("EKF, KF-GINS layout, 10 Hz (block by block)", ["--output-rate", "10", "--out-format", "kfgins"], "day10_kf"),
    ("EKF, CSV, 200 Hz, nav columns (block by block)", ["--columns", "nav"], "day200.csv"),
    ("EKF, CSV, 200 Hz, all columns (block by block)", [], "day200all.csv"),
]
#: the long-recording rows also run on a short synthesised recording (--growth-hours), for the peak RSS
#: growth per hour of recording
GROWTH_VARIANTS = ("EKF, CSV, 10 Hz (block by block)", "EKF, CSV, 200 Hz, nav columns (block by block)")
#: peak RSS growth per hour of recording below which the run's memory counts as bounded [MB/h] (the GNSS
#: fixes' times held, 8 bytes each: about 0.03 MB/h at 1 Hz, 0.3 MB/h at 10 Hz; their other columns are read
#: back from the plain GNSS file a block at a time; the summed IMU of the input checks fills its fixed-size
#: 3.7 MB buffer during the first 1.8 h: about 1.7 MB of a 24 h run's growth over 1 h; the stream fixes glibc's
#: mmap threshold, insnav._malloc: the per-block buffers freed no longer leave the heap growing with holes)
BOUNDED_MB_PER_H = 0.5
#: the speed targets against KF-GINS, CPU time of the whole command (label: minimum KF-GINS / insnav)
KFGINS_TARGETS = {"EKF, CSV, 200 Hz, all columns": 30.0, "EKF, npz, 200 Hz": 40.0}
TIMINGS = re.compile(r"timings \[s\]: read ([\d.]+), filter ([\d.]+), write ([\d.]+)")


def run_cli(work: Path, extra, out_name, yaml: str = "kf-gins-sim.yaml", keep: bool = True) -> dict:
    out = work / "out" / out_name
    if out.exists():
        shutil.rmtree(out) if out.is_dir() else out.unlink()
    args = [sys.executable, "-m", "insnav", "run", "--format", "kfgins", "--config", str(work / yaml),
            "--quiet", "--timings", "--out", str(out)]
    if "--filter" not in extra:
        args += ["--filter", "ekf"]
    err_path = work / "stderr.txt"
    with open(err_path, "wb") as err_f:
        t0 = time.perf_counter()
        p = subprocess.Popen(args + list(extra), stdout=subprocess.DEVNULL, stderr=err_f, cwd=work)
        _, status, ru = os.wait4(p.pid, 0)  # the child's own rusage (peak RSS); Popen does not reap it first
        wall = time.perf_counter() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    stderr = err_path.read_bytes()
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(args + list(extra))}: {stderr.decode()}")
    m = TIMINGS.search(stderr.decode())
    size = sum(f.stat().st_size for f in ([out] if out.is_file() else out.iterdir()) if f.is_file())
    if not keep:
        shutil.rmtree(out) if out.is_dir() else out.unlink()
    return dict(wall=wall, read=float(m[1]), filter=float(m[2]), write=float(m[3]), size=size, rss=ru,
                cpu=ru.ru_utime + ru.ru_stime)


#: what ``insnav run --format kfgins`` loads before it reads a line: the command line, its parser and the
#: modules of the block-by-block run (tests/test_cli_imports.py: the run loads none of the other commands)
STARTUP_CODE = ("import sys; from insnav.cli import build_parser; build_parser('run').parse_args(sys.argv[1:]); "
                "import insnav.io.kfgins_dataset, insnav.filters.stream, insnav.filters.loose, "
                "insnav.filters.health, insnav.filters.sanitize, insnav._progress, insnav._outputs; "
                "import os; os._exit(0)")  # as python -m insnav leaves: no finalization of every module


def startup_cpu(work: Path) -> dict:
    """CPU time [s] (user + system) of a fresh interpreter doing nothing, and of one loading what the
    command loads before its run (:data:`STARTUP_CODE`, numpy's OpenBLAS single-threaded as
    insnav.cli sets it)."""
    out = {}
    for key, code in (("python", "pass"), ("startup", STARTUP_CODE)):
        p = subprocess.Popen([sys.executable, "-c", code, "run", "--format", "kfgins", "--config",
                              str(work / "kf-gins-sim.yaml"), "--quiet", "--out", str(work / "out" / "x.csv")],
                             stdout=subprocess.DEVNULL, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"}, cwd=work)
        _, status, ru = os.wait4(p.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"start-up probe {key}: exit {os.waitstatus_to_exitcode(status)}")
        out[key] = ru.ru_utime + ru.ru_stime
    return out


def run_kfgins(binary: Path, work: Path) -> dict:
    """One KF-GINS run on the track's files in ``work`` (its own three output files, as it writes them)."""
    out = work / "out" / "kfgins_ref"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    t0 = time.perf_counter()
    p = subprocess.Popen([str(binary), "kfgins-ref.yaml"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         cwd=work)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{binary} kfgins-ref.yaml: exit {os.waitstatus_to_exitcode(status)}")
    size = sum(f.stat().st_size for f in out.iterdir())
    shutil.rmtree(out)
    return dict(wall=wall, cpu=ru.ru_utime + ru.ru_stime, rss=ru, size=size)


def api_child(work: Path) -> None:
    """One round of the filter-only figures, printed as JSON (run in its own
    process so that the benchmark's parent stays small: a child's peak RSS
    counts its parent's at fork)."""
    import json

    import insnav
    import insnav.filters.loose as loose
    from insnav.io.kfgins_dataset import load_kfgins

    t0 = time.perf_counter()
    ds, cfg = load_kfgins(work / "kf-gins-sim.yaml")
    out = {"read": time.perf_counter() - t0, "n_imu": len(ds.imu)}
    core_t, core_cpu, core_sys = [], [], []
    real = loose._core.run_loose

    def timed(*args, **kw):
        import resource

        r0 = resource.getrusage(resource.RUSAGE_SELF)
        c1, t1 = time.thread_time(), time.perf_counter()
        r = real(*args, **kw)
        core_t.append(time.perf_counter() - t1)
        core_cpu.append(time.thread_time() - c1)  # the loop runs on this thread (GIL released, no helper)
        core_sys.append(resource.getrusage(resource.RUSAGE_SELF).ru_stime - r0.ru_stime)
        return r

    loose._core = _Shim(real_module=loose._core, run_loose=timed)
    for f in ("ekf", "rbukf"):
        t0 = time.perf_counter()
        sol = insnav.run(ds, filter=f, config=cfg)
        out[f] = time.perf_counter() - t0
        out[f + "_core"] = core_t[-1]
        out[f + "_core_cpu"] = core_cpu[-1]
        out[f + "_core_sys"] = core_sys[-1]
        out["n_rows"] = len(sol)
        del sol
    print(json.dumps(out))


def write_day(work: Path, hours: float, gnss_hz: float = 1.0) -> tuple[int, float]:
    """A long KF-GINS-format recording under ``work`` (never in the repository):
    ``hours`` of a vehicle standing at the KF-GINS track's start point with its
    initial attitude, 200 Hz increments of gravity and the Earth rate plus the
    YAML's white noise (ARW, VRW), and GNSS fixes of that point at ``gnss_hz``
    (default 1 Hz) with the KF-GINS file's sigmas plus their noise.  The filter's cost per sample does
    not depend on the motion.  Written by a child process (its memory is not
    this one's, which the runs would inherit).  Returns (IMU samples, MB)."""
    code = r"""
import sys, numpy as np
from pathlib import Path
from insnav import _core
from insnav.io.kfgins import read_kfgins_config
from insnav.earth import gravity, omega_ie_n
from insnav.sim.trajectory import rotate_n_to_b
work, hours, gnss_hz = Path(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
c = read_kfgins_config(work / "kf-gins-sim.yaml")
lat, lon, h = c["initpos"]
att = np.asarray(c["initatt_rad"], float).reshape(1, 3)
f_b = rotate_n_to_b(att, np.array([[0.0, 0.0, -float(gravity(lat, h))]]))[0]  # specific force at rest
w_b = rotate_n_to_b(att, omega_ie_n(lat).reshape(1, 3))[0]
dt, t0 = 0.005, 456250.004412029
n = int(round(hours * 3600 / dt))
arw, vrw = c["imunoise"]["arw_rad_per_sqrts"], c["imunoise"]["vrw_mps_per_sqrts"]
rng = np.random.default_rng(1)
p = work / "day-imu.txt"
p.write_bytes(b"")
chunk = 1 << 20
for a in range(0, n, chunk):
    k = min(chunk, n - a)
    t = t0 + dt * np.arange(a, a + k)
    dth = w_b * dt + rng.standard_normal((k, 3)) * arw * np.sqrt(dt)
    dv = f_b * dt + rng.standard_normal((k, 3)) * vrw * np.sqrt(dt)
    cols = [t] + [np.ascontiguousarray(dth[:, j]) for j in range(3)] + [np.ascontiguousarray(dv[:, j]) for j in range(3)]
    _core.write_table(str(p), "", cols, [1.0] * 7, [9] + [12] * 6, sep=" ", trim_zeros=False, append=True)
m = int(round(hours * 3600 * gnss_hz))
sig = np.array([0.009, 0.009, 0.016])
gt = np.floor(t0) + 1.0 + np.arange(m) / gnss_hz
d = rng.standard_normal((m, 3)) * sig
R = 6378137.0
rows = np.column_stack([gt, (lat + d[:, 0] / R) * 180 / np.pi, (lon + d[:, 1] / (R * np.cos(lat))) * 180 / np.pi,
                        h - d[:, 2], np.tile(sig, (m, 1))])
np.savetxt(work / "day-gnss.txt", rows, fmt="%.3f %.10f %.10f %.4f %.3f %.3f %.3f")
print(n)
"""
    out = subprocess.run([sys.executable, "-c", code, str(work), str(hours), str(gnss_hz)], capture_output=True, text=True,
                         check=True)
    text = (work / "kf-gins-sim.yaml").read_text().splitlines()
    text = ['imupath: "./day-imu.txt"' if ln.startswith("imupath:") else
            'gnsspath: "./day-gnss.txt"' if ln.startswith("gnsspath:") else ln for ln in text]
    (work / "day.yaml").write_text("\n".join(text) + "\n")
    return int(out.stdout.strip().splitlines()[-1]), (work / "day-imu.txt").stat().st_size / 1e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "cli_end_to_end.md"))
    ap.add_argument("--no-compile", action="store_true",
                    help="do not compile the package's bytecode first (each run then compiles what it imports "
                         "when PYTHONDONTWRITEBYTECODE is set)")
    ap.add_argument("--day-hours", type=float, default=24.0,
                    help="length of the synthesised long recording of the bounded-memory rows [h] (0: none); "
                         "written under the temporary folder, deleted afterwards")
    ap.add_argument("--growth-hours", type=float, default=1.0,
                    help="length of the short synthesised recording whose peak RSS the day's is compared with "
                         "[h] (0: none)")
    ap.add_argument("--growth-repeat", type=int, default=3,
                    help="runs of each growth variant on the short and on the long recording (the median peak "
                         "RSS of each gives the growth per hour: one run's peak varies by a few MB; default "
                         "%(default)s)")
    ap.add_argument("--gnss-hz", type=float, default=1.0,
                    help="GNSS fix rate of the synthesised recordings [Hz] (default %(default)s)")
    ap.add_argument("--growth-only", action="store_true",
                    help="on the synthesised day, run the growth variants alone (not the other bounded-memory rows)")
    ap.add_argument("--kfgins", choices=("auto", "off"), default="auto",
                    help="time KF-GINS beside the variants (auto: build it with bench/_kfgins.py when missing)")
    ap.add_argument("--day-only", action="store_true",
                    help="run the bounded-memory rows alone (the synthesised recordings, no KF-GINS track rounds); "
                         "the document then holds that section only")
    ap.add_argument("--api-child", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.api_child:
        api_child(Path(a.api_child))
        return 0
    if not IMU_XZ.is_file():
        print(f"KF-GINS data not found at {SIM}", file=sys.stderr)
        return 1
    import json

    try:
        import pyarrow  # noqa: F401
        variants = VARIANTS
    except ImportError:
        variants = [v for v in VARIANTS if "Parquet" not in v[0]]
    if not a.no_compile:
        compile_package()
    work = Path(tempfile.mkdtemp(prefix="insnav-e2e-"))
    try:
        for f in ("GNSS-RTK-sim.txt", "kf-gins-sim.yaml"):
            shutil.copy(SIM / f, work / f)
        # in a child: the decompressor's buffers would raise this process's RSS, which its children inherit
        if not a.day_only:
            subprocess.run([sys.executable, "-c", "import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), "
                            "open(sys.argv[2], 'wb'), 1 << 22)", str(IMU_XZ), str(work / "Leador-A15-sim.txt")], check=True)
        (work / "out").mkdir()
        kfgins_bin = None if a.day_only else find_kfgins()
        if kfgins_bin is None and a.kfgins == "auto" and not a.day_only:
            try:  # clones KF-GINS at the pinned commit (needs the network) and builds it in Release
                kfgins_bin = build_kfgins()
            except (OSError, subprocess.CalledProcessError, SystemExit) as e:
                print(f"KF-GINS not built ({e}); the document states no ratio against it", file=sys.stderr)
        if a.kfgins == "off":
            kfgins_bin = None
        if kfgins_bin is not None:  # KF-GINS's own YAML with its outputs in a folder of ours
            text = [("outputpath: \"./out/kfgins_ref\"" if ln.startswith("outputpath:") else ln)
                    for ln in (work / "kf-gins-sim.yaml").read_text().splitlines()]
            (work / "kfgins-ref.yaml").write_text("\n".join(text) + "\n")
        kfg = []
        imu_mb = 0.0 if a.day_only else (work / "Leador-A15-sim.txt").stat().st_size / 1e6

        res = {v[0]: [] for v in variants}
        api = {"ekf": [], "rbukf": []}
        core = {"ekf": [], "rbukf": []}
        core_cpu = {"ekf": [], "rbukf": []}
        core_sys = {"ekf": [], "rbukf": []}
        read_t = []
        start = []
        load = [os.getloadavg()[0]]
        n_rows = n_imu = 0
        for r in range(0 if a.day_only else a.repeat):
            for label, extra, out_name in variants:
                res[label].append(run_cli(work, extra, out_name))
            if kfgins_bin is not None:
                kfg.append(run_kfgins(kfgins_bin, work))
            child = subprocess.run([sys.executable, __file__, "--api-child", str(work)], capture_output=True,
                                   text=True, check=True)
            j = json.loads(child.stdout.strip().splitlines()[-1])
            for f in ("ekf", "rbukf"):
                api[f].append(j[f])
                core[f].append(j[f + "_core"])
                core_cpu[f].append(j[f + "_core_cpu"])
                core_sys[f].append(j[f + "_core_sys"])
            read_t.append(j["read"])
            start.append(startup_cpu(work))
            n_rows, n_imu = j["n_rows"], j["n_imu"]
            load.append(os.getloadavg()[0])
            print(f"round {r + 1}/{a.repeat}: " + ", ".join(f"{res[v[0]][-1]['wall']:.2f}" for v in variants),
                  file=sys.stderr)
        day, short, day_rss = {}, {}, {}  # day_rss: the growth variants' peak RSS of each long run [MB]
        if a.day_hours > 0:
            (work / "Leador-A15-sim.txt").unlink(missing_ok=True)  # room for the day's file
            if 0 < a.growth_hours < a.day_hours:  # the same rows on a short recording: the growth per hour
                sw = work / "short"
                (sw / "out").mkdir(parents=True)
                for f in ("GNSS-RTK-sim.txt", "kf-gins-sim.yaml"):
                    shutil.copy(work / f, sw / f)
                write_day(sw, a.growth_hours, a.gnss_hz)
                for label, extra, out_name in [v for v in DAY_VARIANTS if v[0] in GROWTH_VARIANTS]:
                    short[label] = [run_cli(sw, extra, out_name, yaml="day.yaml", keep=False)
                                    for _ in range(max(1, a.growth_repeat))]
                shutil.rmtree(sw)
            day_n, day_mb = write_day(work, a.day_hours, a.gnss_hz)
            for label, extra, out_name in [v for v in DAY_VARIANTS if (variants is VARIANTS or "Parquet" not in v[0])
                                           and (not a.growth_only or v[0] in GROWTH_VARIANTS)]:
                day[label] = run_cli(work, extra, out_name, yaml="day.yaml", keep=False)
                load.append(os.getloadavg()[0])
                print(f"{a.day_hours:g} h: {label}: {day[label]['wall']:.1f} s, "
                      f"{day[label]['rss'].ru_maxrss / 1024:.0f} MB", file=sys.stderr)
            for label, extra, out_name in [v for v in DAY_VARIANTS if v[0] in short]:  # the growth's repeats
                day_rss[label] = [day[label]["rss"].ru_maxrss / 1024.0] + [
                    run_cli(work, extra, out_name, yaml="day.yaml", keep=False)["rss"].ru_maxrss / 1024.0
                    for _ in range(max(1, a.growth_repeat) - 1)]
    finally:
        shutil.rmtree(work, ignore_errors=True)

    if a.day_only:  # the bounded-memory section alone (not a results document: no stamp)
        lines = ["# End to end: the bounded-memory rows (--day-only)", "",
                 f"Generated by `bench/cli_end_to_end.py --day-only --day-hours {a.day_hours:g} --growth-hours "
                 f"{a.growth_hours:g}{f' --gnss-hz {a.gnss_hz:g}' if a.gnss_hz != 1 else ''}"
                 f"{' --growth-only' if a.growth_only else ''}` at commit {git_commit()}."]
        lines += day_section(a, day, short, day_rss, day_n, day_mb) if day else []
        Path(a.out).write_text("\n".join(lines) + "\n")
        print("\n".join(lines))
        return 0
    med = statistics.median
    imu_array_mb = n_imu * 7 * 8 / 1e6
    out_array_mb = n_rows * 31 * 8 / 1e6
    lines = [
        "# End to end: the insnav command line on the KF-GINS track",
        "",
        f"Generated by `bench/cli_end_to_end.py` at commit {git_commit()}.",
        f"Command: `cd insnav && python3 bench/cli_end_to_end.py --repeat {a.repeat}"
        f"{' --no-compile' if a.no_compile else ''}`",
        "",
        f"KF-GINS simulated track (../shared/data/kfgins/sim): {n_imu:,} IMU samples at 200 Hz "
        f"({imu_mb:.1f} MB of text, read uncompressed unless stated), 3,361 GNSS fixes, {n_rows:,} output rows at "
        "200 Hz.  Each line is a fresh `python -m insnav run --format kfgins --config kf-gins-sim.yaml --quiet "
        "--timings --out ...` process: wall time around the process (start, imports, read, filter, write), "
        "the stages from its `--timings` line, CPU time (user + system, all threads) and peak RSS from "
        "`os.wait4` of that child.  "
        + ("The package's bytecode is not compiled beforehand (--no-compile).  " if a.no_compile else
           "The package's bytecode is compiled beforehand (`compileall`, as pip does on install; this machine "
           "sets PYTHONDONTWRITEBYTECODE, without which each run compiles every module it imports).  ") +
        f"Median of {a.repeat} interleaved rounds; machine: {os.cpu_count()} cores shared with other sessions, "
        f"1-min load average {min(load):.1f} to {max(load):.1f} during the runs.",
        "",
        "| variant | wall [s] (min-max) | CPU [s] | read [s] | filter [s] | write [s] | peak RSS [MB] | output [MB] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, _, _ in variants:
        rs = res[label]
        w = [x["wall"] for x in rs]
        rss = max(x["rss"].ru_maxrss for x in rs) / 1024.0
        lines.append(f"| {label} | {med(w):.2f} ({min(w):.2f}-{max(w):.2f}) | {med(x['cpu'] for x in rs):.2f} | "
                     f"{med(x['read'] for x in rs):.3f} | "
                     f"{med(x['filter'] for x in rs):.3f} | {med(x['write'] for x in rs):.3f} | {rss:.0f} | "
                     f"{rs[-1]['size'] / 1e6:.1f} |")
    lines += day_section(a, day, short, day_rss, day_n, day_mb) if day else []
    lines += [
        "",
        "Filter only: in-process calls in a separate process per round, on the dataset already read:",
        "",
        "| what | EKF [s] | RB-UKF [s] |",
        "|---|---|---|",
        f"| `insnav.run` (sanitize, checks, C++ loop, output arrays) | {med(api['ekf']):.3f} | {med(api['rbukf']):.3f} |",
        f"| of which the C++ loop `_core.run_loose` | {med(core['ekf']):.3f} | {med(core['rbukf']):.3f} |",
        f"| its CPU time (the calling thread: user + system) | {med(core_cpu['ekf']):.3f} | "
        f"{med(core_cpu['rbukf']):.3f} |",
        f"| of which system time (the kernel zeroing the fresh pages of the whole run's output arrays) | "
        f"{med(core_sys['ekf']):.3f} | {med(core_sys['rbukf']):.3f} |",
        f"| reading the files in-process (`load_kfgins`) | {med(read_t):.3f} | |",
        "",
        f"Start-up: a fresh interpreter that loads what the command loads before it reads a line (insnav.cli, "
        f"the `run` parser and its arguments, numpy, the KF-GINS reader, the stream and the loose filter) takes "
        f"{med(x['startup'] for x in start):.3f} s CPU (median), of which the bare interpreter (`python -c pass`) "
        f"{med(x['python'] for x in start):.3f} s; of the CSV run's {med(x['cpu'] for x in res[variants[0][0]]):.2f} s "
        "CPU the rest is the run itself, whose reader and writer threads work beside the filter loop (so the CPU "
        "exceeds the sum of the wall stages).",
        "",
        "The block-by-block run's `filter` stage (the table above) is the same loop at the same cost per "
        "sample, without the whole run's output arrays: `_core.run_loose` allocates all rows at once (the first "
        "call in a process touches every page of them, which the kernel zeroes: the system time above), where "
        "the stream reuses two row buffers of one block; wall times include the machine's other load.",
        "",
        f"Array sizes: IMU {imu_array_mb:.0f} MB (t + 6 increments, float64), all output columns "
        f"{out_array_mb:.0f} MB; peak RSS budget of the issue = 2 x IMU + output = "
        f"{2 * imu_array_mb + out_array_mb:.0f} MB (the Python interpreter with numpy and the extension "
        f"alone is about {_baseline_rss_mb():.0f} MB).",
        "",
    ]
    lines += kfgins_section(kfg, res, variants, med)
    Path(a.out).write_text(with_stamp("\n".join(lines) + "\n", a.out))
    print("\n".join(lines))
    return 0


def day_section(a, day, short, day_rss, day_n, day_mb) -> list[str]:
    """The bounded-memory rows: the synthesised day's table and the peak RSS growth per hour (verdicts)."""
    lines = [
        "",
        f"Bounded memory: a synthesised {a.day_hours:g} h recording ({day_n:,} IMU samples at 200 Hz, "
        f"{day_mb:.0f} MB of KF-GINS text, {a.gnss_hz:g} Hz GNSS fixes; a vehicle standing at the track's start point: "
        "gravity, Earth rate and the YAML's white noise, `write_day` in this script), each run once (the "
        "growth rows below: their peak RSS the median of repeated runs), the IMU "
        "file read, filtered and written block by block (`--stream auto`, insnav.filters.stream).  What is "
        "held: a few blocks of IMU samples, rows and GNSS records, the IMU summed for the input checks (at most "
        "3.7 MB), and the GNSS fixes' times (8 bytes per fix: "
        f"{8 * a.day_hours * 3600 * a.gnss_hz / 1e6:.1f} MB here; held whole, 7 float64 per fix, they would be "
        f"{56 * a.day_hours * 3600 * a.gnss_hz / 1e6:.1f} MB): the fixes' other columns are read back from the "
        "plain GNSS file a block of lines at a time as the set-up, the filter and the input checks (the course "
        "checks too) take them, with no whole-record temporary.  On glibc the run fixes the allocator's mmap "
        "threshold at 128 KiB (insnav._malloc), so the buffers of a few MB freed at each block are unmapped "
        "rather than left as holes in a heap that grows with the recording:",
        "",
        "| variant | wall [s] | CPU [s] | read [s] | filter [s] | write [s] | peak RSS [MB] | output [MB] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label in day:
        x = day[label]
        lines.append(f"| {label} | {x['wall']:.1f} | {x['cpu']:.1f} | {x['read']:.2f} | {x['filter']:.2f} | "
                     f"{x['write']:.2f} | {x['rss'].ru_maxrss / 1024.0:.0f} | {x['size'] / 1e6:.0f} |")
    if short:
        lines.append("")
    for label, runs in short.items():
        rss1 = [x["rss"].ru_maxrss / 1024.0 for x in runs]
        rss2 = day_rss.get(label, [day[label]["rss"].ru_maxrss / 1024.0])
        r1, r2 = statistics.median(rss1), statistics.median(rss2)
        per_h = (r2 - r1) / (a.day_hours - a.growth_hours)
        verdict = ("**bounded**" if per_h < BOUNDED_MB_PER_H else
                   f"**grows with the recording** (bounded: below {BOUNDED_MB_PER_H:g} MB per hour)")
        each = (f" (medians of {len(rss1)} and {len(rss2)} runs: "
                f"{', '.join(f'{x:.0f}' for x in rss1)} / {', '.join(f'{x:.0f}' for x in rss2)} MB)"
                if len(rss1) > 1 or len(rss2) > 1 else "")
        lines.append(f"- {label}: peak RSS {r1:.0f} MB at {a.growth_hours:g} h, {r2:.0f} MB at "
                     f"{a.day_hours:g} h{each}: {per_h:+.2f} MB per hour of recording, {verdict}.")
    return lines


def kfgins_section(kfg, res, variants, med) -> list[str]:
    """KF-GINS beside the variants: its own figures, then KF-GINS CPU / insnav CPU per variant."""
    if not kfg:
        return ["", "KF-GINS side by side: **not measured** (no KF-GINS build; `python bench/_kfgins.py` builds it, "
                "or set INSNAV_KFGINS_BIN), so no speed ratio against it is stated."]
    k_cpu = med(x["cpu"] for x in kfg)
    k_wall = med(x["wall"] for x in kfg)
    lines = [
        "",
        "## Side by side with KF-GINS",
        "",
        f"KF-GINS (i2Nav-WHU, commit `{built_commit()[:7]}`, built on this machine in Release by "
        "`python bench/_kfgins.py`: its own CMake project, -O3 -DNDEBUG) on the same files in every round, "
        "writing its three output files (KF_GINS_Navresult.nav, KF_GINS_IMU_ERR.txt, KF_GINS_STD.txt at 200 Hz):",
        "",
        "| program | wall [s] (min-max) | CPU [s] | peak RSS [MB] | output [MB] |",
        "|---|---|---|---|---|",
        f"| KF-GINS | {k_wall:.2f} ({min(x['wall'] for x in kfg):.2f}-{max(x['wall'] for x in kfg):.2f}) | "
        f"{k_cpu:.2f} | {max(x['rss'].ru_maxrss for x in kfg) / 1024.0:.0f} | {kfg[-1]['size'] / 1e6:.1f} |",
        "",
        "KF-GINS / insnav, medians over the rounds (how many times less time insnav takes); the targets "
        "are in CPU time:",
        "",
        "| insnav variant | CPU ratio | wall ratio | target (CPU) |",
        "|---|---|---|---|",
    ]
    for label, _, _ in variants:
        rs = res[label]
        r_cpu = k_cpu / med(x["cpu"] for x in rs)
        r_wall = k_wall / med(x["wall"] for x in rs)
        t = KFGINS_TARGETS.get(label)
        verdict = "-" if t is None else f">= {t:.0f}x: {'met' if r_cpu >= t else '**not met**'}"
        lines.append(f"| {label} | {r_cpu:.1f}x | {r_wall:.1f}x | {verdict} |")
    return lines


class _Shim:
    """The compiled module with one function replaced (timing wrapper)."""

    def __init__(self, real_module, **over):
        self._real = real_module
        self.__dict__.update(over)

    def __getattr__(self, name):
        return getattr(self._real, name)


def _baseline_rss_mb() -> float:
    code = "import resource, numpy, insnav._core, insnav.cli; print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip()
    return float(out) / 1024.0 if out else float("nan")


if __name__ == "__main__":
    sys.exit(main())
