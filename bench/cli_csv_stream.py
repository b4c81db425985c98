"""``insnav run --format csv`` block by block against the IMU file read whole,
for every output: CSV, npz, Parquet and the KF-GINS layout, at 200 Hz and 10 Hz.

The KF-GINS simulated track's IMU file (56 min at 200 Hz, GPS seconds of week,
rad and m/s increments, FRD, one space between fields) is read as a generic
IMU CSV (``[imu] delimiter = " "``, ``samples = "increments"``) with its GNSS
file and its YAML's initial state, lever arm and IMU noise in a run TOML;
the same run on the track's first quarter shows what grows with the length.
Each variant is a fresh ``python -m insnav run --format csv ... --quiet
--timings`` process; its CPU time (user + system, all threads) and peak RSS
come from ``os.wait4`` (the child's own rusage; this process never holds a
file whole, since a child's peak RSS starts from its parent's).  Median CPU and wall over
``--repeat`` rounds, the largest peak RSS; the streamed and whole-file
solution files are compared: CSV, Parquet and the KF-GINS files byte for
byte, the npz's arrays bit for bit (its zip headers hold the time of writing).
``--day-hours H``: then, once each, the runs on a synthesised recording of H
hours (``cli_end_to_end.write_day``: a vehicle standing at the track's start
point, 200 Hz, written under the temporary folder) read as the same generic
CSV, every output at both rates, with ``--stream on`` (``--day-stream auto``:
whatever path the installed insnav takes, e.g. an older one that writes
Parquet and the KF-GINS layout whole).  ``--only TEXT`` (repeatable) runs the variants whose
label contains one of the texts; ``--no-track`` skips the KF-GINS track.  Prints the figures (no document).

    python bench/cli_csv_stream.py [--repeat 3] [--day-hours 24] [--only Parquet --only KF-GINS] [--no-track]
"""
from __future__ import annotations

import argparse
import itertools
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
SIM = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data")) / "kfgins" / "sim"
IMU_XZ = SIM / "Leador-A15-sim.txt.xz"
WEEK = 2000  # any week: the files hold seconds of week

#: (output label, --out name, extra arguments)
OUTPUTS = [("CSV", "sol.csv", []), ("npz", "sol.npz", []), ("Parquet", "sol.parquet", []),
           ("KF-GINS layout", "kf", ["--out-format", "kfgins"])]
RATES = [("200 Hz", []), ("10 Hz", ["--output-rate", "10"])]
MODES = [("block by block", ["--stream", "on"]), ("IMU read whole (--stream off)", ["--stream", "off"])]
#: (label, output, rate, mode, --out name, extra arguments)
VARIANTS = [(f"EKF, {o}, {r}, {m}", o, r, m, name, [*xo, *xr, *xm])
            for (o, name, xo), (r, xr), (m, xm) in itertools.product(OUTPUTS, RATES, MODES)]


def run_toml(yaml_path: Path) -> str:
    """The run TOML of the track: its YAML's initial state at the first sample at or after starttime,
    lever arm and IMU noise (KF-GINS units -> insnav's), the two files' mapping."""
    raw = {ln.split(":")[0].strip(): ln.split(":", 1)[1] for ln in yaml_path.read_text().splitlines()
           if ":" in ln and not ln.lstrip().startswith("#")}

    def vec(key):
        return [float(x) for x in raw[key].split("#")[0].strip().strip("[]").split(",")]

    pos, vel, att = vec("initpos"), vec("initvel"), vec("initatt")
    tau_s = float(raw["corrtime"].split("#")[0]) * 3600.0
    return "\n".join([
        f"lever_arm_b = {vec('antlever')}",
        "[imu]",
        'columns = ["t", "gx", "gy", "gz", "ax", "ay", "az"]',
        'delimiter = " "',
        'time = "gps_sow"',
        f"gps_week = {WEEK}",
        'samples = "increments"',
        f"gyro_arw_deg_per_sqrt_h = {vec('arw')[0]}",
        f"acc_vrw_m_per_s_per_sqrt_h = {vec('vrw')[0]}",
        f"gyro_bias_sigma_deg_per_h = {vec('gbstd')[0]}",
        f"acc_bias_sigma_mg = {vec('abstd')[0] * 1e-5 / 9.80665e-3}",  # mGal -> mg
        f"gyro_bias_tau_s = {tau_s}",
        f"acc_bias_tau_s = {tau_s}",
        "[gnss]",
        'columns = ["t", "lat", "lon", "h", "sigma_n", "sigma_e", "sigma_d"]',
        'delimiter = " "',
        'time = "gps_sow"',
        f"gps_week = {WEEK}",
        'angle_unit = "deg"',
        "[initial]",
        f"t_s = {float(raw['starttime'].split('#')[0])}",
        f"lat_deg = {pos[0]}", f"lon_deg = {pos[1]}", f"h_m = {pos[2]}",
        f"v_n_mps = {vel}",
        f"roll_deg = {att[0]}", f"pitch_deg = {att[1]}", f"yaw_deg = {att[2]}",
        "",
    ])


