"""The IMU/GNSS time-offset estimate (insnav.data.checks.estimate_time_offset) on the shared
real data and the car presets: the lag as loaded, with 1 s and 18 s GNSS shifts, and its cost.

    PYTHONPATH=python python3 bench/time_offset_lags.py [--data ../shared/data]

Prints one line per dataset (no results document: the figures are quoted in docs/algorithms.md
section 14 and asserted in tests/test_time_offset.py where the data load fast)."""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def datasets(data: Path):
    import insnav.sim as sim
    from insnav.io.csv_dataset import load_csv_run
    from insnav.io.kfgins_dataset import load_kfgins
    from insnav.io.rinex_dataset import load_rinex_run

    w = data / "rtklibexplorer_walk_0827"
    yield "walk loose (RTK .pos)", load_csv_run(w / "raw/imu_1730.csv", w / "raw/gnss_1730_sf.pos",
                                                REPO / "tests/data/walk_0827_loose.toml")[0]
    yield "walk tight (SPP, Doppler)", load_rinex_run(w / "rinex_derived/gnss_1730.obs", w / "rinex_derived/gnss_1730.nav",
                                                      w / "raw/imu_1730.csv", REPO / "tests/data/walk_0827.toml")[0]
    k = data / "kfgins/sim"
    yield "KF-GINS sim track (positions only)", load_kfgins(k / "kf-gins-sim.yaml", k / "Leador-A15-sim.txt.xz",
                                                            k / "GNSS-RTK-sim.txt")[0]
    for name in ("car-mems", "urban-multignss", "seed003-4sat"):
        yield name, sim.simulate(name, seed=0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    args = ap.parse_args()
    from insnav._imu_scan import scan_memo
    from insnav.data.checks import estimate_time_offset

    for name, ds in datasets(Path(args.data)):
        imu = ds.imu
        out = []
        for shift in (0.0, 1.0, 18.0):
            g = dataclasses.replace(ds.gnss, t_valid=ds.gnss.t_valid + shift, t_arrival=ds.gnss.t_arrival + shift)
            e = estimate_time_offset(imu.t, imu.dtheta_b, imu.dv_b, g)
            out.append("none" if e is None else f"{e.lag_s:+.3f} s (r {e.r_peak:.3f}, unshifted {e.r_zero:.3f})")
        cost = []
        for _ in range(7):
            with scan_memo():
                t0 = time.perf_counter()
                estimate_time_offset(imu.t, imu.dtheta_b, imu.dv_b, ds.gnss)
                cost.append(time.perf_counter() - t0)
        print(f"{name}: lag {out[0]}; GNSS +1 s: {out[1]}; GNSS +18 s: {out[2]}; cost min "
              f"{1000 * min(cost):.1f} ms (with the IMU scan), median {1000 * np.median(cost):.1f} ms", flush=True)


if __name__ == "__main__":
    main()
