"""``insnav run --format csv`` block by block against the IMU file read whole.

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
solution files are compared byte for byte.  ``--day-hours H``: then, once
each, the streamed runs on a synthesised recording of H hours
(``cli_end_to_end.write_day``: a vehicle standing at the track's start point,
200 Hz, written under the temporary folder) read as the same generic CSV.
Prints the figures (no document).

    python bench/cli_csv_stream.py [--repeat 3] [--day-hours 4]
"""
from __future__ import annotations

import argparse
import filecmp
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

#: (label, extra arguments)
VARIANTS = [
    ("EKF, CSV, 200 Hz, block by block", ["--stream", "on"]),
    ("EKF, CSV, 200 Hz, IMU read whole (--stream off)", ["--stream", "off"]),
    ("EKF, CSV, 10 Hz, block by block", ["--stream", "on", "--output-rate", "10"]),
    ("EKF, CSV, 10 Hz, IMU read whole (--stream off)", ["--stream", "off", "--output-rate", "10"]),
]


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
    return dict(wall=wall, cpu=ru.ru_utime + ru.ru_stime, rss_mb=ru.ru_maxrss / 1024.0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--day-hours", type=float, default=0.0,
                    help="length of a synthesised recording run block by block afterwards [h] (0: none)")
    a = ap.parse_args(argv)
    if not IMU_XZ.is_file():
        print(f"KF-GINS data not found at {SIM}", file=sys.stderr)
        return 1
    work = Path(tempfile.mkdtemp(prefix="insnav-csvstream-"))
    try:
        shutil.copy(SIM / "GNSS-RTK-sim.txt", work / "GNSS-RTK-sim.txt")
        (work / "run.toml").write_text(run_toml(SIM / "kf-gins-sim.yaml"))
        subprocess.run([sys.executable, "-c", "import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), "
                        "open(sys.argv[2], 'wb'), 1 << 22)", str(IMU_XZ), str(work / "imu.txt")], check=True)
        # line by line, never the whole file: this process's peak RSS is its children's starting point
        with open(work / "imu.txt", "rb") as f:
            n_lines = sum(1 for _ in f)
        with open(work / "imu.txt", "rb") as f, open(work / "imu_quarter.txt", "wb") as g:
            g.writelines(itertools.islice(f, n_lines // 4))
        (work / "out").mkdir()
        res = {}
        load = [os.getloadavg()[0]]
        for imu, share in (("imu_quarter.txt", 0.25), ("imu.txt", 1.0)):
            minutes = n_lines * share / 200.0 / 60.0
            for r in range(a.repeat):
                for label, extra in VARIANTS:
                    out = work / "out" / f"{label.split(',')[2].strip()}-{'on' if 'on' in extra else 'off'}.csv"
                    res.setdefault((minutes, label), []).append(run_cli(work, imu, extra, out))
                load.append(os.getloadavg()[0])
            for rate in ("200 Hz", "10 Hz"):  # the streamed file is the whole-file run's, byte for byte
                same = filecmp.cmp(work / "out" / f"{rate}-on.csv", work / "out" / f"{rate}-off.csv", shallow=False)
                print(f"{minutes:.0f} min, {rate}: streamed file == whole-file run's: {same}")
                if not same:
                    return 1
        if a.day_hours > 0:
            from cli_end_to_end import write_day

            for f in ("imu.txt", "imu_quarter.txt"):
                (work / f).unlink()
            shutil.copy(SIM / "kf-gins-sim.yaml", work / "kf-gins-sim.yaml")
            write_day(work, a.day_hours)
            shutil.copy(work / "day-gnss.txt", work / "GNSS-RTK-sim.txt")
            minutes = a.day_hours * 60.0
            for label, extra in VARIANTS[::2]:  # block by block only (read whole: about 650 MB an hour)
                out = work / "out" / "day.csv"
                res[(minutes, label + " (synthesised, once)")] = [run_cli(work, "day-imu.txt", extra, out)]
                out.unlink()
                load.append(os.getloadavg()[0])
    finally:
        shutil.rmtree(work, ignore_errors=True)
    med = statistics.median
    print(f"load average during the runs: {min(load):.2f} .. {max(load):.2f} (2 cores shared)")
    print("| IMU record | variant | CPU [s] (median) | wall [s] (median) | peak RSS [MB] (max) |")
    print("|---|---|---:|---:|---:|")
    for (minutes, label), rs in res.items():
        print(f"| {minutes:.0f} min at 200 Hz | {label} | {med(x['cpu'] for x in rs):.2f} | "
              f"{med(x['wall'] for x in rs):.2f} | {max(x['rss_mb'] for x in rs):.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