def run_cli(work: Path, imu: str, extra, out: Path) -> dict:
    args = [sys.executable, "-m", "insnav", "run", "--format", "csv", "--imu", str(work / imu), "--gnss",
            str(work / "GNSS-RTK-sim.txt"), "--config", str(work / "run.toml"), "--out", str(out), "--quiet",
            "--timings", *extra]
    err_path = work / "stderr.txt"
    with open(err_path, "wb") as err_f:
        t0 = time.perf_counter()
        p = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=err_f, cwd=work)
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t0
    err = err_path.read_text()
    if os.waitstatus_to_exitcode(status) != 0 or "note:" in err:
        raise RuntimeError(f"{' '.join(args)}: {err}")
    files = list(out.iterdir()) if out.is_dir() else [out]
    mb = sum(f.stat().st_size for f in files if not f.name.endswith((".csv", ".toml")) or f == out) / 1e6
    return dict(wall=wall, cpu=ru.ru_utime + ru.ru_stime, rss_mb=ru.ru_maxrss / 1024.0, out_mb=mb)


def same_output(a: Path, b: Path) -> bool:
    """The streamed and the whole-file run wrote the same solution: the same bytes (CSV, Parquet, the
    KF-GINS files), the same npz arrays bit for bit.  Compared in a child process: what it reads
    would otherwise stay in this process's memory, where every later child's peak RSS starts."""
    p = subprocess.run([sys.executable, __file__, "--compare", str(a), str(b)], capture_output=True, text=True)
    if p.returncode not in (0, 1):
        raise RuntimeError(p.stderr)
    return p.returncode == 0


def _same(a: Path, b: Path) -> bool:
    if a.suffix == ".npz":
        import numpy as np

        with np.load(a) as za, np.load(b) as zb:
            return za.files == zb.files and all(za[k].dtype == zb[k].dtype and za[k].tobytes() == zb[k].tobytes()
                                                for k in za.files)
    if a.is_dir():
        names = sorted(f.name for f in a.iterdir())
        return names == sorted(f.name for f in b.iterdir()) and all(_same(a / n, b / n) for n in names)
    with open(a, "rb") as fa, open(b, "rb") as fb:  # a block at a time
        while True:
            x, y = fa.read(1 << 22), fb.read(1 << 22)
            if x != y:
                return False
            if not x:
                return True


