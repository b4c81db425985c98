"""Simulator benchmark: 1 h at 200 Hz with IMU errors and 1 Hz raw GNSS (target <= 2 s).

Run: ``cd insnav && python3 bench/bench_sim.py [--repeats 5]`` (prints the
median of the runs, by wall clock and by process CPU time, and the load average: the
machine may be shared).
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

import insnav.sim as sim

SCENARIO = {
    "name": "bench-1h-200Hz",
    "seed": 7,
    "initial": {"lat_deg": 34.2, "lon_deg": 108.7, "h_m": 100.0, "speed_mps": 20.0,
                "heading_deg": 35.0},
    "motion": {"transition_s": 2.0, "coordinated_turns": True, "segments": [
        {"duration_s": 300.0},
        {"duration_s": 60.0, "heading_change_deg": 90.0},
        {"duration_s": 600.0, "pitch_amp_deg": 3.0, "pitch_period_s": 20.0},
        {"duration_s": 60.0, "target_speed_mps": 30.0, "target_path_angle_deg": 3.0},
        {"duration_s": 600.0},
        {"duration_s": 60.0, "target_path_angle_deg": 0.0, "heading_change_deg": -120.0},
        {"duration_s": 1200.0, "roll_amp_deg": 5.0, "roll_period_s": 15.0},
        {"duration_s": 120.0, "heading_change_deg": 180.0},
        {"duration_s": 600.0},
    ]},
    "imu": {"rate_hz": 200.0,
            "gyro": {"bias_sigma_dph": 10.0, "gm_sigma_dph": 1.0, "gm_tau_s": 300.0,
                     "arw_deg_per_sqrth": 0.2, "scale_sigma_ppm": 500.0,
                     "misalignment_sigma_mrad": 0.5},
            "accel": {"bias_sigma_mg": 2.0, "gm_sigma_mg": 0.2, "gm_tau_s": 300.0,
                      "vrw_mps_per_sqrth": 0.1, "scale_sigma_ppm": 500.0}},
    "truth": {"rate_hz": 10.0},
    "gnss": {"rate_hz": 1.0, "lever_arm_b_m": [0.5, 0.1, -0.8]},
    "gnss_raw": {"enabled": True, "rate_hz": 1.0, "sigma_pr_m": 3.0, "sigma_prr_mps": 0.05,
                 "clock_bias0_m": 100.0, "clock_drift0_mps": 0.1,
                 "clock_drift_rw_mps_per_sqrts": 0.01},
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    load0 = os.getloadavg()
    times, cpu = [], []
    for _ in range(a.repeats):
        t, c = time.perf_counter(), time.process_time()
        ds = sim.simulate(SCENARIO)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    load1 = os.getloadavg()
    print(f"command: cd insnav && python3 bench/bench_sim.py --repeats {a.repeats}")
    print(f"simulate 1 h @ 200 Hz ({len(ds.imu)} IMU samples) + IMU errors + 1 Hz raw GNSS "
          f"({len(ds.gnss_raw)} observations) + truth @ 10 Hz")
    print(f"wall [s]: {', '.join(f'{x:.3f}' for x in times)}; median {np.median(times):.3f} s (target <= 2 s)")
    print(f"process CPU [s]: {', '.join(f'{x:.3f}' for x in cpu)}; median {np.median(cpu):.3f} s")
    print(f"load average (1 min) before/after: {load0[0]:.2f}/{load1[0]:.2f} on {os.cpu_count()} cores")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