def remove(out: Path) -> None:
    if out.is_dir():
        shutil.rmtree(out)
    else:
        for f in out.parent.glob(out.name + "*"):
            f.unlink()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--day-hours", type=float, default=0.0,
                    help="length of a synthesised recording run block by block afterwards [h] (0: none)")
    ap.add_argument("--day-stream", choices=("on", "auto"), default="on",
                    help="--stream of the day's runs (auto: measure whatever path the installed insnav takes)")
    ap.add_argument("--only", action="append", default=[],
                    help="run only the variants whose label contains this text (repeatable)")
    ap.add_argument("--no-track", action="store_true", help="skip the KF-GINS track (only the day)")
    ap.add_argument("--compare", nargs=2, type=Path, help=argparse.SUPPRESS)  # same_output's child
    a = ap.parse_args(argv)
    if a.compare:
        return 0 if _same(*a.compare) else 1
    variants = [v for v in VARIANTS if not a.only or any(w in v[0] for w in a.only)]
    if not IMU_XZ.is_file():
        print(f"KF-GINS data not found at {SIM}", file=sys.stderr)
        return 1
    work = Path(tempfile.mkdtemp(prefix="insnav-csvstream-"))
    res = {}
    load = [os.getloadavg()[0]]
    try:
        shutil.copy(SIM / "GNSS-RTK-sim.txt", work / "GNSS-RTK-sim.txt")
        (work / "run.toml").write_text(run_toml(SIM / "kf-gins-sim.yaml"))
        (work / "out").mkdir()
        if not a.no_track:
            subprocess.run([sys.executable, "-c", "import lzma, shutil, sys; shutil.copyfileobj(lzma.open("
                            "sys.argv[1]), open(sys.argv[2], 'wb'), 1 << 22)", str(IMU_XZ), str(work / "imu.txt")],
                           check=True)
            # line by line, never the whole file: this process's peak RSS is its children's starting point
            with open(work / "imu.txt", "rb") as f:
                n_lines = sum(1 for _ in f)
            with open(work / "imu.txt", "rb") as f, open(work / "imu_quarter.txt", "wb") as g:
                g.writelines(itertools.islice(f, n_lines // 4))
            for imu, share in (("imu_quarter.txt", 0.25), ("imu.txt", 1.0)):
                minutes = n_lines * share / 200.0 / 60.0
                for r in range(a.repeat):
                    for label, o, rate, mode, name, extra in variants:
                        out = work / "out" / f"{o}-{rate}-{mode[:5]}" / name
                        out.parent.mkdir(exist_ok=True)
                        if r:
                            remove(out)
                        res.setdefault((minutes, label), []).append(run_cli(work, imu, extra, out))
                    load.append(os.getloadavg()[0])
                pairs = {(o, rate, name) for _, o, rate, _, name, _ in variants}
                for o, rate, name in sorted(pairs):  # the streamed solution is the whole-file run's
                    on, off = (work / "out" / f"{o}-{rate}-{m[:5]}" / name for m, _ in MODES)
                    if on.exists() and off.exists():
                        same = same_output(on, off)
                        print(f"{minutes:.0f} min, {o}, {rate}: streamed == whole-file run's: {same}")
                        if not same:
                            return 1
                shutil.rmtree(work / "out")
                (work / "out").mkdir()
            for f in ("imu.txt", "imu_quarter.txt"):
                (work / f).unlink()
        if a.day_hours > 0:
            from cli_end_to_end import write_day

            shutil.copy(SIM / "kf-gins-sim.yaml", work / "kf-gins-sim.yaml")
            write_day(work, a.day_hours)
            shutil.copy(work / "day-gnss.txt", work / "GNSS-RTK-sim.txt")
            minutes = a.day_hours * 60.0
            for label, o, rate, mode, name, extra in variants:
                if mode != MODES[0][0]:  # block by block only (read whole: about 650 MB an hour)
                    continue
                out = work / "out" / name
                extra = [x if x != "on" else a.day_stream for x in extra]
                tag = " (synthesised, once)" if a.day_stream == "on" else " (synthesised, once, --stream auto)"
                key = (minutes, label.replace(", block by block", "") + tag)
                res[key] = [run_cli(work, "day-imu.txt", extra, out)]
                remove(out)
                load.append(os.getloadavg()[0])
                print(f"{a.day_hours:g} h: {key[1]}: {res[key][0]}", file=sys.stderr)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    med = statistics.median
    print(f"load average during the runs: {min(load):.2f} .. {max(load):.2f} (2 cores shared)")
    print("| IMU record | variant | CPU [s] (median) | wall [s] (median) | peak RSS [MB] (max) | output [MB] |")
    print("|---|---|---:|---:|---:|---:|")
    for (minutes, label), rs in res.items():
        print(f"| {minutes:.0f} min at 200 Hz | {label} | {med(x['cpu'] for x in rs):.2f} | "
              f"{med(x['wall'] for x in rs):.2f} | {max(x['rss_mb'] for x in rs):.0f} | {rs[-1]['out_mb']:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
